"""The angle between a pixel's ray and its shadow plane (pipeline.ray_plane_angles, report.json's
edges.<edge>.ray_plane_angle_deg and grazing_share): how much a plane's error is magnified in depth, and the
scan's warning when the rays graze the planes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gnomon.camera.models import OpenCVCamera
from gnomon.geometry.surface import _ray_plane_angles_numpy, ray_plane_angles
from gnomon.reconstruct.edges import GRAZING_DEG


def test_angles_follow_the_plane_interpolated_at_each_pixels_time() -> None:
    """A 64×48 camera; plane row k contains the camera's y axis and is turned by 10·k degrees about it
    (normal (cos 10k°, 0, −sin 10k°)). A pixel on the centre row at time t meets the plane interpolated
    between rows floor(t) and floor(t)+1; its angle is arcsin(|n·r|/|n||r|), computed here from the ray's
    azimuth. Missing plane rows give NaN."""
    cam = OpenCVCamera(64, 48, 50.0, 50.0, 31.5, 23.5)
    rays = cam.ray_map().astype(np.float64)
    k = np.arange(4)
    planes = np.c_[np.cos(np.radians(10 * k)), np.zeros(4), -np.sin(np.radians(10 * k)), np.zeros(4)]
    times = np.full((48, 64), 1.25)
    where = np.zeros((48, 64), bool)
    where[23, :] = True
    got = ray_plane_angles(rays, times, planes, where)
    n = 0.75 * planes[1, :3] + 0.25 * planes[2, :3]
    r = rays[23]
    want = np.degrees(np.arcsin(np.abs(r @ n) / (np.linalg.norm(n) * np.linalg.norm(r, axis=1))))
    np.testing.assert_allclose(got, want, atol=1e-9)
    # the centre ray (along z) meets the plane, turned 12.5° from it, at about 12.5°
    assert abs(got[31] - 12.5) < 1.0  # its ray is 0.6° off the axis, towards the plane
    planes[2] = np.nan
    assert np.isnan(ray_plane_angles(rays, times, planes, where)).all()


def test_kernel_angles_equal_the_numpy_definition() -> None:
    """The kernel's angles are the numpy definition's (random rays, times between and on the rows,
    missing rows, a sparse selection)."""
    rng = np.random.default_rng(4)
    h, w, n = 19, 27, 9
    rays = rng.normal(0, 0.4, (h, w, 3)) + np.array([0.0, 0.0, 1.0])
    planes = np.c_[rng.normal(0, 1, (n, 3)), rng.normal(0, 100, n)]
    planes[5] = np.nan
    times = rng.uniform(-0.5, n - 0.5, (h, w))
    times[::4, ::3] = np.floor(times[::4, ::3])
    where = rng.random((h, w)) < 0.6
    got = ray_plane_angles(rays, times, planes, where)
    want = _ray_plane_angles_numpy(rays, times, planes, where)
    assert got.shape == (int(where.sum()),) and np.isnan(want).any() and np.isfinite(want).sum() > 100
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))


@pytest.mark.slow
def test_a_lamp_above_the_camera_warns_and_errs_as_its_angles_say(desk_scan, tmp_path) -> None:
    """The desk capture of ``desk_scan`` again with its lamp 60 mm straight above the camera: every shadow
    plane passes within 60 mm of the camera's centre, 650 mm from the scene, so the rays meet the planes at
    under 2° (sin α ≲ 60/650) instead of the lamp-to-the-side scene's ~30°. The scan must say so (and the
    side-lit one not), and its depth errors must grow as the angles predict: same noise, same sweep, so the
    median error over the swept pixels scales with the median 1/sin α, within a factor of 2 either way."""
    from gnomon.cli import main
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    simulate_desk_lamp(tmp_path / "capture", DeskLampConfig(width=400, height=300, frames=120, seed=5,
                                                             pencil_photos=0, lamp_above_camera=60.0))
    assert main(["scan", str(tmp_path / "capture" / "field_log.toml"), "--out", str(tmp_path / "scan"),
                 "--quiet", "--no-rrd"]) == 0
    results = {}
    for name, root in (("side", desk_scan), ("above", tmp_path)):
        report = json.loads((root / "scan" / "report.json").read_text())
        truth = np.load(root / "capture" / "ground_truth.npz")
        depth = np.load(root / "scan" / "depth.npy")
        swept = truth["swept"] & np.isfinite(depth)
        err = np.median(np.abs(depth[swept] - truth["depth"][swept]))
        edges = [v for k, v in report["edges"].items() if k != "disagreement"]
        angle = np.median([e["ray_plane_angle_deg"]["p50"] for e in edges])
        share = np.mean([e["grazing_share"] for e in edges])
        grazing = [w for w in report["warnings"] if f"under {GRAZING_DEG:g}°" in w]
        results[name] = (err, angle, share, grazing)
    err_side, angle_side, share_side, warned_side = results["side"]
    err_above, angle_above, share_above, warned_above = results["above"]
    assert share_side == 0.0 and not warned_side and angle_side > 20.0
    assert share_above > 0.9 and angle_above < np.degrees(np.arcsin(60.0 / 650.0))
    assert len(warned_above) == 1 and "max_sigma" in warned_above[0]
    predicted = np.sin(np.radians(angle_side)) / np.sin(np.radians(angle_above))
    assert 0.5 * predicted < err_above / err_side < 2.0 * predicted, (err_above, err_side, predicted)
