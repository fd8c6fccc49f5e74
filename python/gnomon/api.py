"""Gnomon's Python API: scan, load and simulate from a script or a notebook.

>>> import gnomon
>>> field_log = gnomon.simulate("desk_lamp", "capture", width=400, height=300, frames=120)
>>> s = gnomon.scan(field_log)                 # in memory; out="scan" also writes the files
>>> s.points.shape, s.depth.shape, s.report["coverage"]["points"]
>>> again = gnomon.load_scan("scan")           # the same arrays, read back from a scan folder

Arrays are numpy, in the units the field log declares (``Scan.units``);
``world`` is the field log's world frame (z up), ``camera`` the OpenCV
camera frame (x right, y down, z forward). Errors in the input raise
:class:`gnomon.errors.GnomonError` (the message names the file, key or frame).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gnomon.errors import GnomonError
from gnomon.simulate.scenes import SCENES, simulate

if TYPE_CHECKING:
    from gnomon.config.specs import FieldLog
    from gnomon.fuse.run import FuseResult

__all__ = ["SCENES", "Scan", "ScanMesh", "fuse", "load_scan", "scan", "simulate"]


@dataclass(repr=False)
class ScanMesh:
    """The surface mesh: ``vertices`` (V, 3) float32 world, ``faces`` (F, 3) int32 (counter-clockwise
    seen from the camera), ``normals`` (V, 3) float32 unit (towards the camera), ``colors`` (V, 3)
    uint8 RGB, ``pixels`` (V, 2) float32 pixel (u, v) of each vertex."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    pixels: np.ndarray | None

    def __repr__(self) -> str:
        return f"ScanMesh({len(self.vertices)} vertices, {len(self.faces)} faces)"


@dataclass(repr=False)
class Scan:
    """A scan's result, in memory or read back from its folder.

    Per pixel (H, W), NaN or False where there is no point:

    * ``depth`` camera Z (world units), ``sigma`` its predicted standard deviation,
      ``shadow_time`` when the shadow crossed the pixel (capture frames, sub-frame),
      ``undersampled`` the edge crossed it in fewer than 2 frames, ``rgb`` (H, W, 3) uint8
      colour image (the mesh's texture).

    Per point (N, row-major over the pixels with a depth):

    * ``points`` (N, 3) float32 world coordinates, ``colors`` (N, 3) uint8,
      ``normals`` (N, 3) float32 unit normals towards the camera, ``point_sigma`` (N,),
      ``pixels`` (N, 2) float32 (u, v).

    ``coverage`` (H, W) uint8 class per pixel (:data:`gnomon.outputs.images.COVERAGE_CLASSES`:
    no shadow seen, point, no depth, under-sampled point, cropped, ambiguous, edges
    disagree, no neighbour at its depth, no direct light); ``coverage.npy`` in the scan folder (None
    from :func:`load_scan` of a folder written before it existed).

    ``mesh`` (:class:`ScanMesh`), ``K`` (3, 3), ``dist`` lens distortion (OpenCV
    k1 k2 p1 p2 k3; None for a Tsai camera), ``R``, ``t`` world → camera
    (``X_cam = R·X_world + t``), ``units``, ``report`` (report.json's content),
    ``warnings``, ``folder`` (where the files are, None if not written).
    """

    depth: np.ndarray
    sigma: np.ndarray
    shadow_time: np.ndarray | None
    undersampled: np.ndarray | None
    rgb: np.ndarray | None
    points: np.ndarray
    colors: np.ndarray | None
    normals: np.ndarray | None
    point_sigma: np.ndarray | None
    pixels: np.ndarray | None
    mesh: ScanMesh | None
    K: np.ndarray
    dist: np.ndarray | None
    R: np.ndarray
    t: np.ndarray
    units: str
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    folder: Path | None = None
    coverage: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)  # facts worth knowing, with nothing to do (report.json's notes)

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: the pixels with a point."""
        return np.isfinite(self.depth)

    def _summary(self) -> list[tuple[str, str]]:
        """(what, value) lines of the short summary a notebook or a print shows."""
        h, w = self.depth.shape
        sigma = self.point_sigma if self.point_sigma is not None and len(self.point_sigma) else None
        rows = [("points", f"{len(self.points):,} of {w}×{h} pixels ({100 * len(self.points) / (w * h):.1f} %)"),
                ("units", self.units)]
        if sigma is not None:
            rows.append(("median σ", f"{float(np.nanmedian(sigma)):.3g} {self.units}"))
        if self.mesh is not None:
            rows.append(("mesh", f"{len(self.mesh.vertices):,} vertices, {len(self.mesh.faces):,} faces"))
        if "site" in self.report:
            s = self.report["site"]
            rows.append(("site", f"{s['latitude_deg']:.5f}° N, {s['longitude_deg']:.5f}° E"))
        rows.append(("warnings", str(len(self.warnings))))
        if self.notes:
            rows.append(("notes", str(len(self.notes))))
        rows.append(("folder", str(self.folder) if self.folder is not None else "(in memory)"))
        return rows

    def __repr__(self) -> str:
        return "Scan(" + ", ".join(f"{k}: {v}" for k, v in self._summary()) + ")"

    def _repr_html_(self) -> str:
        import html

        body = "".join(f"<tr><th style='text-align:left'>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>"
                       for k, v in self._summary())
        warn = "".join(f"<li>{html.escape(x)}</li>" for x in self.warnings)
        return f"<b>gnomon Scan</b><table>{body}</table>" + (f"<ul>{warn}</ul>" if warn else "")

    @property
    def camera_centre(self) -> np.ndarray:
        """(3,) the camera's centre, world frame."""
        return -self.R.T @ self.t


