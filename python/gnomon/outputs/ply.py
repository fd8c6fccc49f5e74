"""PLY files: binary little-endian writer and a reader for what we (and others) write.

Layouts written by Gnomon (the outputs of `gnomon scan` and `gnomon merge`)::

    points.ply   element vertex N: float x y z [float nx ny nz] [uchar red green blue]
                 [float scalar_sigma quality] [float scalar_u scalar_v]
    mesh.ply     element vertex N: float x y z [float nx ny nz] [uchar red green blue]
                 element face M:   list uchar int vertex_indices   (triangles)

Coordinates are float32 in world units (the units go into an ``obj_info units <u>`` line and a
``comment units <u>`` line, see :func:`units_comment`); ``scalar_sigma`` is the per-point standard
deviation of the depth in the same units, written again as ``quality``; ``nx ny nz`` the unit surface
normal (world frame, towards the camera); ``scalar_u scalar_v`` are the pixel coordinates (OpenCV
convention, pixel centres at integers) the point came from. The names are those the tools keep:
CloudCompare shows each ``scalar_*`` property as a scalar field and drops other names; MeshLab keeps
``quality`` as the vertex quality and drops the rest. Files of earlier versions (``sigma``, ``u``,
``v``) are read as well.

Files are written atomically (temporary file beside the target, then rename).
The float32 arrays are written as they are, so a write/read round trip is
bit-for-bit.

:func:`read_ply` reads binary little- and big-endian and ASCII PLY with any
scalar properties and list properties, and returns a dict of numpy arrays (see
its docstring). A malformed file raises :class:`gnomon.errors.GnomonError`
naming the file.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from gnomon import __version__
from gnomon.errors import GnomonError
from gnomon.geometry.surface import Surface
from gnomon.util.atomic import atomic_path

__all__ = [
    "write_scan_mesh_ply",
    "write_points_ply",
    "write_mesh_ply",
    "read_ply",
    "PlyData",
    "units_comment",
]


class PlyData(TypedDict, total=False):
    """What :func:`read_ply` returns (the array keys only when the file has those properties)."""

    xyz: np.ndarray
    normals: np.ndarray
    rgb: np.ndarray
    sigma: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    elements: dict[str, dict[str, np.ndarray]]
    comments: list[str]

# PLY scalar type names → numpy kinds (both the classic and the sized names).
_PLY_TYPES: dict[str, str] = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}


def units_comment(units: str) -> str:
    """The comment line that records the world units, e.g. ``units mm``."""
    return f"units {units}"


# --------------------------------------------------------------------------- writing


def _check_comments(comments: Iterable[str]) -> list[str]:
    out = []
    for c in comments:
        c = str(c)
        if "\n" in c or "\r" in c:
            raise ValueError(f"PLY comment must be a single line: {c!r}")
        out.append(c)
    return out


def _header(elements: list[tuple[str, int, list[str]]], comments: list[str]) -> bytes:
    lines = ["ply", "format binary_little_endian 1.0"]
    # the units also where a PLY header has its own place for the object's description (obj_info)
    lines += [f"obj_info {c}" for c in comments if c.startswith("units ")]
    lines += [f"comment {c}" if c else "comment" for c in comments]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        lines += props
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def _as_rows(a: np.ndarray | None, n: int, cols: int | None, dtype: str, what: str) -> np.ndarray | None:
    if a is None:
        return None
    arr = np.asarray(a)
    shape = (n,) if cols is None else (n, cols)
    if arr.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=dtype)


def _vertex_table(
    xyz: np.ndarray,
    rgb: np.ndarray | None,
    sigma: np.ndarray | None = None,
    uv: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> tuple[np.ndarray, list[str]]:
    xyz = np.asarray(xyz)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f"xyz must have shape (N, 3), got {xyz.shape}")
    n = xyz.shape[0]
    xyz = np.ascontiguousarray(xyz, dtype="<f4")
    rgb = _as_rows(rgb, n, 3, "u1", "rgb")
    sigma = _as_rows(sigma, n, None, "<f4", "sigma")
    uv = _as_rows(uv, n, 2, "<f4", "uv")
    normals = _as_rows(normals, n, 3, "<f4", "normals")

    fields: list[tuple] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    props = ["property float x", "property float y", "property float z"]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        props += ["property float nx", "property float ny", "property float nz"]
    if rgb is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        props += ["property uchar red", "property uchar green", "property uchar blue"]
    if sigma is not None:
        fields += [("scalar_sigma", "<f4"), ("quality", "<f4")]
        props += ["property float scalar_sigma", "property float quality"]
    if uv is not None:
        fields += [("scalar_u", "<f4"), ("scalar_v", "<f4")]
        props += ["property float scalar_u", "property float scalar_v"]

    table = np.empty(n, dtype=np.dtype(fields))  # packed: no alignment padding
    # Each array's rows copied into their bytes of the table at once (a field per array, viewed as raw
    # bytes: one pass over the table per array instead of one per column; the same bytes).
    parts = [a for a in (xyz, normals, rgb, sigma, sigma, uv) if a is not None]
    widths = [a.itemsize * (a.shape[1] if a.ndim == 2 else 1) for a in parts]
    groups = np.dtype({"names": [f"g{k}" for k in range(len(parts))],
                       "formats": [np.dtype((np.void, w)) for w in widths],
                       "offsets": np.cumsum([0, *widths[:-1]]).tolist(), "itemsize": table.dtype.itemsize})
    raw = table.view(groups)
    for k, (a, w) in enumerate(zip(parts, widths, strict=True)):
        raw[f"g{k}"] = a.view(np.dtype((np.void, w))).reshape(n)
    return table, props


def write_points_ply(
    path: str | os.PathLike,
    xyz: np.ndarray,
    rgb: np.ndarray | None = None,
    sigma: np.ndarray | None = None,
    uv: np.ndarray | None = None,
    comments: Iterable[str] = (),
    normals: np.ndarray | None = None,
) -> None:
    """Write a point cloud as binary little-endian PLY, atomically.

    ``xyz`` (N, 3) float32 world coordinates; ``rgb`` (N, 3) uint8 or None;
    ``sigma`` (N,) float32 or None; ``uv`` (N, 2) float32 pixel coordinates or
    None; ``normals`` (N, 3) float32 unit normals or None; ``comments`` one
    line each (e.g. :func:`units_comment`).
    """
    table, props = _vertex_table(xyz, rgb, sigma, uv, normals)
    header = _header([("vertex", len(table), props)], _check_comments(comments))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(table.data)  # the packed table's own buffer: no copy of it as bytes


def write_mesh_ply(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray,
    rgb: np.ndarray | None = None,
    comments: Iterable[str] = (),
    normals: np.ndarray | None = None,
    sigma: np.ndarray | None = None,
) -> None:
    """Write a triangle mesh as binary little-endian PLY, atomically.

    ``vertices`` (N, 3) float32; ``faces`` (M, 3) int32 vertex indices (0-based);
    ``rgb`` (N, 3) uint8 per-vertex colour or None; ``normals`` (N, 3) float32
    per-vertex unit normals or None; ``sigma`` (N,) float32 per-vertex σ (world units) or None.
    """
    table, props = _vertex_table(vertices, rgb, sigma, normals=normals)
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (M, 3), got {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= len(table)):
        raise ValueError("faces index vertices out of range")
    face_table = np.empty(len(f), dtype=np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    raw = face_table.view(np.dtype({"names": ["n", "i"], "formats": ["u1", np.dtype((np.void, 12))], "offsets": [0, 1],
                                    "itemsize": 13}))  # each face's three indices as one field of raw bytes
    raw["n"] = 3
    raw["i"] = np.ascontiguousarray(f, dtype="<i4").view(np.dtype((np.void, 12))).reshape(len(f))
    header = _header(
        [("vertex", len(table), props), ("face", len(f), ["property list uchar int vertex_indices"])],
        _check_comments(comments),
    )
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(table.data)  # the packed tables' own buffers: no copy of them as bytes
            fh.write(face_table.data)


# --------------------------------------------------------------------------- reading


class _Element:
    def __init__(self, name: str, count: int):
        self.name = name
        self.count = count
        # (name, scalar type) or (name, (count type, item type)) for lists
        self.props: list[tuple[str, str | tuple[str, str]]] = []


def _parse_header(raw: bytes, where: str) -> tuple[str, list[str], list[_Element], int]:
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise GnomonError(f"{where}: not a PLY file")
    nl = raw.find(b"\n", end)
    if nl < 0:
        raise GnomonError(f"{where}: truncated PLY header")
    body_start = nl + 1
    try:
        text = raw[:end].decode("ascii")
    except UnicodeDecodeError:
        raise GnomonError(f"{where}: PLY header is not ASCII") from None
    fmt = ""
    comments: list[str] = []
    elements: list[_Element] = []
    for lineno, line in enumerate(text.replace("\r", "").split("\n")[1:], start=2):
        parts = line.split()
        if not parts:
            continue
        key = parts[0]
        try:
            if key == "format":
                fmt = parts[1]
                if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
                    raise GnomonError(f"{where}: unsupported PLY format {fmt!r}")
            elif key == "comment":
                comments.append(line[len("comment"):].strip())
            elif key == "obj_info":
                continue
            elif key == "element":
                elements.append(_Element(parts[1], int(parts[2])))
            elif key == "property":
                if not elements:
                    raise ValueError("property before any element")
                if parts[1] == "list":
                    elements[-1].props.append((parts[4], (_PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]])))
                else:
                    elements[-1].props.append((parts[2], _PLY_TYPES[parts[1]]))
            else:
                raise ValueError(f"unknown keyword {key!r}")
        except GnomonError:
            raise
        except (IndexError, KeyError, ValueError) as exc:
            raise GnomonError(f"{where}: bad PLY header line {lineno}: {line.strip()!r} ({exc})") from None
    if not fmt:
        raise GnomonError(f"{where}: PLY header has no format line")
    return fmt, comments, elements, body_start


def _read_binary_element(buf: memoryview, pos: int, el: _Element, endian: str, where: str):
    """Return ({prop: array}, new_pos) for one element of a binary PLY body."""
    if not any(isinstance(t, tuple) for _, t in el.props):
        dt = np.dtype([(n, endian + t) for n, t in el.props if isinstance(t, str)])  # (all are, checked above)
        nbytes = dt.itemsize * el.count
        if pos + nbytes > len(buf):
            raise GnomonError(f"{where}: truncated PLY body in element {el.name!r}")
        table = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
        return {n: table[n].astype(table[n].dtype.newbyteorder("="), copy=True) for n, _ in el.props}, pos + nbytes

    if el.count == 0:
        return {n: np.empty((0,), dtype=t if isinstance(t, str) else t[1]) for n, t in el.props}, pos

    # Fast path: every list has the same length as the first one (triangles).
    if pos < len(buf):
        first_len = None
        off = pos
        fields: list[tuple[Any, ...]] = []
        for n, t in el.props:
            if isinstance(t, tuple):
                cnt_t, item_t = t
                if first_len is None:
                    first_len = int(np.frombuffer(buf, dtype=endian + cnt_t, count=1, offset=off)[0])
                fields.append((n + "__n", endian + cnt_t))
                fields.append((n, endian + item_t, (first_len,)))
                off += np.dtype(cnt_t).itemsize + np.dtype(item_t).itemsize * first_len
            else:
                fields.append((n, endian + t))
                off += np.dtype(t).itemsize
        dt = np.dtype(fields)
        nbytes = dt.itemsize * el.count
        if pos + nbytes <= len(buf):
            table = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
            uniform = all(
                np.all(table[n + "__n"] == first_len) for n, t in el.props if isinstance(t, tuple)
            )
            if uniform:
                out = {}
                for n, _ in el.props:
                    a = table[n]
                    out[n] = a.astype(a.dtype.newbyteorder("="), copy=True)
                return out, pos + nbytes

    # General (slow) path: variable-length lists.
    cols: dict[str, list] = {n: [] for n, _ in el.props}
    try:
        for _ in range(el.count):
            for n, t in el.props:
                if isinstance(t, tuple):
                    cnt_t, item_t = t
                    k = int(np.frombuffer(buf, dtype=endian + cnt_t, count=1, offset=pos)[0])
                    pos += np.dtype(cnt_t).itemsize
                    cols[n].append(np.frombuffer(buf, dtype=endian + item_t, count=k, offset=pos).copy())
                    pos += np.dtype(item_t).itemsize * k
                else:
                    cols[n].append(np.frombuffer(buf, dtype=endian + t, count=1, offset=pos)[0])
                    pos += np.dtype(t).itemsize
    except ValueError:
        raise GnomonError(f"{where}: truncated PLY body in element {el.name!r}") from None
    out = {}
    for n, t in el.props:
        if isinstance(t, tuple):
            arr = np.empty(len(cols[n]), dtype=object)
            arr[:] = cols[n]
            out[n] = arr
        else:
            out[n] = np.asarray(cols[n], dtype=t)
    return out, pos


def _read_ascii_elements(body: bytes, elements: list[_Element], where: str) -> dict[str, dict[str, np.ndarray]]:
    tokens = body.split()
    i = 0
    result: dict[str, dict[str, np.ndarray]] = {}
    try:
        for el in elements:
            cols: dict[str, list] = {n: [] for n, _ in el.props}
            for _ in range(el.count):
                for n, t in el.props:
                    if isinstance(t, tuple):
                        k = int(tokens[i])
                        i += 1
                        cols[n].append(np.array([float(x) for x in tokens[i:i + k]], dtype=t[1]))
                        i += k
                    else:
                        cols[n].append(float(tokens[i]))
                        i += 1
            out = {}
            for n, t in el.props:
                if isinstance(t, tuple):
                    lens = {len(v) for v in cols[n]}
                    if len(lens) == 1:
                        out[n] = np.stack(cols[n]) if cols[n] else np.empty((0, 0), dtype=t[1])
                    else:
                        arr = np.empty(len(cols[n]), dtype=object)
                        arr[:] = cols[n]
                        out[n] = arr
                else:
                    out[n] = np.asarray(cols[n], dtype=t)
            result[el.name] = out
    except (IndexError, ValueError):
        raise GnomonError(f"{where}: truncated or malformed ASCII PLY body") from None
    return result


def read_ply(path: str | os.PathLike) -> PlyData:
    """Read a PLY file into a dict of numpy arrays.

    Keys (present only when the file has the matching properties):

    * ``xyz`` (N, 3) float32 (from vertex x, y, z; other float types are kept
      as they are), ``normals`` (N, 3) (nx, ny, nz), ``rgb`` (N, 3) uint8 (red, green, blue), ``sigma`` (N,),
      ``uv`` (N, 2) (u, v), ``faces`` (M, 3) int32 when every face is a triangle
      (otherwise an object array of index arrays);
    * ``elements``: {element name: {property name: array}} with every element
      and property of the file, as read;
    * ``comments``: the comment lines (a list of str).

    A missing or malformed file raises GnomonError naming it.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise GnomonError(f"{p}: no such file") from None
    except OSError as exc:
        raise GnomonError(f"{p}: cannot read ({exc.strerror})") from None
    where = str(p)
    fmt, comments, elements, body_start = _parse_header(raw, where)

    if fmt == "ascii":
        data = _read_ascii_elements(raw[body_start:], elements, where)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        buf = memoryview(raw)
        pos = body_start
        data = {}
        for el in elements:
            data[el.name], pos = _read_binary_element(buf, pos, el, endian, where)

    out: PlyData = {"elements": data, "comments": comments}
    v = data.get("vertex", {})
    if all(k in v for k in ("x", "y", "z")):
        out["xyz"] = np.stack([v["x"], v["y"], v["z"]], axis=1)
    if all(k in v for k in ("nx", "ny", "nz")):
        out["normals"] = np.stack([v["nx"], v["ny"], v["nz"]], axis=1)
    if all(k in v for k in ("red", "green", "blue")):
        out["rgb"] = np.stack([v["red"], v["green"], v["blue"]], axis=1).astype(np.uint8, copy=False)
    for name in ("scalar_sigma", "sigma"):  # this version's name, an earlier one's
        if name in v:
            out["sigma"] = v[name]
            break
    for u_name, v_name in (("scalar_u", "scalar_v"), ("u", "v")):
        if u_name in v and v_name in v:
            out["uv"] = np.stack([v[u_name], v[v_name]], axis=1)
            break
    f = data.get("face", {})
    idx = f.get("vertex_indices", f.get("vertex_index"))
    if idx is not None:
        if idx.dtype != object and idx.ndim == 2 and idx.shape[1] == 3:
            out["faces"] = idx.astype(np.int32, copy=False)
        else:
            out["faces"] = idx
    return out


def write_scan_mesh_ply(folder: Path, surface: Surface, units: str) -> None:
    """mesh.ply: the surface's mesh with its vertices' colours and normals (world frame, ``units``)."""
    mesh = surface.mesh
    write_mesh_ply(folder / "mesh.ply", mesh.vertices, mesh.faces, surface.vertex_rgb,
                   comments=[f"gnomon {__version__}", units_comment(units), "frame world"], normals=mesh.normals)
