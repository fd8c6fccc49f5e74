"""A triangle mesh on the pixel grid, cut at depth discontinuities.

Each 2×2 block of valid pixels gives two triangles (split along the shorter
diagonal in depth); a triangle is kept only when the depths of its corners
agree within ``max_relative_jump`` of their depth, so the mesh does not bridge
an occlusion boundary with a curtain of long thin triangles.

Pieces are *edge*-connected components (triangles sharing an edge); small
pieces are dropped, and a vertex where pieces (or fans of one piece) touch
only at that vertex is split into one copy per fan, so the mesh has no
non-manifold vertices (every vertex's triangles form a single fan).

Normals come from the pixel grid: the cross product of the surface's
tangents along the image rows and columns (central differences between
neighbours on the same side of any depth jump), oriented towards the camera.

Its files are written by :mod:`gnomon.outputs` (the formats' registry,
:mod:`gnomon.outputs.formats`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel

__all__ = [
    "GridMesh",
    "grid_faces",
    "grid_mesh",
    "grid_normals",
    "face_components",
    "component_labels",
    "remove_small_components",
    "clean_faces",
    "split_non_manifold_vertices",
    "non_manifold_vertex_count",
    "face_normals",
]

# Pieces of the mesh with fewer vertices are dropped (specks, torn slivers): remove_small_components' default.
MIN_PIECE_VERTICES = 50


@dataclass
class GridMesh:
    """A triangle mesh whose vertices are pixels of a grid.

    ``vertices`` (V, 3) float32 (world frame, world units); ``faces`` (F, 3)
    int32 into them, counter-clockwise seen from the camera; ``pixel_index``
    (V,) the row-major pixel each vertex comes from (a pixel carries several
    vertices where a non-manifold vertex was split); ``normals`` (V, 3) float32
    unit normals towards the camera, or None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    pixel_index: np.ndarray
    normals: np.ndarray | None = None

    def pixel_uv(self, width: int) -> np.ndarray:
        """(V, 2) float32 pixel coordinates (u, v) of the vertices (OpenCV: centres at integers)."""
        v, u = np.divmod(self.pixel_index.astype(np.int64), int(width))
        return np.stack([u, v], axis=1).astype(np.float32)


def grid_mesh(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, max_relative_jump: float,
              sigma: np.ndarray | None = None, sigma_factor: float = 5.0,
              normals: np.ndarray | None = None) -> GridMesh:
    """Mesh the valid pixels of an (H, W) grid.

    ``points`` (H, W, 3) the coordinates to use for vertices (any frame),
    ``depth`` (H, W) camera Z for the discontinuity test. A triangle is cut
    when its corners' depths spread more than ``max_relative_jump·Z`` and, when
    ``sigma`` (σZ per pixel) is given, more than ``sigma_factor·σ`` too, so
    noise alone never tears a smooth surface. ``normals`` (H, W, 3), when
    given, become the vertices' normals.
    Faces are oriented counter-clockwise as seen from the camera.
    """
    pixel_index = np.flatnonzero(valid)
    # np.take: the same rows as fancy indexing, several times faster on (N, 3) arrays; a new array
    vertices = np.take(points.reshape(-1, 3), pixel_index, axis=0).astype(np.float32, copy=False)
    vn = None if normals is None else np.take(normals.reshape(-1, 3), pixel_index, axis=0).astype(np.float32,
                                                                                                  copy=False)
    return GridMesh(vertices, grid_faces(depth, valid, max_relative_jump, sigma, sigma_factor), pixel_index, vn)


def grid_faces(depth: np.ndarray, valid: np.ndarray, max_relative_jump: float, sigma: np.ndarray | None = None,
               sigma_factor: float = 5.0) -> np.ndarray:
    """:func:`grid_mesh`'s faces (F, 3) int32 alone, into the valid pixels in row-major order (for a caller that
    has their vertices already)."""
    if depth.dtype == np.float32 and (sigma is None or sigma.dtype == np.float32):
        # the same faces from the kernel (f32 arithmetic, as numpy does on these maps)
        sig32 = np.zeros(depth.shape, np.float32) if sigma is None else np.ascontiguousarray(sigma)
        faces: np.ndarray = _kernel.grid_faces(np.ascontiguousarray(valid, dtype=np.uint8),
                                               np.ascontiguousarray(depth), sig32, max_relative_jump, sigma_factor)
        return faces
    return _grid_faces_numpy(depth, valid, max_relative_jump, sigma, sigma_factor)