def _camera_arrays(report: dict) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    import cv2

    cam = report["camera"]
    rvec = np.asarray(cam["pose"]["rvec"], dtype=np.float64)
    t = np.asarray(cam["pose"]["tvec"], dtype=np.float64)
    R = cv2.Rodrigues(rvec)[0]
    if "fx" in cam:
        K = np.array([[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]])
        dist = np.asarray(cam.get("dist", [0.0] * 5), dtype=np.float64)
    else:  # Tsai: the pinhole part only
        from gnomon.camera.calibration import camera_from_table

        c = camera_from_table({k: v for k, v in cam.items() if k != "pose"}, "report.json: camera")
        K, dist = np.asarray(c.K, dtype=np.float64), None
    return K, dist, R, t


def _from_result(result, folder: Path | None) -> Scan:
    """A :class:`Scan` from the pipeline's in-memory result."""
    s = result.surface
    K, dist, R, t = _camera_arrays(result.report)
    w = s.depth.shape[1]
    mesh = ScanMesh(s.mesh.vertices, s.mesh.faces, s.mesh.normals, s.vertex_rgb, s.mesh.pixel_uv(w))
    return Scan(depth=s.depth, sigma=s.sigma, shadow_time=result.shadow_time, undersampled=result.undersampled,
                rgb=s.rgb, points=s.points_world, colors=s.colors, normals=s.normals,
                point_sigma=s.sigma[s.valid], pixels=s.uv, mesh=mesh, K=K, dist=dist, R=R, t=t,
                units=str(result.report["units"]), report=result.report, warnings=list(result.warnings),
                notes=list(result.notes), folder=folder, coverage=result.coverage)


@contextmanager
def _tracker(field_log: str | os.PathLike, tiles: str | None, scheduler: str | None, workers: int | None,
             frame_stride: int) -> Iterator[tuple[FieldLog, Any]]:
    """The field log, read once, and the pass over its frames: None (the in-process tracker), or a
    :class:`gnomon.capture.tiles.TiledTracker` on a Dask cluster (``scheduler``'s, or a local one of
    ``workers`` processes), closed afterwards."""
    from gnomon.config.fieldlog import load_field_log

    if tiles is None:
        if scheduler or workers is not None:
            raise GnomonError("--scheduler and --workers are for tiled scans: add --tiles RxC")
        yield load_field_log(Path(field_log)), None
        return
    from gnomon.capture.tiles import TiledTracker, TileGrid
    from gnomon.runs.batch import close_client, connect_client

    grid = TileGrid.parse(tiles)
    if workers is not None and (workers < 1 or scheduler):
        raise GnomonError("--workers N (N >= 1) sizes a local cluster; not with --scheduler")
    log = load_field_log(Path(field_log))
    cam = log.camera
    grid.bounds((cam.height, cam.width))  # a bad tiling fails here, before any cluster starts
    client, cluster = connect_client(scheduler, workers)
    try:
        yield log, TiledTracker(client, grid, frame_stride=frame_stride)
    finally:
        close_client(client, cluster)


