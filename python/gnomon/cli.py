"""The `gnomon` command line.

User errors (:class:`gnomon.errors.GnomonError`) print one line on stderr,
``gnomon: error: ...``, and exit with code 2. So do bad arguments (argparse)
and failures of the filesystem an output is written to (no space, a file-size
limit, a read-only filesystem, no permission): they name the path.

SIGTERM and SIGHUP (``timeout``, a closed SSH session) stop a run like Ctrl-C:
the run's staging folder is removed, nothing is published, and the exit code
is 128 + the signal's number. A closed pipe on stdout (``gnomon sun | head -1``)
ends the run quietly. Writes past a file-size limit (``ulimit -f``) fail with
EFBIG instead of killing the process (SIGXFSZ is ignored).
"""

from __future__ import annotations

import argparse
import atexit
import ctypes
import errno
import gc
import importlib
import os
import signal
import sys
from collections.abc import Sequence

from gnomon import __version__, _kernel
from gnomon.commands import COMMANDS
from gnomon.errors import GnomonError
from gnomon.util import interrupts

#: ``OSError`` numbers that describe the environment (disk, permissions, limits), not a bug.
ENVIRONMENT_ERRNOS = frozenset(
    getattr(errno, name) for name in (
        "ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EACCES", "EPERM", "ENOENT", "ENOTDIR", "EISDIR", "EXDEV",
        "EIO", "ENAMETOOLONG", "ELOOP", "EMFILE", "ENFILE", "ENOMEM", "ETXTBSY", "EBUSY", "ENOTEMPTY",
        "EEXIST", "ESTALE",
    ) if hasattr(errno, name)
)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, delivered as an interrupt so every cleanup runs."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_terminated(signum: int, frame) -> None:
    if interrupts.postpone(signum, frame):  # inside a held block, or inside importlib: later
        return
    raise Terminated(signum)


_interrupted = False  # a SIGINT arrived during this run (numpy may turn it into an ImportError)


def _raise_interrupted(signum: int, frame) -> None:
    global _interrupted
    _interrupted = True
    if interrupts.postpone(signum, frame):
        return
    raise KeyboardInterrupt


def version_text() -> str:
    """``gnomon X.Y.Z (kernel X.Y.Z, SIMD avx2)``: the version and the instruction set
    the kernel's hot loops run on here (chosen at run time; see ``gnomon bench``)."""
    return f"gnomon {__version__} (kernel {_kernel.__version__}, SIMD {_kernel.simd_path()})"


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``gnomon`` parser. With ``argv``, only the command it names is imported and built in
    full; the others are listed by name and help line (:data:`gnomon.commands.COMMANDS`), which is
    all ``gnomon --help``, ``--version`` or a misspelt command needs, so none of them loads a
    command's modules (numpy, OpenCV, pandas ...). Without ``argv``, every command is built."""
    parser = argparse.ArgumentParser(
        prog="gnomon",
        description="Shadow-sweep 3D scanning with a desk lamp or the sun.",
    )
    parser.add_argument("--version", action="version", version=version_text())
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    chosen = None if argv is None else _command_named(argv)
    for name, help_line in COMMANDS.items():
        if argv is None or name == chosen:
            module = importlib.import_module(f"gnomon.commands.{name}")
            module.register(subparsers)
        else:
            subparsers.add_parser(name, help=help_line)
    return parser


def _command_named(argv: Sequence[str]) -> str | None:
    """The sub-command ``argv`` runs: its first argument that is not an option (the top-level
    options, --help and --version, take no value), or None."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in COMMANDS else None


def _install_signal_handlers() -> dict:
    """SIGTERM/SIGHUP → :class:`Terminated`; SIGXFSZ ignored. Returns the previous handlers."""
    previous: dict = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGHUP):
            previous[sig] = signal.signal(sig, _raise_terminated)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupted)
        if hasattr(signal, "SIGXFSZ"):
            previous[signal.SIGXFSZ] = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    except ValueError:  # not the main thread (an embedding application): leave signals alone
        pass
    return previous


def _restore_signal_handlers(previous: dict) -> None:
    for sig, handler in previous.items():
        try:
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        except (ValueError, TypeError):
            pass


def _stdout_closed() -> None:
    """stdout's reader went away: point stdout at /dev/null so the final flush cannot fail too."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def _caused_by_interrupt(exc: BaseException) -> bool:
    seen = 0
    e: BaseException | None = exc
    while e is not None and seen < 20:
        if isinstance(e, KeyboardInterrupt):
            return True
        e = e.__cause__ or e.__context__
        seen += 1
    return False