def _grid_faces_numpy(depth: np.ndarray, valid: np.ndarray, max_relative_jump: float,
                      sigma: np.ndarray | None, sigma_factor: float) -> np.ndarray:
    """grid_mesh's faces (F, 3) int32, in numpy (the kernel's ``grid_faces`` gives the same on float32 maps)."""
    h, w = valid.shape
    index = np.full((h, w), -1, dtype=np.int64)
    pixel_index = np.flatnonzero(valid)
    index.ravel()[pixel_index] = np.arange(len(pixel_index))
    z = np.where(valid, depth, np.nan)

    sig = np.zeros_like(z) if sigma is None else np.where(valid, np.nan_to_num(sigma), 0.0)
    sa, sb, sc, sd = sig[:-1, :-1], sig[:-1, 1:], sig[1:, :-1], sig[1:, 1:]
    a, b = index[:-1, :-1], index[:-1, 1:]  # top-left, top-right
    c, d = index[1:, :-1], index[1:, 1:]  # bottom-left, bottom-right
    za, zb, zc, zd = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]

    def close(zs, ss) -> np.ndarray:
        stack = np.stack(zs)
        finite = np.all(np.isfinite(stack), axis=0)
        filled = np.where(finite, stack, 0.0)
        spread = filled.max(axis=0) - filled.min(axis=0)
        allowed = np.maximum(max_relative_jump * filled.min(axis=0), sigma_factor * np.max(np.stack(ss), axis=0))
        return finite & (spread <= allowed)

    # Split each quad along the diagonal whose ends are closer in depth; with
    # one corner missing, along the diagonal that leaves a whole triangle.
    with np.errstate(invalid="ignore"):
        split_ad = np.abs(za - zd) <= np.abs(zb - zc)
    split_ad = np.where(np.isnan(zb) | np.isnan(zc), True, split_ad)
    split_ad = np.where(np.isnan(za) | np.isnan(zd), False, split_ad)
    tris = []
    for (p, q, r), zs, ss, use in (
        ((a, c, d), (za, zc, zd), (sa, sc, sd), split_ad),
        ((a, d, b), (za, zd, zb), (sa, sd, sb), split_ad),
        ((a, c, b), (za, zc, zb), (sa, sc, sb), ~split_ad),
        ((b, c, d), (zb, zc, zd), (sb, sc, sd), ~split_ad),
    ):
        keep = use & close(zs, ss)
        tris.append(np.stack([p[keep], q[keep], r[keep]], axis=1))
    return np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32)


def grid_normals(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, camera_centre: np.ndarray,
                 max_relative_jump: float) -> np.ndarray:
    """Unit surface normals (H, W, 3) float32 from the pixel grid, oriented towards the camera.

    ``points`` (H, W, 3) in any frame (world units), ``camera_centre`` (3,) the
    camera's centre in that frame, ``depth`` (H, W) camera Z for the
    discontinuity test: a neighbour whose depth differs by more than
    ``max_relative_jump·Z`` lies across an occlusion and is not used. The
    tangents along the row and the column are central differences where both
    neighbours qualify, one-sided where only one does; a pixel with no
    qualifying neighbour in a direction gets the unit vector towards the
    camera. NaN where ``valid`` is False.

    On float32 maps the kernel computes it (``_kernel.grid_normals``, rows in
    parallel, the same f64 arithmetic); :func:`_grid_normals_numpy` is the
    definition in numpy.
    """
    if points.dtype == np.float32 and depth.dtype == np.float32:
        centre = np.asarray(camera_centre, dtype=np.float64).reshape(3)
        return _kernel.grid_normals(np.ascontiguousarray(points), np.ascontiguousarray(depth),
                                    np.ascontiguousarray(valid, dtype=np.uint8),
                                    (float(centre[0]), float(centre[1]), float(centre[2])),
                                    float(max_relative_jump))
    return _grid_normals_numpy(points, depth, valid, camera_centre, max_relative_jump)


