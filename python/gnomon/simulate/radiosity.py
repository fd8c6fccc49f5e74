"""One bounce of interreflection between Lambertian surfaces: patches, form factors, gathering.

The simulator's own, independent of the scanner (plain numpy on the primitives of
:mod:`gnomon.simulate.geometry`). A scene's surfaces are cut into small flat
*patches* (a centre, a unit normal, an area; each with sub-samples spread over it);
the light a patch sends on is its albedo times the direct irradiance it receives,
averaged over its sub-samples (so a shadow narrower than the patch dims it in
proportion). A receiving point ``P`` with normal ``n`` then gathers, from each patch
``j`` it sees,

    E_ind(P) = Σ_j F(P, j) · ρ_j · E_dir(j),

    F(P, j) = A_j · cos θ_P · cos θ_j / (π r² + A_j) · V(P, j),

the form factor from a differential area to a small patch in the disc form of
Wallace, Elmquist & Haines (SIGGRAPH 1989): exact for a disc of area ``A_j`` facing
``P`` head on, and bounded as ``r → 0``. ``V`` is 1 when no solid of the scene lies on
the segment between them (the scene's planes meet in a concave corner and never
hide one another; each solid is convex, so its own faces are dealt with by the
cosines). Irradiance is in the scene's own unit (the direct term's ``E·cos/d²``),
so a radiance is ``ρ_P · (ambient + E_dir(P) + E_ind(P))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gnomon.simulate import geometry as geo

__all__ = ["Patches", "ReceiverGrid", "box_patches", "concat_patches", "cylinder_patches", "form_factors",
           "plane_patches", "receiver_grid", "sphere_patches", "segment_blocked"]

SURFACE_OFFSET = 1e-3  # mm: points are moved off their surface along the normal before a visibility test


@dataclass(frozen=True)
class Patches:
    """Patches (J of them): ``centre`` (J, 3), unit ``normal`` (J, 3), ``area`` (J,) mm², ``albedo`` (J,);
    their sub-samples ``sub_points`` (M, 3) with ``sub_patch`` (M,) the patch each belongs to and
    ``sub_weight`` (M,) its share of that patch's area (the shares of a patch add up to 1)."""

    centre: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    albedo: np.ndarray
    sub_points: np.ndarray
    sub_patch: np.ndarray
    sub_weight: np.ndarray

    def __len__(self) -> int:
        return len(self.area)

    def average(self, sub_values: np.ndarray) -> np.ndarray:
        """Per-patch area average of a value given at the sub-samples (M,) → (J,)."""
        return np.bincount(self.sub_patch, weights=self.sub_weight * sub_values, minlength=len(self))


def _grid_patches(origin, ax_a, ax_b, len_a: float, len_b: float, size: float, sub: int, normal, albedo_fn,
                  keep_fn=None) -> Patches:
    """Rectangle ``origin + a·ax_a + b·ax_b`` (a ∈ [0, len_a], b ∈ [0, len_b]) in square-ish patches of about
    ``size`` mm with ``sub`` × ``sub`` sub-samples each; ``albedo_fn(points)`` gives the albedo."""
    origin, ax_a, ax_b = (np.asarray(x, dtype=np.float64) for x in (origin, ax_a, ax_b))
    na, nb = max(1, int(round(len_a / size))), max(1, int(round(len_b / size)))
    da, db = len_a / na, len_b / nb
    ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
    ca = (ia.ravel() + 0.5) * da
    cb = (ib.ravel() + 0.5) * db
    offs = (np.arange(sub) + 0.5) / sub - 0.5
    sa, sb = np.meshgrid(offs, offs, indexing="ij")
    sub_a = ca[:, None] + sa.ravel()[None] * da
    sub_b = cb[:, None] + sb.ravel()[None] * db
    subs = origin + sub_a[..., None] * ax_a + sub_b[..., None] * ax_b  # (J, s², 3)
    centre = origin + ca[:, None] * ax_a + cb[:, None] * ax_b
    J = len(centre)
    if keep_fn is not None:
        keep = keep_fn(centre)
        centre, subs, J = centre[keep], subs[keep], int(keep.sum())
    s2 = sub * sub
    sub_points = subs.reshape(-1, 3)
    albedo = albedo_fn(sub_points).reshape(J, s2).mean(axis=1)
    n = np.broadcast_to(np.asarray(normal, dtype=np.float64), (J, 3)).copy()
    return Patches(centre, n, np.full(J, da * db), albedo, sub_points, np.repeat(np.arange(J), s2),
                   np.full(J * s2, 1.0 / s2))


def plane_patches(origin, ax_a, ax_b, len_a: float, len_b: float, size: float, sub: int, albedo_fn) -> Patches:
    """A rectangle of a plane (normal ``ax_a × ax_b``) cut into patches (see :func:`_grid_patches`)."""
    n = np.cross(np.asarray(ax_a, float), np.asarray(ax_b, float))
    return _grid_patches(origin, ax_a, ax_b, len_a, len_b, size, sub, n / np.linalg.norm(n), albedo_fn)


