"""Sun scans outdoors: frame times, the world frame's heading, illumination, sun shadow planes.

* **Time**: every frame's UTC time (:mod:`gnomon.timestamps`); sub-frame
  shadow times map to UTC by interpolation between frames.
* **Heading**: the world frame is tied to East-North-Up by the compass heading
  of its x axis (world z up; :func:`gnomon.sun.R_world_from_enu`), given in
  ``[site] heading_deg`` or measured from a vertical gnomon: the shadow of a
  vertical pole on the ground points away from the sun's azimuth, whatever
  the elevation, so its direction in the world frame against the sun's
  azimuth at that instant gives the heading.
* **Illumination**: sun strength, sky and auto-exposure drift over a
  time-lapse. Each frame is decoded to linear irradiance and divided by a
  robust global gain against the first frame (the median per-pixel ratio:
  the shadow covers a small part of the view). A frame whose gain drops
  suddenly below its recent history is a cloud passing (direct light falls,
  sky light stays — no single gain fixes that) and is skipped. Frames with
  the sun at or below the horizon are skipped too.
* **Planes**: with a ``[pole]`` of known axis, the shadow's centre plane
  contains the axis and the sun direction — no reference plane is needed
  where the shadow falls; the sun direction is evaluated at sub-frame steps,
  so each pixel's plane uses the sun at its own shadow time. Without a pole,
  the plane contains the shadow line on a reference plane and the sun
  direction (:func:`gnomon.shadow_planes.sun_shadow_planes`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from gnomon.camera import Pose
from gnomon.errors import GnomonError
from gnomon.fieldlog import FieldLog, PlaneSpec
from gnomon.reference_lines import PlaneInCamera
from gnomon.sun import Site, enu_to_world, sun_direction_enu, sun_position
from gnomon.timestamps import frame_times, interpolate_times

# A frame whose global gain falls below this fraction of its recent history is a cloud.
CLOUD_DROP = 0.85
GAIN_HISTORY = 9
# Normalised linear irradiance is fed to the tracker as uint16 at this scale (headroom ×2).
LINEAR_SCALE = 32768.0
# Sun directions per frame interval for the pole's plane table.
SUBSTEPS = 8


def site_of(log: FieldLog) -> Site:
    s = log.site
    assert s is not None
    return Site(s.latitude_deg, s.longitude_deg, s.altitude_m, s.pressure_pa, s.temperature_c, s.timezone)


def capture_times(log: FieldLog, n_frames: int | None = None) -> pd.DatetimeIndex:
    """UTC time of every frame of the capture."""
    c = log.capture
    tz = log.site.timezone if log.site else None
    if c.timestamps is None:
        raise GnomonError(f"{log.path}: [capture] has no 'timestamps'; a sun scan needs the time of every frame")
    files = list(c.image_files) if c.image_files else (n_frames or 0)
    return frame_times(files, c.timestamps, pattern=c.time_pattern, start=c.start, fps=c.fps, site_tz=tz)


def sun_world(times, site: Site, heading_deg: float) -> np.ndarray:
    """Unit directions towards the sun (N, 3) in the world frame; naive times are UTC."""
    index = pd.DatetimeIndex(times)
    if index.tz is None:  # datetime64 arrays from interpolation are UTC, not site-local
        index = index.tz_localize("UTC")
    return enu_to_world(sun_direction_enu(index, site), heading_deg)


@dataclass
class HeadingEstimate:
    heading_deg: float
    sigma_deg: float
    frame: str
    sun_azimuth_deg: float


def _ground_plane(log: FieldLog) -> PlaneSpec:
    for p in log.planes:
        if abs(p.normal[2]) > 0.9:  # horizontal in the world frame (z up)
            return p
    raise GnomonError(f"{log.path}: [gnomon] needs a horizontal [[planes]] entry (the ground)")


def heading_from_gnomon(log: FieldLog, pose: Pose, times: pd.DatetimeIndex, site: Site,
                        sigma_px: float = 0.5) -> HeadingEstimate:
    """The world x axis' compass heading from a vertical pole's shadow in one frame.

    ``[gnomon] base_px`` (the pole's foot) and ``shadow_px`` (a point on its
    shadow's centre line on the ground) are back-projected onto the ground;
    the shadow's world angle φ (from x towards y) and the sun's azimuth A at
    that frame give ``heading = A + 180° + φ``. σ from ``sigma_px`` on each
    pixel coordinate, propagated numerically.
    """
    g = log.gnomon
    assert g is not None
    names = [p.name for p in log.capture.image_files]
    frame_name = g.frame.split("/")[-1]
    if frame_name not in names:
        raise GnomonError(f"{log.path}: [gnomon] frame {g.frame!r} is not one of the capture's frames")
    k = names.index(frame_name)
    azimuth = float(sun_position(times[k:k + 1], site).azimuth_deg[0])
    ground = PlaneInCamera.from_world(_ground_plane(log).point, _ground_plane(log).normal, pose)

    def phi(px: np.ndarray) -> float:
        pts = pose.camera_to_world(ground.intersect(log.camera.rays(px.reshape(2, 2))))
        if not np.all(np.isfinite(pts)):
            raise GnomonError(f"{log.path}: [gnomon] base_px or shadow_px does not see the ground plane")
        d = pts[1] - pts[0]
        return float(np.degrees(np.arctan2(d[1], d[0])))

    px = np.concatenate([g.base_px, g.shadow_px])
    phi0 = phi(px)
    jac = []
    for i in range(4):
        step = np.zeros(4)
        step[i] = 0.01
        jac.append((((phi(px + step) - phi(px - step)) + 180) % 360 - 180) / 0.02)
    sigma = float(np.sqrt(np.sum(np.square(jac))) * sigma_px)
    return HeadingEstimate(float((azimuth + 180.0 + phi0) % 360.0), sigma, g.frame, azimuth)


class IlluminationNormalizer:
    """Per-frame linearisation, gain normalisation and cloud detection (streaming).

    ``normalize(frame)`` returns the frame as uint16 normalised linear
    irradiance (``LINEAR_SCALE`` = 1.0), or None for a frame to skip.
    """

    def __init__(self, lut: np.ndarray, step: int = 4):
        self.lut = lut.astype(np.float32)
        self.step = step
        self.reference: np.ndarray | None = None
        self.gains: list[float] = []
        self.accepted: list[float] = []

    def gain(self, linear: np.ndarray) -> float:
        sub = linear[:: self.step, :: self.step]
        if self.reference is None:
            self.reference = sub.copy()
            return 1.0
        ok = self.reference > 0.02
        return float(np.median(sub[ok] / self.reference[ok]))

    def normalize(self, frame: np.ndarray) -> np.ndarray | None:
        linear = self.lut[frame]
        g = self.gain(linear)
        self.gains.append(g)
        if len(self.accepted) >= 3:
            recent = float(np.median(self.accepted[-GAIN_HISTORY:]))
            if g < CLOUD_DROP * recent:
                return None
        self.accepted.append(g)
        return np.clip(linear * (LINEAR_SCALE / max(g, 1e-6)), 0, 65535).astype(np.uint16)


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


def pole_plane_table(pole_base: np.ndarray, pole_top: np.ndarray, timeline: SunTimeline, site: Site,
                     heading_deg: float, pose: Pose) -> np.ndarray:
    """Camera-frame planes containing the pole's axis and the sun, every 1/SUBSTEPS tracker frame.

    Row k is the plane at tracker time k / SUBSTEPS; triangulate with
    ``times · SUBSTEPS``.
    """
    n = len(timeline.used)
    tau = np.arange((n - 1) * SUBSTEPS + 1) / SUBSTEPS
    utc = timeline.utc(tau)
    d = sun_world(pd.DatetimeIndex(utc), site, heading_deg)
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


def below_horizon(times: pd.DatetimeIndex, site: Site) -> np.ndarray:
    return np.asarray(sun_position(times, site).apparent_elevation_deg) <= 0.0
