"""Output files written on a few worker threads, waited for together."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any


class Writers:
    """Output files written on a few worker threads (numpy, the kernel, zlib and the file
    system release the GIL); leaving the ``with`` block waits for every one and re-raises the
    first failure, in the order they were added."""

    WORKERS = 3

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(max_workers=self.WORKERS, thread_name_prefix="gnomon-writer")
        self._jobs: list[Any] = []

    def add(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        self._jobs.append(self._pool.submit(fn, *args, **kwargs))

    def wait(self) -> None:
        """Wait for the files added so far; re-raise the first failure."""
        for job in self._jobs:
            job.result()

    def __enter__(self) -> Writers:
        return self

    def __exit__(self, *exc: object) -> None:
        self._pool.shutdown(wait=True)
        if exc[0] is None:
            for job in self._jobs:
                job.result()