def _grid_normals_numpy(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, camera_centre: np.ndarray,
                        max_relative_jump: float) -> np.ndarray:
    """:func:`grid_normals` in numpy (the kernel's ``grid_normals`` gives the same on float32 maps)."""
    p = np.where(valid[..., None], points, np.nan).astype(np.float64)
    z = np.where(valid, depth, np.nan).astype(np.float64)
    h, w = valid.shape

    def tangent(axis: int) -> np.ndarray:
        pad = [(0, 0)] * 3
        pad[axis] = (1, 1)
        pp = np.pad(p, pad, constant_values=np.nan)
        zp = np.pad(z, pad[:2], constant_values=np.nan)
        sl = [slice(None)] * 2
        lo, hi, mid = list(sl), list(sl), list(sl)
        lo[axis], hi[axis] = slice(0, -2), slice(2, None)
        mid[axis] = slice(1, -1)
        with np.errstate(invalid="ignore"):
            ok_lo = np.abs(zp[tuple(lo)] - z) <= max_relative_jump * np.abs(z)
            ok_hi = np.abs(zp[tuple(hi)] - z) <= max_relative_jump * np.abs(z)
        t_both = pp[tuple(hi)] - pp[tuple(lo)]
        t_hi = pp[tuple(hi)] - p
        t_lo = p - pp[tuple(lo)]
        t = np.where((ok_lo & ok_hi)[..., None], t_both, np.where(ok_hi[..., None], t_hi,
                                                                  np.where(ok_lo[..., None], t_lo, np.nan)))
        return t

    n = np.cross(tangent(1), tangent(0))  # along u × along v
    to_cam = np.asarray(camera_centre, dtype=np.float64).reshape(1, 1, 3) - p
    to_cam /= np.linalg.norm(to_cam, axis=2, keepdims=True)
    norm = np.linalg.norm(n, axis=2, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
    bad = ~np.isfinite(n).all(axis=2) | (norm[..., 0] == 0)
    n[bad] = to_cam[bad]
    flip = np.einsum("hwk,hwk->hw", n, to_cam) < 0
    n[flip] *= -1.0
    n[~valid] = np.nan
    assert n.shape == (h, w, 3)
    return n.astype(np.float32)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) float32 unit normals of the triangles (right-hand rule over the corner order)."""
    v = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces)
    a = v[f[:, 0]]
    b = v[f[:, 1]] - a
    c = v[f[:, 2]] - a
    n = np.empty_like(a)
    n[:, 0] = b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1]
    n[:, 1] = b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2]
    n[:, 2] = b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]
    norm = np.sqrt(np.einsum("ij,ij->i", n, n))
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= norm[:, None]
    n[norm == 0] = 0.0
    return n


def _connected(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Component label (0..k-1) of n nodes linked by the pairs (a[i], b[i])."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)[1]


def face_components(faces: np.ndarray) -> np.ndarray:
    """Edge-connected component label of every face: faces sharing an edge are connected.

    Faces touching at a single vertex are *not* connected.
    """
    f = np.asarray(faces, dtype=np.int64)
    m = len(f)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.minimum(e[:, 0], e[:, 1]) * (int(f.max()) + 1) + np.maximum(e[:, 0], e[:, 1])
    face = np.tile(np.arange(m), 3)
    order = np.argsort(key, kind="stable")
    k, fo = key[order], face[order]
    same = k[1:] == k[:-1]
    return _connected(m, fo[:-1][same], fo[1:][same])


def component_labels(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """Edge-connected component label of every vertex (−1 for a vertex in no face).

    A vertex shared by several components (they touch only there) takes the
    label of one of them; :func:`split_non_manifold_vertices` separates them.
    """
    labels = np.full(n_vertices, -1, dtype=np.int64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f):
        comp = face_components(f)
        labels[f.ravel()] = np.repeat(comp, 3)
    return labels


def _fans(faces: np.ndarray, corners: np.ndarray | None = None) -> np.ndarray:
    """Fan label of face corners (``corners`` indices into ``faces.ravel()``, default all).

    Two corners at the same vertex are in one fan when their triangles share
    an edge at that vertex; a manifold vertex has exactly one fan.
    """
    f = np.asarray(faces, dtype=np.int64)
    corner = np.arange(f.size) if corners is None else np.asarray(corners, dtype=np.int64)
    v = f.ravel()[corner]
    nxt = f[:, [1, 2, 0]].ravel()[corner]
    prv = f[:, [2, 0, 1]].ravel()[corner]
    n = int(f.max()) + 1
    # Each corner has two edges at its vertex: (v, next) and (v, previous).
    key = np.concatenate([v * n + nxt, v * n + prv])
    owner = np.tile(np.arange(len(corner)), 2)
    order = np.argsort(key, kind="stable")
    k, o = key[order], owner[order]
    same = k[1:] == k[:-1]
    return _connected(len(corner), o[:-1][same], o[1:][same])


def _candidate_corners(f: np.ndarray) -> np.ndarray:
    """Corners at vertices that may have several fans.

    A vertex whose triangles form one fan has as many triangles as interior
    edges (a closed fan) or one more (an open fan); more than one more means
    several open fans. (A closed fan plus another fan cannot occur on a pixel
    grid: the closed fan fills every quad around the vertex.)
    """
    n = int(f.max()) + 1
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    keys, counts = np.unique(lo * n + hi, return_counts=True)
    shared = keys[counts >= 2]
    interior = np.bincount(shared // n, minlength=n) + np.bincount(shared % n, minlength=n)
    open_fans = np.bincount(f.ravel(), minlength=n) - interior
    return np.flatnonzero((open_fans >= 2)[f.ravel()])


def non_manifold_vertex_count(faces: np.ndarray) -> int:
    """Vertices whose triangles form more than one fan (pieces touching at a point)."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0
    fan = _fans(f)
    # a fan belongs to one vertex: count the distinct fans at each vertex
    first = np.unique(fan, return_index=True)[1]
    return int(np.count_nonzero(np.bincount(f.ravel()[first]) > 1))