def _os_error_line(exc: OSError) -> str:
    where = exc.filename if exc.filename is not None else "?"
    extra = f" -> {exc.filename2}" if getattr(exc, "filename2", None) else ""
    return f"{where}{extra}: {exc.strerror or exc}"


_exit_collection_skipped = False


def _skip_exit_collection() -> None:
    """Let the interpreter's teardown skip its cyclic garbage collections: after a scan they traverse
    the ~10^5 objects rerun, pyarrow, numpy and OpenCV leave, several times (0.2–0.4 s between the
    run's end and the process's). ``gc.freeze`` at exit (atexit runs it after the handlers registered
    later, rerun's among them) exempts them; the process's memory goes back to the system anyway.
    Only for the process's own command line (``main()`` without ``argv``), never for a caller's."""
    global _exit_collection_skipped
    if not _exit_collection_skipped:
        _exit_collection_skipped = True
        atexit.register(gc.freeze)


#: glibc's ``mallopt`` parameter for the number of malloc arenas (``M_ARENA_MAX`` in malloc.h).
M_ARENA_MAX = -8


def one_malloc_arena() -> bool:
    """Let every thread of the process allocate from glibc's one main arena (``mallopt(M_ARENA_MAX, 1)``).

    A scan runs about ten threads (frame decoders, the kernel's rayon pool, output writers, the
    recording). By default glibc gives threads arenas of their own (up to 8 per core), whose heaps
    it hands back to the system as arrays are freed, so the next frame's or map's array is faulted
    in and zeroed page by page again. One arena keeps freed memory for the next array. Measured on
    ``gnomon simulate desk_lamp`` captures, eight alternated runs of ``gnomon scan`` each: at
    1920×1080 × 300 frames, peak memory 1443 → 1189 MiB and CPU 8.62 → 7.81 s (medians); at
    1024×768 × 166 frames, 799 → 645 MiB and 4.29 → 4.08 s. Only for the process's own command line
    (``main()`` without ``argv``), never for a caller's process; skipped when ``MALLOC_ARENA_MAX`` is
    set (the user's choice) or the C library is not glibc. Returns whether it took effect.
    """
    if os.environ.get("MALLOC_ARENA_MAX") is not None or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return False
    if not hasattr(libc, "gnu_get_libc_version") or not hasattr(libc, "mallopt"):  # musl's mallopt is a stub
        return False
    return bool(libc.mallopt(M_ARENA_MAX, 1) == 1)


def main(argv: list[str] | None = None) -> int:
    # rerun's writer thread logs its own errors on stderr; ours are one line.
    os.environ.setdefault("RUST_LOG", "off")
    # So does FFmpeg's decoder inside OpenCV ("Get current frame error" for a codec it cannot decode); a video
    # it cannot read is named by our own line (gnomon.capture.frames). OPENCV_FFMPEG_LOGLEVEL in the environment wins.
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    # And OpenCV's own warnings ("can't open camera by index"): a camera or stream it cannot open is ours too.
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    if argv is None:  # the process's command line: the process ends with this run
        one_malloc_arena()
        _skip_exit_collection()
    previous = _install_signal_handlers()
    try:
        if argv is None:
            argv = sys.argv[1:]
        parser = build_parser(argv)
        args = parser.parse_args(argv)
        return int(args.func(args) or 0)
    except GnomonError as exc:
        print(f"gnomon: error: {exc}", file=sys.stderr)
        return 2
    except Terminated as exc:
        print(f"gnomon: terminated ({exc})", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("gnomon: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _stdout_closed()
        return 128 + getattr(signal, "SIGPIPE", 13)
    except ImportError as exc:
        # numpy turns a Ctrl-C during its import into an ImportError (not always chained to it)
        if not (_interrupted or _caused_by_interrupt(exc)):
            raise
        print("gnomon: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:
        if exc.errno not in ENVIRONMENT_ERRNOS:
            raise
        print(f"gnomon: error: {_os_error_line(exc)}", file=sys.stderr)
        return 2
    except MemoryError:
        print("gnomon: error: out of memory (an input larger than this machine can hold?)", file=sys.stderr)
        return 2
    finally:
        _restore_signal_handlers(previous)
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            _stdout_closed()
        except (OSError, ValueError):
            pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
