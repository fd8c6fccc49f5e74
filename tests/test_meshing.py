"""Grid mesh and neighbour-support filtering."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.errors import GnomonError
from gnomon.geometry.meshing import grid_mesh, non_manifold_vertex_count
from gnomon.geometry.triangulation import supported_by_neighbours


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


# ---------------------------------------------------------------- kernel against numpy

def _bumpy_surface(seed: int, h: int = 40, w: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float32 depth (steps, holes, single missing pixels that leave bow-ties), σ and validity."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:h, 0:w]
    depth = (500 + 0.5 * u + 30 * (u > w // 2) + 8 * np.sin(v / 3) + rng.normal(0, 0.3, (h, w))).astype(np.float32)
    valid = rng.random((h, w)) > 0.12
    valid[5:9, 5:30] = False
    sigma = rng.uniform(0.05, 2.0, (h, w)).astype(np.float32)
    sigma[rng.random((h, w)) < 0.02] = np.nan
    return np.where(valid, depth, np.nan).astype(np.float32), sigma, valid


def test_kernel_faces_and_clean_up_equal_the_numpy_definitions() -> None:
    from gnomon.geometry.meshing import _grid_faces_numpy, _remove_small_components_numpy, remove_small_components

    for seed in range(4):
        depth, sigma, valid = _bumpy_surface(seed)
        mesh = grid_mesh(grid_points(depth), depth, valid, 0.02, sigma=sigma)
        np.testing.assert_array_equal(mesh.faces, _grid_faces_numpy(depth, valid, 0.02, sigma, 5.0))
        assert non_manifold_vertex_count(mesh.faces) > 0  # the split of bow-ties is exercised
        for min_vertices in (1, 5, 50):
            ref = _remove_small_components_numpy(mesh, min_vertices)
            # the edges bucketed (any mesh), and found by their place on the pixel grid (width given)
            for fast in (remove_small_components(mesh, min_vertices),
                         remove_small_components(mesh, min_vertices, width=valid.shape[1])):
                np.testing.assert_array_equal(fast.faces, ref.faces)
                np.testing.assert_array_equal(fast.pixel_index, ref.pixel_index)
                np.testing.assert_array_equal(fast.vertices, ref.vertices)
                assert non_manifold_vertex_count(fast.faces) == 0


def test_clean_up_on_the_grid_falls_back_for_a_mesh_off_it() -> None:
    from gnomon import _kernel
    from gnomon.geometry.meshing import GridMesh, _remove_small_components_numpy, remove_small_components

    depth, sigma, valid = _bumpy_surface(7)
    mesh = grid_mesh(grid_points(depth), depth, valid, 0.02, sigma=sigma)
    n, w = len(mesh.vertices), valid.shape[1]
    # a face joining far pixels (no grid step): the same pieces as the numpy definition finds
    far = np.vstack([mesh.faces, [[0, n // 2, n - 1]]]).astype(np.int32)
    off = GridMesh(mesh.vertices, far, mesh.pixel_index, mesh.normals)
    ref = _remove_small_components_numpy(off, 5)
    fast = remove_small_components(off, 5, width=w)
    np.testing.assert_array_equal(fast.faces, ref.faces)
    np.testing.assert_array_equal(fast.pixel_index, ref.pixel_index)
    assert len(ref.faces) > 0
    with pytest.raises(Exception, match="pixels"):
        _kernel.clean_faces(n, far, 5, mesh.pixel_index[1:].astype(np.int64), w)


def test_kernel_obj_text_equals_the_numpy_text() -> None:
    from gnomon import _kernel
    from gnomon.outputs.obj import _decimals_for, _obj_body_numpy

    rng = np.random.default_rng(3)
    v = rng.normal(0, 1, (300, 3)) * np.array([1.0, 1e3, 1e-3])
    v[5] = [np.nan, -0.0, np.inf]
    v[6] = [-0.00000001, 123456.5, -999.99999]
    f = rng.integers(0, len(v), (500, 3))
    uv = rng.random((300, 2))
    nrm = rng.normal(0, 1, (300, 3))
    for t in (None, uv):
        for n in (None, nrm):
            fast = _kernel.obj_text(v, _decimals_for(v), t, n, f)
            assert fast == _obj_body_numpy(v, f, t, n)


def _normals_by_loops(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, centre: np.ndarray,
                      jump: float) -> np.ndarray:
    """grid_normals written out pixel by pixel: the tangent along each axis from the neighbours
    within the depth jump (central, else one-sided), their cross product towards the camera."""
    h, w = valid.shape
    out = np.full((h, w, 3), np.nan)
    p = points.astype(np.float64)
    z = depth.astype(np.float64)

    def near(v: int, u: int, v0: int, u0: int) -> bool:
        return 0 <= v < h and 0 <= u < w and bool(valid[v, u]) and abs(z[v, u] - z[v0, u0]) <= jump * abs(z[v0, u0])

    for v in range(h):
        for u in range(w):
            if not valid[v, u]:
                continue
            tangents = []
            for dv, du in ((0, 1), (1, 0)):
                lo, hi = near(v - dv, u - du, v, u), near(v + dv, u + du, v, u)
                if lo and hi:
                    tangents.append(p[v + dv, u + du] - p[v - dv, u - du])
                elif hi:
                    tangents.append(p[v + dv, u + du] - p[v, u])
                elif lo:
                    tangents.append(p[v, u] - p[v - dv, u - du])
                else:
                    tangents.append(np.full(3, np.nan))
            to_cam = centre - p[v, u]
            to_cam = to_cam / np.sqrt(to_cam @ to_cam)
            n = np.cross(tangents[0], tangents[1])
            length = np.sqrt(n @ n)
            n = n / length if np.isfinite(n).all() and length > 0 else to_cam
            out[v, u] = -n if n @ to_cam < 0 else n
    return out


def test_kernel_grid_normals_equal_a_per_pixel_computation() -> None:
    from gnomon.geometry.meshing import _grid_normals_numpy, grid_normals

    centre = np.array([20.0, -15.0, -400.0])
    for seed in range(3):
        depth, _, valid = _bumpy_surface(seed, h=23, w=31)
        points = grid_points(depth).astype(np.float32)
        points[~valid] = np.nan
        fast = grid_normals(points, depth, valid, centre, 0.02)
        assert fast.dtype == np.float32 and fast.shape == (23, 31, 3)
        slow = _normals_by_loops(points, depth, valid, centre, 0.02)
        # f64 arithmetic in both, rounded to float32 once: a few float32 ulps
        np.testing.assert_allclose(fast, slow, rtol=0, atol=2e-7)
        np.testing.assert_array_equal(np.isnan(fast), ~valid[..., None].repeat(3, axis=2))
        np.testing.assert_allclose(fast, _grid_normals_numpy(points, depth, valid, centre, 0.02), rtol=0, atol=2e-7)
        # every case occurs: central, one-sided and no tangent (isolated pixels face the camera)
        lengths = np.linalg.norm(fast[valid], axis=1)
        np.testing.assert_allclose(lengths, 1.0, atol=1e-6)


def test_kernel_world_points_equal_the_camera_points_moved_to_the_world() -> None:
    """build_surface's world points (the kernel, per pixel) are points_from_depth then Pose.camera_to_world."""
    from gnomon import _kernel
    from gnomon.camera.models import Pose
    from gnomon.geometry.surface import points_from_depth

    rng = np.random.default_rng(3)
    h, w = 17, 29
    rays = rng.normal(0, 0.3, (h, w, 3)) + np.array([0.0, 0.0, 1.0])
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    depth = rng.uniform(300, 700, (h, w)).astype(np.float32)
    valid = rng.random((h, w)) < 0.8
    depth[~valid & (rng.random((h, w)) < 0.5)] = np.nan
    pose = Pose.from_rvec_tvec(np.array([2.4, 0.06, -0.04]), np.array([-3.0, 5.0, 650.0]))
    fast = _kernel.world_points(rays, depth, valid.astype(np.uint8), pose.R, pose.t)
    assert fast.dtype == np.float32 and fast.shape == (h, w, 3)
    slow = pose.camera_to_world(points_from_depth(rays, depth)[valid].astype(np.float64)).astype(np.float32)
    # the same f64 arithmetic (the sum over the rotation in another order), rounded to float32 once
    np.testing.assert_allclose(fast[valid], slow, rtol=2e-7, atol=1e-5)
    assert np.isnan(fast[~valid]).all()
    with pytest.raises(GnomonError):
        _kernel.world_points(rays[:, :-1], depth, valid.astype(np.uint8), pose.R, pose.t)


