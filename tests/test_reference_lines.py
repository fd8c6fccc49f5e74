"""Shadow lines on a reference plane from the shadow-time map (isochrones)."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.camera.models import OpenCVCamera, Pose
from gnomon.geometry.reference_lines import (
    PlaneInCamera,
    ReferencePlane,
    fit_line_robust,
    isochrone_crossings,
    measure_reference_lines,
    region_mask,
)
from gnomon.light.shadow_planes import lamp_shadow_planes

CAMERA = OpenCVCamera(160, 120, 150.0, 152.0, 80.3, 59.1, (-0.2, 0.08, 0.001, -0.002, 0.0))
# Camera 400 mm above the desk, tilted 20° about x.
POSE = Pose.from_rvec_tvec(np.array([np.pi + np.radians(20), 0, 0]), np.array([10.0, 30.0, 420.0]))
X0, SPEED = -150.0, 5.0  # world x of the shadow line at frame 0, mm per frame


def desk_times() -> np.ndarray:
    """Exact shadow times of a line x = X0 + SPEED·t sweeping the desk (z = 0)."""
    rays = CAMERA.ray_map().reshape(-1, 3)
    n = POSE.R @ np.array([0, 0, 1.0])
    d = n @ POSE.t
    pts_cam = rays * (d / (rays @ n))[:, None]
    pts = POSE.camera_to_world(pts_cam)
    return ((pts[:, 0] - X0) / SPEED).reshape(CAMERA.height, CAMERA.width)


def test_crossings_on_a_ramp() -> None:
    times = np.tile(np.arange(10) * 0.4, (3, 1))  # 0, 0.4, ..., 3.6 along each row
    f, u, v = isochrone_crossings(times, n_frames=5)
    # frames 0..3 cross each row once, at u = t / 0.4
    assert sorted(set(f.tolist())) == [0, 1, 2, 3]
    np.testing.assert_allclose(u, f / 0.4, atol=1e-12)
    assert len(f) == 4 * 3


def test_robust_line_ignores_outliers() -> None:
    rng = np.random.default_rng(1)
    s = np.linspace(-50, 50, 200)
    xy = np.stack([3 + 0.6 * s, -2 + 0.8 * s], axis=1) + rng.normal(0, 0.01, (200, 2))
    xy[::10] += rng.normal(0, 20, (20, 2))  # 10 % gross outliers
    c, d, inl = fit_line_robust(xy)
    assert abs(abs(d @ np.array([0.6, 0.8])) - 1) < 1e-5
    assert inl.sum() >= 175 and not inl[::10].all()


def test_lines_recover_the_world_line_through_distortion() -> None:
    times = desk_times()
    rng = np.random.default_rng(0)
    corrupt = rng.random(times.shape) < 0.01
    times[corrupt] += rng.normal(0, 10, corrupt.sum())  # wrong shadow times
    spec = ReferencePlane("desk", PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE),
                          region_mask((120, 160), [(0, 0, 160, 15), (0, 100, 160, 120)]))
    n_frames = 60
    lines = measure_reference_lines(times, n_frames, spec, CAMERA)
    found = np.flatnonzero(lines.found)
    assert len(found) > 40
    for t in found:
        p_world = POSE.camera_to_world(lines.point[t])
        d_world = POSE.R.T @ lines.direction[t]
        assert abs(p_world[2]) < 1e-6  # on the desk
        assert p_world[0] == pytest.approx(X0 + SPEED * t, abs=0.02)  # 0.02 mm ≪ a pixel (~2.7 mm)
        assert abs(abs(d_world[1]) - 1) < 1e-6  # along world y


def test_lamp_planes_contain_lamp_and_line() -> None:
    times = desk_times()
    spec = ReferencePlane("desk", PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE),
                          region_mask((120, 160), [(0, 0, 160, 15), (0, 100, 160, 120)]))
    lines = measure_reference_lines(times, 60, spec, CAMERA)
    lamp_world = np.array([-300.0, 0.0, 500.0])
    lamp_cam = POSE.world_to_camera(lamp_world)
    planes, degenerate = lamp_shadow_planes([lines], lamp_cam)
    assert degenerate == 0
    for t in np.flatnonzero(lines.found):
        n, d = planes[t, :3], planes[t, 3]
        assert abs(np.linalg.norm(n) - 1) < 1e-12
        assert abs(n @ lamp_cam - d) < 1e-9
        for s in (-100.0, 100.0):
            q = lines.point[t] + s * lines.direction[t]
            assert abs(n @ q - d) < 1e-9
    # consistently oriented normals, so interpolation between frames is safe
    valid = planes[np.isfinite(planes[:, 0])]
    assert np.all(np.sum(valid[1:, :3] * valid[:-1, :3], axis=1) > 0)


def test_one_fit_over_a_mask_with_holes_and_a_gap() -> None:
    """Regions of any shape are one set: a polygon with a hole (a marker) and a
    disjoint rectangle give one line per frame, fitted over all crossings."""
    from gnomon.geometry.reference_lines import lines_on_plane, region_mask

    times = desk_times()
    poly = np.array([[5.0, 2.0], [150.0, 2.0], [150.0, 40.0], [5.0, 40.0]])
    mask = region_mask(times.shape, rectangles=[(0, 95, 160, 120)], polygons=[poly])
    mask[10:30, 60:90] = False  # a marker punched out of the polygon
    assert mask[20, 20] and not mask[20, 70] and not mask[60, 80] and mask[100, 80]
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE)
    lines = lines_on_plane(times, 60, plane, mask, CAMERA, "desk")
    found = np.flatnonzero(lines.found & ~lines.extrapolated)
    assert len(found) > 40
    for t in found:
        p_world = POSE.camera_to_world(lines.point[t])
        assert p_world[0] == pytest.approx(X0 + SPEED * t, abs=0.02)
        # judged by extent: the line runs through both areas (and across the hole)
        assert lines.extent[t] > 0.5 * np.nanmax(lines.extent)


def test_short_lines_take_their_direction_from_neighbours() -> None:
    """A line seen only over a short stretch (most of it hidden) is not trusted
    for its direction: that comes from the neighbouring long lines, and its
    offset is still measured."""
    from gnomon.geometry.reference_lines import PlaneInCamera, lines_on_plane

    times = desk_times()
    rng = np.random.default_rng(3)
    # Mostly hidden for the frames 25..35: only a short stretch of the line is bare.
    hidden = (times > 25) & (times < 35)
    hidden[:, :] &= np.arange(times.shape[0])[:, None] > 20
    times = times + rng.normal(0, 0.01, times.shape)
    times[hidden] = np.nan
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE)
    lines = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk")
    short = [t for t in range(27, 34) if lines.found[t]]
    assert short and all(lines.extrapolated[t] for t in short)
    for t in short:
        d_world = POSE.R.T @ lines.direction[t]
        assert abs(abs(d_world[1]) - 1) < 1e-4
        assert POSE.camera_to_world(lines.point[t])[0] == pytest.approx(X0 + SPEED * t, abs=0.1)


def test_kernel_fits_equal_the_numpy_fits() -> None:
    """The kernel's per-frame fits (``_kernel.frame_lines``) give the numpy definition's lines: the same
    frames, inliers, pixels and points, the same sense, points and directions within 1e-12 mm (1e-12)
    and RMS and extents within round-off; on noisy times with a hidden stretch (extrapolated frames),
    then with wrong times in 1 % of the pixels and the sweep reversed."""
    from gnomon.geometry.reference_lines import PlaneInCamera, lines_on_plane

    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE)
    for seed, sign, outliers in ((0, 1.0, 0.0), (1, -1.0, 0.01)):
        rng = np.random.default_rng(seed)
        times = desk_times()
        times = (times if sign > 0 else 40.0 - times) + rng.normal(0, 0.05, times.shape)
        wrong = rng.random(times.shape) < outliers
        times[wrong] = rng.uniform(0, 40, wrong.sum())
        times[(times > 25) & (times < 35) & (np.arange(120)[:, None] > 20)] = np.nan
        got = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk")
        want = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk", kernel=False)
        assert got.found.sum() > 30 and (got.extrapolated.any() or outliers)
        np.testing.assert_array_equal(got.found, want.found)
        np.testing.assert_array_equal(got.extrapolated, want.extrapolated)
        np.testing.assert_array_equal(got.count, want.count)
        np.testing.assert_allclose(got.point, want.point, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.direction, want.direction, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.rms, want.rms, rtol=1e-10)
        np.testing.assert_allclose(got.extent, want.extent, rtol=1e-12)
        for a, b in zip(got.pixels + got.points, want.pixels + want.points, strict=True):
            np.testing.assert_array_equal(a, b)


def test_speeds_are_each_frames_speed() -> None:
    """ReferenceLines.speeds() gives speed(t) of every frame bit for bit (the first and last lines have one
    neighbour, the frames next to a missing line one), and the sweep's 5 mm per frame."""
    from gnomon.geometry.reference_lines import PlaneInCamera, lines_on_plane

    times = desk_times() + np.random.default_rng(2).normal(0, 0.02, (120, 160))
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE)
    lines = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk")
    lines.point[30] = np.nan  # a frame without a line
    speeds = lines.speeds()
    want = np.array([lines.speed(t) for t in range(60)])
    np.testing.assert_array_equal(speeds, want)
    found = np.flatnonzero(lines.found)
    assert len(found) > 40
    np.testing.assert_allclose(speeds[found], SPEED, rtol=0.02)


