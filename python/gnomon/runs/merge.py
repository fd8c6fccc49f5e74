"""`gnomon merge`: fuse two scans of one scene taken from the same camera.

Typical use (Bouguet & Perona §5): one scan with the lamp left of the camera,
one with it right; each fills the other's cast shadows, and where both see a
point the better-conditioned one dominates. The scans must share the camera
(same image grid and pose), which is how such a pair is captured: the camera
stays, the lamp moves.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnomon.camera.calibration import camera_from_table
from gnomon.camera.models import CameraModel, Pose
from gnomon.errors import GnomonError
from gnomon.geometry.surface import Surface, build_surface
from gnomon.geometry.triangulation import supported_by_neighbours
from gnomon.outputs import ply
from gnomon.outputs.formats import OutputContext
from gnomon.outputs.publish import recover, staged_outputs
from gnomon.outputs.scan_files import write_surface
from gnomon.reconstruct.fusion import fuse_depths
from gnomon.recording.scan_log import record_surface
from gnomon.recording.worker import open_recorder
from gnomon.runs.scan import ScanOptions
from gnomon.util import atomic


@dataclass
class ScanOnDisk:
    """The parts of a scan's output folder that a merge needs."""

    folder: Path
    depth: np.ndarray
    sigma: np.ndarray
    rgb: np.ndarray  # (H, W, 3)
    camera: CameraModel
    pose: Pose
    units: str
    max_depth_jump: float


def load_scan(folder: str | Path) -> ScanOnDisk:
    """Read depth.npy, sigma.npy, report.json and points.ply of a scan output folder."""
    f = Path(folder)
    if not f.is_dir():
        raise GnomonError(f"{f}: not a scan output folder")
    recover(f)  # a publication a killed run left half-done is completed first
    for name in ("depth.npy", "sigma.npy", "report.json", "points.ply"):
        if not (f / name).is_file():
            raise GnomonError(f"{f}: missing {name} (is it the output folder of `gnomon scan`?)")
    try:
        report = json.loads((f / "report.json").read_text())
        cam = dict(report["camera"])
        pose_table = cam.pop("pose")
        camera = camera_from_table(cam, f"{f / 'report.json'}: camera")
        pose = Pose.from_rvec_tvec(np.array(pose_table["rvec"], float), np.array(pose_table["tvec"], float))
        units = str(report["units"])
        jump = float(report["settings"]["max_depth_jump"])
    except (ValueError, KeyError, TypeError) as exc:
        raise GnomonError(f"{f / 'report.json'}: not a gnomon scan report ({exc})") from None
    depth = _load_map(f / "depth.npy", camera)
    sigma = _load_map(f / "sigma.npy", camera)
    try:
        points = ply.read_ply(f / "points.ply")
    except GnomonError:
        raise
    except (ValueError, KeyError, TypeError, EOFError, OSError, IndexError) as exc:
        raise GnomonError(f"{f / 'points.ply'}: not a readable gnomon point cloud ({exc})") from None
    rgb = np.zeros((camera.height, camera.width, 3), np.uint8)
    if points.get("uv") is not None and points.get("rgb") is not None:
        uv = np.asarray(points["uv"], dtype=np.float64)
        if uv.size and not (np.all(np.isfinite(uv)) and uv[:, 0].min() >= 0 and uv[:, 1].min() >= 0
                            and uv[:, 0].max() < camera.width and uv[:, 1].max() < camera.height):
            raise GnomonError(f"{f / 'points.ply'}: pixel coordinates u v outside the "
                              f"{camera.width}x{camera.height} image")
        u, v = uv[:, 0].astype(np.int64), uv[:, 1].astype(np.int64)
        rgb[v, u] = points["rgb"]
    return ScanOnDisk(f, depth, sigma, rgb, camera, pose, units, jump)


def _load_map(path: Path, camera: CameraModel) -> np.ndarray:
    """A per-pixel float map (.npy) of the camera's size, or a one-line error naming the file."""
    try:
        m = np.load(path, allow_pickle=False)
    except (ValueError, EOFError, OSError) as exc:  # truncated, empty, text, pickled objects
        raise GnomonError(f"{path}: not a readable .npy map ({exc})") from None
    if not isinstance(m, np.ndarray) or m.dtype.kind != "f":
        raise GnomonError(f"{path}: expected a float map, got {getattr(m, 'dtype', type(m).__name__)}")
    if m.shape != (camera.height, camera.width):
        raise GnomonError(f"{path}: shape {m.shape} does not match the {camera.width}x{camera.height} camera")
    return m


