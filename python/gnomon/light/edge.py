"""The sun past a straight edge of the scene (a roof line): the shadow planes through the edge and the sun.

A straight occluding edge from ``a`` to ``b`` (world) casts, with the sun in direction ``d(t)``, a shadow
whose boundary lies in the plane through the edge containing ``d(t)`` — the pole's construction
(:func:`gnomon.light.sun.pole_plane_table`) with the edge in the axis' place. Unlike a pole's shadow, an
edge's shadow does not pass and go: over the day its boundary moves one way across the surface, so a pixel
goes into the shadow (or out of it) once and stays — a step, which the tracker reports in place of a dip
(``tracks_steps``: :mod:`gnomon.capture.steps`). Both kinds of step lie on the same plane family (the edge's
shadow boundary at the step's time), so the entering and the leaving steps are two edges of the scan,
triangulated on the same planes and fused.

With ``body`` (a point of the occluder away from the edge: the side its shadow falls on) each point's step
must go the way the edge's shadow moves there at that time — into the shadow where the plane sweeps towards
the shadowed side, out of it otherwise —, and every point's ray towards the sun must pass the edge between
``a`` and ``b`` (the point lies down-sun of the edge). Points that fail are refused, counted by reason
(:meth:`SunWithEdge.screen`): another edge's step (a balcony's, a window reveal's) triangulated on the wrong
planes mostly fails them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon.camera.models import Pose
from gnomon.capture.tracking import ShadowTimes
from gnomon.errors import Remark
from gnomon.light.base import EdgePlanes, EdgeTimes, ReferenceGeometry, Screening
from gnomon.light.sun import SUBSTEPS, SunClock, SunLight, substep_sun_world

__all__ = ["PILE_UP", "PILE_UP_FRAMES", "REFUSED_NOTE", "SunWithEdge", "pile_ups"]

# A warning lists the edge checks' refusals when they refuse more than this share of the points.
REFUSED_NOTE = 0.1
# A frame holds a pile-up of steps when it has more than PILE_UP times the median count of the frames around it
# (± PILE_UP_FRAMES): a cloud that dims the sun as the edge's shadow arrives makes every point the shadow
# reaches in the cloud's frames step at its onset (the penumbra's mid-level is crossed early), and leaves a
# hole of too few steps after it, as long as the cloud lasts.
PILE_UP = 1.6
PILE_UP_FRAMES = 16
# The hole begins within this many frames after the pile-up.
HOLE_AFTER = 3


def _rows(table: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Rows of ``table`` (M, C) at fractional row indices ``times`` (...,), linearly between rows; NaN outside."""
    m = len(table)
    ok = np.isfinite(times) & (times >= 0) & (times <= m - 1)
    t = np.where(ok, times, 0.0)
    k = np.minimum(np.floor(t).astype(np.int64), max(m - 2, 0))
    f = (t - k)[..., None]
    out = table[k] * (1 - f) + table[np.minimum(k + 1, m - 1)] * f
    return np.where(ok[..., None], out, np.nan)


def pile_ups(times: np.ndarray, n_frames: int) -> list[tuple[int, int]]:
    """Spans of tracker frames ``(first, last)`` (inclusive) where the steps' times ``times`` (H, W, NaN = none)
    pile up in a frame (``PILE_UP`` times the median count of the frames around it) and then thin out (a hole:
    frames with fewer than 1/``PILE_UP`` of it, beginning within ``HOLE_AFTER`` frames): from the frame before
    the pile-up to the end of the hole, and a frame more."""
    t = times[np.isfinite(times)]
    if t.size == 0:
        return []
    counts = np.bincount(np.clip(np.floor(t).astype(np.int64), 0, n_frames - 1), minlength=n_frames)
    local = np.array([np.median(counts[max(f - PILE_UP_FRAMES, 0):f + PILE_UP_FRAMES + 1]) for f in range(n_frames)])
    spans: list[tuple[int, int]] = []
    hole = counts * PILE_UP < local
    for f in np.flatnonzero(counts > PILE_UP * np.maximum(local, 1.0)):
        ahead = np.flatnonzero(hole[f + 1:f + 1 + HOLE_AFTER])
        if not ahead.size:  # no frames emptied after it: the geometry's (a row of windows), not a cloud's
            continue
        end = int(f) + 1 + int(ahead[0])
        while end + 1 < n_frames and hole[end + 1]:
            end += 1
        span = (max(int(f) - 1, 0), min(end + 1, n_frames - 1))
        if spans and span[0] <= spans[-1][1]:
            spans[-1] = (spans[-1][0], max(spans[-1][1], span[1]))
        else:
            spans.append(span)
    return spans


