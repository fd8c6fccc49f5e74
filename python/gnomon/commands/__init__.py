"""One module per `gnomon` sub-command.

Each module defines ``register(subparsers)``, which adds its parser and sets
``func`` to a callable ``run(args) -> int``. The CLI imports them in order.
"""

COMMANDS = ("demo", "simulate", "calibrate", "init", "regions", "preview", "sun", "scan", "live", "merge", "batch",
            "review", "bench")
