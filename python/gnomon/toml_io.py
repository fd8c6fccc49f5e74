"""Reading and writing the small TOML files Gnomon uses (field logs, camera files).

Reading is the standard library's ``tomllib``. Writing covers what our files
hold — tables, arrays of tables, strings, numbers, booleans and (nested) lists
of those — so we need no extra dependency. Floats are written with ``repr``,
which round-trips exactly.
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from gnomon import atomic
from gnomon.errors import GnomonError


def load(path: str | os.PathLike) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is a :class:`GnomonError`."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise GnomonError(f"{p}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise GnomonError(f"{p}: not valid TOML: {exc}") from None


def _value(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "nan"
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        return repr(f)
    if isinstance(v, str):
        escaped = v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
        return f'"{escaped}"'
    if isinstance(v, np.ndarray):
        return _value(v.tolist())
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and all(_is_table(x) for x in v)


def _emit(table: Mapping[str, Any], prefix: str, out: list[str]) -> None:
    for key, v in table.items():
        if not (_is_table(v) or _is_table_array(v)):
            out.append(f"{key} = {_value(v)}")
    for key, v in table.items():
        name = f"{prefix}.{key}" if prefix else key
        if _is_table(v):
            out.append("")
            out.append(f"[{name}]")
            _emit(v, name, out)
        elif _is_table_array(v):
            for item in v:
                out.append("")
                out.append(f"[[{name}]]")
                _emit(item, name, out)


def dumps(data: Mapping[str, Any], header: str = "") -> str:
    """Serialise nested dicts to TOML text; ``header`` lines become comments."""
    out: list[str] = [f"# {line}" if line else "#" for line in header.splitlines()]
    _emit(data, "", out)
    return "\n".join(out).lstrip("\n") + "\n"


def dump(data: Mapping[str, Any], path: str | os.PathLike, header: str = "") -> None:
    """Write ``data`` as TOML to ``path`` atomically."""
    atomic.write_text(path, dumps(data, header))
