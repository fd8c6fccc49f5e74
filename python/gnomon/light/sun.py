"""The sun outdoors: frame times, the world frame's heading, sun shadow planes.

* **Time**: every frame's UTC time (:mod:`gnomon.light.timestamps`); sub-frame
  shadow times map to UTC by interpolation between frames (:class:`SunTimeline`).
* **Heading**: the world frame is tied to East-North-Up by the compass heading
  of its x axis (world z up; :func:`gnomon.light.ephemeris.R_world_from_enu`), given in
  ``[site] heading_deg`` or measured from a vertical gnomon: the shadow of a
  vertical pole on the ground points away from the sun's azimuth, whatever
  the elevation, so its direction in the world frame against the sun's
  azimuth at that instant gives the heading (:func:`heading_from_gnomon`).
* **Night**: frames with the sun at or below the horizon are not tracked.
* **Planes**: without a pole (:class:`SunWithLines`) each frame's plane
  contains the shadow line on a reference plane and the direction towards the
  sun (:func:`gnomon.light.shadow_planes.sun_shadow_planes`). With a ``[pole]`` of
  known axis (:class:`SunWithPole`) the shadow's centre plane contains the
  axis and the sun direction, so no reference plane is needed where the shadow
  falls; the sun direction is evaluated at ``SUBSTEPS`` steps per frame, so
  each pixel's plane uses the sun at its own shadow time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
import pandas as pd

from gnomon.camera.models import CameraModel, Pose
from gnomon.capture.tracking import ShadowTimes, TrackedSequence, linear
from gnomon.errors import GnomonError, Remark
from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines, ReferencePlane
from gnomon.geometry.triangulation import triangulate
from gnomon.geometry.uncertainty import MIN_FRAMES_PER_TRANSITION, linear_noise_at_threshold
from gnomon.geometry.validity import (
    contrast_above_noise,
    contrast_like_neighbours,
    dip_in_frames,
    event_order,
    fully_lit_like_neighbours,
    global_event_frames,
    inside_sequence,
    not_in_global_event,
    pole_shadow_consistency,
)
from gnomon.light.base import (
    EdgePlanes,
    EdgeTimes,
    LightModel,
    Recorder,
    ReferenceGeometry,
    Screening,
    skipped_frames_warning,
)
from gnomon.light.dip_choice import choose_dips
from gnomon.light.ephemeris import Site, enu_to_world, sun_direction_enu, sun_position
from gnomon.light.georef import georeference_report
from gnomon.light.shadow_planes import sun_shadow_planes
from gnomon.light.timestamps import interpolate_times

__all__ = [
    "SUBSTEPS", "HeadingEstimate", "SunClock", "SunTimeline", "SunWithLines", "SunWithPole", "below_horizon",
    "heading_from_gnomon", "pole_plane_table", "substep_sun_world", "sun_directions_camera", "sun_world",
]

# Sun directions per frame interval for the pole's plane table.
SUBSTEPS = 8
# A warning lists the pole checks' refusals when they refuse more than this share of the candidates.
REFUSED_NOTE = 0.1
# A dip deeper than the share of the disc the pole hides by more than this many σ is not the pole's.
DEPTH_SIGMAS = 4.0


def sun_world(times: Any, site: Site, heading_deg: float) -> np.ndarray:
    """Unit directions towards the sun (N, 3) in the world frame; naive times are UTC."""
    index = pd.DatetimeIndex(times)
    if index.tz is None:  # datetime64 arrays from interpolation are UTC, not site-local
        index = index.tz_localize("UTC")
    return enu_to_world(sun_direction_enu(index, site), heading_deg)


def below_horizon(times: pd.DatetimeIndex, site: Site) -> np.ndarray:
    """(N,) bool: the sun is at or below the horizon at each time."""
    return np.asarray(sun_position(times, site).apparent_elevation_deg) <= 0.0


@dataclass
class HeadingEstimate:
    heading_deg: float
    sigma_deg: float
    frame: str
    sun_azimuth_deg: float


def heading_from_gnomon(camera: CameraModel, pose: Pose, ground: PlaneInCamera, base_px: np.ndarray,
                        shadow_px: np.ndarray, when: pd.DatetimeIndex, site: Site, frame: str,
                        sigma_px: float = 0.5, where: str = "[gnomon]") -> HeadingEstimate:
    """The world x axis' compass heading from a vertical pole's shadow in one frame.

    ``base_px`` (the pole's foot) and ``shadow_px`` (a point on its shadow's
    centre line on the ``ground``) are back-projected onto the ground; the
    shadow's world angle φ (from x towards y) and the sun's azimuth A at
    ``when`` (one time) give ``heading = A + 180° + φ``. σ from ``sigma_px`` on
    each pixel coordinate, propagated numerically. ``frame`` names the photo,
    ``where`` the field-log table (for errors).
    """
    azimuth = float(sun_position(when, site).azimuth_deg[0])

    def phi(px: np.ndarray) -> float:
        pts = pose.camera_to_world(ground.intersect(camera.rays(px.reshape(2, 2))))
        if not np.all(np.isfinite(pts)):
            raise GnomonError(f"{where} base_px or shadow_px does not see the ground plane")
        d = pts[1] - pts[0]
        return float(np.degrees(np.arctan2(d[1], d[0])))

    px = np.concatenate([base_px, shadow_px])
    phi0 = phi(px)
    jac = []
    for i in range(4):
        step = np.zeros(4)
        step[i] = 0.01
        jac.append((((phi(px + step) - phi(px - step)) + 180) % 360 - 180) / 0.02)
    sigma = float(np.sqrt(np.sum(np.square(jac))) * sigma_px)
    return HeadingEstimate(float((azimuth + 180.0 + phi0) % 360.0), sigma, frame, azimuth)


@dataclass
class SunTimeline:
    """Which frames were tracked, and when: maps the tracker's frame index to UTC."""

    times: pd.DatetimeIndex  # every frame of the capture
    used: np.ndarray  # capture indices fed to the tracker, in order
    skipped_cloud: list[int] = field(default_factory=list)
    skipped_night: list[int] = field(default_factory=list)

    def utc(self, tracker_times: np.ndarray) -> np.ndarray:
        """datetime64[ns] of fractional tracker frame indices (NaN → NaT)."""
        t = np.asarray(tracker_times, dtype=np.float64)
        capture_index = np.interp(np.nan_to_num(t, nan=0.0), np.arange(len(self.used)), self.used.astype(float))
        capture_index = np.where(np.isfinite(t), capture_index, np.nan)
        return interpolate_times(self.times, capture_index)


