"""The registered views fused into one surface with σ per vertex, and what of it is closed.

1. **The points, weighted by σ.** Every view's object points, in the reference frame, are summed
   into one voxel grid (``voxel`` world units, about the scans' point spacing): per voxel the
   inverse-variance mean of the points (weights ``1/σ²``), their weighted mean normal and colour,
   ``σ = (Σ 1/σ²)^(-1/2)`` and which views saw it. The grid holds only occupied voxels and takes the
   views one at a time, so memory grows with the object's surface, not with the number of views.
2. **The surface.** Screened Poisson reconstruction (Open3D, Kazhdan & Hoppe 2013) of the fused
   points, at the octree depth whose cell is at most ``cell`` voxels (3: on the simulated figure,
   0.116 mm RMS against 0.099 mm at 1.5 voxels, in a third of the time); where no fused point lies within
   ``trim`` voxels of the surface it is cut away (Poisson closes every surface; only what a view
   saw is kept), and pieces of less than ``min_piece`` of the faces are dropped.
3. **σ per vertex**: the σ of the inverse-variance mean of the fused points within 2 voxels.
4. **Closed or not**: a boundary edge (of one face) is a hole's edge; the holes are traced as loops,
   each with its size and place, and named ``"on the set-up"`` where at least 30 % of its edge lies
   along a set-up plane (the desk under a desk object, and what no view sees close to it) or
   ``"unseen"`` elsewhere.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from gnomon.fuse.o3d import open3d

#: A hole with this share of its edge's vertices along a set-up plane is the set-up's (the desk under the object).
SETUP_SHARE = 0.3

__all__ = ["FusedPoints", "FusedMesh", "Hole", "VoxelFusion", "poisson_surface", "holes"]


@dataclass
class FusedPoints:
    """The σ-weighted points of every view (reference frame): ``points`` (N, 3), ``normals`` (N, 3) unit,
    ``sigma`` (N,) world units, ``rgb`` (N, 3) uint8, ``views`` (N,) how many views saw each voxel."""

    points: np.ndarray
    normals: np.ndarray
    sigma: np.ndarray
    rgb: np.ndarray
    views: np.ndarray


@dataclass
class Hole:
    """A boundary loop of the fused mesh: its edges, perimeter (world units), centre (reference frame),
    and ``where``: ``"on the set-up"`` (along a set-up plane, e.g. the desk under the object) or ``"unseen"``."""

    edges: int
    perimeter: float
    centre: list[float]
    where: str


@dataclass
class FusedMesh:
    """The fused surface (reference frame): vertices (V, 3) float64, faces (F, 3) int32, normals (V, 3),
    colours (V, 3) uint8, σ per vertex (V,) world units; whether it is closed and its holes."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    rgb: np.ndarray
    sigma: np.ndarray
    watertight: bool = False
    edge_manifold: bool = False
    pieces: int = 0
    holes: list[Hole] = field(default_factory=list)


class VoxelFusion:
    """The σ-weighted voxel sums of :class:`FusedPoints`, fed one view at a time (:meth:`add`)."""

    def __init__(self, voxel: float) -> None:
        self.voxel = float(voxel)
        self.keys = np.zeros(0, np.int64)
        self.sums = np.zeros((0, 11))   # Σw, Σw·p (3), Σw·n (3), Σ rgb (3), Σ 1
        self.seen = np.zeros(0, np.int64)  # bit k: view k

    def _key(self, P: np.ndarray) -> np.ndarray:
        ijk = np.floor(P / self.voxel).astype(np.int64) + (1 << 20)
        return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]

    def add(self, view: int, points: np.ndarray, normals: np.ndarray, sigma: np.ndarray,
            rgb: np.ndarray | None) -> None:
        w = 1.0 / sigma**2
        col = np.zeros((len(points), 3)) if rgb is None else rgb.astype(np.float64)
        rows = np.column_stack([w, w[:, None] * points, w[:, None] * normals, col, np.ones(len(points))])
        keys = np.concatenate([self.keys, self._key(points)])
        rows = np.concatenate([self.sums, rows])
        seen = np.concatenate([self.seen, np.full(len(points), 1 << view, np.int64)])
        self.keys, inv = np.unique(keys, return_inverse=True)
        sums = np.zeros((len(self.keys), rows.shape[1]))
        np.add.at(sums, inv, rows)
        self.sums = sums
        bits = np.zeros(len(self.keys), np.int64)
        np.bitwise_or.at(bits, inv, seen)
        self.seen = bits

    def result(self) -> FusedPoints:
        s = self.sums
        w = s[:, 0]
        P = s[:, 1:4] / w[:, None]
        N = s[:, 4:7]
        N = N / np.maximum(np.linalg.norm(N, axis=1), 1e-12)[:, None]
        rgb = np.clip(np.rint(s[:, 7:10] / s[:, 10:11]), 0, 255).astype(np.uint8)
        views = np.array([bin(int(b)).count("1") for b in self.seen], dtype=np.int32)
        return FusedPoints(P, N, 1.0 / np.sqrt(w), rgb, views)


