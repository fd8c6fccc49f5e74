"""Can the sweep fix a wall its marks leave uncertain? (a script, not a test)

    PYTHONPATH=python python benchmarks/wall_tilt.py [--out DIR]

Simulates the two_plane scene (800x600, seed 0), scans it as shipped to get the shadow times, and then,
holding the desk at its true place, turns the true wall by small angles about two axes: the desk-wall
fold, and the wall's own axis across it (the wall kept through a point of the true fold). For each wall it
fits every frame's shadow lines on both planes (``lines_on_plane``), the frames' shadow planes through them
(``two_plane_shadow_planes``), and the point closest to all of them (``light_point_or_line``: a point lamp's
planes all pass through it). Printed: how far the planes miss that point (RMS, scene units), per wall. A
wall the sweep could fix would show a clear minimum at the truth along both axes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from gnomon.camera.models import Pose  # noqa: E402
from gnomon.config.fieldlog import load_field_log  # noqa: E402
from gnomon.config.setup import plane_region_mask  # noqa: E402
from gnomon.geometry.reference_lines import PlaneInCamera, lines_on_plane  # noqa: E402
from gnomon.geometry.validity import light_point_or_line  # noqa: E402
from gnomon.light.shadow_planes import two_plane_shadow_planes  # noqa: E402
from gnomon.runs.scan import ScanOptions, run_scan  # noqa: E402
from gnomon.simulate import TwoPlaneConfig, simulate_two_plane  # noqa: E402

CAMERA_FRAME = Pose(np.eye(3), np.zeros(3))


def turned(axis: np.ndarray, deg: float) -> np.ndarray:
    """The rotation by ``deg`` about ``axis`` (Rodrigues)."""
    a = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    r = np.radians(deg)
    return np.eye(3) + np.sin(r) * k + (1.0 - np.cos(r)) * k @ k


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="gnomon-wall-tilt-"))
    capture = root / "capture"
    if not (capture / "field_log.toml").exists():
        simulate_two_plane(capture, TwoPlaneConfig(seed=0))
    result = run_scan(capture / "field_log.toml", root / "scan", ScanOptions(progress=False, rrd=False))
    times = np.load(root / "scan" / "shadow_time.npy").astype(np.float64)
    log = load_field_log(capture / "field_log.toml")
    truth = dict(np.load(capture / "ground_truth.npz"))
    camera, n_frames = result.setup.camera, len(log.capture.image_files)
    shape = (camera.height, camera.width)
    masks = [plane_region_mask(p, shape) for p in log.planes]
    R, t = truth["R"], truth["t"].ravel()
    normals = [R @ n for n in truth["plane_normals"][:2]]
    offsets = [float(n @ (R @ p + t)) for n, p in zip(normals, truth["plane_points"][:2], strict=True)]
    fold = np.cross(normals[0], normals[1])
    fold /= np.linalg.norm(fold)
    on_fold = np.linalg.solve(np.array([normals[0], normals[1], fold]), [offsets[0], offsets[1], 0.0])
    across = np.cross(normals[1], fold)
    desk = PlaneInCamera.from_world(normals[0] * offsets[0], normals[0], CAMERA_FRAME)

    def miss(wall_normal: np.ndarray) -> float:
        wall = PlaneInCamera.from_world(on_fold, wall_normal, CAMERA_FRAME)
        lines = [lines_on_plane(times, n_frames, desk, masks[0], camera, "desk"),
                 lines_on_plane(times, n_frames, wall, masks[1], camera, "wall")]
        planes, _ = two_plane_shadow_planes(lines)
        planes = planes[np.all(np.isfinite(planes), axis=1)]
        point = light_point_or_line(planes).point
        norms = np.linalg.norm(planes[:, :3], axis=1)
        return float(np.sqrt(np.mean(((planes[:, :3] @ point - planes[:, 3]) / norms) ** 2)))

    angles = (-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0)
    print(f"the shadow planes' RMS miss of their common point ({log.capture.units}), the wall turned about:")
    for name, axis in (("the desk-wall fold", fold), ("its axis across the fold", across)):
        values = [miss(turned(axis, a) @ normals[1]) for a in angles]
        print(f"  {name:26s} " + "  ".join(f"{a:+.0f}°: {v:.4f}" for a, v in zip(angles, values, strict=True)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
