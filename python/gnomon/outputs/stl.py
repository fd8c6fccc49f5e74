"""Binary STL: a mesh's triangles with their normals (float32, little-endian), for printing and CAD.

:func:`write_scan_stl` is the scan's ``stl`` mesh format (:mod:`gnomon.outputs.formats`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gnomon import __version__, _kernel
from gnomon.geometry.meshing import face_normals
from gnomon.geometry.surface import Surface
from gnomon.util import atomic

__all__ = ["write_scan_stl", "write_stl"]


def write_stl(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, header: str = "gnomon mesh") -> None:
    """Write a triangle mesh as binary STL (float32, little-endian), atomically.

    Each triangle carries its unit normal (right-hand rule over its corners);
    STL has no units: the coordinates are the world units (say which in
    ``header``, at most 80 ASCII characters; it must not start with ``solid``).
    """

    v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.intp).reshape(-1, 3)
    head = header.encode("ascii")[:80]
    if head.lower().startswith(b"solid"):
        raise ValueError("a binary STL header must not start with 'solid'")
    # the records (normal, corners, attribute) packed by the kernel, rows in parallel (_stl_table_numpy: the same)
    records = _kernel.stl_records(np.ascontiguousarray(v), np.ascontiguousarray(f, dtype=np.int32))
    atomic.write_parts(path, [head.ljust(80, b" "), np.uint32(len(f)).astype("<u4").tobytes(), records])


def _stl_table_numpy(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """write_stl's records in numpy (the kernel's ``stl_records`` gives the same bytes)."""
    table = np.zeros(len(f), dtype=np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
    table["n"] = face_normals(v, f)
    table["v"] = v[f]
    return table.view(np.uint8)


def write_scan_stl(folder: Path, surface: Surface, units: str) -> None:
    """mesh.stl: the surface's mesh (STL has no units: the header says which)."""
    write_stl(folder / "mesh.stl", surface.mesh.vertices, surface.mesh.faces,
              header=f"gnomon {__version__} mesh, units {units}")
