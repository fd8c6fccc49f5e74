"""Progress on stderr: a small bar for long steps, and a line per stage of a run (no dependency, no global state)."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO


class Progress:
    """``with Progress("tracking", total) as bar: bar.update(i + 1)``.

    On a terminal it redraws one line; elsewhere (CI, logs) it prints at most
    ten lines per step. ``enabled=False`` makes it silent.
    """

    def __init__(self, label: str, total: int, *, enabled: bool = True, stream: TextIO | None = None):
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = time.perf_counter()
        self._last_decile = -1
        self._last_draw = 0.0

    def update(self, done: int) -> None:
        if not self.enabled:
            return
        frac = min(done / self.total, 1.0)
        now = time.perf_counter()
        if self.tty:
            if now - self._last_draw < 0.1 and done < self.total:
                return
            self._last_draw = now
            bar = "#" * int(frac * 30)
            self.stream.write(f"\r{self.label:>12} [{bar:<30}] {done}/{self.total} {now - self.start:5.1f}s")
            self.stream.flush()
        else:
            decile = int(frac * 10)
            if decile != self._last_decile:
                self._last_decile = decile
                self.stream.write(f"{self.label}: {done}/{self.total} ({frac:.0%}, {now - self.start:.1f}s)\n")

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


class Stages:
    """A line on stderr per stage of a run: ``with stages("fusion and mesh"): ...``.

    On a terminal the stage's name shows while it runs and its time once done; elsewhere one line per
    stage once done (``scan: fusion and mesh 1.3 s``). ``enabled=False`` makes it silent.
    """

    def __init__(self, label: str, *, enabled: bool = True, stream: TextIO | None = None):
        self.label, self.enabled = label, enabled
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        if not self.enabled:
            yield
            return
        start = time.perf_counter()
        if self.tty:
            self.stream.write(f"{self.label:>12} {stage} …")
            self.stream.flush()
        yield
        took = time.perf_counter() - start
        line = f"\r{self.label:>12} {stage} {took:.1f} s" if self.tty else f"{self.label}: {stage} {took:.1f} s"
        self.stream.write(line + "\n")
        self.stream.flush()
