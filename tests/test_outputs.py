"""A scan's files, read by independent readers (plyfile, trimesh): normals, texture, STL, manifoldness."""

from __future__ import annotations

import json

import numpy as np
import plyfile
import pytest
import trimesh

from gnomon.camera.models import Pose


def _camera_centre(scan) -> np.ndarray:
    cam = json.loads((scan / "report.json").read_text())["camera"]
    pose = Pose.from_rvec_tvec(np.array(cam["pose"]["rvec"]), np.array(cam["pose"]["tvec"]))
    return pose.camera_centre_world


def _vertices(path) -> dict[str, np.ndarray]:
    v = plyfile.PlyData.read(str(path))["vertex"].data
    return {name: np.asarray(v[name]) for name in v.dtype.names}


def _non_manifold_vertices(faces: np.ndarray) -> int:
    """Vertices whose triangles form more than one fan (written out plainly, with a union-find)."""
    parent: dict[tuple[int, int], tuple[int, int]] = {}

    def find(c):
        while parent[c] != c:
            parent[c] = parent[parent[c]]
            c = parent[c]
        return c

    by_edge: dict[tuple[int, int], tuple[int, int]] = {}  # (vertex, other end) → a corner
    for fi, tri in enumerate(faces.tolist()):
        for k in range(3):
            corner = (fi, k)
            parent[corner] = corner
            v = tri[k]
            for other in (tri[(k + 1) % 3], tri[(k + 2) % 3]):
                seen = by_edge.setdefault((v, other), corner)
                if seen != corner:
                    parent[find(corner)] = find(seen)
    fans: dict[int, set] = {}
    for fi, tri in enumerate(faces.tolist()):
        for k in range(3):
            fans.setdefault(tri[k], set()).add(find((fi, k)))
    return sum(len(s) > 1 for s in fans.values())


@pytest.mark.slow
def test_points_have_unit_normals_towards_the_camera(desk_scan) -> None:
    scan = desk_scan / "scan"
    v = _vertices(scan / "points.ply")
    assert {"nx", "ny", "nz"} <= set(v)
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    n = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float64)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    to_cam = _camera_centre(scan) - xyz
    assert np.all(np.einsum("ij,ij->i", n, to_cam) > 0)
    # On the bare desk (world z = 0, z up) the normal is +z, tilted by the depth noise: σ over
    # the two-pixel baseline of a central difference, tan τ = √2·σ / (2·spacing).
    gt = np.load(desk_scan / "capture" / "ground_truth.npz")
    u, vv = np.rint(v["scalar_u"]).astype(int), np.rint(v["scalar_v"]).astype(int)
    desk = gt["object_id"][vv, u] == 0
    assert desk.sum() > 20_000
    grid = np.full((300, 400, 3), np.nan)
    grid[vv, u] = xyz
    spacing = np.nanmedian(np.linalg.norm(grid[:, 1:] - grid[:, :-1], axis=2))
    tau = np.degrees(np.arctan(np.sqrt(2) * np.median(v["scalar_sigma"][desk]) / (2 * spacing)))
    angle = np.degrees(np.arccos(np.clip(n[desk, 2], -1, 1)))
    assert np.median(angle) < 1.5 * tau, (np.median(angle), tau)
    # the noise averages out: the mean normal is +z within a degree
    mean = n[desk].mean(axis=0)
    assert np.degrees(np.arccos(mean[2] / np.linalg.norm(mean))) < 1.0


@pytest.mark.slow
def test_mesh_ply_normals_agree_with_the_faces(desk_scan) -> None:
    scan = desk_scan / "scan"
    data = plyfile.PlyData.read(str(scan / "mesh.ply"))
    v = data["vertex"].data
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    n = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float64)
    faces = np.stack(data["face"].data["vertex_indices"]).astype(np.int64)
    fn = np.cross(xyz[faces[:, 1]] - xyz[faces[:, 0]], xyz[faces[:, 2]] - xyz[faces[:, 0]])
    agree = np.einsum("ij,ij->i", fn, n[faces].mean(axis=1)) > 0
    assert agree.mean() > 0.999, agree.mean()
    assert np.all(np.einsum("ij,ij->i", n, _camera_centre(scan) - xyz) > 0)


@pytest.mark.slow
def test_mesh_has_no_non_manifold_vertex(desk_scan) -> None:
    data = plyfile.PlyData.read(str(desk_scan / "scan" / "mesh.ply"))
    faces = np.stack(data["face"].data["vertex_indices"]).astype(np.int64)
    assert len(faces) > 100_000
    assert _non_manifold_vertices(faces) == 0
    # the check itself finds a bow tie
    assert _non_manifold_vertices(np.array([[0, 1, 2], [0, 3, 4]])) == 1


@pytest.mark.slow
def test_obj_loads_with_its_texture_and_stl_with_its_faces(desk_scan) -> None:
    scan = desk_scan / "scan"
    ref = plyfile.PlyData.read(str(scan / "mesh.ply"))
    n_vertices, n_faces = ref["vertex"].count, ref["face"].count
    obj = trimesh.load(scan / "mesh.obj", process=False, maintain_order=True)
    assert isinstance(obj, trimesh.Trimesh)
    assert len(obj.vertices) == n_vertices and len(obj.faces) == n_faces
    assert obj.visual.kind == "texture"
    image = obj.visual.material.image
    assert image is not None and image.size == (400, 300)
    uv = np.asarray(obj.visual.uv)
    assert uv.shape == (n_vertices, 2) and uv.min() > 0 and uv.max() < 1
    # texture coordinates sample each vertex's own pixel: compare with the mesh.ply colours
    px = np.clip((uv[:, 0] * 400).astype(int), 0, 399), np.clip(((1 - uv[:, 1]) * 300).astype(int), 0, 299)
    tex = np.asarray(image.convert("RGB"))[px[1], px[0]]
    rgb = np.stack([ref["vertex"].data[c] for c in ("red", "green", "blue")], axis=1)
    np.testing.assert_array_equal(tex, rgb)
    with open(scan / "mesh.obj") as fh:
        assert not any(line.startswith("v ") and len(line.split()) != 4 for line in fh)
    stl = trimesh.load(scan / "mesh.stl", process=False)
    assert len(stl.faces) == n_faces
    xyz = np.stack([ref["vertex"].data[c] for c in "xyz"], axis=1)
    faces = np.stack(ref["face"].data["vertex_indices"])
    np.testing.assert_allclose(stl.triangles, xyz[faces], rtol=0, atol=1e-4)