def substep_sun_world(timeline: SunTimeline, site: Site, heading_deg: float) -> np.ndarray:
    """Unit directions towards the sun (world), row k at tracker time k / SUBSTEPS."""
    n = len(timeline.used)
    tau = np.arange((n - 1) * SUBSTEPS + 1) / SUBSTEPS
    return sun_world(pd.DatetimeIndex(timeline.utc(tau)), site, heading_deg)


def pole_plane_table(pole_base: np.ndarray, pole_top: np.ndarray, timeline: SunTimeline, site: Site,
                     heading_deg: float, pose: Pose) -> np.ndarray:
    """Camera-frame planes containing the pole's axis and the sun, every 1/SUBSTEPS tracker frame.

    Row k is the plane at tracker time k / SUBSTEPS; triangulate with
    ``times · SUBSTEPS``.
    """
    d = substep_sun_world(timeline, site, heading_deg)
    axis = (pole_top - pole_base) / np.linalg.norm(pole_top - pole_base)
    normal_w = np.cross(axis, d)
    norm = np.linalg.norm(normal_w, axis=1, keepdims=True)
    normal_w = np.where(norm > 1e-9, normal_w / np.maximum(norm, 1e-12), np.nan)
    n_cam = normal_w @ pose.R.T
    base_cam = pose.world_to_camera(pole_base)
    planes = np.concatenate([n_cam, (n_cam @ base_cam)[:, None]], axis=1)
    return planes


