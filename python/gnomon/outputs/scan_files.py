"""The files of a scan folder: points, mesh, maps, depth.npz, the ENU cloud and report.json.

Each writer takes plain values (a :class:`~gnomon.geometry.surface.Surface`, maps, dicts) and writes
atomically (:mod:`gnomon.util.atomic`); the mesh's formats come from the registry
(:mod:`gnomon.outputs.formats`). `gnomon scan`, `gnomon merge` and `gnomon live` write through here.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon import __version__
from gnomon.geometry.surface import Surface, SurfacePoints
from gnomon.outputs import ply
from gnomon.outputs.formats import DEFAULT_MESH_FORMATS, FORMATS, OutputContext
from gnomon.outputs.images import write_preview
from gnomon.outputs.obj import write_texture
from gnomon.outputs.writers import Writers
from gnomon.util import atomic
from gnomon.util.timing import timed


def write_surface(folder: Path, surface: Surface, ctx: OutputContext, writers: Writers | None = None,
                  mesh_formats: tuple[str, ...] = DEFAULT_MESH_FORMATS, cloud_formats: tuple[str, ...] = ()) -> None:
    """points.ply, depth.npy, sigma.npy, mesh.png (the colour image), the mesh in each of ``mesh_formats``
    and the cloud in each of ``cloud_formats`` (:data:`gnomon.outputs.formats.FORMATS`; mesh.ply always),
    each atomically.

    ``writers``: write on its threads (waited for by its owner), else here, concurrently."""
    if writers is None:
        with Writers() as own:
            write_surface(folder, surface, ctx, own, mesh_formats, cloud_formats)
        return
    write_mesh_files(folder, surface, ctx, writers, mesh_formats)  # the longest first
    write_point_files(folder, surface, ctx, writers, texture=not writes_texture(mesh_formats),
                      cloud_formats=cloud_formats)


def writes_texture(mesh_formats: tuple[str, ...]) -> bool:
    """Whether one of the mesh formats writes mesh.png itself (else the point files do)."""
    return any(FORMATS[name].texture for name in mesh_formats)


def write_point_files(folder: Path, points: Surface | SurfacePoints, ctx: OutputContext, writers: Writers, *,
                      texture: bool, cloud_formats: tuple[str, ...] = ()) -> None:
    """points.ply, depth.npy, sigma.npy, the cloud in each of ``cloud_formats`` and, with ``texture``,
    mesh.png (else a mesh format writes it)."""
    comments = [f"gnomon {__version__}", ply.units_comment(ctx.units), "frame world"]
    for name in cloud_formats:
        writers.add(FORMATS[name].write, folder, points, ctx)
    if texture:  # the colour image alone (load_scan's and merge's colours)
        writers.add(write_texture, folder / "mesh.png", points.rgb)
    writers.add(ply.write_points_ply, folder / "points.ply", points.points_world, points.colors,
                points.sigma[points.valid], points.uv, comments=comments, normals=points.normals)
    writers.add(atomic.save_npy, folder / "depth.npy", points.depth)
    writers.add(atomic.save_npy, folder / "sigma.npy", points.sigma)


def write_mesh_files(folder: Path, surface: Surface, ctx: OutputContext, writers: Writers,
                     mesh_formats: tuple[str, ...]) -> None:
    """The mesh in each of ``mesh_formats`` and in every always-written mesh format (mesh.ply), the
    always-written last (the others take longer)."""
    chosen = [FORMATS[name] for name in mesh_formats if not FORMATS[name].always]
    chosen += [f for f in FORMATS.values() if f.always and f.kind == "mesh"]
    for fmt in chosen:
        writers.add(fmt.write, folder, surface, ctx)


def write_maps(folder: Path, surface: Surface | SurfacePoints, shadow_time: np.ndarray, undersampled: np.ndarray,
               coverage: np.ndarray | None, camera: dict[str, Any], site: dict[str, Any] | None, units: str,
                writers: Writers) -> None:
    """undersampled.npy, coverage.npy, shadow_time.npy, depth.npz, preview.png, points_enu.ply (with a site)."""
    writers.add(atomic.save_npy, folder / "undersampled.npy", undersampled)
    if coverage is not None:
        writers.add(atomic.save_npy, folder / "coverage.npy", coverage)
    writers.add(atomic.save_npy, folder / "shadow_time.npy", shadow_time.astype(np.float32))
    writers.add(write_depth_npz, folder / "depth.npz", surface.depth, surface.sigma, camera, units)
    if coverage is not None:
        writers.add(write_preview, folder / "preview.png", surface.rgb, surface.depth, surface.sigma, coverage,
                    units=units)
    if site is not None:
        writers.add(write_enu_points, folder / "points_enu.ply", surface, site)


def write_depth_npz(path: Path, depth: np.ndarray, sigma: np.ndarray, camera: dict[str, Any], units: str) -> None:
    """depth.npz: the depth and σ maps with the camera that makes them usable.

    ``depth``, ``sigma`` (H, W) float32 camera Z and its σ (world units, NaN =
    none); ``K`` (3, 3) and ``dist`` (k1 k2 p1 p2 k3; OpenCV; the pinhole part
    and zeros for a Tsai camera, whose own parameters are in ``camera_toml``);
    ``R`` (3, 3), ``t`` (3,) and ``rvec`` world → camera (``X_cam = R·X_world +
    t``); ``image_size`` (width, height); ``units`` the world units;
    ``camera_toml`` the camera table as report.json gives it (JSON text).
    """
    rvec = np.asarray(camera["pose"]["rvec"], dtype=np.float64)
    if "fx" in camera:
        K = np.array([[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0.0, 0.0, 1.0]])
        dist = np.asarray(camera.get("dist", [0.0] * 5), dtype=np.float64)
    else:
        K, dist = np.full((3, 3), np.nan), np.zeros(5)
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, depth=depth.astype(np.float32), sigma=sigma.astype(np.float32), K=K, dist=dist,
                     R=cv2.Rodrigues(rvec)[0], t=np.asarray(camera["pose"]["tvec"], dtype=np.float64), rvec=rvec,
                     image_size=np.array(depth.shape[::-1], dtype=np.int64), units=np.array(units),
                     camera_toml=np.array(json.dumps(camera, default=json_default)))


def write_enu_points(path: Path, surface: Surface | SurfacePoints, site: dict[str, Any]) -> None:
    """points_enu.ply: the cloud in East-North-Up metres from the site (report.json's ``site``)."""
    m = np.asarray(site["world_to_enu"], dtype=np.float64)
    enu = surface.points_world.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    comments = [f"gnomon {__version__}", ply.units_comment("m"), "frame ENU",
                f"origin latitude {site['latitude_deg']!r} longitude {site['longitude_deg']!r} "
                f"altitude {site['altitude_m']!r} ({site.get('datum', 'WGS84')})"]
    scale = float(np.linalg.norm(m[0, :3]))  # metres per world unit
    # float32 keeps ~0.1 mm at 1 km from the site
    ply.write_points_ply(path, enu.astype(np.float32), surface.colors, surface.sigma[surface.valid] * scale,
                         surface.uv, comments=comments, normals=surface.normals @ (m[:3, :3] / scale).T)


def json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_report(folder: Path, report: dict[str, Any], t: float, c: float, started: float | None,
                 before_report: Callable[[], None] | None) -> None:
    """report.json, once the output files (whose wait since ``t``, CPU clock ``c``, it gives) and, with
    ``before_report``, the recording are done."""
    timings, cpu = report["timings_s"], report.setdefault("cpu_timings_s", {})
    timings["outputs_s"] = time.perf_counter() - t
    cpu["outputs_s"] = time.process_time() - c
    if before_report is not None:
        with timed(timings, "recording_wait_s"):  # the recording still being logged or encoded
            before_report()
    if started is not None:
        timings["total_s"] = time.perf_counter() - started
    atomic.write_text(folder / "report.json", json.dumps(report, indent=2, default=json_default))