def poisson_surface(fused: FusedPoints, voxel: float, *, trim: float = 2.0, min_piece: float = 0.01,
                    threads: int = 0, cell: float = 3.0) -> FusedMesh:
    """Screened Poisson surface of the fused points, cut to what was seen (see the module)."""
    o3d = open3d()
    P = fused.points
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    pcd.normals = o3d.utility.Vector3dVector(fused.normals)
    lo, hi = np.percentile(P, [0.5, 99.5], axis=0)  # the object's size, not a stray point's
    extent = float(np.max(hi - lo))
    depth = max(6, min(12, math.ceil(math.log2(1.1 * extent / (cell * voxel)))))
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth, scale=1.1,
                                                                         linear_fit=False, n_threads=threads)
    V = np.asarray(mesh.vertices)
    F = np.asarray(mesh.triangles)
    tree = cKDTree(P)
    d, _ = tree.query(V, distance_upper_bound=trim * voxel)
    keep_v = np.isfinite(d)
    keep_f = keep_v[F].all(axis=1)
    F = F[keep_f]
    # Pieces: drop the small ones (stray points make islands).
    if len(F):
        labels = _face_components(F, len(V))
        sizes = np.bincount(labels)
        F = F[sizes[labels] >= min_piece * len(F)]
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    remap = np.cumsum(used) - 1
    V = V[used]
    F = remap[F].astype(np.int32)
    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    out.compute_vertex_normals()
    normals = np.asarray(out.vertex_normals).copy()
    # σ per vertex: the inverse-variance mean of the fused points within 2 voxels (the nearest 16).
    dist, idx = tree.query(V, k=16, distance_upper_bound=2.0 * voxel)
    inv_var = np.concatenate([1.0 / fused.sigma**2, [0.0]])  # index len(P): no neighbour
    total = inv_var[idx].sum(axis=1)
    nearest = idx[:, 0]
    nearest = np.minimum(nearest, len(P) - 1)
    sig = np.where(total > 0, 1.0 / np.sqrt(np.maximum(total, 1e-300)), fused.sigma[nearest])
    pieces = int(_face_components(F, len(V)).max() + 1) if len(F) else 0
    return FusedMesh(V, F, normals, fused.rgb[nearest], sig, watertight=bool(out.is_watertight()),
                     edge_manifold=bool(out.is_edge_manifold(allow_boundary_edges=True)), pieces=pieces)


def _face_components(F: np.ndarray, n_vertices: int) -> np.ndarray:
    """Each face's connected piece (faces sharing a vertex are joined)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nf = len(F)
    rows = np.repeat(np.arange(nf), 3)
    A = coo_matrix((np.ones(3 * nf), (rows, F.ravel())), shape=(nf, n_vertices)).tocsr()
    # faces and vertices in one graph: a face's piece is its component
    from scipy.sparse import bmat
    G = bmat([[None, A], [A.T, None]]).tocsr()
    _, labels = connected_components(G, directed=False)
    face_labels = labels[:nf]
    _, compact = np.unique(face_labels, return_inverse=True)
    return compact


def holes(mesh: FusedMesh, planes: Iterable[tuple[np.ndarray, float]], band: float) -> list[Hole]:
    """The mesh's boundary loops (edges of one face), each named by where it lies (see :class:`Hole`)."""
    F = mesh.faces.astype(np.int64)
    if not len(F):
        return []
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e[:, 0] * len(mesh.vertices) + e[:, 1], return_counts=True)
    once = uniq[counts == 1]
    boundary = np.column_stack([once // len(mesh.vertices), once % len(mesh.vertices)])
    if not len(boundary):
        return []
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(mesh.vertices)
    G = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n, n))
    _, labels = connected_components(G, directed=False)
    loop_of_edge = labels[boundary[:, 0]]
    planes = list(planes)
    out = []
    V = mesh.vertices
    for lab in np.unique(loop_of_edge):
        edges = boundary[loop_of_edge == lab]
        verts = np.unique(edges)
        length = float(np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1).sum())
        on_setup = any(np.mean(np.abs(V[verts] @ nrm - d) < band) >= SETUP_SHARE for nrm, d in planes)
        out.append(Hole(int(len(edges)), length, V[verts].mean(axis=0).tolist(),
                        "on the set-up" if on_setup else "unseen"))
    out.sort(key=lambda h: -h.perimeter)
    return out