def sun_directions_camera(timeline: SunTimeline, site: Site, heading_deg: float, pose: Pose) -> np.ndarray:
    """Directions towards the sun (tracker frames, 3) in the camera frame."""
    d = sun_world(timeline.times[timeline.used], site, heading_deg)
    return d @ pose.R.T


@dataclass
class SunClock:
    """The sun over a capture: site, every frame's UTC time, the world frame's heading."""

    site: Site
    times: pd.DatetimeIndex  # every capture frame
    heading_deg: float
    heading_source: str
    heading_sigma_deg: float | None = None
    gnomon_estimate: HeadingEstimate | None = None

    def __post_init__(self) -> None:
        self.night = below_horizon(self.times, self.site)


class SunLight(LightModel):
    """What both sun models share: night frames, clock time, the timeline, report and recording."""

    kind = "sun"
    mode = ""

    def __init__(self, clock: SunClock, pose: Pose):
        self.clock, self.pose = clock, pose
        self.timeline: SunTimeline | None = None

    def skipped_frames(self, n_frames: int) -> np.ndarray:
        return np.asarray(self.clock.night, dtype=bool)

    def undersampling_advice(self, factor: float) -> str:
        """The sun sets the shadow's speed: only the interval between frames can change."""
        seconds = np.diff(self.clock.times.asi8) / 1e9
        day = seconds[seconds > 0]
        if not day.size:
            return f"take {factor:.1f}× as many frames per hour"
        interval = float(np.median(day))
        return (f"take the frames {factor:.1f}× as often (every {interval / factor:.0f} s instead of "
                f"{interval:.0f} s; the sun sets the shadow's speed)")

    def frame_time(self, index: int) -> datetime:
        return self.clock.times[index]

    def georeference(self, units: str) -> dict[str, Any]:
        site = self.clock.site
        return georeference_report(site.latitude_deg, site.longitude_deg, site.altitude_m, self.clock.heading_deg,
                                   units)

    def after_tracking(self, used: np.ndarray, skipped_dips: list[int]) -> list[str]:
        night = [int(i) for i in np.flatnonzero(self.clock.night)]
        self.timeline = SunTimeline(self.clock.times, np.asarray(used), list(skipped_dips), night)
        warnings: list[str] = []
        if night:
            warnings.append(Remark(f"{len(night)} frames skipped: the sun is below the horizon "
                                   f"(first {self.clock.times[night[0]].isoformat()})", night))
        if skipped_dips:
            warnings.append(skipped_frames_warning(list(skipped_dips), "cloud dips"))
        return warnings

    def _timeline(self) -> SunTimeline:
        if self.timeline is None:
            raise RuntimeError("the sun's timeline is set by after_tracking()")
        return self.timeline

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        clock, timeline = self.clock, self._timeline()
        est = clock.gnomon_estimate
        return {
            "light": {"kind": self.kind, "position": None},
            "sun": {
                "heading_deg": clock.heading_deg, "heading_source": clock.heading_source,
                "heading_sigma_deg": clock.heading_sigma_deg,
                "gnomon_heading_deg": est.heading_deg if est else None,
                "gnomon_heading_sigma_deg": est.sigma_deg if est else None,
                "frames_used": int(len(timeline.used)),
                "skipped_cloud": [int(i) for i in timeline.skipped_cloud],
                "skipped_night": [int(i) for i in timeline.skipped_night],
                "first_frame_utc": clock.times[0].isoformat(), "last_frame_utc": clock.times[-1].isoformat(),
                "mode": self.mode,
            },
        }

    def _anchor(self, points_world: np.ndarray) -> np.ndarray:
        """Where the sun's arrow starts in the recording (world)."""
        return np.nanmean(points_world, axis=0)

    def record(self, recorder: Recorder, points_world: np.ndarray, stride: int) -> None:
        clock = self.clock
        anchor = self._anchor(points_world)
        extent = float(np.nanmax(np.ptp(points_world, axis=0))) if len(points_world) else 1.0
        for k in range(0, len(clock.times), max(stride, 1)):
            d = sun_world(clock.times[k:k + 1], clock.site, clock.heading_deg)[0]
            recorder.log_sun(k, d, anchor, 0.5 * extent, clock.times[k])


