"""Frames whose shadow crossed one reference plane only get their plane from the light the others located."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines
from gnomon.geometry.validity import light_point_or_line
from gnomon.light.shadow_planes import complete_from_light


def _plane(normal, point) -> PlaneInCamera:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return PlaneInCamera(n, float(n @ np.asarray(point, float)), np.asarray(point, float), e1, np.cross(n, e1))


def _lines(reference: PlaneInCamera, shadow: np.ndarray, name: str) -> ReferenceLines:
    """Each shadow plane's exact line on ``reference`` (camera frame, mm)."""
    n = len(shadow)
    point, direction = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    for t, (a, b, c, d) in enumerate(shadow):
        m = np.array([a, b, c])
        u = np.cross(m, reference.normal)
        u /= np.linalg.norm(u)
        # the point of both planes nearest the reference plane's origin
        A = np.array([m, reference.normal, u])
        point[t] = np.linalg.solve(A, [d, reference.offset, u @ reference.origin])
        direction[t] = u
    return ReferenceLines(name, reference, point, direction, np.zeros(n), np.full(n, 50), [np.zeros((0, 2))] * n,
                          np.zeros(n, bool), [np.zeros((0, 3))] * n)


@pytest.mark.parametrize("line_light", [False, True])
def test_one_line_frames_get_the_plane_through_the_light(line_light: bool) -> None:
    # camera frame: a desk below and ahead, a wall behind it (mm)
    desk = _plane([0.0, -0.9, -0.44], [0.0, 300.0, 1500.0])
    wall = _plane([0.0, 0.2, -1.0], [0.0, 0.0, 2000.0])
    lamp = np.array([600.0, -900.0, 1900.0])
    n = 40
    if line_light:  # a stick moved parallel to itself: every plane contains the lamp's line along the stick
        axis = np.array([0.1, 0.3, 1.0]) / np.linalg.norm([0.1, 0.3, 1.0])
        normals = [np.cross(axis, [np.cos(a), np.sin(a), 0.0]) for a in np.linspace(0.3, 1.2, n)]
    else:  # a stick turned about the lamp
        normals = [np.array([np.cos(a), 0.3 * np.sin(2 * a), np.sin(a)]) for a in np.linspace(0.2, 1.3, n)]
    normals = [m / np.linalg.norm(m) for m in normals]
    truth = np.array([[*m, m @ lamp] for m in normals])
    lines = [_lines(desk, truth, "desk"), _lines(wall, truth, "wall")]
    measured = truth.copy()
    measured[:6] = np.nan  # the shadow is on the wall only at the start …
    lines[0].point[:6] = np.nan
    measured[-4:] = np.nan  # … and on the desk only at the end
    lines[1].point[-4:] = np.nan
    est = light_point_or_line(measured)
    assert est.degenerate == line_light
    done, added = complete_from_light(measured, lines, est.point, est.direction)
    assert added == 10
    for t in [*range(6), *range(n - 4, n)]:
        sign = np.sign(done[t, :3] @ truth[t, :3])
        assert np.allclose(sign * done[t], truth[t], atol=1e-6)