def test_kernel_stl_records_equal_a_per_face_computation(tmp_path) -> None:
    from gnomon.outputs.stl import _stl_table_numpy, write_stl

    rng = np.random.default_rng(7)
    v = (rng.normal(0, 1, (60, 3)) * np.array([10.0, 1.0, 100.0])).astype(np.float32)
    f = rng.integers(0, len(v), (200, 3)).astype(np.int32)
    f[3] = [4, 4, 9]  # degenerate: zero normal
    write_stl(tmp_path / "m.stl", v, f, header="test")
    data = (tmp_path / "m.stl").read_bytes()
    assert data[:4] == b"test" and len(data) == 84 + 50 * len(f)
    assert int(np.frombuffer(data[80:84], "<u4")[0]) == len(f)
    rec = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
    np.testing.assert_array_equal(rec["v"], v[f])
    assert not rec["attr"].any()
    for k, (a, b, c) in enumerate(v[f].astype(np.float64)):
        n = np.cross(b - a, c - a)
        length = np.sqrt(n @ n)
        expect = n / length if length > 0 else np.zeros(3)
        np.testing.assert_allclose(rec["n"][k], expect, rtol=0, atol=1e-5)
    assert np.array_equal(rec["n"][3], np.zeros(3, np.float32))
    assert data[84:] == _stl_table_numpy(v, f).tobytes()


