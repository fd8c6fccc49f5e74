"""σZ by first-order propagation (gnomon.geometry.uncertainty.depth_sigma): the kernel's per-pixel pass against
the numpy definition, and the value on a plane whose depth moves at a known rate; the image noise at each
pixel's threshold (linear_noise_at_threshold), the kernel's lookup against numpy's."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.camera.models import OpenCVCamera
from gnomon.capture.tracking import decoding_lut
from gnomon.errors import KernelParameterError
from gnomon.geometry.triangulation import triangulate
from gnomon.geometry.uncertainty import (
    _depth_sigma_numpy,
    _linear_noise_at_threshold_numpy,
    depth_sigma,
    linear_noise_at_threshold,
)


def _scene(seed: int) -> tuple[np.ndarray, ...]:
    """A 40×30 camera, planes turning about the y axis through Z = 500 (rows 0..11, rows 4 and 9
    missing), times between and on the rows (some NaN, some outside), line σ with NaN rows."""
    rng = np.random.default_rng(seed)
    cam = OpenCVCamera(40, 30, 40.0, 40.0, 19.5, 14.5, dist=np.array([-0.1, 0.02, 0.0, 0.0, 0.0]))
    rays = cam.ray_map().astype(np.float64)
    n = 12
    angle = np.radians(np.linspace(30.0, 60.0, n))
    normal = np.c_[np.cos(angle), np.zeros(n), -np.sin(angle)]
    planes = np.c_[normal, normal @ np.array([0.0, 0.0, 500.0])]
    planes[[4, 9]] = np.nan
    times = rng.uniform(-0.5, n - 0.5, (30, 40)).astype(np.float32)
    times[::5, ::3] = np.floor(times[::5, ::3])
    times[::7, ::2] = np.nan
    depth = triangulate(rays, times, planes).depth
    depth[::6, ::5] = np.nan  # screened out
    sigma_t = rng.uniform(0.01, 0.3, (30, 40)).astype(np.float32)
    line = rng.uniform(0.01, 0.1, n)
    line[[2, 7]] = np.nan
    return rays, times, planes, depth, sigma_t, line


def test_kernel_depth_sigma_equals_the_numpy_definition() -> None:
    """Every field bit for bit, on maps with missing times, planes, depths and line σ (also with no
    line σ at all: the fill is 0)."""
    for seed in range(3):
        rays, times, planes, depth, sigma_t, line = _scene(seed)
        for lines in (line, np.full_like(line, np.nan)):
            got = depth_sigma(rays, times, planes, depth, sigma_t, lines)
            want = _depth_sigma_numpy(rays, times, planes, depth, sigma_t, lines)
            assert np.isfinite(want.sigma_z).sum() > 300
            for field in ("sigma_z", "dz_dt", "sigma_t_line", "sigma_t_pixel"):
                a, b = getattr(got, field), getattr(want, field)
                assert a.dtype == b.dtype == np.float32
                np.testing.assert_array_equal(a, b, err_msg=field)


def test_sigma_of_a_plane_moving_at_a_known_rate() -> None:
    """Planes Z = 400 + 2·t (frame t): every depth changes by 2 per frame, so σZ = 2·sqrt(σt² + σline²)
    within the f32 depths' round-off (≈ 4e-5 at Z = 400, over the 0.5-frame difference)."""
    cam = OpenCVCamera(20, 10, 30.0, 30.0, 9.5, 4.5)
    rays = cam.ray_map().astype(np.float64)
    t = np.arange(10.0)
    planes = np.c_[np.zeros((10, 2)), np.ones(10), 400.0 + 2.0 * t]
    times = np.full((10, 20), 4.5, np.float32)
    depth = triangulate(rays, times, planes).depth
    sigma_t = np.full((10, 20), 0.3, np.float32)
    line = np.full(10, 0.4)
    got = depth_sigma(rays, times, planes, depth, sigma_t, line)
    # dZ/dt along each ray: 2 per frame in Z
    np.testing.assert_allclose(got.dz_dt, 2.0, atol=2e-4)
    np.testing.assert_allclose(got.sigma_z, 2.0 * np.hypot(0.3, 0.4), atol=2e-4)


