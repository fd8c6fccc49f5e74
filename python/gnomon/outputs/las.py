"""LAS and LAZ point clouds (laspy; LAZ compressed by its lazrs backend), for survey software.

What PDAL, QGIS, CloudCompare and survey packages exchange: LAS 1.4, point format 7 (x, y, z as
scaled 32-bit integers with a float64 offset, so projected coordinates keep 0.1 mm at any
easting or northing; 16-bit RGB), the coordinate reference system inside the file (a WKT VLR), and
per point, as extra dimensions described in the file: ``sigma`` (the depth's 1σ, in the CRS's
length unit), ``normal_x/y/z`` (unit normal, same axes as x, y, z) and ``pixel_u``/``pixel_v``
(the image pixel the point came from; OpenCV convention, pixel centres at integers).

A georeferenced scan (a sun scan) is written in a projected CRS (:mod:`gnomon.outputs.crs`: the
site's UTM zone by default, ``[output] crs`` on request); a desk scan in its own world frame, its
units declared by an engineering CRS.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from gnomon import __version__
from gnomon.geometry.surface import Surface, SurfacePoints
from gnomon.util.atomic import atomic_path

__all__ = ["EXTRA_DIMENSIONS", "write_las", "write_scan_las", "write_scan_laz"]

#: The extra dimensions written per point, and what each holds.
EXTRA_DIMENSIONS = {
    "sigma": "depth 1-sigma, CRS length unit",
    "normal_x": "unit normal, x",
    "normal_y": "unit normal, y",
    "normal_z": "unit normal, z",
    "pixel_u": "image column, px",
    "pixel_v": "image row, px",
}

#: Coordinate resolution (the LAS scale), in metres and in millimetres.
RESOLUTION = {"m": 1e-4, "mm": 1e-2}


def write_las(path: str | os.PathLike, xyz: np.ndarray, crs: Any, *, resolution: float, rgb: np.ndarray | None = None,
              sigma: np.ndarray | None = None, normals: np.ndarray | None = None,
              uv: np.ndarray | None = None) -> None:
    """Write (N, 3) float64 ``xyz`` (in ``crs``, a pyproj CRS) as LAS, or LAZ when ``path`` ends in
    ``.laz``, atomically; ``resolution`` the coordinate step (the LAS scale, in the CRS's unit).

    ``rgb`` (N, 3) uint8; ``sigma`` (N,) in the CRS's unit; ``normals`` (N, 3); ``uv`` (N, 2) pixels.
    """
    import laspy

    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.generating_software = f"gnomon {__version__}"[:32]
    header.system_identifier = "gnomon shadow scan"
    header.scales = np.full(3, resolution)
    header.offsets = np.floor(xyz.min(axis=0) / resolution) * resolution if len(xyz) else np.zeros(3)
    header.add_extra_dims([laspy.ExtraBytesParams(name=name, type=np.float32, description=what)
                           for name, what in EXTRA_DIMENSIONS.items()])
    header.add_crs(crs)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if rgb is not None:
        c = np.asarray(rgb, dtype=np.uint16).reshape(-1, 3) * 257  # 8 → 16 bits, 255 → 65535
        las.red, las.green, las.blue = c[:, 0], c[:, 1], c[:, 2]
    nan = np.full(len(xyz), np.nan, np.float32)
    las.sigma = nan if sigma is None else np.asarray(sigma, dtype=np.float32)
    n = np.full((len(xyz), 3), np.nan, np.float32) if normals is None else np.asarray(normals, np.float32)
    las.normal_x, las.normal_y, las.normal_z = n[:, 0], n[:, 1], n[:, 2]
    p = np.full((len(xyz), 2), np.nan, np.float32) if uv is None else np.asarray(uv, np.float32)
    las.pixel_u, las.pixel_v = p[:, 0], p[:, 1]
    compressed = Path(path).suffix.lower() == ".laz"
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            las.write(fh, do_compress=compressed, laz_backend=laspy.LazBackend.Lazrs if compressed else None)


def _scan_cloud(folder: Path, points: Surface | SurfacePoints, units: str, site: dict[str, Any] | None,
                crs: str | None, suffix: str) -> None:
    """points.las/.laz of a scan: projected coordinates for a georeferenced scan, else its own frame."""
    from gnomon.outputs.crs import local_crs, survey_frame

    sigma = points.sigma[points.valid]
    if site is not None:
        m = np.asarray(site["world_to_enu"], dtype=np.float64)
        enu = points.points_world.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        metres = float(np.linalg.norm(m[0, :3]))  # metres per world unit
        frame = survey_frame(site, crs)
        xyz = frame.from_enu(enu, site)
        normals = frame.directions_from_enu(points.normals @ (m[:3, :3] / metres).T, site)
        write_las(folder / f"points.{suffix}", xyz, frame.crs, resolution=RESOLUTION["m"], rgb=points.colors,
                  sigma=sigma * metres, normals=normals, uv=points.uv)
    else:
        write_las(folder / f"points.{suffix}", points.points_world, local_crs(units), resolution=RESOLUTION[units],
                  rgb=points.colors, sigma=sigma, normals=points.normals, uv=points.uv)


def write_scan_las(folder: Path, points: Surface | SurfacePoints, units: str, site: dict[str, Any] | None = None,
                   crs: str | None = None) -> None:
    """points.las: the scan's cloud (see the module)."""
    _scan_cloud(folder, points, units, site, crs, "las")


def write_scan_laz(folder: Path, points: Surface | SurfacePoints, units: str, site: dict[str, Any] | None = None,
                   crs: str | None = None) -> None:
    """points.laz: the scan's cloud, LAZ-compressed (see the module)."""
    _scan_cloud(folder, points, units, site, crs, "laz")