def scan(field_log: str | os.PathLike, out: str | os.PathLike | None = None, *, rrd: bool | None = None,
         rrd_path: str | os.PathLike | None = None, view: bool = False, progress: bool = False,
         frame_stride: int = 10, tiles: str | None = None, scheduler: str | None = None,
         workers: int | None = None, mesh_formats: tuple[str, ...] | None = None,
         cloud_formats: tuple[str, ...] | None = None, crs: str | None = None, rrd_full: bool = False) -> Scan:
    """Scan the capture a field log describes; return the result, and write it if ``out`` is given.

    ``field_log`` the capture's TOML field log (format: field_logs/README.md;
    its ``[output]`` table sets the crop). ``out`` a folder for the files
    (points.ply, mesh.*, depth.npz, preview.png, report.json, …, published
    as a whole only on success); None keeps everything in memory.

    ``rrd`` also write the rerun recording (default: when ``out`` is given),
    to ``rrd_path`` (default ``out/scan.rrd``); ``view`` also stream it to a
    rerun viewer started here (where a display exists; the file is written
    either way); ``frame_stride`` keep every n-th frame image in it; ``rrd_full`` the mesh and the maps
    at full size in it too (by default the points at full size, the maps at the frames' stored size).
    ``progress`` a progress bar on stderr. ``mesh_formats`` the mesh's files among
    ``("ply", "obj", "stl")`` (mesh.ply always; default: the field log's ``[output] mesh_formats``,
    else mesh.ply only). ``cloud_formats`` survey point clouds among ``("las", "laz")`` (``()``: none;
    default: the field log's ``[output] cloud_formats``, else LAZ for a sun scan, none for a desk scan), in
    ``crs`` (a sun scan's; default: the field log's ``[output] crs``, else the site's UTM zone).

    ``tiles`` ``"RxC"``: track R × C image tiles on Dask workers and stitch
    the maps (the same result; ``pip install "gnomon[dask]"``, see
    docs/batch.md), on the running scheduler at ``scheduler`` (an address)
    or on a local cluster of ``workers`` processes; the report's
    ``tracking`` says where each tile ran.

    `gnomon scan` calls this function with its options (``--no-rrd`` is
    ``rrd=False``, ``--rrd PATH`` ``rrd_path``, ``--quiet`` ``progress=False``)
    and prints the summary; error messages name the command's options.
    """
    from gnomon.runs.scan import ScanOptions, prepare_scan, run_scan
    from gnomon.runs.scan import scan as scan_in_memory

    frame_stride = max(1, int(frame_stride))
    if out is None and (rrd or rrd_path is not None or view):
        raise ValueError("a recording needs an output folder: give out=")
    formats = _formats(mesh_formats, "mesh")
    if out is not None and (rrd is None or rrd or view):
        from gnomon.recording.recorder import warm_rerun_import

        warm_rerun_import()  # rerun (≈ 1 s) imported on a thread while the field log is read
    with _tracker(field_log, tiles, scheduler, workers, frame_stride) as (log, track):
        if out is not None:
            opts = ScanOptions(rrd=True if rrd is None else bool(rrd), progress=progress,
                               rrd_path=None if rrd_path is None else Path(rrd_path), view=view,
                               frame_stride=frame_stride, track=track, mesh_formats=formats,
                               cloud_formats=_formats(cloud_formats, "cloud"), crs=crs, rrd_full=bool(rrd_full))
            return _from_result(run_scan(log, Path(out), opts), Path(out))
        setup, source = prepare_scan(log, formats, _formats(cloud_formats, "cloud"), crs)
        result = scan_in_memory(setup, source, None, progress=progress, frame_stride=frame_stride,
                                **({} if track is None else {"track": track}))
        return _from_result(result, None)


def _formats(value: Any, kind: str) -> tuple[str, ...] | None:
    """scan()'s ``mesh_formats`` (kind "mesh") or ``cloud_formats`` ("cloud") checked (None: the field log's)."""
    from gnomon.outputs.formats import formats_of_kind, names_of

    if value is None:
        return None
    chosen = formats_of_kind(list(value) if isinstance(value, (list, tuple)) else value, kind)
    if chosen is None:
        raise GnomonError(f"{kind}_formats: expected 'all' or formats among {', '.join(names_of(kind))}, "
                          f"got {value!r}")
    return chosen


