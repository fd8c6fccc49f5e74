import signal
import sys

_interrupted: list[int] = []


def _on_sigint(signum: int, frame: object) -> None:
    _interrupted.append(signum)
    raise KeyboardInterrupt


try:
    signal.signal(signal.SIGINT, _on_sigint)  # gnomon.cli.main installs its own
except ValueError:  # not the main thread
    pass
try:
    from gnomon.cli import main
except KeyboardInterrupt:  # Ctrl-C while Python is still importing
    sys.stderr.write("gnomon: interrupted\n")
    sys.exit(130)
except ImportError:
    if not _interrupted:  # numpy turns a Ctrl-C during its import into an ImportError
        raise
    sys.stderr.write("gnomon: interrupted\n")
    sys.exit(130)
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.exit(main())
