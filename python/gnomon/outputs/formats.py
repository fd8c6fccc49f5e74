"""The registry of a scan's mesh formats: one table, a line a format.

A format has a name (as ``[output] mesh_formats`` in the field log, ``--mesh-formats`` on the command
line and ``mesh_formats=`` in :func:`gnomon.scan` give it), the files it writes into a scan folder,
and a writer ``write(folder, surface, units)`` of a :class:`~gnomon.geometry.surface.Surface` whose
coordinates are in ``units`` (world frame). The field log's parser, the command line, the API, the
scan's writers and the publishing of a scan folder (:mod:`gnomon.outputs.publish`) all read this
table, so adding a format is one module with its writer and one line in :data:`FORMATS`
(tests/test_mesh_formats.py adds one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gnomon.geometry.surface import Surface
from gnomon.outputs.obj import write_scan_obj
from gnomon.outputs.ply import write_scan_mesh_ply
from gnomon.outputs.stl import write_scan_stl

__all__ = ["DEFAULT_MESH_FORMATS", "FORMATS", "MESH_FORMATS", "MeshFormat", "mesh_format", "mesh_formats"]


@dataclass(frozen=True)
class MeshFormat:
    """One mesh format of a scan folder."""

    name: str  # lower case, as the field log and the command line name it
    files: tuple[str, ...]  # what it writes into the scan folder
    write: Callable[[Path, Surface, str], None]  # (folder, surface, units)
    texture: bool = False  # it writes mesh.png (the colour image) itself
    always: bool = False  # written by every scan, whatever is asked


#: Every mesh format, in the order they are listed and written (the first is always written).
FORMATS: dict[str, MeshFormat] = {
    "ply": MeshFormat("ply", ("mesh.ply",), write_scan_mesh_ply, always=True),
    "obj": MeshFormat("obj", ("mesh.obj", "mesh.mtl", "mesh.png"), write_scan_obj, texture=True),
    "stl": MeshFormat("stl", ("mesh.stl",), write_scan_stl),
}

#: The formats this version ships (``"all"`` means the registry's formats at the time it is read).
MESH_FORMATS = tuple(FORMATS)
DEFAULT_MESH_FORMATS = tuple(name for name, f in FORMATS.items() if f.always)


def mesh_format(name: str) -> MeshFormat:
    """The registry's entry of a format chosen by :func:`mesh_formats`."""
    return FORMATS[name]


def mesh_formats(value: object) -> tuple[str, ...] | None:
    """The mesh formats a value asks for (``"all"``, a list of names, or names joined by commas, any
    case), the always-written ones among them, in the registry's order; None if it names no known format."""
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        return None
    known = tuple(FORMATS)
    wanted = {n.strip().lower() for n in names} - {""}
    if wanted == {"all"}:
        return known
    if not wanted <= set(known):
        return None
    return tuple(f for f in known if f in wanted or FORMATS[f].always)
