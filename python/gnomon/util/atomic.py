"""Atomic file output: write to a temporary file beside the target, fsync, then rename.

An interrupted run never leaves a truncated file that looks whole: the target
either keeps its old content (or does not exist) or has the complete new one,
also after a power loss. A failed write raises ``OSError`` naming the target.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is untouched.
    """
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise type(exc)(exc.errno, exc.strerror, str(exc.filename or target)) from exc
    os.close(fd)
    tmp_path = Path(tmp)
    # mkstemp makes the file private (0600); outputs get the usual umask mode.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)
    try:
        yield tmp_path
        _fsync(tmp_path)
        os.replace(tmp_path, target)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        if exc.filename is None:  # a failed write() names no file: name the output
            raise type(exc)(exc.errno, exc.strerror or str(exc), str(target)) from exc
        raise
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _fsync(path: Path) -> None:
    """Force a file's data to disk before it is renamed over the target (crash safety)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


class _Stream:
    """A file as numpy's writers see a plain stream: they write through ``write``, whose failure carries
    the system's reason (no space left, file too large), not through ``ndarray.tofile``, whose short write
    on a full disk raises an OSError without one."""

    def __init__(self, fh) -> None:
        self._fh = fh

    def write(self, data) -> int:
        return self._fh.write(data)


def save_npy(path: str | os.PathLike, array: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(_Stream(fh), array)


def write_parts(path: str | os.PathLike, parts: list) -> None:
    """Write byte buffers (bytes or uint8 arrays) one after the other into ``path``, atomically (no
    joined copy in memory)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            for part in parts:
                fh.write(part)