def _load_npy(path: Path, shape: tuple[int, int] | None = None) -> np.ndarray | None:
    if not path.is_file():
        return None
    try:
        a = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise GnomonError(f"{path}: not a numpy array file ({exc})") from None
    if shape is not None and a.shape[:2] != shape:
        raise GnomonError(f"{path}: shape {a.shape} does not match the {shape[1]}x{shape[0]} camera")
    return a


def load_scan(folder: str | os.PathLike) -> Scan:
    """Read a scan's output folder (written by `gnomon scan` or :func:`scan`) back into a :class:`Scan`.

    Needs report.json, points.ply and depth (depth.npz or depth.npy); reads the
    mesh, maps and texture when present. A missing or malformed file raises
    :class:`GnomonError` naming it.
    """
    import cv2

    from gnomon.outputs import ply

    f = Path(folder)
    if not f.is_dir():
        raise GnomonError(f"{f}: not a scan output folder")
    try:
        report = json.loads((f / "report.json").read_text())
        K, dist, R, t = _camera_arrays(report)
        w, h = (int(x) for x in report["inputs"]["image_size"])
        units = str(report["units"])
    except FileNotFoundError:
        raise GnomonError(f"{f / 'report.json'}: missing (is it the output folder of `gnomon scan`?)") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise GnomonError(f"{f / 'report.json'}: not a gnomon scan report ({exc})") from None
    depth = sigma = None
    if (f / "depth.npz").is_file():
        try:
            with np.load(f / "depth.npz", allow_pickle=False) as z:
                depth, sigma = z["depth"], z["sigma"]
        except (ValueError, OSError, KeyError) as exc:
            raise GnomonError(f"{f / 'depth.npz'}: not a gnomon depth file ({exc})") from None
    else:
        depth, sigma = _load_npy(f / "depth.npy", (h, w)), _load_npy(f / "sigma.npy", (h, w))
    if depth is None:
        raise GnomonError(f"{f}: missing depth.npz (or depth.npy)")
    if depth.shape != (h, w):
        raise GnomonError(f"{f}: depth shape {depth.shape} does not match the {w}x{h} camera")
    pts = ply.read_ply(f / "points.ply")
    mesh = None
    if (f / "mesh.ply").is_file():
        m = ply.read_ply(f / "mesh.ply")
        mesh = ScanMesh(m["xyz"], np.asarray(m.get("faces", np.zeros((0, 3), np.int32))), m.get("normals"),
                        m.get("rgb"), None)
    rgb = None
    if (f / "mesh.png").is_file():
        img = cv2.imread(str(f / "mesh.png"), cv2.IMREAD_COLOR)
        rgb = None if img is None else np.ascontiguousarray(img[:, :, ::-1])
    return Scan(depth=depth, sigma=sigma if sigma is not None else np.full_like(depth, np.nan),
                shadow_time=_load_npy(f / "shadow_time.npy", (h, w)),
                undersampled=_load_npy(f / "undersampled.npy", (h, w)), rgb=rgb,
                coverage=_load_npy(f / "coverage.npy", (h, w)),
                points=pts["xyz"], colors=pts.get("rgb"), normals=pts.get("normals"),
                point_sigma=pts.get("sigma"), pixels=pts.get("uv"), mesh=mesh, K=K, dist=dist, R=R, t=t,
                units=units, report=report, warnings=list(report.get("warnings", [])),
                notes=list(report.get("notes", [])), folder=f)


def fuse(scans: list[str | os.PathLike], out: str | os.PathLike | None = None, *, voxel: float | None = None,
         mesh_formats: tuple[str, ...] = ("ply",), rrd: bool = True) -> FuseResult:
    """Several scans of one object (or building) from several places made into one model (`gnomon fuse`).

    ``scans`` scan folders; ``out`` the model's folder (None: in memory only). Returns a
    :class:`gnomon.fuse.run.FuseResult`: ``registration.poses`` each scan's pose in the first one's
    world frame, ``mesh`` (σ per vertex, holes), ``points``, ``report`` (report.json's content).
    Needs Open3D (``pip install "gnomon[fuse]"``).
    """
    from gnomon.fuse.run import fuse_scans

    return fuse_scans(scans, out, voxel=voxel, mesh_formats=mesh_formats, rrd=rrd)
