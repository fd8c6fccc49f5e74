"""Kernel triangulation: camera rays against per-frame shadow planes."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel


def pinhole_rays(h: int, w: int, f: float = 100.0) -> np.ndarray:
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    d = np.stack([(u - (w - 1) / 2) / f, (v - (h - 1) / 2) / f, np.ones_like(u)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def ray_plane(rays: np.ndarray, plane: np.ndarray) -> np.ndarray:
    n, d = plane[:3], plane[3]
    return rays * (d / (rays @ n))[..., None]


def unit_plane(p: np.ndarray) -> np.ndarray:
    return p / np.linalg.norm(p[:3])


def test_known_plane_gives_exact_points():
    rays = pinhole_rays(6, 8)
    plane = np.array([0.1, -0.2, 1.0, 500.0])  # not unit: the kernel normalises
    times = np.zeros((6, 8), np.float32)
    points, valid = _kernel.triangulate(rays, times, plane[None, :])
    assert points.dtype == np.float32 and points.shape == (6, 8, 3)
    assert valid.dtype == bool and valid.all()
    expect = ray_plane(rays, plane)
    np.testing.assert_allclose(points, expect, rtol=1e-6)
    # Every point lies on the plane.
    n = plane[:3] / np.linalg.norm(plane[:3])
    np.testing.assert_allclose(points.astype(np.float64) @ n, 500 / np.linalg.norm(plane[:3]), rtol=1e-6)


def test_fractional_time_interpolates_between_planes():
    rays = pinhole_rays(5, 5)
    a = unit_plane(np.array([0.0, 0.3, 1.0, 400.0]))
    b = unit_plane(np.array([0.2, 0.0, 1.0, 600.0]))
    planes = np.stack([a, b, a])
    times = np.full((5, 5), 0.25, np.float32)
    times[0, 0] = 1.0  # exact frame: plane b
    times[4, 4] = 1.5  # between b and a
    points, valid = _kernel.triangulate(rays, times, planes)
    assert valid.all()

    def lerp(p, q, s):
        if p[:3] @ q[:3] < 0:
            q = -q
        r = (1 - s) * p + s * q
        return r / np.linalg.norm(r[:3])

    np.testing.assert_allclose(points[1, 2], ray_plane(rays[1, 2], lerp(a, b, 0.25)), rtol=1e-6)
    np.testing.assert_allclose(points[0, 0], ray_plane(rays[0, 0], b), rtol=1e-6)
    np.testing.assert_allclose(points[4, 4], ray_plane(rays[4, 4], lerp(b, a, 0.5)), rtol=1e-6)
    # Parallel planes z = 400 and z = 600: a quarter of the way is z = 450,
    # whichever orientation the second plane is given in.
    flat = np.array([[0, 0, 1, 400.0], [0, 0, -1, -600.0]])
    p, ok = _kernel.triangulate(rays, np.full((5, 5), 0.25, np.float32), flat)
    assert ok.all()
    np.testing.assert_allclose(p[..., 2], 450, rtol=1e-6)


def test_missing_planes_and_bad_times_are_invalid():
    rays = pinhole_rays(1, 7)
    z = [0.0, 0.0, 1.0, 300.0]
    planes = np.array([z, [np.nan] * 4, z, [0.0, 0.0, 1.0, -300.0]])
    #                  NaN     <0    >N-1  NaN plane  half NaN  behind  ok
    times = np.array([[np.nan, -0.5, 3.5, 1.0, 0.5, 3.0, 2.0]], np.float32)
    points, valid = _kernel.triangulate(rays, times, planes)
    np.testing.assert_array_equal(valid, [[False] * 6 + [True]])
    assert np.isnan(points[0, :6]).all()
    np.testing.assert_allclose(points[0, 6], ray_plane(rays[0, 6], np.array(z)), rtol=1e-6)


def test_grazing_rays_are_rejected():
    rays = np.array([[[1.0, 0.0, 1e-4]]])
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    plane = np.array([[0.0, 0.0, 1.0, 1.0]])
    t = np.zeros((1, 1), np.float32)
    assert not _kernel.triangulate(rays, t, plane)[1][0, 0]
    assert _kernel.triangulate(rays, t, plane, min_cos=1e-5)[1][0, 0]


def test_bad_inputs_raise_value_error():
    rays = pinhole_rays(2, 3)
    times = np.zeros((2, 3), np.float32)
    planes = np.array([[0, 0, 1, 1.0]])
    with pytest.raises(ValueError, match="rays"):
        _kernel.triangulate(rays[:, :2], times, planes)
    with pytest.raises(ValueError, match="float32"):
        _kernel.triangulate(rays, times.astype(np.float64), planes)
    with pytest.raises(ValueError, match="planes"):
        _kernel.triangulate(rays, times, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="min_cos"):
        _kernel.triangulate(rays, times, planes, min_cos=2.0)


def test_depth_only_is_the_points_z() -> None:
    """triangulation.triangulate_depth (the kernel's Z only) is triangulate(...).depth bit for bit, and the
    Z of the exact ray-plane points: interpolated planes, NaN times, missing planes, times outside."""
    from gnomon.geometry.triangulation import triangulate, triangulate_depth

    rng = np.random.default_rng(5)
    rays = pinhole_rays(30, 40, f=60.0)
    planes = np.stack([unit_plane(np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), 1.0, 400.0 + 10 * k]))
                       for k in range(12)])
    planes[4] = np.nan
    times = rng.uniform(-1.0, 12.0, (30, 40)).astype(np.float32)
    times[rng.random(times.shape) < 0.1] = np.nan
    times[0, :12] = np.arange(12)  # exact frames
    depth = triangulate_depth(rays, times, planes)
    ref = triangulate(rays, times, planes).depth
    assert depth.dtype == np.float32 and depth.shape == (30, 40)
    assert np.array_equal(depth.view(np.uint32), ref.view(np.uint32))
    assert 0.5 < np.isfinite(depth).mean() < 0.95
    expect = ray_plane(rays[0, 0], planes[0])[2]
    np.testing.assert_allclose(depth[0, 0], expect, rtol=1e-6)