def _check_same_camera(a: ScanOnDisk, b: ScanOnDisk) -> None:
    if (a.camera.width, a.camera.height) != (b.camera.width, b.camera.height):
        raise GnomonError(f"{b.folder}: image size {b.camera.width}x{b.camera.height} differs from "
                          f"{a.folder}'s {a.camera.width}x{a.camera.height}; merge needs one camera")
    if a.units != b.units:
        raise GnomonError(f"{b.folder}: units {b.units!r} differ from {a.folder}'s {a.units!r}")
    probe = np.array([[0.0, 0.0], [a.camera.width - 1.0, a.camera.height - 1.0], [a.camera.width / 2, 0.0]])
    rays_differ = np.max(np.abs(a.camera.rays(probe) - b.camera.rays(probe))) > 1e-4
    moved = np.linalg.norm(a.pose.camera_centre_world - b.pose.camera_centre_world)
    scale = max(float(np.linalg.norm(a.pose.t)), 1e-9)
    if rays_differ or moved > 1e-3 * scale:
        raise GnomonError(f"{b.folder}: its camera (intrinsics or pose) differs from {a.folder}'s; "
                          "merge fuses scans taken with one fixed camera")


def merge_scans(scan_a: str | Path, scan_b: str | Path, out_dir: str | Path, *, method: str = "gaussian",
                beta: float = 10.0, options: ScanOptions | None = None) -> tuple[Surface, dict]:
    """Fuse two scans per pixel and write the merged outputs into ``out_dir``."""
    opts = options or ScanOptions()
    t0 = time.perf_counter()
    a, b = load_scan(scan_a), load_scan(scan_b)
    _check_same_camera(a, b)
    jump = max(a.max_depth_jump, b.max_depth_jump)
    depth, sigma, conflict = fuse_depths([a.depth, b.depth], [a.sigma, b.sigma], jump, method, beta)
    keep = supported_by_neighbours(depth, jump)
    rgb = np.where(np.isfinite(a.depth)[..., None], a.rgb, b.rgb)
    surface = build_surface(a.camera.ray_map(), a.pose, depth, sigma, keep, rgb, jump)
    only_a = np.isfinite(a.depth) & ~np.isfinite(b.depth)
    only_b = np.isfinite(b.depth) & ~np.isfinite(a.depth)
    both = np.isfinite(a.depth) & np.isfinite(b.depth)
    diff = (a.depth - b.depth)[both]
    report = {
        "inputs": [str(a.folder), str(b.folder)],
        "units": a.units,
        "camera": json.loads((a.folder / "report.json").read_text())["camera"],
        "settings": {"method": method, "beta": beta if method == "sigmoid" else None, "max_depth_jump": jump},
        "coverage": {
            "points": int(keep.sum()),
            "scan_a_points": int(np.isfinite(a.depth).sum()),
            "scan_b_points": int(np.isfinite(b.depth).sum()),
            "only_a": int(only_a.sum()), "only_b": int(only_b.sum()), "both": int(both.sum()),
            "conflicts": int(conflict.sum()),
            "mesh_faces": int(len(surface.mesh.faces)),
        },
        "disagreement": {"rms": float(np.sqrt(np.mean(diff**2))) if diff.size else None,
                         "median_abs": float(np.median(np.abs(diff))) if diff.size else None},
    }
    recorder = None
    with staged_outputs(Path(out_dir)) as staging:
        merge_opts = ScanOptions(rrd=opts.rrd, view=opts.view, progress=False, frame_stride=opts.frame_stride)
        recorder = open_recorder(staging, merge_opts, f"merge {a.folder.name} + {b.folder.name}", "merge.rrd")
        try:
            write_surface(staging, surface, OutputContext(a.units))
            report["timings_s"] = {"total_s": time.perf_counter() - t0}
            if recorder is not None:
                recorder.log_camera(a.camera.K, a.camera.width, a.camera.height, a.pose.R, a.pose.t, a.units)
                record_surface(recorder, surface, None, [], {"coverage": report["coverage"]})
                recorder.close()
                recorder = None
            atomic.write_text(staging / "report.json", json.dumps(report, indent=2))
        finally:
            if recorder is not None:
                recorder.abort()
    return surface, report
