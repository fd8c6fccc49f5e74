"""``facade_sun`` with ``roof_edge``: no pole; the roof line across the street sweeps its shadow up the facade.

The scene of :mod:`gnomon.simulate.facade_sun` (facade, balconies, ledge, windows, the same sun, clouds,
exposure drift, camera) without its pole. Across the street stands a row of buildings whose front wall is the
plane y = ``EDGE_Y`` (40 m, 15 m behind the camera) and whose flat roof ends at z = ``EDGE_Z`` (22 m): its roof
line, the straight edge from ``EDGE_A`` to ``EDGE_B`` (x = ∓150 m), is the only occluder the scan is told
about. Over the capture (default 11:40–14:59 local, the sun's d_z/d_y falling from 0.54 to 0.31) the edge's
shadow climbs the facade from z ≈ 0.2 m to ≈ 9.7 m: every point in that band goes from lit to shadowed once,
a *step*, not a dip. The street (the ground) stays in that building's shadow throughout.

Shadow (exact, analytic): seen from a point P the edge is a straight line across the sky; the sun's centre lies
an angle δ(P, t) = asin(n̂_P · d(t)) above it, n̂_P the unit normal of the plane through P and the edge,
oriented away from ``EDGE_BODY`` (a point of the building across the street, on its wall below the roof
line). The occluded fraction of the uniform disc of angular radius ρ is the disc's share beyond a chord at
signed distance δ/ρ from its centre (:func:`gnomon.simulate.shadow._disc_fraction`), exact up to the flat-disc
approximation (~ρ²). It replaces the pole's occluded fraction in the radiometry of ``facade_sun``; the
building's own shadows, sky, clouds and gain are as there. The building across the street is not otherwise
rendered (it is behind the camera; the sky light it hides is not modelled).

Ground truth, besides ``facade_sun``'s geometry (``depth``, ``points_world``, ``object_id``, …):

* ``edge_time`` (H, W): the fractional frame at which the plane through the edge containing the sun's
  direction (the penumbra's centre, δ = 0) passes the point, with the sun direction between frames along the
  renormalised chord (as ``facade_sun``): n̂_P · ((1 − τ)·d_k + τ·d_{k+1}) = 0 is linear in τ, so the time is
  exact. NaN where δ does not change sign within the capture;
* ``edge_direction`` (H, W) int8: +1 the point enters the shadow at ``edge_time``, −1 it leaves it, 0 none;
* ``swept_surface``: the edge's shadow crossed the point at ``1 ≤ edge_time ≤ N − 2`` while it was otherwise
  lit (in every frame the penumbra touched it, and one either side: the sun above the horizon, n·d > 0.05, at
  least half the disc seen past the facade's own balconies, ledge and reveals), mixed pixels included;
* ``swept``: ``swept_surface``, the whole disc seen past the facade's building in those frames, and not mixed
  (``facade_sun``'s blur-footprint test);
* ``edge_a``, ``edge_b``, ``edge_body`` (3,) world; ``edge_planes_world`` (N, 4) the plane through the edge and
  d_k at each frame (``[n, d]``, ``n·X = d``, n̂ oriented towards the lit side);
* the pole's arrays of ``facade_sun`` are there but describe a pole that is not in the scene.

The field log has ``[edge]`` (``a``, ``b``, ``body``) instead of ``[pole]`` and ``[gnomon]``, and one reference
plane, the facade (its regions bare wall the edge's shadow swept).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from gnomon.simulate import shadow
from gnomon.simulate.facade_sun import RHO, WALL, FacadeSunConfig, FacadeSunResult, FacadeSunScene, simulate_facade_sun

__all__ = ["EDGE_A", "EDGE_B", "EDGE_BODY", "EDGE_Y", "EDGE_Z", "RoofEdgeScene", "simulate_roof_edge"]

EDGE_Y = 40.0   # m: the front wall of the building across the street
EDGE_Z = 22.0   # m: its roof line
EDGE_A = np.array([-150.0, EDGE_Y, EDGE_Z])
EDGE_B = np.array([150.0, EDGE_Y, EDGE_Z])
EDGE_BODY = np.array([0.0, EDGE_Y, 0.0])  # on its wall, below the roof line: the shadowed side


def edge_normals(P: np.ndarray) -> np.ndarray:
    """(..., 3) unit normals of the planes through each point P (..., 3, world) and the edge, pointing to
    the lit side (away from ``EDGE_BODY``)."""
    e = (EDGE_B - EDGE_A) / np.linalg.norm(EDGE_B - EDGE_A)
    n = np.cross(e, EDGE_A - P)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    body = np.einsum("...i,...i->...", n, EDGE_BODY - P)
    return np.where((body > 0)[..., None], -n, n)


class RoofEdgeScene(FacadeSunScene):
    """The facade lit by the sun past the roof line across the street (see the module docstring)."""

    def __init__(self, config: FacadeSunConfig) -> None:
        if not config.roof_edge:
            raise ValueError("RoofEdgeScene needs FacadeSunConfig(roof_edge=True)")
        super().__init__(config)

    # ------------------------------------------------------------- the swept occluder: the edge
    def pole_occlusion(self, k: int, *, restrict: bool = True) -> np.ndarray:
        """The occluded fraction of the sun's disc by the building across the street at frame k (padded
        grid): the edge is this scene's swept occluder, in the pole's place in the radiometry."""
        return self._edge_occlusion(self.sun_world[k])

    def _edge_normals_f(self) -> np.ndarray:
        if not hasattr(self, "_n_edge_f"):
            self._n_edge_f = edge_normals(self._P0)
        return self._n_edge_f

    def _edge_occlusion(self, d: np.ndarray) -> np.ndarray:
        delta = np.arcsin(np.clip(self._edge_normals_f() @ d, -1.0, 1.0))
        return np.where(self.hit_f, shadow._disc_fraction(-delta / RHO), 0.0)

    # ------------------------------------------------------------- ground truth
    def _ground_truth(self) -> None:
        super()._ground_truth()  # the geometry, the building's light and the mixed pixels (and the unused pole's)
        N = self.N
        n_f = self._edge_normals_f()
        nc = n_f[self.crop]
        hit = self.hit_f[self.crop]
        time = np.full(hit.shape, np.nan)
        direction = np.zeros(hit.shape, dtype=np.int8)
        prev = nc @ self.sun_world[0]
        for k in range(N - 1):
            nxt = nc @ self.sun_world[k + 1]
            change = hit & np.isnan(time) & (np.sign(prev) != np.sign(nxt)) & (prev != 0)
            with np.errstate(invalid="ignore", divide="ignore"):
                tau = prev / (prev - nxt)
            time = np.where(change, k + tau, time)
            direction = np.where(change, np.where(prev > 0, 1, -1), direction).astype(np.int8)
            prev = nxt
        # The penumbra's frames: |δ| < ρ (with a frame's margin either side).
        band = math.sin(RHO)
        first = np.full(hit.shape, np.inf)
        last = np.full(hit.shape, -np.inf)
        for k in range(N):
            inside = np.abs(nc @ self.sun_world[k]) < band
            first = np.where(inside, np.minimum(first, k), first)
            last = np.where(inside, np.maximum(last, k), last)
        first = np.minimum(first, np.floor(np.nan_to_num(time, nan=np.inf))) - 1
        last = np.maximum(last, np.ceil(np.nan_to_num(time, nan=-np.inf))) + 1
        crossed = hit & (time >= 1.0) & (time <= N - 2.0)
        seen = crossed.copy()
        strict = crossed.copy()
        for k in range(N):
            passing = crossed & (k >= first) & (k <= last)
            if not passing.any():
                continue
            cos_ok = (np.einsum("...i,i->...", self._n0, self.sun_world[k]) > 0.05)[self.crop]
            vis = self.building_visibility(k)[self.crop]
            seen &= (cos_ok & (vis >= 0.5)) | ~passing
            strict &= (cos_ok & (vis >= 1.0 - 1e-9)) | ~passing
        self.edge_time = np.where(crossed | ~np.isnan(time), time, np.nan)
        self.edge_direction = np.where(np.isfinite(time), direction, 0).astype(np.int8)
        self.swept_surface = seen
        self.swept = strict & self.unmixed
        self.cloud_free_passage = self.swept.copy()
        free = self.cloud_free_passage
        for kc in np.nonzero(self.cloud)[0]:
            free &= ~((kc >= first) & (kc <= last))
        self.regions = {"facade": self._regions(WALL)}

    def edge_planes_world(self) -> np.ndarray:
        """(N, 4) the plane through the edge containing d_k at each frame, n̂ towards the lit side."""
        e = EDGE_B - EDGE_A
        n = np.cross(e, self.sun_world)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        n = np.where(((n @ (EDGE_BODY - EDGE_A)) > 0)[:, None], -n, n)
        return np.concatenate([n, (n @ EDGE_A)[:, None]], axis=-1)

    # ------------------------------------------------------------- outputs
    def ground_truth_arrays(self) -> dict[str, np.ndarray]:
        out = super().ground_truth_arrays()
        out.update(edge_time=self.edge_time.astype(np.float32), edge_direction=self.edge_direction,
                   edge_a=EDGE_A.copy(), edge_b=EDGE_B.copy(), edge_body=EDGE_BODY.copy(),
                   edge_planes_world=self.edge_planes_world())
        return out

    def field_log(self) -> dict:
        regions = self.regions
        self.regions = {"ground": [], **regions}  # the base writes both planes; only the facade is kept
        try:
            log = super().field_log()
        finally:
            self.regions = regions
        for key in ("pole", "gnomon"):
            log.pop(key)
        log["planes"] = [p for p in log["planes"] if p["name"] == "facade"]
        log["edge"] = {"a": EDGE_A.tolist(), "b": EDGE_B.tolist(), "body": EDGE_BODY.tolist()}
        return log

    def summary(self) -> dict:
        out = super().summary()
        out["scene"] = "facade_sun (roof_edge)"
        out.pop("pole")
        out.pop("gnomon_observation")
        out["edge"] = {"a": EDGE_A.tolist(), "b": EDGE_B.tolist(), "body": EDGE_BODY.tolist(),
                       "swept_surface_pixels": int(self.swept_surface.sum())}
        return out


def simulate_roof_edge(out_dir, config: FacadeSunConfig | None = None, *,
                       progress: Callable[[int, int], None] | None = None) -> FacadeSunResult:
    """Render the roof-edge capture (``config.roof_edge`` is set) into ``out_dir``, as
    :func:`gnomon.simulate.facade_sun.simulate_facade_sun` writes its scene."""
    config = FacadeSunConfig(roof_edge=True) if config is None else config
    if not config.roof_edge:
        config = FacadeSunConfig(**{**config.__dict__, "roof_edge": True})
    return simulate_facade_sun(out_dir, config, progress=progress, scene=RoofEdgeScene(config))
