"""Choosing between a pixel's two candidate dips by the geometry of the surfaces they make.

The tracker keeps two candidate dips per pixel (the deepest and the deepest
other, :class:`gnomon.capture.tracking.SecondDips`). Where another moving shadow (a
lamp post, a passer-by) darkens the scene besides the occluder the light model
knows, either may be the occluder's. Each candidate, triangulated on the light
model's own shadow planes, gives a depth; the wrong one gives a point metres
off the surface. One pixel alone cannot tell them apart (both may pass every
check of its light model), but the surfaces they build can:

* **Connected surfaces.** Two candidates of neighbouring pixels (8-neighbours)
  belong to one surface when their depths differ by at most
  ``LINK_SHARE · max_jump · Z`` (half the depth step that separates surfaces
  elsewhere in the scan). The
  connected components of this graph over (pixel, candidate) nodes are the
  surfaces each interpretation makes.
* **The reference planes.** The field log's bare regions lie on planes of
  known position. A surface is *supported* when more of its nodes on the
  regions lie on their plane (within ``max_jump · Z``) than off it, or when
  most of its nodes lie on one of the reference planes (extended beyond the
  regions). A node on a region but off its plane is never chosen.

When the regions show another shadow (a share ``STRICT_OFF_SHARE`` of their
candidate nodes off the plane), only supported surfaces are trusted, since
an unverified one may be the other shadow's: per pixel, the candidate on a
supported surface when the other is not; both supported is ambiguous, neither
is refused (no point). Otherwise the tracker's own verdict stands (its
deepest dip, unless ambiguous): resolving its ambiguous pixels by the surfaces
would add points where the dip was not clean (another object's penumbra).
Memory and time are linear in the pixels (one sparse graph).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LINK_SHARE", "NEAR_PLANE_SHARE", "STRICT_OFF_SHARE", "DipChoice", "choose_dips"]

# The regions show another moving shadow when this share of their candidate nodes lies off the plane.
STRICT_OFF_SHARE = 0.1
# Neighbouring candidates are one surface when their depths differ by at most this share of the
# depth jump that separates surfaces: a surface's neighbouring pixels differ by much less, and a
# looser link lets one interpretation's surface leak into the other's where they cross.
LINK_SHARE = 0.5
# A surface is supported when at least this share of its nodes lies on a reference plane.
NEAR_PLANE_SHARE = 0.5


@dataclass
class DipChoice:
    """``choice`` (H, W) int8: 0 = no candidate chosen, 1 = the best dip, 2 = the second.
    ``ambiguous`` (H, W) bool: both candidates on supported surfaces. ``strict``: the regions
    showed another shadow (only supported surfaces trusted). Counts for the report:
    ``candidates`` (pixels with a candidate), ``second_chosen`` (pixels whose second dip replaced the
    best), ``best_kept``,
    ``refused`` (pixels with a candidate but none trusted), ``off_region`` (region nodes off
    their plane), ``on_region``."""

    choice: np.ndarray
    ambiguous: np.ndarray
    strict: bool
    counts: dict[str, int]


def _components(depth: np.ndarray, max_jump: float) -> tuple[np.ndarray, int]:
    """Labels (2, H, W) of the connected surfaces over the candidates' depths (NaN = no node, label 0
    there: meaningless) and the number of labels."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    k, h, w = depth.shape
    # Only the nodes that exist are numbered (int32: two candidates of any image fit).
    node = np.isfinite(depth)
    index = np.full((k, h, w), -1, dtype=np.int32)
    index[node] = np.arange(int(node.sum()), dtype=np.int32)
    rows, cols = [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        src = (slice(0, h - dy), slice(max(0, -dx), w - max(0, dx)))
        dst = (slice(dy, h), slice(max(0, dx), w + min(0, dx)))
        for a in range(k):
            for b in range(k):
                z1, z2 = depth[a][src], depth[b][dst]
                with np.errstate(invalid="ignore"):
                    linked = np.abs(z1 - z2) <= max_jump * np.fmin(z1, z2)
                rows.append(index[a][src][linked])
                cols.append(index[b][dst][linked])
    r, c = np.concatenate(rows), np.concatenate(cols)
    count = int(node.sum())
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(count, count))
    n, found = connected_components(graph, directed=False)
    labels = np.zeros((k, h, w), dtype=np.int32)
    labels[node] = found
    return labels, int(n)


def choose_dips(depth: np.ndarray, region_depth: np.ndarray, plane_depths: list[np.ndarray],
                max_jump: float, fallback: np.ndarray) -> DipChoice:
    """Choose per pixel between two candidate dips by the surfaces they make (module docstring).

    ``depth`` (2, H, W): each candidate's depth (camera Z, NaN where it is absent or its light
    model refuses it); ``region_depth`` (H, W): the depth of the reference plane a region pixel
    belongs to (NaN off the regions); ``plane_depths``: per reference plane, (H, W) the depth at
    which each pixel's ray meets it (NaN = never); ``max_jump``: the relative depth step
    separating surfaces (``[scan] max_depth_jump``); ``fallback`` (H, W) bool: where the best
    dip stands when the regions show no other shadow (the tracker's own verdict: not ambiguous).
    """
    if depth.ndim != 3 or depth.shape[0] != 2:
        raise ValueError(f"depth: expected (2, H, W) candidate depths, got shape {depth.shape}")
    node = np.isfinite(depth)
    labels, n = _components(depth, LINK_SHARE * max_jump)
    labels = np.where(node, labels, 0)
    with np.errstate(invalid="ignore"):
        on_plane = node & (np.abs(depth - region_depth[None]) <= max_jump * region_depth[None])
        off_plane = node & np.isfinite(region_depth)[None] & ~on_plane
        near = np.zeros_like(node)
        for zp in plane_depths:
            near |= node & (np.abs(depth - zp[None]) <= max_jump * zp[None])
    size = np.bincount(labels[node], minlength=n)
    on = np.bincount(labels[on_plane], minlength=n)
    off = np.bincount(labels[off_plane], minlength=n)
    close = np.bincount(labels[near], minlength=n)
    supported = (on > off) | (close >= NEAR_PLANE_SHARE * np.maximum(size, 1))
    sup = node & supported[labels] & ~off_plane
    n_on, n_off = int(on_plane.sum()), int(off_plane.sum())
    strict = n_off > STRICT_OFF_SHARE * max(n_on + n_off, 1)
    choice = np.zeros(depth.shape[1:], dtype=np.int8)
    if strict:
        choice[sup[0] & ~sup[1]] = 1
        choice[sup[1] & ~sup[0]] = 2
        ambiguous = sup[0] & sup[1]
    else:
        choice[fallback] = 1
        ambiguous = np.zeros_like(fallback)
    had = node.any(axis=0)
    counts = {
        "candidates": int(had.sum()),
        "second_chosen": int((choice == 2).sum()),
        "best_kept": int((choice == 1).sum()),
        "ambiguous": int(ambiguous.sum()),
        "refused": int((had & (choice == 0) & ~ambiguous).sum()),
        "on_region": n_on,
        "off_region": n_off,
    }
    return DipChoice(choice, ambiguous, strict, counts)
