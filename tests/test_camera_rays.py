"""OpenCVCamera.ray_map (Newton in the kernel, undistortPoints where it fails) against OpenCV."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gnomon import _kernel
from gnomon.camera.models import (
    _UNDISTORT_CRITERIA,
    RAY_MAP_TOL_PX,
    OpenCVCamera,
    pixel_grid,
    ray_map_newton,
    undistort_points,
)

# Barrel distortion strong enough that the image corners sit near the fold of the lens
# (distorted radius 0.64 of at most ~0.66 for these coefficients): a fisheye-like corner,
# where Newton needs many steps and the fixed-point iteration converges slowly.
STRONG = OpenCVCamera(1280, 960, 1250.0, 1250.0, 640.0, 480.0, (-0.4, 0.05, 0.001, -0.001, 0.0))
# The frog-sized capture's camera: an ordinary lens.
ORDINARY = OpenCVCamera(1024, 768, 1152.0, 1150.08, 515.084, 381.068, (-0.12, 0.05, 0.001, -0.0008, 0.0))


def _reprojection_px(cam: OpenCVCamera, rays: np.ndarray) -> np.ndarray:
    """|projectPoints(ray) - pixel| per pixel (H*W,), with OpenCV as the independent reference."""
    pts = np.ascontiguousarray(rays.reshape(-1, 1, 3))
    pix, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist_coeffs)
    return np.hypot(*(pix.reshape(-1, 2) - pixel_grid(cam.width, cam.height)).T)


def test_strongly_distorted_rays_reproject_to_their_pixels():
    rays = STRONG.ray_map()
    assert rays.shape == (960, 1280, 3)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-15)
    err = _reprojection_px(STRONG, rays)
    assert err.max() < 1e-6, err.max()
    # the corners really are strongly distorted: their rays are ~14 % off the pinhole's
    r_pinhole = np.hypot(640.0, 480.0) / 1250.0
    r_ray = np.hypot(*(rays[0, 0, :2] / rays[0, 0, 2]))
    assert r_ray > 1.12 * r_pinhole


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_pixels_newton_leaves_fall_back_to_undistort_points():
    _, solved = _kernel.ray_map(STRONG.width, STRONG.height, (STRONG.fx, STRONG.fy, STRONG.cx, STRONG.cy),
                                STRONG.dist, RAY_MAP_TOL_PX, 2)
    assert 0 < (~solved).sum() < solved.size  # two steps leave the outer pixels unsolved
    assert not solved[0, 0] and solved[480, 640]
    err = _reprojection_px(STRONG, ray_map_newton(STRONG, 2))
    assert err.max() < 1e-6, err.max()


def test_unsolvable_pixels_are_flagged_not_guessed():
    # beyond the fold (distorted radius > ~0.61 for k1 = -0.4 alone) no ray maps to the pixel
    rays, solved = _kernel.ray_map(4, 1, (100.0, 100.0, -70.0, 0.0), (-0.4, 0.0, 0.0, 0.0, 0.0), RAY_MAP_TOL_PX, 50)
    assert not solved.any() and np.isnan(rays).all()


def test_ordinary_camera_map_equals_undistort_points():
    rays = ORDINARY.ray_map()
    grid = pixel_grid(ORDINARY.width, ORDINARY.height).reshape(-1, 1, 2)
    ref = undistort_points(grid, ORDINARY.K, ORDINARY.dist_coeffs, _UNDISTORT_CRITERIA).reshape(-1, 2)
    xy = (rays[..., :2] / rays[..., 2:]).reshape(-1, 2)
    diff_px = np.abs(xy - ref) * [ORDINARY.fx, ORDINARY.fy]
    assert diff_px.max() < 1e-9, diff_px.max()
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-15)