def test_a_stick_tilting_a_little_completes_from_the_lamp_point() -> None:
    """A point lamp and a stick swept across the scene while its tilt drifts by 3° (the CMU frog's hand-held
    stick): every plane contains the lamp, and they nearly share one direction (the stick's), so the light
    estimate is degenerate (a line). Completing the one-line frames with that line makes each plane
    contain the stick's mean direction (the planes at the sweep's ends are off by a tenth of the drift or
    more); the lamp point, though poorly located along the stick, gives the exact plane. The choice is
    measured on the two-plane frames (each completed from one of its lines, the light located without it):
    the point wins, and the completed frames are exact (1e-6)."""
    from gnomon.light.shadow_planes import completion_light

    desk = _plane([0.0, -0.9, -0.44], [0.0, 300.0, 1500.0])
    wall = _plane([0.0, 0.2, -1.0], [0.0, 0.0, 2000.0])
    lamp = np.array([600.0, -900.0, 1900.0])
    n = 40
    axis = np.array([0.1, 0.3, 1.0]) / np.linalg.norm([0.1, 0.3, 1.0])
    side = np.cross(axis, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    drift = np.radians(3.0)
    normals = []
    for k, a in enumerate(np.linspace(0.3, 1.2, n)):
        stick = np.cos(drift * (k / (n - 1) - 0.5)) * axis + np.sin(drift * (k / (n - 1) - 0.5)) * side
        m = np.cross(stick, [np.cos(a), np.sin(a), 0.0])
        normals.append(m / np.linalg.norm(m))
    truth = np.array([[*m, m @ lamp] for m in normals])
    lines = [_lines(desk, truth, "desk"), _lines(wall, truth, "wall")]
    measured = truth.copy()
    measured[:6] = np.nan
    lines[0].point[:6] = np.nan
    measured[-4:] = np.nan
    lines[1].point[-4:] = np.nan
    assert light_point_or_line(measured).degenerate
    light = completion_light(measured, lines)
    assert light.model == "point" and light.direction is None
    assert light.errors_deg["point"] < 1e-4 < light.errors_deg["line"]
    done, added = complete_from_light(measured, lines, light.point, light.direction)
    assert added == 10
    est = light_point_or_line(measured)
    by_line, _ = complete_from_light(measured, lines, est.point, est.direction)
    for t in [*range(6), *range(n - 4, n)]:
        sign = np.sign(done[t, :3] @ truth[t, :3])
        assert np.allclose(sign * done[t], truth[t], atol=1e-6)
    off = [np.degrees(np.arccos(min(1.0, abs(by_line[t, :3] @ truth[t, :3])))) for t in (0, n - 1)]
    assert max(off) > 0.1 * np.degrees(drift)  # what the line model would have given: 0.29° and 0.42° here


def test_a_stick_moved_parallel_to_itself_completes_from_the_line() -> None:
    """The planes of a stick moved parallel to itself share its direction exactly: both models complete the
    two-plane frames exactly (the least-squares point lies on the line), so the tie keeps the line."""
    from gnomon.light.shadow_planes import completion_light

    desk = _plane([0.0, -0.9, -0.44], [0.0, 300.0, 1500.0])
    wall = _plane([0.0, 0.2, -1.0], [0.0, 0.0, 2000.0])
    lamp = np.array([600.0, -900.0, 1900.0])
    axis = np.array([0.1, 0.3, 1.0]) / np.linalg.norm([0.1, 0.3, 1.0])
    normals = [np.cross(axis, [np.cos(a), np.sin(a), 0.0]) for a in np.linspace(0.3, 1.2, 30)]
    truth = np.array([[*(m / np.linalg.norm(m)), (m / np.linalg.norm(m)) @ lamp] for m in normals])
    lines = [_lines(desk, truth, "desk"), _lines(wall, truth, "wall")]
    light = completion_light(truth, lines)
    assert light.errors_deg["line"] < 1e-4 and light.errors_deg["point"] < 1e-4
    assert light.model == "line" or light.errors_deg["point"] < light.errors_deg["line"]


def _rotate_about(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: ``v`` turned by ``angle`` (rad) about the unit ``axis``."""
    return v * np.cos(angle) + np.cross(axis, v) * np.sin(angle) + axis * (axis @ v) * (1 - np.cos(angle))


def test_completion_sigma_is_the_depth_change_of_the_plane_turned_about_its_line() -> None:
    """A completed plane is exact along its line and off by a turn about it. Turning the plane by a small
    angle about the line and intersecting each pixel's ray with both planes by hand gives the change of
    camera Z that :func:`completion_depth_sigma` predicts for a 1σ of that angle, at every distance from
    the line (first order: the second-order terms are ~angle·tan(ray-plane angle), under 1e-3 here), and
    the interpolated plane between a completed and a measured row carries its weight's share."""
    from gnomon.geometry.uncertainty import completion_depth_sigma

    angle = 1e-4
    p0 = np.array([0.0, 100.0, 1800.0])  # the completing line (camera frame, mm): a point and a direction
    u = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])
    normal = np.cross(u, [0.3, -1.0, 0.4])
    normal /= np.linalg.norm(normal)
    turned = _rotate_about(normal, u, angle)
    plane = np.array([*normal, normal @ p0])
    planes = np.stack([plane, plane])
    # pixels whose rays meet the plane 0–400 mm from the line on either side
    along = np.cross(normal, u)
    targets = [p0 + s * u + q * along for s in (-200.0, 0.0, 300.0) for q in (-400.0, -50.0, 0.0, 120.0, 400.0)]
    rays = np.array([x / np.linalg.norm(x) for x in targets])[None]
    depth = np.array([x[2] for x in targets])[None]
    z_turned = (turned @ p0) * rays[..., 2] / (rays @ turned)
    line_point, line_direction = np.stack([p0, np.full(3, np.nan)]), np.stack([u, np.full(3, np.nan)])
    at_row = completion_depth_sigma(rays, np.zeros(depth.shape), depth, planes, line_point, line_direction, angle)
    np.testing.assert_allclose(at_row, np.abs(z_turned - depth), rtol=1e-3, atol=1e-9)
    assert at_row.max() > 0.02  # 400 mm off the line at 1e-4 rad: tens of microns, not nothing
    between = completion_depth_sigma(rays, np.full(depth.shape, 0.25), depth, planes, line_point, line_direction,
                                     angle)
    np.testing.assert_allclose(between, 0.75 * at_row, rtol=1e-6)
    measured_only = completion_depth_sigma(rays, np.zeros(depth.shape), depth, planes, np.full((2, 3), np.nan),
                                           np.full((2, 3), np.nan), angle)
    assert np.all(measured_only == 0)


