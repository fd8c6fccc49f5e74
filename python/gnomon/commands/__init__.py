"""One module per `gnomon` sub-command.

Each module defines ``register(subparsers)``, which adds its parser (with the help line
:data:`COMMANDS` gives it) and sets ``func`` to a callable ``run(args) -> int``. The CLI
imports a command's module only when that command runs (see :func:`gnomon.cli.build_parser`):
``gnomon --help`` and ``gnomon --version`` list the commands from :data:`COMMANDS` alone.
"""

#: Each sub-command and its one-line help, in the order ``gnomon --help`` lists them.
COMMANDS: dict[str, str] = {
    "demo": "simulate synthetic captures, scan them, and report accuracy",
    "simulate": "write a synthetic capture + field log + ground truth",
    "calibrate": "calibrate the camera (chessboard photos) or the lamp (pencil photos)",
    "init": "write a commented field-log template for a capture",
    "regions": "propose each reference plane's bare, swept regions from a first pass",
    "preview": "a picture of what a field log assumes (regions, markers, grids), before scanning",
    "sun": "the sun's direction at a site and time (NREL SPA)",
    "scan": "reconstruct 3D from a field log",
    "live": "scan while the shadow moves: live view, then the scan's outputs",
    "merge": "fuse two scans of one scene (e.g. lamp left and right)",
    "fuse": "several scans of one object or building, from several places, made into one model",
    "batch": "run many scans (and merges of scan pairs) on a Dask cluster",
    "review": "summarise, export, compare recordings",
    "bench": "kernel throughput vs the numpy reference",
}
