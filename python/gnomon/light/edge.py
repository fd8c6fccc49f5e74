"""The sun past a straight edge of the scene (a roof line): the shadow planes through the edge and the sun.

A straight occluding edge from ``a`` to ``b`` (world) casts, with the sun in direction ``d(t)``, a shadow
whose boundary lies in the plane through the edge containing ``d(t)`` — the pole's construction
(:func:`gnomon.light.sun.pole_plane_table`) with the edge in the axis' place. Unlike a pole's shadow, an
edge's shadow does not pass and go: over the day its boundary moves one way across the surface, so a pixel
goes into the shadow (or out of it) once and stays — a step, which the tracker reports in place of a dip
(``tracks_steps``: :mod:`gnomon.capture.steps`). Both kinds of step lie on the same plane family (the edge's
shadow boundary at the step's time), so the entering and the leaving steps are two edges of the scan,
triangulated on the same planes and fused.

Every point's ray towards the sun must pass the edge's line beyond the point (the point lies down-sun of the
edge), between ``a`` and ``b`` when they are given; with ``body`` (a point of the occluder away from the edge: the
side its shadow falls on) its step must go the way the edge's shadow moves there at that time — into the
shadow where the plane sweeps towards the shadowed side, out of it otherwise. The step must not sit in a
pile-up of steps (a cloud dimming the sun as the shadow arrived, :func:`pile_ups`), and the point must have
seen at least half the sun as the edge passed (:func:`gnomon.geometry.validity.fully_lit_like_neighbours`: the
edge hides the whole disc once past). Points that fail are refused, counted by reason
(:meth:`SunWithEdge.screen`).

Without ``a`` and ``b`` the edge is found: the line all the frames' planes share, each through the shadow's
line on the reference planes and the sun (:func:`common_line`), each scan edge from its own steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gnomon.camera.models import Pose
from gnomon.capture.tracking import ShadowTimes
from gnomon.errors import Remark
from gnomon.geometry.validity import fully_lit_like_neighbours
from gnomon.light.base import EdgePlanes, EdgeTimes, ReferenceGeometry, Screening
from gnomon.light.shadow_planes import sun_shadow_planes
from gnomon.light.sun import REFUSED_NOTE, SUBSTEPS, SunClock, SunLight, substep_sun_world, sun_directions_camera

__all__ = ["PILE_UP", "PILE_UP_FRAMES", "CommonLine", "SunWithEdge", "common_line", "pile_ups"]

# A frame holds a pile-up of steps when it has more than PILE_UP times the median count of the frames around it
# (± PILE_UP_FRAMES): a cloud that dims the sun as the edge's shadow arrives makes every point the shadow
# reaches in the cloud's frames step at its onset (the penumbra's mid-level is crossed early), and leaves a
# hole of too few steps after it, as long as the cloud lasts.
PILE_UP = 1.6
PILE_UP_FRAMES = 16
# The hole begins within this many frames after the pile-up.
HOLE_AFTER = 3
# An edge found from the reference lines needs this many frames' planes, turning by at least this much about it.
MIN_LINE_PLANES = 10
MIN_LINE_TURN_DEG = 2.0
# Planes farther from the common line than this many robust σ (1.4826 · median distance) are left out of its fit.
LINE_OUTLIER_SIGMAS = 3.0


@dataclass(frozen=True)
class CommonLine:
    """The line a family of planes shares (camera frame): ``point`` (the foot of the perpendicular from the
    camera centre), unit ``direction``; ``planes`` used of ``offered``; ``rms`` their distance from it (world
    units) and ``turn_deg`` the angle their normals span about it (how well its place is fixed)."""

    point: np.ndarray
    direction: np.ndarray
    planes: int
    offered: int
    rms: float
    turn_deg: float


def common_line(planes: np.ndarray) -> CommonLine | None:
    """The line every plane of ``planes`` (N, 4) rows ``[n, d]``, ``n·X = d``, NaN rows none) contains, by least
    squares: its direction the normals' least singular vector, its point the minimum-norm solution of ``n·X = d``;
    planes more than ``LINE_OUTLIER_SIGMAS`` robust σ from it are left out and the fit repeated. None with fewer
    than ``MIN_LINE_PLANES`` planes."""
    ok = np.all(np.isfinite(planes), axis=1)
    n, d = planes[ok, :3], planes[ok, 3]
    keep = np.ones(len(n), dtype=bool)
    for _ in range(4):
        if keep.sum() < MIN_LINE_PLANES:
            return None
        e = np.linalg.svd(n[keep])[2][-1]
        x = np.linalg.lstsq(n[keep], d[keep], rcond=None)[0]
        x -= e * (x @ e)
        dist = np.abs(n @ x - d)
        scale = 1.4826 * float(np.median(dist[keep]))
        new = dist <= max(LINE_OUTLIER_SIGMAS * scale, 1e-12)
        if np.array_equal(new, keep):
            break
        keep = new
    if keep.sum() < MIN_LINE_PLANES:
        return None
    # the normals' spread about the line: their angles in the plane perpendicular to it
    u = n[keep][0] - e * (n[keep][0] @ e)  # the first normal, square to the line: angle 0
    u /= np.linalg.norm(u)
    v = np.cross(e, u)
    angle = np.degrees(np.arctan2(n[keep] @ v, n[keep] @ u))
    angle = (angle + 90.0) % 180.0 - 90.0  # a normal and its opposite are one plane
    return CommonLine(x, e, int(keep.sum()), int(len(n)), float(np.sqrt(np.mean(dist[keep] ** 2))),
                      float(np.ptp(angle)))


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

    def __init__(self, clock: SunClock, pose: Pose, a_world: np.ndarray | None, b_world: np.ndarray | None,
                 body_world: np.ndarray | None = None):
        super().__init__(clock, pose)
        # None: found from each edge's shadow lines on the reference planes (:meth:`shadow_planes`)
        self.a_world = None if a_world is None else np.asarray(a_world, dtype=np.float64)
        self.b_world = None if b_world is None else np.asarray(b_world, dtype=np.float64)
        self.body_world = None if body_world is None else np.asarray(body_world, dtype=np.float64)
        self._sun: np.ndarray | None = None
        # per scan edge ("enter", "leave"): the edge found from its lines, world (a, b) and the fit
        self.found: dict[str, tuple[np.ndarray, np.ndarray, CommonLine] | None] = {}

    def _sun_world(self) -> np.ndarray:
        """Unit directions towards the sun (world) every 1/SUBSTEPS tracker frame."""
        if self._sun is None:
            c = self.clock
            self._sun = substep_sun_world(self._timeline(), c.site, c.heading_deg)
        return self._sun

    def _ends(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The edge's ends (world) for the scan edge ``name``: as given, or as found from its lines."""
        if self.a_world is not None and self.b_world is not None:
            return self.a_world, self.b_world
        found = self.found.get(name)
        return None if found is None else (found[0], found[1])

    def _plane_table(self, a_world: np.ndarray, b_world: np.ndarray) -> np.ndarray:
        """(M, 4) camera-frame planes through the edge ``a`` → ``b`` containing the sun, every 1/SUBSTEPS tracker
        frame; with ``body``, each normal points to the lit side (away from the occluder)."""
        d = self._sun_world()
        n = np.cross(b_world - a_world, d)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        if self.body_world is not None:
            n = np.where(((n @ (self.body_world - a_world)) > 0)[:, None], -n, n)
        n_cam = n @ self.pose.R.T
        a_cam = self.pose.world_to_camera(a_world)
        return np.concatenate([n_cam, (n_cam @ a_cam)[:, None]], axis=1)

    def shadow_planes(self, edge: EdgeTimes, geometry: ReferenceGeometry) -> EdgePlanes:
        """The table through the edge; without ``a`` and ``b``, through the line all the frames' planes share, each
        plane through the frame's shadow line on the reference planes and the sun (:func:`common_line`)."""
        lines = []
        if self.a_world is None or self.b_world is None:
            lines = geometry.lines(edge.times)
            c = self.clock
            planes, _ = sun_shadow_planes(lines, sun_directions_camera(self._timeline(), c.site, c.heading_deg,
                                                                       self.pose))
            fit = common_line(planes)
            if fit is None or fit.turn_deg < MIN_LINE_TURN_DEG:
                self.found[edge.name] = None
                rows = (len(self._timeline().used) - 1) * SUBSTEPS + 1
                return EdgePlanes(np.full((rows, 4), np.nan), 0, lines, np.zeros(rows), SUBSTEPS, measured=False)
            a = self.pose.camera_to_world(fit.point)
            self.found[edge.name] = (a, a + fit.direction @ self.pose.R, fit)
        ends = self._ends(edge.name)
        assert ends is not None
        table = self._plane_table(*ends)
        return EdgePlanes(table, 0, lines, np.zeros(len(table)), SUBSTEPS, measured=False)

    def screen(self, edge: EdgeTimes, points_cam: np.ndarray, times: ShadowTimes, n_frames: int,
               relative_depth: np.ndarray | None = None,
               relative_depth_sigma: np.ndarray | None = None,
               levelled: np.ndarray | None = None) -> Screening:
        """Only points down-sun of the edge (between its ends when they were given), not in a pile-up of steps,
        that saw at least half the sun as the edge passed and, with ``body``, whose step goes the way the edge's
        shadow moves there and then."""
        had = np.isfinite(points_cam[..., 2])
        ends = self._ends(edge.name)
        if ends is None:  # no edge found from this edge's lines: no planes, no points
            return Screening(np.zeros(had.shape, dtype=bool))
        given = self.a_world is not None
        rows = edge.times.astype(np.float64) * SUBSTEPS
        X = np.where(had[..., None], points_cam, 0.0)
        # The sun's ray from X meets the edge's line (X lies in the plane through both): X + s·d = a + u·(b − a).
        R = self.pose.R
        d = _rows(self._sun_world() @ R.T, rows)
        a, b = self.pose.world_to_camera(ends[0]), self.pose.world_to_camera(ends[1])
        e = b - a
        w = a - X
        ee, de, dd = float(e @ e), d @ e, np.einsum("...i,...i->...", d, d)
        dw, ew = np.einsum("...i,...i->...", d, w), w @ e
        det = de * de - dd * ee  # the normal equations of s·d − u·e = w
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (de * ew - ee * dw) / det
            u = (dd * ew - de * dw) / det
        down_sun = (s > 0) & (((u >= 0) & (u <= 1)) | (not given))  # a found edge has no ends
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
            table = self._plane_table(*ends)
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
        if relative_depth is not None:
            # The edge hides the whole disc once past: the step takes the direct share of the lit level, less
            # where another object (a reveal, a ledge) hid part of the disc as the edge passed (its time biased).
            full = fully_lit_like_neighbours(relative_depth, np.ones(had.shape), sound)
            rejected["saw_less_than_half_the_sun"] = int((sound & ~full).sum())
            sound &= full
        notes: list[str] = []
        if rejected["step_in_a_pile_up_of_steps"]:
            notes.append(Remark(f"{rejected['step_in_a_pile_up_of_steps']} points refused: their "
                                f"steps piled up in tracker frames {[list(sp) for sp in spans][:6]} (a cloud dimming "
                                "the sun as the edge's shadow arrived moves the step to the cloud's onset); the "
                                "surface the shadow reached then has no points: a capture on a clear day fills it"))
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
        edge: dict[str, Any] = {
            "a": None if self.a_world is None else self.a_world.tolist(),
            "b": None if self.b_world is None else self.b_world.tolist(),
            "body": None if self.body_world is None else self.body_world.tolist(),
            "found_from_lines": self.a_world is None}
        if self.found and all(f is None for f in self.found.values()):
            warnings.append(f"no straight edge found from the shadow's lines on the reference planes (fewer than "
                            f"{MIN_LINE_PLANES} frames' planes, or turning by less than {MIN_LINE_TURN_DEG:g}° about "
                            "their common line): no points; give [edge] a and b, or reference regions the edge's "
                            "shadow crosses")
        for name, found in self.found.items():
            if found is None:  # this edge's steps did not cross the reference regions: no points from it
                edge[name] = None
                continue
            a, b, fit = found
            edge[name] = {"point": a.tolist(), "direction": (b - a).tolist(), "planes": fit.planes,
                          "planes_offered": fit.offered, "rms": fit.rms, "turn_deg": fit.turn_deg}
        out["sun"]["edge"] = edge
        return out