def test_kernel_crossings_equal_the_numpy_definition() -> None:
    """The kernel's isochrone crossings are the numpy definition's, value for value and in order: sweeps
    along the rows and along the columns, in both senses, with noise, wrong single-pixel times (lines
    crossing a frame twice), missing times and times outside the frames; with and without ``unique``."""
    from gnomon.geometry.reference_lines import _isochrone_crossings_numpy, isochrone_crossings

    rng = np.random.default_rng(5)
    v, u = np.mgrid[0:47, 0:63].astype(np.float64)
    for sweep in (0.3 * u + 0.05 * v, -0.3 * u + 20, 0.02 * u + 0.4 * v, -0.5 * v + 30, 0.4 * u - 3):
        times = (sweep + rng.normal(0, 0.05, sweep.shape)).astype(np.float32)
        wrong = rng.random(times.shape) < 0.02
        times[wrong] = rng.uniform(-2, 30, wrong.sum()).astype(np.float32)
        times[rng.random(times.shape) < 0.05] = np.nan
        for unique in (True, False):
            got = isochrone_crossings(times, 25, unique)
            want = _isochrone_crossings_numpy(times, 25, unique)
            assert len(want[0]) > 300
            for a, b in zip(got, want, strict=True):
                assert a.dtype == b.dtype
                np.testing.assert_array_equal(a, b)
    flat = np.full((5, 7), 3.0, np.float32)  # no step: no crossing
    assert all(len(x) == 0 for x in isochrone_crossings(flat, 10))
    assert all(len(x) == 0 for x in isochrone_crossings(np.zeros((0, 4), np.float32), 10))


