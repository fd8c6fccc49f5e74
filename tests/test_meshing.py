"""Grid mesh and neighbour-support filtering."""

from __future__ import annotations

import numpy as np

from gnomon.meshing import grid_mesh
from gnomon.triangulation import supported_by_neighbours


def grid_points(depth: np.ndarray) -> np.ndarray:
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([u, v, depth], axis=-1)


def test_flat_grid_gives_two_triangles_per_quad() -> None:
    depth = np.full((5, 7), 100.0)
    valid = np.ones_like(depth, dtype=bool)
    mesh = grid_mesh(grid_points(depth), depth, valid, 0.02)
    assert len(mesh.vertices) == 35
    assert len(mesh.faces) == 2 * 4 * 6
    # every face is counter-clockwise in the image (u right, v down): positive cross z in (u, -v)
    v = mesh.vertices
    a, b, c = v[mesh.faces[:, 0]], v[mesh.faces[:, 1]], v[mesh.faces[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert np.all(cross > 0) or np.all(cross < 0)


def test_mesh_is_cut_at_a_depth_step() -> None:
    depth = np.full((4, 8), 100.0)
    depth[:, 4:] = 150.0  # a 50 % step between columns 3 and 4
    valid = np.ones_like(depth, dtype=bool)
    mesh = grid_mesh(grid_points(depth), depth, valid, 0.02)
    assert len(mesh.faces) == 2 * 3 * 3 * 2  # two 4x4 halves, none across the step
    z = mesh.vertices[:, 2][mesh.faces]
    assert np.all(z.max(axis=1) - z.min(axis=1) < 1.0)


def test_invalid_pixels_leave_holes() -> None:
    depth = np.full((3, 3), 100.0)
    valid = np.ones_like(depth, dtype=bool)
    valid[1, 1] = False
    depth[1, 1] = np.nan
    mesh = grid_mesh(grid_points(depth), depth, valid, 0.02)
    # one triangle per quad survives: the one without the hole
    assert len(mesh.vertices) == 8 and len(mesh.faces) == 4
    assert 4 not in mesh.pixel_index[mesh.faces]


def test_isolated_spike_is_rejected_but_a_step_is_kept() -> None:
    depth = np.full((9, 9), 100.0, dtype=np.float32)
    depth[:, 5:] = 130.0
    depth[2, 2] = 160.0  # a lone wrong depth
    keep = supported_by_neighbours(depth, 0.02)
    assert not keep[2, 2]
    keep[2, 2] = True
    assert keep.all()
