"""Interrupts that wait: SIGINT, SIGTERM and SIGHUP held off a block of code, and off importlib.

``gnomon.cli`` turns SIGTERM and SIGHUP into :class:`~gnomon.cli.Terminated` and SIGINT into
``KeyboardInterrupt``, raised in the main thread at its next bytecode, wherever that is, so that
every ``finally`` and ``with`` on the way out runs (the staging folder of a scan is removed, the
recording's file with it). Two kinds of place must not see such an exception:

* a block that makes or publishes something and must not stop half-way: a scan's staging folder
  made but not yet known to the code that removes it, or the output folder being swapped in.
  :func:`held` marks such a block; an interrupt that comes meanwhile is delivered when it ends.
  Blocking the signals (``pthread_sigmask``) is not enough once other threads run: the kernel
  hands a process's signal to any thread that does not block it, and Python runs its handler in
  the main thread all the same.
* an import: importlib's code takes and gives back its locks, and an exception raised between
  taking its global lock and the ``try`` that releases it leaves the lock held for ever, so that
  every later import, on any thread, waits (a scan hung so: its writer thread waiting to import,
  the main thread waiting for the writer). A signal that comes while importlib's code is anywhere on
  the main thread's stack (whose innermost frame alone did not prevent the hang) is sent again a few
  milliseconds later: an import delays it by its own length at most.

The handlers call :func:`postpone` first; it says whether the signal was put off.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["REDELIVER_S", "held", "postpone"]

INTERRUPTS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
# Seconds after which a signal that came inside importlib's code is sent again.
REDELIVER_S = 0.005

_depth = 0  # blocks of :func:`held` entered and not left (the main thread's)
_pending: list[int] = []  # signals put off by those blocks, in order


@contextmanager
def held() -> Iterator[None]:
    """Hold SIGINT/SIGTERM/SIGHUP off the block: one that comes meanwhile is delivered when it ends
    (by the handlers ``gnomon.cli`` installs; elsewhere, on the calling thread, as far as blocking
    the signals there reaches)."""
    global _depth
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, INTERRUPTS)
    except (AttributeError, ValueError, OSError):  # no sigmask here
        old = None
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        put_off = list(_pending) if _depth == 0 else []
        if _depth == 0:
            _pending.clear()
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)  # one blocked meanwhile is handled from here
        if put_off:
            signal.raise_signal(put_off[0])  # its handler raises here, after the block


def _in_import_machinery(frame: FrameType | None) -> bool:
    """The main thread was importing when the signal came: importlib's code on its stack."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def postpone(signum: int, frame: FrameType | None) -> bool:
    """For a signal handler: True when the signal must not be raised in ``frame`` now and has been put
    off: until the :func:`held` block ends, or (inside importlib) sent to the main thread again after
    :data:`REDELIVER_S`."""
    if _depth > 0:
        if signum not in _pending:
            _pending.append(signum)
        return True
    if not _in_import_machinery(frame):
        return False
    main_id = threading.main_thread().ident
    if main_id is None:
        return False
    timer = threading.Timer(REDELIVER_S, signal.pthread_kill, (main_id, signum))
    timer.daemon = True
    timer.start()
    return True
