"""The angle between a pixel's ray and its shadow plane (pipeline.ray_plane_angles, report.json's
edges.<edge>.ray_plane_angle_deg): how much a plane's error is magnified in depth."""

from __future__ import annotations

import numpy as np

from gnomon.camera import OpenCVCamera
from gnomon.pipeline import _ray_plane_angles_numpy, ray_plane_angles


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
