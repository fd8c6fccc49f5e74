"""Wall and CPU time of a block of code, into a dict of stage timings."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


@contextmanager
def timed(timings: dict[str, float], key: str, cpu: dict[str, float] | None = None,
           clock: Callable[[], float] = time.process_time) -> Iterator[None]:
    """Wall time of the block into ``timings[key]``; with ``cpu``, its CPU time into ``cpu[key]``
    (``clock``: the process's, all threads, or ``time.thread_time`` for one thread's)."""
    t, c = time.perf_counter(), clock()
    yield
    timings[key] = time.perf_counter() - t
    if cpu is not None:
        cpu[key] = clock() - c