def test_a_ray_that_leaves_the_planes_within_the_step_has_a_large_sigma() -> None:
    """Between rows 0 and 1 the plane is n·X = d with n = (1, 0, 0.016·(0.75 − t)), d = t − 0.375: the
    ray along the optical axis meets it at Z = d / n_z = 31.25 at t = 0.5, behind the camera at
    t = 0.25, and lies in it at t = 0.75, so neither t ± 0.25 gives a depth. ∂Z/∂t there is
    0.375 / (0.016·(0.75 − t)²) = 375 per frame: σZ = 375·σt, not the typical σ a missing one gets
    (σt 0.1 frame: 37.5). The kernel and the numpy definition agree bit for bit, on the other pixels
    of a map too (their steps of 0.25 frame exist: unchanged)."""
    cam = OpenCVCamera(9, 9, 20.0, 20.0, 4.0, 4.0)
    rays = cam.ray_map().astype(np.float64)
    planes = np.array([[1.0, 0.0, 0.012, -0.375], [1.0, 0.0, -0.004, 0.625]])
    times = np.full((9, 9), 0.5, np.float32)
    depth = triangulate(rays, times, planes).depth
    assert abs(depth[4, 4] - 31.25) < 0.01
    sigma_t = np.full((9, 9), 0.1, np.float32)
    got = depth_sigma(rays, times, planes, depth, sigma_t, np.zeros(2))
    want = _depth_sigma_numpy(rays, times, planes, depth, sigma_t, np.zeros(2))
    assert abs(got.dz_dt[4, 4] - 375.0) < 1.0 and abs(got.sigma_z[4, 4] - 37.5) < 0.1
    for field in ("sigma_z", "dz_dt"):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    assert np.isfinite(want.sigma_z[np.isfinite(depth)]).all()


# --------------------------------------------------------------------------- time scatter the noise misses


def test_unmodelled_time_scatter_is_what_the_lines_show_beyond_the_noise() -> None:
    from gnomon.geometry.validity import LineResiduals, unmodelled_time_scatter

    desk = LineResiduals("desk", residual_frames=0.25, expected_frames=0.07, frames=40)
    wall = LineResiduals("wall", residual_frames=0.5, expected_frames=0.3, frames=40)
    assert unmodelled_time_scatter([desk]) == pytest.approx(0.24)  # sqrt(0.25² − 0.07²)
    assert unmodelled_time_scatter([desk, wall, None]) == pytest.approx(0.24)  # the smaller: 0.24 < 0.4
    assert unmodelled_time_scatter([LineResiduals("desk", 0.05, 0.07, 40)]) == 0.0  # the noise explains it
    assert unmodelled_time_scatter([None]) == 0.0 and unmodelled_time_scatter([]) == 0.0