def sphere_patches(sphere: geo.Sphere, size: float, albedo: float) -> Patches:
    """A sphere in about equal-area patches of side ``size`` (a Fibonacci lattice; one sample each)."""
    area = 4.0 * math.pi * sphere.r ** 2
    n = max(8, int(round(area / size ** 2)))
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    rr = np.sqrt(1.0 - z * z)
    normal = np.stack([rr * np.cos(phi), rr * np.sin(phi), z], axis=1)
    centre = sphere.c + sphere.r * normal
    return Patches(centre, normal, np.full(n, area / n), np.full(n, albedo), centre.copy(), np.arange(n),
                   np.ones(n))


def box_patches(box: geo.Box, size: float, albedo: float, sub: int = 2) -> Patches:
    """A box's six faces, each cut into patches of about ``size`` mm."""
    parts = []
    full = 2.0 * box.half
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        for sign in (-1.0, 1.0):
            n_local = np.zeros(3)
            n_local[axis] = sign
            corner = np.zeros(3)
            corner[axis] = sign * box.half[axis]
            corner[a], corner[b] = -box.half[a], -box.half[b]
            origin = box.c + box.axes @ corner
            ax_a, ax_b = box.axes[:, a], box.axes[:, b]
            parts.append(_grid_patches(origin, ax_a, ax_b, full[a], full[b], size, sub, box.axes @ n_local,
                                       lambda X: np.full(len(X), albedo)))
    return concat_patches(parts)


def cylinder_patches(cyl: geo.Cylinder, size: float, albedo: float) -> Patches:
    """A capped cylinder's side (rings × sectors) and caps (a ring of sectors each), one sample per patch."""
    a = cyl.a
    e1 = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    n_ang = max(8, int(round(2 * math.pi * cyl.r / size)))
    n_len = max(1, int(round(2 * cyl.h / size)))
    ang = (np.arange(n_ang) + 0.5) * 2 * math.pi / n_ang
    z = ((np.arange(n_len) + 0.5) / n_len - 0.5) * 2 * cyl.h
    radial = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2  # (n_ang, 3)
    side_n = np.repeat(radial, n_len, axis=0)
    side_c = cyl.c + cyl.r * side_n + np.tile(z, n_ang)[:, None] * a
    side_area = np.full(len(side_c), 2 * math.pi * cyl.r * 2 * cyl.h / len(side_c))
    caps_c, caps_n = [], []
    for s in (-1.0, 1.0):
        caps_c.append(cyl.c + s * cyl.h * a + 0.6 * cyl.r * radial)
        caps_n.append(np.broadcast_to(s * a, radial.shape))
    centre = np.concatenate([side_c, *caps_c])
    normal = np.concatenate([side_n, *caps_n])
    area = np.concatenate([side_area, np.full(2 * n_ang, math.pi * cyl.r ** 2 / n_ang)])
    n = len(centre)
    return Patches(centre, normal, area, np.full(n, albedo), centre.copy(), np.arange(n), np.ones(n))


def concat_patches(parts: list[Patches]) -> Patches:
    offsets = np.cumsum([0] + [len(p) for p in parts[:-1]])
    return Patches(np.concatenate([p.centre for p in parts]), np.concatenate([p.normal for p in parts]),
                   np.concatenate([p.area for p in parts]), np.concatenate([p.albedo for p in parts]),
                   np.concatenate([p.sub_points for p in parts]),
                   np.concatenate([p.sub_patch + o for p, o in zip(parts, offsets, strict=True)]),
                   np.concatenate([p.sub_weight for p in parts]))


def segment_blocked(a: np.ndarray, b: np.ndarray, solids: list[geo.Surface]) -> np.ndarray:
    """(…,) bool: a solid meets the open segment from ``a`` to ``b`` (…, 3)."""
    d = b - a
    blocked = np.zeros(np.broadcast(a[..., 0], b[..., 0]).shape, dtype=bool)
    for s in solids:
        blocked |= s.intersect(a, d) < 1.0 - 1e-9
    return blocked


