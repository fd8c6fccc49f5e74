"""Reading and writing the small TOML files Gnomon uses (field logs, camera files).

Reading is the standard library's ``tomllib``; writing is ``tomli-w``, which
quotes keys and escapes strings as TOML requires (a key with a space, a
string with a control character), so everything written reads back equal.
numpy scalars and arrays are written as plain numbers and (nested) arrays;
floats with ``repr``, which round-trips exactly.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from gnomon.errors import GnomonError
from gnomon.util import atomic

__all__ = ["load", "dumps", "dump"]


def load(path: str | os.PathLike) -> dict[str, Any]:
    """Parse a TOML file; a missing, binary, non-UTF-8 or malformed file is a :class:`GnomonError`."""
    from gnomon.util.validate import read_text

    p = Path(path)
    text = read_text(p, "file")  # missing, a folder, binary or not UTF-8: one line naming it
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise GnomonError(f"{p}: not valid TOML: {exc}") from None


def _plain(v: Any) -> Any:
    """numpy scalars and arrays, tuples and paths → the types tomli-w writes."""
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, str):
        return v
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps(data: Mapping[str, Any], header: str = "") -> str:
    """Serialise nested dicts to TOML text; ``header`` lines become comments."""
    head = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return head + tomli_w.dumps(_plain(data))


def dump(data: Mapping[str, Any], path: str | os.PathLike, header: str = "") -> None:
    """Write ``data`` as TOML to ``path`` atomically."""
    atomic.write_text(path, dumps(data, header))