class SunWithEdge(SunLight):
    """Planes through a straight edge (world ``a`` → ``b``) and the sun; ``body`` (world, optional) a point of
    the occluder off the edge. Two edges, the entering and the leaving steps, on the same planes."""

    mode = "edge"
    tracks_steps = True
    planes_from_reference_lines = False  # the planes need the capture's whole timeline

    def __init__(self, clock: SunClock, pose: Pose, a_world: np.ndarray, b_world: np.ndarray,
                 body_world: np.ndarray | None = None):
        super().__init__(clock, pose)
        self.a_world = np.asarray(a_world, dtype=np.float64)
        self.b_world = np.asarray(b_world, dtype=np.float64)
        self.body_world = None if body_world is None else np.asarray(body_world, dtype=np.float64)
        self._sun: np.ndarray | None = None

    def _sun_world(self) -> np.ndarray:
        """Unit directions towards the sun (world) every 1/SUBSTEPS tracker frame."""
        if self._sun is None:
            c = self.clock
            self._sun = substep_sun_world(self._timeline(), c.site, c.heading_deg)
        return self._sun

    def _plane_table(self) -> np.ndarray:
        """(M, 4) camera-frame planes through the edge containing the sun, every 1/SUBSTEPS tracker frame; with
        ``body``, each normal points to the lit side (away from the occluder)."""
        d = self._sun_world()
        n = np.cross(self.b_world - self.a_world, d)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        if self.body_world is not None:
            n = np.where(((n @ (self.body_world - self.a_world)) > 0)[:, None], -n, n)
        n_cam = n @ self.pose.R.T
        a_cam = self.pose.world_to_camera(self.a_world)
        return np.concatenate([n_cam, (n_cam @ a_cam)[:, None]], axis=1)

    def shadow_planes(self, edge: EdgeTimes, geometry: ReferenceGeometry) -> EdgePlanes:
        table = self._plane_table()
        return EdgePlanes(table, 0, [], np.zeros(len(table)), SUBSTEPS, measured=False)

    def screen(self, edge: EdgeTimes, points_cam: np.ndarray, times: ShadowTimes, n_frames: int,
               relative_depth: np.ndarray | None = None,
               relative_depth_sigma: np.ndarray | None = None,
               levelled: np.ndarray | None = None) -> Screening:
        """Only points down-sun of the edge between its ends and, with ``body``, whose step goes the way the
        edge's shadow moves there and then."""
        had = np.isfinite(points_cam[..., 2])
        rows = edge.times.astype(np.float64) * SUBSTEPS
        X = np.where(had[..., None], points_cam, 0.0)
        # The sun's ray from X meets the edge's line (X lies in the plane through both): X + s·d = a + u·(b − a).
        R = self.pose.R
        d = _rows(self._sun_world() @ R.T, rows)
        a, b = self.pose.world_to_camera(self.a_world), self.pose.world_to_camera(self.b_world)
        e = b - a
        w = a - X
        ee, de, dd = float(e @ e), d @ e, np.einsum("...i,...i->...", d, d)
        dw, ew = np.einsum("...i,...i->...", d, w), w @ e
        det = de * de - dd * ee  # the normal equations of s·d − u·e = w
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (de * ew - ee * dw) / det
            u = (dd * ew - de * dw) / det
        down_sun = (s > 0) & (u >= 0) & (u <= 1)
        rejected = {"not_down_sun_of_the_edge": int((had & ~down_sun).sum())}
        sound = had & down_sun
        piled = np.zeros(had.shape, dtype=bool)
        spans = pile_ups(edge.times, n_frames)
        for first, last in spans:
            with np.errstate(invalid="ignore"):
                piled |= (edge.times >= first) & (edge.times < last + 1)
        rejected["step_in_a_pile_up_of_steps"] = int((sound & piled).sum())
        sound &= ~piled
        if self.body_world is not None:
            # Signed distance to the plane (positive: lit) a little before and after the step's time.
            table = self._plane_table()
            h = 0.5 * SUBSTEPS
            before = _rows(table, rows - h)
            after = _rows(table, rows + h)
            s_before = np.einsum("...i,...i->...", before[..., :3], X) - before[..., 3]
            s_after = np.einsum("...i,...i->...", after[..., :3], X) - after[..., 3]
            entering = edge.name == "enter"
            with np.errstate(invalid="ignore"):
                goes = (s_after < s_before) if entering else (s_after > s_before)
            # at the sequence's ends the plane half a frame away does not exist: the step's own side decides
            goes = np.where(np.isfinite(s_before) & np.isfinite(s_after), goes, True)
            rejected["step_against_the_edge_shadow_motion"] = int((sound & ~goes).sum())
            sound &= goes
        notes: list[str] = []
        if rejected["step_in_a_pile_up_of_steps"]:
            notes.append(Remark(f"{rejected['step_in_a_pile_up_of_steps']} points refused: their "
                                f"steps piled up in tracker frames {[list(sp) for sp in spans][:6]} (a cloud dimming "
                                "the "
                                "sun as the edge's shadow arrived moves the step to the cloud's onset); the surface "
                                "the shadow reached then has no points: a capture on a clear day fills it"))
        n_had = max(int(had.sum()), 1)
        refused = n_had - int(sound.sum())
        if refused > REFUSED_NOTE * n_had:
            notes.append(Remark(f"{refused} of {n_had} points ({100 * refused / n_had:.0f} %) "
                                f"refused as not the [edge]'s shadow ("
                                f"{', '.join(f'{k}: {v}' for k, v in rejected.items() if v)}); check [edge] a, b "
                                "and body, or the building's other shadow edges crossing the view"))
        return Screening(sound, rejected, notes)

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        out = super().report(planes_cam, warnings)
        out["sun"]["edge"] = {"a": self.a_world.tolist(), "b": self.b_world.tolist(),
                              "body": None if self.body_world is None else self.body_world.tolist()}
        return out
