"""Frames whose shadow crossed one reference plane only get their plane from the light the others located."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.reference_lines import PlaneInCamera, ReferenceLines
from gnomon.shadow_planes import complete_from_light
from gnomon.validity import light_point_or_line


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