def test_a_time_error_no_image_noise_explains_reaches_the_depth_sigma(tmp_path) -> None:
    import json

    from conftest import write_tiny_capture
    from gnomon.cli import main

    def scan(jitter: float) -> tuple[dict, np.ndarray, np.ndarray]:
        log = write_tiny_capture(tmp_path / f"j{jitter}", n_frames=96, time_jitter_frames=jitter, noise_dn=0.5)
        out = tmp_path / f"j{jitter}_scan"
        assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0
        report = json.loads((out / "report.json").read_text())
        depth, sigma = np.load(out / "depth.npy"), np.load(out / "sigma.npy")
        ok = np.isfinite(depth)
        return report, np.abs(depth[ok] - 500.0), sigma[ok]  # the desk is 500 mm under the camera

    clean, err0, sig0 = scan(0.0)
    assert all(clean["edges"][e]["unmodelled_sigma_t_frames"] == 0.0 for e in ("enter", "leave"))
    assert 1.4826 * np.median(err0 / sig0) < 1.5  # the noise model alone is right here
    # Every pixel sees the band 0.3 frame (1σ) early or late. The lines' crossings are interpolated
    # between neighbouring pixels, which averages two pixels' errors: they show about 0.3/√2.
    jittered, err, sig = scan(0.3)
    for e in ("enter", "leave"):
        assert 0.15 < jittered["edges"][e]["unmodelled_sigma_t_frames"] < 0.35
    assert np.median(sig) > 5 * np.median(sig0)
    # σZ now carries the scatter: the errors are a few σ, not tens (without it, ≈ 10 σ at the median)
    assert 1.4826 * np.median(err / sig) < 2.5
    assert np.median(err) > 5 * np.median(sig0)  # and the error is real


def test_noise_at_threshold_from_the_kernel_equals_numpys_searchsorted() -> None:
    """float32 levels against sRGB, gamma and linear tables (uint8 and uint16), the tables' own entries and
    their float32 neighbours, NaN and ±inf included: the kernel's lookup gives numpy's values bit for bit; an
    unsorted table is refused by the kernel (and left to numpy by the function)."""
    rng = np.random.default_rng(5)
    for lut in (decoding_lut("srgb", np.uint8), decoding_lut(2.2, np.uint16), decoding_lut(1.0, np.uint8)):
        values = rng.uniform(-0.1, 1.1, 30000).astype(np.float32)
        picks = lut[rng.integers(0, len(lut), 3000)]
        values[:3000] = picks
        values[3000:6000] = np.nextafter(picks, np.float32(2.0))
        values[6000:9000] = np.nextafter(picks, np.float32(-1.0))
        values[9000:9003] = [np.nan, np.inf, -np.inf]
        values = values.reshape(150, 200)
        for sigma_dn in (1.7, 0.4):
            got = linear_noise_at_threshold(sigma_dn, values, lut)
            want = _linear_noise_at_threshold_numpy(sigma_dn, values, lut)
            assert got.dtype == np.float32 and got.shape == values.shape
            assert got.tobytes() == want.tobytes()
    unsorted = np.array([0.0, 0.5, 0.25], np.float32)
    with pytest.raises(KernelParameterError):
        _kernel.lut_lookup(unsorted, np.zeros(3), 1.0, np.zeros(4, np.float32))
    values = np.array([[0.1, 0.3, 0.6]], np.float32)
    assert np.array_equal(linear_noise_at_threshold(2.0, values, unsorted),
                          _linear_noise_at_threshold_numpy(2.0, values, unsorted))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_interpolation_time_sigma_is_its_formula_bit_for_bit(dtype) -> None:
    """interpolation_time_sigma (computed in place in one array) is 0.035·(1.5 / max(w, 0.5))³ with
    w = contrast / slope where the slope is positive, NaN elsewhere, as float32, bit for bit: float32 and
    float64 inputs, zero, negative and NaN slopes, edges shorter than half a frame (the floor)."""
    from gnomon.geometry.uncertainty import interpolation_time_sigma

    rng = np.random.default_rng(2)
    contrast = rng.uniform(0.0, 2.0, (60, 70)).astype(dtype)
    slope = rng.uniform(-0.2, 3.0, (60, 70)).astype(dtype)
    slope[::7, ::5] = 0.0
    slope[1::9, ::4] = np.nan
    contrast[2::11, ::3] = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(slope > 0, contrast / slope, np.nan)
        want = (0.035 * (1.5 / np.maximum(w, 0.5)) ** 3).astype(np.float32)
    got = interpolation_time_sigma(contrast, slope)
    assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
    assert np.isnan(got).any() and (got == np.float32(0.035 * 27)).any()  # NaN slopes, the half-frame floor