def split_non_manifold_vertices(mesh: GridMesh) -> GridMesh:
    """One vertex copy per fan: pieces that touch only at a vertex get their own vertices.

    Positions, pixels and normals are copied; the faces' shape is unchanged.
    Vertices in no face are dropped.
    """
    f = np.asarray(mesh.faces, dtype=np.int64)
    if len(f) == 0:
        return GridMesh(mesh.vertices[:0], mesh.faces[:0].astype(np.int32), mesh.pixel_index[:0],
                        None if mesh.normals is None else mesh.normals[:0])
    n = len(mesh.vertices)
    v = f.ravel()
    old = np.flatnonzero(np.bincount(v, minlength=n) > 0)  # used vertices keep their order
    remap = np.full(n, -1, dtype=np.int64)
    remap[old] = np.arange(len(old))
    new = remap[v]
    corners = _candidate_corners(f)
    if len(corners):
        fan = _fans(f, corners)
        fans, first = np.unique(fan, return_index=True)  # fans, in order of label
        fan_vertex = v[corners[first]]
        # the first fan at each vertex keeps it; every further fan gets a copy
        order = np.lexsort((fans, fan_vertex))
        extra = np.zeros(len(fans), dtype=bool)
        extra[order[1:]] = fan_vertex[order[1:]] == fan_vertex[order[:-1]]
        copy_id = np.full(len(fans), -1, dtype=np.int64)
        copy_id[extra] = len(old) + np.arange(int(extra.sum()))
        fan_to_new = np.where(extra, copy_id, remap[fan_vertex])
        new[corners] = fan_to_new[np.searchsorted(fans, fan)]
        old = np.concatenate([old, fan_vertex[extra]])
    faces = new.reshape(-1, 3).astype(np.int32)
    normals = None if mesh.normals is None else mesh.normals[old]
    return GridMesh(mesh.vertices[old], faces, mesh.pixel_index[old], normals)


def remove_small_components(mesh: GridMesh, min_vertices: int = MIN_PIECE_VERTICES,
                            width: int | None = None) -> GridMesh:
    """Drop edge-connected pieces with fewer than ``min_vertices`` vertices (specks, torn slivers).

    Vertices in no face are dropped too (the point cloud still has them), and
    the vertices where kept pieces touch only at a point are split
    (:func:`split_non_manifold_vertices`): the result has no non-manifold vertex.
    ``width``: the pixel grid's width when the mesh is on it (see :func:`clean_faces`).
    """
    faces, source = clean_faces(len(mesh.vertices), mesh.faces, mesh.pixel_index, min_vertices, width)
    return GridMesh(np.take(mesh.vertices, source, axis=0), faces, np.take(mesh.pixel_index, source),
                    None if mesh.normals is None else np.take(mesh.normals, source, axis=0))


def clean_faces(n_vertices: int, faces: np.ndarray, pixel_index: np.ndarray,
                min_vertices: int = MIN_PIECE_VERTICES, width: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`remove_small_components`' faces (F', 3) int32 into the new vertices and the old vertex each new
    one copies (V',) int64, for a mesh of ``n_vertices`` vertices (none of which it needs but their count).

    ``width``: the pixel grid's width when the mesh is on it (``pixel_index`` the row-major pixels of the
    vertices, increasing, every edge a grid step: :func:`grid_faces`' mesh); the kernel then finds the faces
    that share an edge by the edge's place on the grid (the same result, faster)."""
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if width is None:
        return _kernel.clean_faces(int(n_vertices), faces, int(min_vertices))
    return _kernel.clean_faces(int(n_vertices), faces, int(min_vertices),
                               np.ascontiguousarray(pixel_index, dtype=np.int64), int(width))


def _remove_small_components_numpy(mesh: GridMesh, min_vertices: int = 50) -> GridMesh:
    """:func:`remove_small_components` in numpy and scipy (the kernel's ``clean_faces`` gives the same)."""
    f = np.asarray(mesh.faces, dtype=np.int64)
    if len(f):
        comp = face_components(f)
        # vertices per component (a vertex shared by two components counts for each)
        # vertices per piece (a vertex where pieces touch counts for one of them)
        vertex_comp = np.full(len(mesh.vertices), -1, dtype=np.int64)
        vertex_comp[f.ravel()] = np.repeat(comp, 3)
        used = vertex_comp[vertex_comp >= 0]
        sizes = np.bincount(used, minlength=int(comp.max()) + 1)
        f = f[sizes[comp] >= min_vertices]
    return split_non_manifold_vertices(GridMesh(mesh.vertices, f.astype(np.int32), mesh.pixel_index,
                                                mesh.normals))


# --------------------------------------------------------------------------- writers
