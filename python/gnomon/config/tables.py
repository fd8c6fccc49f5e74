"""The TOML tables of Gnomon's own files read with one-line errors naming the file, the table and the key.

:class:`Table` takes its keys one by one (with their types, ranges and defaults checked); whatever a
table holds beyond what was taken is an error at :meth:`Table.done`. The field log
(:mod:`gnomon.config.fieldlog`), the pencil log (:mod:`gnomon.config.pencil_log`) and the light kinds'
own keys (:mod:`gnomon.config.lights`) are read through it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.errors import FieldLogError


class Table:
    """A TOML table being read: takes keys one by one, then rejects leftovers."""

    def __init__(self, path: Path, name: str, data: Any):
        if not isinstance(data, dict):
            raise FieldLogError(f"{path}: [{name}] must be a table")
        self.path, self.name, self.data = path, name, dict(data)

    def where(self, key: str) -> str:
        return f"{self.path}: [{self.name}] {key}"

    def error(self, key: str, message: str) -> FieldLogError:
        return FieldLogError(f"{self.where(key)}: {message}")

    def take(self, key: str, default: Any = ...) -> Any:
        """Pop ``key``; without a default the key is required."""
        if key in self.data:
            return self.data.pop(key)
        if default is ...:
            raise FieldLogError(f"{self.path}: [{self.name}] missing required key '{key}'")
        return default

    def number(self, key: str, default: Any = ..., *, positive: bool = False) -> float:
        v = self.take(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.error(key, f"expected a finite number, got {v!r}")
        if positive and v <= 0:
            raise self.error(key, f"must be > 0, got {v!r}")
        return float(v)

    def integer(self, key: str, default: Any = ..., *, minimum: int | None = None) -> int:
        v = self.take(key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(key, f"expected an integer, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be ≥ {minimum}, got {v}")
        return int(v)

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        v = self.take(key, default)
        if not isinstance(v, str):
            raise self.error(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(key, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
        return v

    def vector(self, key: str, n: int, default: Any = ...) -> np.ndarray:
        v = self.take(key, default)
        ok = isinstance(v, (list, tuple)) and len(v) == n
        ok = ok and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        if not ok or not all(math.isfinite(x) for x in v):
            raise self.error(key, f"expected {n} finite numbers, got {v!r}")
        return np.asarray(v, dtype=np.float64)

    def subtable(self, key: str, *, required: bool = False) -> Table | None:
        if key not in self.data:
            if required:
                raise FieldLogError(f"{self.path}: missing required table [{self.name}.{key}]")
            return None
        return Table(self.path, f"{self.name}.{key}", self.data.pop(key))

    def done(self) -> None:
        if self.data:
            key = sorted(self.data)[0]
            raise FieldLogError(f"{self.path}: [{self.name}] unknown key '{key}'")


def boolean(t: Table, key: str, default: bool) -> bool:
    v = t.take(key, default)
    if not isinstance(v, bool):
        raise t.error(key, f"expected true or false, got {v!r}")
    return v