def test_kernel_fusion_equals_fuse_depths_then_neighbour_support() -> None:
    """_kernel.fuse_supported is fuse_depths (Gaussian weights) then supported_by_neighbours: random
    depths with missing estimates, conflicts, isolated pixels and a depth step."""
    from gnomon import _kernel
    from gnomon.reconstruct.fusion import fuse_depths

    rng = np.random.default_rng(8)
    h, w = 33, 41
    for k in (1, 2, 3):
        base = np.where(np.arange(w)[None, :] < 20, 500.0, 620.0) + rng.normal(0, 0.5, (h, w))
        depths = (base[None] + rng.normal(0, 0.3, (k, h, w))).astype(np.float32)
        sigmas = rng.uniform(0.05, 0.5, (k, h, w)).astype(np.float32)
        depths[rng.random((k, h, w)) < 0.15] = np.nan
        sigmas[rng.random((k, h, w)) < 0.05] = 0.0  # no estimate
        depths[0][rng.random((h, w)) < 0.05] += 60.0  # conflicts with the others
        depths[:, 5, 5] = 900.0  # isolated: no neighbour shares it
        fused, sigma, conflict = fuse_depths(list(depths), list(sigmas), 0.02)
        keep = supported_by_neighbours(fused, 0.02)
        got_depth, got_sigma, code = _kernel.fuse_supported(depths, sigmas, 0.02)
        np.testing.assert_array_equal(got_depth, np.where(keep, fused, np.nan).astype(np.float32))
        np.testing.assert_array_equal(got_sigma, np.where(keep, sigma, np.nan).astype(np.float32))
        np.testing.assert_array_equal(code == 2, conflict)
        np.testing.assert_array_equal(code == 3, np.isfinite(fused) & ~keep)
        assert (code == 3).any() and (k == 1 or conflict.any())
