"""A triangle mesh on the pixel grid, cut at depth discontinuities.

Each 2×2 block of valid pixels gives two triangles (split along the shorter
diagonal in depth); a triangle is kept only when the depths of its corners
agree within ``max_relative_jump`` of their depth, so the mesh does not bridge
an occlusion boundary with a curtain of long thin triangles.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np


@dataclass
class GridMesh:
    """``vertices`` (V, 3) float32, ``faces`` (F, 3) int32 into them, ``pixel_index`` (V,) row-major."""

    vertices: np.ndarray
    faces: np.ndarray
    pixel_index: np.ndarray


def grid_mesh(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, max_relative_jump: float,
              sigma: np.ndarray | None = None, sigma_factor: float = 5.0) -> GridMesh:
    """Mesh the valid pixels of an (H, W) grid.

    ``points`` (H, W, 3) the coordinates to use for vertices (any frame),
    ``depth`` (H, W) camera Z for the discontinuity test. A triangle is cut
    when its corners' depths spread more than ``max_relative_jump·Z`` and, when
    ``sigma`` (σZ per pixel) is given, more than ``sigma_factor·σ`` too, so
    noise alone never tears a smooth surface.
    Faces are oriented counter-clockwise as seen from the camera.
    """
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
    faces = np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32)
    vertices = points.reshape(-1, 3)[pixel_index].astype(np.float32)
    return GridMesh(vertices, faces, pixel_index)


def component_labels(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """Connected-component label of every vertex (vertices sharing a face are connected).

    Label propagation with pointer jumping: each pass gives every face's
    vertices the smallest label among them, then shortcuts label chains.
    """
    labels = np.arange(n_vertices)
    if len(faces) == 0:
        return labels
    f = faces.astype(np.int64)
    while True:
        m = np.minimum(np.minimum(labels[f[:, 0]], labels[f[:, 1]]), labels[f[:, 2]])
        new = labels.copy()
        for k in range(3):
            np.minimum.at(new, f[:, k], m)
        np.minimum.at(new, labels, new)  # a root takes the smallest label pointing to it
        while True:
            jumped = new[new]
            if np.array_equal(jumped, new):
                break
            new = jumped
        if np.array_equal(new, labels):
            return labels
        labels = new


def remove_small_components(mesh: GridMesh, min_vertices: int = 50) -> GridMesh:
    """Drop mesh pieces with fewer than ``min_vertices`` vertices (specks, torn slivers).

    Isolated vertices (in no face) are kept out of the mesh too; the point
    cloud still has them.
    """
    labels = component_labels(len(mesh.vertices), mesh.faces)
    sizes = np.bincount(labels, minlength=len(mesh.vertices))
    in_face = np.zeros(len(mesh.vertices), dtype=bool)
    in_face[mesh.faces.ravel()] = True
    keep_v = in_face & (sizes[labels] >= min_vertices)
    remap = np.full(len(mesh.vertices), -1, dtype=np.int64)
    remap[keep_v] = np.arange(int(keep_v.sum()))
    faces = remap[mesh.faces]
    faces = faces[np.all(faces >= 0, axis=1)].astype(np.int32)
    return GridMesh(mesh.vertices[keep_v], faces, mesh.pixel_index[keep_v])


def write_obj(path, vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray | None = None) -> None:
    """Write a triangle mesh as Wavefront OBJ, atomically.

    Vertices as ``v x y z`` (world units), with ``r g b`` in 0..1 appended when
    colours are given (the common vertex-colour extension); faces 1-based.
    """
    from gnomon import atomic

    v = np.asarray(vertices, dtype=np.float64)
    buf = io.StringIO()
    buf.write(f"# gnomon mesh: {len(v)} vertices, {len(faces)} faces\n")
    if rgb is not None:
        table = np.concatenate([v, np.asarray(rgb, dtype=np.float64) / 255.0], axis=1)
        np.savetxt(buf, table, fmt="v %.7g %.7g %.7g %.4f %.4f %.4f")
    else:
        np.savetxt(buf, v, fmt="v %.7g %.7g %.7g")
    np.savetxt(buf, np.asarray(faces, dtype=np.int64) + 1, fmt="f %d %d %d")
    atomic.write_text(path, buf.getvalue())
