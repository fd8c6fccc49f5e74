"""A triangle mesh on the pixel grid, cut at depth discontinuities.

Each 2×2 block of valid pixels gives two triangles (split along the shorter
diagonal in depth); a triangle is kept only when the depths of its corners
agree within ``max_relative_jump`` of their depth, so the mesh does not bridge
an occlusion boundary with a curtain of long thin triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class GridMesh:
    """``vertices`` (V, 3) float32, ``faces`` (F, 3) int32 into them, ``pixel_index`` (V,) row-major."""

    vertices: np.ndarray
    faces: np.ndarray
    pixel_index: np.ndarray


def grid_mesh(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, max_relative_jump: float) -> GridMesh:
    """Mesh the valid pixels of an (H, W) grid.

    ``points`` (H, W, 3) the coordinates to use for vertices (any frame),
    ``depth`` (H, W) camera Z for the discontinuity test.
    Faces are oriented counter-clockwise as seen from the camera.
    """
    h, w = valid.shape
    index = np.full((h, w), -1, dtype=np.int64)
    pixel_index = np.flatnonzero(valid)
    index.ravel()[pixel_index] = np.arange(len(pixel_index))
    z = np.where(valid, depth, np.nan)

    a, b = index[:-1, :-1], index[:-1, 1:]  # top-left, top-right
    c, d = index[1:, :-1], index[1:, 1:]  # bottom-left, bottom-right
    za, zb, zc, zd = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]

    def close(*zs: np.ndarray) -> np.ndarray:
        stack = np.stack(zs)
        finite = np.all(np.isfinite(stack), axis=0)
        filled = np.where(finite, stack, 0.0)
        spread = filled.max(axis=0) - filled.min(axis=0)
        return finite & (spread <= max_relative_jump * filled.min(axis=0))

    # Split each quad along the diagonal whose ends are closer in depth; with
    # one corner missing, along the diagonal that leaves a whole triangle.
    with np.errstate(invalid="ignore"):
        split_ad = np.abs(za - zd) <= np.abs(zb - zc)
    split_ad = np.where(np.isnan(zb) | np.isnan(zc), True, split_ad)
    split_ad = np.where(np.isnan(za) | np.isnan(zd), False, split_ad)
    tris = []
    for (p, q, r), zs, use in (
        ((a, c, d), (za, zc, zd), split_ad),
        ((a, d, b), (za, zd, zb), split_ad),
        ((a, c, b), (za, zc, zb), ~split_ad),
        ((b, c, d), (zb, zc, zd), ~split_ad),
    ):
        keep = use & close(*zs)
        tris.append(np.stack([p[keep], q[keep], r[keep]], axis=1))
    faces = np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32)
    vertices = points.reshape(-1, 3)[pixel_index].astype(np.float32)
    return GridMesh(vertices, faces, pixel_index)
