"""The registry of a scan's file formats: one table, a line a format.

A format has a name (as the field log's ``[output] mesh_formats`` / ``cloud_formats``, the command
line's ``--mesh-formats`` / ``--cloud-formats`` and :func:`gnomon.scan`'s arguments give it), a kind
(a ``"mesh"`` of the surface, or a ``"cloud"`` of its points), the files it writes into a scan
folder, and a writer ``write(folder, surface, context)``: the surface (world frame) and an
:class:`OutputContext` (its units, where it is on Earth, the CRS asked for). The field log's parser,
the command line, the API, the scan's writers and the publishing of a scan folder
(:mod:`gnomon.outputs.publish`) all read this table, so adding a format is one module with its writer
and one line in :data:`FORMATS` (tests/test_mesh_formats.py adds one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gnomon.geometry.surface import Surface, SurfacePoints
from gnomon.outputs.obj import write_scan_obj
from gnomon.outputs.ply import write_scan_mesh_ply
from gnomon.outputs.stl import write_scan_stl

__all__ = ["DEFAULT_MESH_FORMATS", "FORMATS", "MESH_FORMATS", "CLOUD_FORMATS", "MeshFormat", "OutputContext",
           "cloud_formats", "formats_of_kind", "mesh_format", "mesh_formats", "names_of"]


@dataclass(frozen=True)
class OutputContext:
    """What a writer needs besides the surface."""

    units: str  # the world units of the surface ("mm" or "m")
    site: dict[str, Any] | None = None  # report.json's site: where the world frame is on Earth (sun scans)
    crs: str | None = None  # [output] crs: the CRS of survey files (default: the site's UTM zone)


@dataclass(frozen=True)
class MeshFormat:
    """One file format of a scan folder (the name is historical: a mesh's or a cloud's)."""

    name: str  # lower case, as the field log and the command line name it
    files: tuple[str, ...]  # what it writes into the scan folder
    write: Callable[[Path, Any, OutputContext], None]  # (folder, Surface (mesh) or SurfacePoints (cloud), context)
    texture: bool = False  # it writes mesh.png (the colour image) itself
    always: bool = False  # written by every scan, whatever is asked
    kind: str = "mesh"  # "mesh": needs the surface's mesh; "cloud": its points only (written before the mesh)


def _mesh_ply(folder: Path, surface: Surface, ctx: OutputContext) -> None:
    write_scan_mesh_ply(folder, surface, ctx.units)


def _obj(folder: Path, surface: Surface, ctx: OutputContext) -> None:
    write_scan_obj(folder, surface, ctx.units)


def _stl(folder: Path, surface: Surface, ctx: OutputContext) -> None:
    write_scan_stl(folder, surface, ctx.units)


def _cloud(suffix: str) -> Callable[[Path, Surface | SurfacePoints, OutputContext], None]:
    def write(folder: Path, points: Surface | SurfacePoints, ctx: OutputContext) -> None:
        from gnomon.outputs import las  # laspy, lazrs, pyproj: loaded when a survey file is written

        (las.write_scan_laz if suffix == "laz" else las.write_scan_las)(folder, points, ctx.units, ctx.site, ctx.crs)
    return write


#: Every format, in the order they are listed and written (of each kind, the always-written first).
FORMATS: dict[str, MeshFormat] = {
    "ply": MeshFormat("ply", ("mesh.ply",), _mesh_ply, always=True),
    "obj": MeshFormat("obj", ("mesh.obj", "mesh.mtl", "mesh.png"), _obj, texture=True),
    "stl": MeshFormat("stl", ("mesh.stl",), _stl),
    "las": MeshFormat("las", ("points.las",), _cloud("las"), kind="cloud"),
    "laz": MeshFormat("laz", ("points.laz",), _cloud("laz"), kind="cloud"),
}


def names_of(kind: str) -> tuple[str, ...]:
    """The registered formats of a kind ("mesh" or "cloud"), in the registry's order."""
    return tuple(name for name, f in FORMATS.items() if f.kind == kind)


#: The formats this version ships (``"all"`` means the registry's formats at the time it is read).
MESH_FORMATS = names_of("mesh")
CLOUD_FORMATS = names_of("cloud")
DEFAULT_MESH_FORMATS = tuple(name for name, f in FORMATS.items() if f.always)


def mesh_format(name: str) -> MeshFormat:
    """The registry's entry of a format chosen by :func:`mesh_formats` or :func:`cloud_formats`."""
    return FORMATS[name]


def formats_of_kind(value: object, kind: str) -> tuple[str, ...] | None:
    """The formats of ``kind`` a value asks for (see :func:`mesh_formats`); None if it names no known one."""
    return _chosen(value, kind)


def _chosen(value: object, kind: str) -> tuple[str, ...] | None:
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        return None
    known = names_of(kind)
    wanted = {n.strip().lower() for n in names} - {""}
    if wanted == {"all"}:
        return known
    if not wanted <= set(known):
        return None
    return tuple(f for f in known if f in wanted or FORMATS[f].always)


def mesh_formats(value: object) -> tuple[str, ...] | None:
    """The mesh formats a value asks for (``"all"``, a list of names, or names joined by commas, any
    case), the always-written ones among them, in the registry's order; None if it names no known format."""
    return _chosen(value, "mesh")


def cloud_formats(value: object) -> tuple[str, ...] | None:
    """The point-cloud formats a value asks for (as :func:`mesh_formats`; none is always written)."""
    return _chosen(value, "cloud")