class SunWithLines(SunLight):
    """Planes through each frame's shadow line on a reference plane and the sun direction."""

    mode = "reference lines"

    def planes_from_lines(self, lines: list[ReferenceLines]) -> tuple[np.ndarray, int]:
        c = self.clock
        return sun_shadow_planes(lines, sun_directions_camera(self._timeline(), c.site, c.heading_deg, self.pose))


MIN_CONTRAST_RATIO = 0.55


class SunWithPole(SunLight):
    """Planes through a vertical pole's axis and the sun: one edge, the shadow's centre line.

    ``base_world``, ``top_world`` (3,): two points of the pole's axis; ``radius``: the pole's (world units).
    """

    mode = "pole"
    chooses_dips = True
    planes_from_reference_lines = False  # the pole's planes need the capture's whole timeline

    def __init__(self, clock: SunClock, pose: Pose, base_world: np.ndarray, top_world: np.ndarray,
                 radius: float = 0.0):
        super().__init__(clock, pose)
        # How choose_dips chose (report.json's sun.dip_choice): None before it ran.
        self.dip_choice: dict[str, Any] | None = None
        self.base_world = np.asarray(base_world, dtype=np.float64)
        self.top_world = np.asarray(top_world, dtype=np.float64)
        self.radius = float(radius)

    def edges(self, enter: EdgeTimes, leave: EdgeTimes, wanted: str) -> list[EdgeTimes]:
        """The centre between entering and leaving edge: the pole's axis plane."""
        centre = ((enter.times + leave.times) / 2).astype(np.float32)
        return [EdgeTimes("centre", centre, leave.slope, 0.5 * np.hypot(enter.sigma_t, leave.sigma_t))]

    def shadow_planes(self, edge: EdgeTimes, geometry: ReferenceGeometry) -> EdgePlanes:
        return EdgePlanes(self._plane_table(), 0, [], np.zeros(len(self._plane_table())), SUBSTEPS, measured=False)

    def _plane_table(self) -> np.ndarray:
        c = self.clock
        return pole_plane_table(self.base_world, self.top_world, self._timeline(), c.site, c.heading_deg, self.pose)

    def _pole_can_explain(self, enter: np.ndarray, leave: np.ndarray, depth: np.ndarray, ray_map: np.ndarray,
                          relative_depth: np.ndarray, relative_depth_sigma: np.ndarray, n_frames: int) -> np.ndarray:
        """(H, W) bool: a dip (times in tracker frames, its centre triangulated at ``depth``) the pole's
        shadow can explain: in order, inside the sequence, on the shadow side below the top, as long as
        the shadow lasts there and no deeper than the pole makes it (the checks of :meth:`screen`)."""
        c, pose = self.clock, self.pose
        points = ray_map * (depth / ray_map[..., 2])[..., None]
        check = pole_shadow_consistency(points, enter, leave,
                                        sun_directions_camera(self._timeline(), c.site, c.heading_deg, pose),
                                        pose.world_to_camera(self.base_world), pose.world_to_camera(self.top_world),
                                        self.radius)
        with np.errstate(invalid="ignore"):
            too_deep = relative_depth - DEPTH_SIGMAS * relative_depth_sigma > check.occlusion
        return (np.isfinite(depth) & event_order(enter, leave) & inside_sequence(enter, leave, n_frames)
                & check.ok & ~too_deep)

    def choose_dips(self, tracked: TrackedSequence, ray_map: np.ndarray, planes: tuple[ReferencePlane, ...],
                    max_jump: float, min_contrast_dn: float) -> list[str]:
        """Between each pixel's two candidate dips, the pole's: each candidate's centre triangulated on
        the pole's planes, kept where the pole's shadow can explain it, and chosen by the surfaces the
        candidates make against the reference planes (:func:`gnomon.light.dip_choice.choose_dips`) when the
        regions show another moving shadow; otherwise the tracker's verdict stands."""
        second, times = tracked.second, tracked.times
        if second is None:
            return []
        table = self._plane_table()
        lut, n = tracked.lut, tracked.n_frames

        def candidate(enter: np.ndarray, leave: np.ndarray, imax: np.ndarray, imin: np.ndarray,
                      contrast: np.ndarray) -> np.ndarray:
            centre = ((enter + leave) / 2 * SUBSTEPS).astype(np.float32)
            depth = triangulate(ray_map, centre, table).depth
            hi, lo = linear(imax, lut), linear(imin, lut)
            s_hi = linear_noise_at_threshold(tracked.noise_dn, hi, lut)
            s_lo = linear_noise_at_threshold(tracked.noise_dn, lo, lut)
            with np.errstate(invalid="ignore", divide="ignore"):
                rel = np.where(hi > 0, (hi - lo) / hi, np.nan)
                rel_sigma = np.where(hi > 0, np.hypot(s_lo / hi, lo * s_hi / hi**2), np.nan)
            deep = contrast_above_noise(contrast, tracked.noise_dn) & (contrast >= min_contrast_dn)
            ok = deep & self._pole_can_explain(enter, leave, depth, ray_map, rel, rel_sigma, n)
            return np.where(ok, depth, np.nan)

        depth = np.stack([candidate(second.best_enter, second.best_leave, times.imax, times.imin, times.contrast),
                          candidate(second.enter, second.leave, second.imax, second.imin, second.contrast)])
        shape = times.enter.shape
        region_depth = np.full(shape, np.nan)
        plane_depths = []
        for p in planes:
            zp = p.plane.intersect(ray_map.reshape(-1, 3).astype(np.float64))[:, 2].reshape(shape)
            plane_depths.append(zp)
            region_depth[p.mask] = zp[p.mask]
        dc = choose_dips(depth, region_depth, plane_depths, max_jump, times.valid)
        self.dip_choice = {"another_shadow_on_the_regions": dc.strict, **dc.counts}
        if not dc.strict:  # no other shadow on the regions: the tracker's verdict stands
            return []
        best, other = dc.choice == 1, dc.choice == 2
        old_contrast = times.contrast.copy()
        for name in ("enter", "leave", "enter_slope", "leave_slope"):
            getattr(times, name)[best] = getattr(second, f"best_{name}")[best]
        for name in ("imax", "imin", "contrast", "threshold", "enter", "leave", "enter_slope", "leave_slope"):
            getattr(times, name)[other] = getattr(second, name)[other]
        times.rival[other] = old_contrast[other]
        chosen = dc.choice > 0
        times.enter[~chosen] = np.nan
        times.leave[~chosen] = np.nan
        times.ambiguous = (times.ambiguous & ~chosen) | dc.ambiguous
        times.valid = chosen
        k = dc.counts
        return [f"pole's dip chosen by geometry: the reference regions show another moving shadow "
                f"({k['off_region']} of {k['on_region'] + k['off_region']} of their candidate dips put the point "
                f"off their plane), so only surfaces the reference planes support are kept; of {k['candidates']} "
                f"pixels with a dip the pole's shadow can explain, {k['second_chosen']} took their second dip (the "
                f"deepest was another shadow's), {k['best_kept']} kept their deepest, {k['ambiguous']} stay "
                f"ambiguous and {k['refused']} ({100 * k['refused'] / max(k['candidates'], 1):.0f} %) were refused"]

    def screen(self, edge: EdgeTimes, points_cam: np.ndarray, times: ShadowTimes, n_frames: int,
               relative_depth: np.ndarray | None = None,
               relative_depth_sigma: np.ndarray | None = None,
               levelled: np.ndarray | None = None) -> Screening:
        """Only points where the pole's shadow can fall, lasting as long as it lasts there, and (given
        the dips' relative depths) no deeper than it can be there, nor in another object's penumbra."""
        c, pose = self.clock, self.pose
        check = pole_shadow_consistency(points_cam, times.enter, times.leave,
                                        sun_directions_camera(self._timeline(), c.site, c.heading_deg, pose),
                                        pose.world_to_camera(self.base_world), pose.world_to_camera(self.top_world),
                                        self.radius)
        spikes = np.union1d(global_event_frames(times.enter, n_frames), global_event_frames(times.leave, n_frames))
        ordered = event_order(times.enter, times.leave) & inside_sequence(times.enter, times.leave, n_frames)
        calm = not_in_global_event(times.enter, spikes) & not_in_global_event(times.leave, spikes)
        had = np.isfinite(points_cam[..., 2])
        rejected = {
            "leave_before_enter_or_at_the_ends": int((had & ~ordered).sum()),
            "global_darkening": int((had & ordered & ~calm).sum()),
            "not_on_the_pole_shadow_side": int((had & ordered & calm & ~check.shadow_side).sum()),
            "dip_duration_unlike_the_pole_shadow": int((had & ordered & calm & check.shadow_side
                                                        & ~check.duration).sum()),
        }
        sound = ordered & calm & check.ok
        if relative_depth is not None:
            # The pole hides the share f of the disc there: it removes at most f of the light
            # (all of it direct). A deeper dip is another, wider object's shadow (a lamp post).
            sigma = relative_depth_sigma if relative_depth_sigma is not None else 0.0
            with np.errstate(invalid="ignore"):
                too_deep = relative_depth - DEPTH_SIGMAS * sigma > check.occlusion
            rejected["dip_deeper_than_the_pole_makes_there"] = int((had & sound & too_deep).sum())
            sound &= ~too_deep
        # A dip seen in frames levelled pixel by pixel (a cloud's) is shallower than in clear frames, the
        # more so the deeper the cloud in its frame: the levels bring the lit samples back to their clear
        # level, not the shadowed ones (sky light only, brighter under the cloud). Such a dip is compared
        # with the dips centred in the same frame; the others with each other.
        cloudy = dip_in_frames(times.enter, times.leave, levelled, n_frames)
        # A shadow that lasts w < 1 frame is seen by the pixel's samples only in part, at a random phase:
        # its darkest sample catches about w of its depth at the least likely phases.
        with np.errstate(invalid="ignore"):
            ratio = MIN_CONTRAST_RATIO * np.clip(np.nan_to_num(check.predicted_frames, nan=1.0), 0.0, 1.0)
        deep = np.zeros_like(sound)
        for under, group in ((True, sound & cloudy), (False, sound & ~cloudy)):
            if under:
                part = np.zeros_like(group)
                with np.errstate(invalid="ignore"):
                    frame = np.round((times.enter + times.leave) / 2)
                for f in np.unique(frame[group]):
                    part |= contrast_like_neighbours(times.contrast, group & (frame == f), min_ratio=ratio)
            else:
                part = contrast_like_neighbours(times.contrast, group, min_ratio=ratio)
            if relative_depth is not None:
                # Where the shadow lasts MIN_FRAMES_PER_TRANSITION frames or more, the darkest sample sees
                # its full depth and the half-disc test applies; a shorter dip is sampled at a random
                # phase (its darkest sample may sit on a flank), and only the loose contrast test does.
                resolved = group & (check.predicted_frames >= MIN_FRAMES_PER_TRANSITION)
                part = np.where(resolved, fully_lit_like_neighbours(relative_depth, check.occlusion, resolved), part)
            deep |= part
        rejected["dip_shallower_than_its_neighbours"] = int((had & sound & ~deep).sum())
        sound &= deep
        notes = []
        if len(spikes):
            notes.append(f"{rejected['global_darkening']} pixels had their shadow event in frames "
                         f"{[int(f) for f in spikes[:8]]} where most of the image darkened at once (a cloud, not "
                         "the pole's shadow): no points there")
        n_had = max(int(had.sum()), 1)
        refused = n_had - int((had & sound).sum())
        if refused > REFUSED_NOTE * n_had:
            notes.append(Remark(f"{refused} of {n_had} pixels ({100 * refused / n_had:.0f} %) were refused as not "
                                f"the pole's shadow ({', '.join(f'{k}: {v}' for k, v in rejected.items() if v)})"))
        return Screening(sound, rejected, notes)

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        out = super().report(planes_cam, warnings)
        if self.dip_choice is not None:
            out["sun"]["dip_choice"] = self.dip_choice
        return out

    def _anchor(self, points_world: np.ndarray) -> np.ndarray:
        return self.base_world