def test_a_frame_whose_crossings_scatter_far_more_than_the_planes_lines_has_no_line() -> None:
    """Where a sweep stops, a frame's few crossings may line up only roughly (a real desk-lamp capture:
    25 crossings at 19-24 times the plane's typical line RMS): such a frame has no line, rather than a
    plane tens of mm off; the frames around keep theirs."""
    from gnomon.geometry.reference_lines import MAX_LINE_SCATTER, PlaneInCamera, lines_on_plane

    times = desk_times()
    rng = np.random.default_rng(5)
    times = times + rng.normal(0, 0.01, times.shape)  # 0.05 mm of line scatter
    late = (times > 40.5) & (times < 43.5)
    times[late] += rng.normal(0, 0.6, late.sum())  # frames 41..43: 3 mm of scatter
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0, 0, 1.0]), POSE)
    lines = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk")
    typical = float(np.nanmedian(lines.rms))
    assert not lines.found[41:44].any()
    assert lines.found[5:40].all() and np.nanmax(lines.rms) <= MAX_LINE_SCATTER * typical
    # the gate is what drops them: the same frames, unchecked, fit lines far more scattered
    unchecked = lines_on_plane(times, 60, plane, np.ones(times.shape, dtype=bool), CAMERA, "desk",
                               max_scatter=None)
    assert unchecked.found[41:44].all() and np.all(unchecked.rms[41:44] > MAX_LINE_SCATTER * typical)