def test_kernel_completion_sigma_is_its_numpy_definition() -> None:
    """The kernel's completion σ (``_kernel.completion_sigma``) equals the numpy definition value for value,
    on rows completed and measured, times between them, at and beyond both ends and NaN, depths NaN, a
    missing plane row and a ray grazing its plane (the cosine floor)."""
    from gnomon.geometry.uncertainty import _completion_depth_sigma_numpy, completion_depth_sigma

    rng = np.random.default_rng(11)
    h, w, n = 37, 53, 9
    rays = rng.normal([0.0, 0.0, 1.0], [0.3, 0.3, 0.05], size=(h, w, 3))
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    times = rng.uniform(-1.5, n + 0.5, size=(h, w)).astype(np.float32)
    times[::5, ::3] = np.round(times[::5, ::3])  # whole rows
    times[3, :7] = [np.nan, np.inf, -np.inf, 0.0, n - 1, n - 1.25, n + 3.0]
    depth = rng.uniform(800.0, 2500.0, size=(h, w)).astype(np.float32)
    depth[::7, ::4] = np.nan
    normals = rng.normal(size=(n, 3)) * 2.0  # not unit: the definition normalises them
    planes = np.column_stack([normals, rng.uniform(-500.0, 500.0, n)])
    planes[4] = np.nan  # a missing row
    rays[5, 5] = np.cross(normals[2], [0.0, 1.0, 0.0]) / np.linalg.norm(np.cross(normals[2], [0.0, 1.0, 0.0]))
    times[5, 5] = 2.0  # its ray lies in row 2's plane: the cosine floor
    line_point = rng.uniform(-300.0, 300.0, size=(n, 3)) + [0.0, 0.0, 1500.0]
    line_direction = rng.normal(size=(n, 3))
    line_direction /= np.linalg.norm(line_direction, axis=1, keepdims=True)
    line_point[[1, 6, 7]] = np.nan  # measured rows
    line_direction[[1, 6, 7]] = np.nan
    kernel = completion_depth_sigma(rays, times, depth, planes, line_point, line_direction, 3e-3)
    reference = _completion_depth_sigma_numpy(rays, times, depth, planes, line_point, line_direction, 3e-3)
    assert kernel.dtype == np.float32 and kernel.shape == (h, w)
    np.testing.assert_array_equal(kernel, reference)
    assert np.count_nonzero(reference > 0) > h * w // 3  # most pixels involve a completed row
    for args in ((np.full((n, 3), np.nan), np.full((n, 3), np.nan), 3e-3), (line_point, line_direction, 0.0)):
        np.testing.assert_array_equal(completion_depth_sigma(rays, times, depth, planes, *args), 0.0)


def test_a_point_light_measures_its_completion_error() -> None:
    """When the two-plane frames fix the lamp as a point, the completion's error is measured all the same
    (leave one out), so the completed planes' σ has a size: exact lines complete exactly (< 1e-4°)."""
    from gnomon.light.shadow_planes import completion_light

    desk = _plane([0.0, -0.9, -0.44], [0.0, 300.0, 1500.0])
    wall = _plane([0.0, 0.2, -1.0], [0.0, 0.0, 2000.0])
    lamp = np.array([600.0, -900.0, 1900.0])
    normals = [np.array([np.cos(a), 0.3 * np.sin(2 * a), np.sin(a)]) for a in np.linspace(0.2, 1.3, 40)]
    truth = np.array([[*(m / np.linalg.norm(m)), (m / np.linalg.norm(m)) @ lamp] for m in normals])
    lines = [_lines(desk, truth, "desk"), _lines(wall, truth, "wall")]
    light = completion_light(truth, lines)
    assert light.model == "point" and not light_point_or_line(truth).degenerate
    assert 0 <= light.errors_deg["point"] < 1e-4