def form_factors(points: np.ndarray, normals: np.ndarray, patches: Patches, solids: list[geo.Surface], *,
                 chunk: int = 256) -> np.ndarray:
    """(R, J) float32: the form factor from each receiving point (R, 3) with unit normal (R, 3) to each patch,
    visibility included (see the module docstring)."""
    R = len(points)
    out = np.zeros((R, len(patches)), dtype=np.float32)
    pc = patches.centre + SURFACE_OFFSET * patches.normal
    for r0 in range(0, R, chunk):
        P = points[r0:r0 + chunk, None, :] + SURFACE_OFFSET * normals[r0:r0 + chunk, None, :]
        n = normals[r0:r0 + chunk, None, :]
        v = pc[None] - P                                   # (r, J, 3)
        d2 = np.einsum("rji,rji->rj", v, v)
        inv = 1.0 / np.sqrt(d2)
        cos_r = np.einsum("rji,rji->rj", v, n) * inv
        cos_j = -np.einsum("rji,ji->rj", v, patches.normal) * inv
        F = patches.area * np.maximum(cos_r, 0.0) * np.maximum(cos_j, 0.0) / (math.pi * d2 + patches.area)
        front = F > 0
        if solids and front.any():
            ri, ji = np.nonzero(front)
            blocked = segment_blocked(P[ri, 0], np.broadcast_to(pc[ji], (len(ji), 3)), solids)
            F[ri[blocked], ji[blocked]] = 0.0
        out[r0:r0 + chunk] = F
    return out


@dataclass(frozen=True)
class ReceiverGrid:
    """Where bounced light is gathered and how each pixel takes it: the receiving points ``rx`` (rows, cols of
    the image grid), the pixels that hit a surface ``pixel_index`` (rows, cols), and per such pixel the four
    receiving points ``nodes`` (P, 4) it interpolates and their ``weights`` (P, 4) float32 (adding up to 1)."""

    rx: tuple[np.ndarray, np.ndarray]
    pixel_index: tuple[np.ndarray, np.ndarray]
    nodes: np.ndarray
    weights: np.ndarray

    def spread(self, at_rx: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        """A value given at the receiving points (R,) → the image grid (``shape``), 0 where no surface."""
        out = np.zeros(shape, dtype=np.float32)
        out[self.pixel_index] = np.einsum("ij,ij->i", at_rx[self.nodes], self.weights)
        return out


def receiver_grid(hit: np.ndarray, ids: np.ndarray, normals: np.ndarray, step: int, normal_cos: float
                  ) -> ReceiverGrid:
    """Receiving points every ``step``-th pixel of an image grid (H, W) (the last row and column included), and
    the pixels that have none of their own surface around them; each pixel that ``hit`` a surface takes the
    bilinear weights of the grid points around it that lie on the same object (``ids``) with a normal within
    ``acos(normal_cos)`` of its own (``normals`` (H, W, 3)), or its own receiving point where none does."""
    Hf, Wf = hit.shape
    rows = np.unique(np.r_[np.arange(0, Hf, step), Hf - 1])
    cols = np.unique(np.r_[np.arange(0, Wf, step), Wf - 1])
    node_v, node_u = np.meshgrid(rows, cols, indexing="ij")
    node_id = np.full(node_v.shape, -1, dtype=np.int64)
    node_ok = hit[node_v, node_u]
    node_id[node_ok] = np.arange(int(node_ok.sum()))
    rx_v, rx_u = [node_v[node_ok]], [node_u[node_ok]]
    n_nodes = int(node_ok.sum())
    vv, uu = np.nonzero(hit)
    i0 = np.clip(np.searchsorted(rows, vv, side="right") - 1, 0, len(rows) - 1)
    j0 = np.clip(np.searchsorted(cols, uu, side="right") - 1, 0, len(cols) - 1)
    i1, j1 = np.minimum(i0 + 1, len(rows) - 1), np.minimum(j0 + 1, len(cols) - 1)
    fy = np.where(i1 > i0, (vv - rows[i0]) / np.maximum(rows[i1] - rows[i0], 1), 0.0)
    fx = np.where(j1 > j0, (uu - cols[j0]) / np.maximum(cols[j1] - cols[j0], 1), 0.0)
    idx = np.zeros((len(vv), 4), dtype=np.int64)
    wts = np.zeros((len(vv), 4))
    for k, (ii, jj, w) in enumerate(((i0, j0, (1 - fy) * (1 - fx)), (i0, j1, (1 - fy) * fx),
                                     (i1, j0, fy * (1 - fx)), (i1, j1, fy * fx))):
        nv, nu = rows[ii], cols[jj]
        good = (node_id[ii, jj] >= 0) & (ids[nv, nu] == ids[vv, uu]) & \
            (np.einsum("ij,ij->i", normals[nv, nu], normals[vv, uu]) >= normal_cos)
        idx[:, k] = np.where(good, node_id[ii, jj], 0)
        wts[:, k] = np.where(good, w, 0.0)
    total = wts.sum(axis=1)
    lone = total < 1e-9
    idx[lone, 0] = n_nodes + np.arange(int(lone.sum()))
    wts[lone] = [1.0, 0.0, 0.0, 0.0]
    total[lone] = 1.0
    rx_v.append(vv[lone])
    rx_u.append(uu[lone])
    return ReceiverGrid((np.concatenate(rx_v), np.concatenate(rx_u)), (vv, uu), idx,
                        (wts / total[:, None]).astype(np.float32))
