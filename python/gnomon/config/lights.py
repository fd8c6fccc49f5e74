"""The registry of light kinds: how a field log's light becomes a light model.

One table, :data:`LIGHTS`, a line a kind (as pvlib's ModelChain picks its models by name): the
``[light] kind`` it answers to, how its own ``[light]`` keys are read, what else the field log must
give for it, how it becomes a :class:`~gnomon.light.LightModel` once the camera's pose and the
number of frames are known, and how the tracker treats its dips. The field log's parser
(:mod:`gnomon.config.fieldlog`) and the scan's set-up (:mod:`gnomon.config.setup`) only look kinds up
here, so a new kind of light is one model in :mod:`gnomon.light` and one line in :data:`LIGHTS`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gnomon.camera.models import Pose
from gnomon.capture.frames import decode_frame_file
from gnomon.capture.registration import MOTION_TOLERANCE_PX, motion_between
from gnomon.config.specs import CaptureSpec, FieldLog, GnomonSpec, LightSpec, PlaneSpec, SiteSpec
from gnomon.config.tables import Table
from gnomon.errors import FieldLogError, FrameError, GnomonError
from gnomon.geometry.reference_lines import PlaneInCamera
from gnomon.light import LampLight, LightModel, TwoPlaneLight
from gnomon.util import toml_io

if TYPE_CHECKING:
    import pandas as pd

    from gnomon.light.ephemeris import Site
    from gnomon.light.sun import HeadingEstimate, SunClock

__all__ = ["LIGHTS", "LightKind", "LightSections", "light_kind", "light_model", "registers"]


@dataclass(frozen=True)
class LightSections:
    """The parts of a field log a kind of light may need besides its own ``[light]`` table."""

    path: Path  # the field log
    capture: CaptureSpec
    planes: tuple[PlaneSpec, ...]
    site: SiteSpec | None
    gnomon: GnomonSpec | None


@dataclass(frozen=True)
class LightKind:
    """One kind of light a field log can name."""

    name: str  # [light] kind
    summary: str  # one line, for messages and templates
    parse: Callable[[Table, Path], LightSpec]  # its [light] table (the field log's folder for relative paths)
    check: Callable[[LightSections], None]  # what else the field log must give (a FieldLogError if not)
    build: Callable[[FieldLog, Pose, int, list[str]], LightModel]  # (log, world → camera pose, frames, warnings)
    dip_width: str = "auto"  # the tracker's dip width: "auto" (widened as the shadows need) or "sun" (kept)
    # [capture] register = "auto" registers the frames (gnomon.capture.registration): a capture of hours
    # (the sun's) on a tripod that settles and warms; a sweep of minutes is left as read.
    register: bool = False


# ------------------------------------------------------------------------ the lamp


def _parse_lamp(t: Table, base: Path) -> LightSpec:
    if "file" in t.data:
        # the output of `gnomon calibrate lamp`: its [light] table
        lamp_file = base / t.string("file")
        data = toml_io.load(lamp_file)
        position = Table(lamp_file, "light", data.get("light", {})).vector("position", 3)
    else:
        position = t.vector("position", 3)
    t.done()
    return LightSpec("lamp", position)


def _lamp(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> LightModel:
    assert log.light.position is not None  # the parser requires it
    return LampLight(log.light.position, pose)


# ------------------------------------------------------------------------ two planes


def _parse_kind_only(kind: str) -> Callable[[Table, Path], LightSpec]:
    def parse(t: Table, base: Path) -> LightSpec:
        t.done()
        return LightSpec(kind)
    return parse


def _check_two_planes(s: LightSections) -> None:
    if len(s.planes) < 2:
        raise FieldLogError(f"{s.path}: [light] kind 'two-plane' needs two [[planes]] (e.g. desk and wall)")


def _two_plane(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> LightModel:
    return TwoPlaneLight(pose)


# ------------------------------------------------------------------------ the sun


def _check_sun(s: LightSections) -> None:
    if s.site is None:
        raise FieldLogError(f"{s.path}: [light] kind 'sun' needs a [site] table (latitude, longitude, ...)")
    if s.capture.timestamps is None:
        raise FieldLogError(f"{s.path}: [capture] a sun scan needs 'timestamps' (filename, exif or start+fps)")
    if s.site.heading_deg is None and s.gnomon is None:
        raise FieldLogError(f"{s.path}: [site] a sun scan needs 'heading_deg', or a [gnomon] table to measure it")


def _sun(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> LightModel:
    from gnomon.light.edge import SunWithEdge  # pandas and pvlib: loaded by sun scans only
    from gnomon.light.sun import SunWithLines, SunWithPole

    clock = _sun_clock(log, pose, n_frames, warnings)
    if log.edge is not None:
        return SunWithEdge(clock, pose, log.edge.a, log.edge.b, log.edge.body)
    if log.pole is not None:
        return SunWithPole(clock, pose, log.pole.base, log.pole.top, log.pole.radius)
    return SunWithLines(clock, pose)


#: The field log's [site] key of each :class:`Site` field.
SITE_KEYS = {"latitude_deg": "latitude", "longitude_deg": "longitude", "altitude_m": "altitude",
             "pressure_pa": "pressure_pa", "temperature_c": "temperature_c", "timezone": "timezone"}


def _site(log: FieldLog) -> Site:
    from gnomon.light.ephemeris import Site, SiteError

    s = log.site
    assert s is not None
    try:
        return Site(s.latitude_deg, s.longitude_deg, s.altitude_m, s.pressure_pa, s.temperature_c, s.timezone)
    except SiteError as exc:
        raise exc.named(SITE_KEYS, prefix=f"{log.path}: [site] ") from None


def _capture_times(log: FieldLog, n_frames: int) -> pd.DatetimeIndex:
    """UTC time of every frame of the capture."""
    from gnomon.light.timestamps import frame_times

    c = log.capture
    if c.timestamps is None:
        raise GnomonError(f"{log.path}: [capture] has no 'timestamps'; a sun scan needs the time of every frame")
    files = list(c.image_files) if c.image_files else n_frames
    times = frame_times(files, c.timestamps, pattern=c.time_pattern, start=c.start, fps=c.fps,
                        site_tz=log.site.timezone if log.site else None)
    if len(times) != n_frames:
        raise FrameError(f"{log.path}: {len(times)} timestamps for {n_frames} frames")
    return times


def _gnomon_heading(log: FieldLog, g: GnomonSpec, pose: Pose, times: pd.DatetimeIndex,
                    site: Site) -> HeadingEstimate:
    from gnomon.light.sun import heading_from_gnomon

    names = [p.name for p in log.capture.image_files]
    frame_name = g.frame.split("/")[-1]
    if frame_name not in names:
        raise GnomonError(f"{log.path}: [gnomon] frame {g.frame!r} is not one of the capture's frames")
    k = names.index(frame_name)
    ground = next((p for p in log.planes if abs(p.normal[2]) > 0.9), None)  # horizontal (world z up)
    if ground is None:
        raise GnomonError(f"{log.path}: [gnomon] needs a horizontal [[planes]] entry (the ground)")
    plane = PlaneInCamera.from_world(ground.point, ground.normal, pose)
    base, shadow = g.base_px, g.shadow_px
    if k > 0 and registers(log):
        # The pixels are the gnomon frame's; the scan's grid is the first frame's (gnomon.capture.registration).
        first, _, _ = decode_frame_file(log.capture.image_files[0])
        grey, _, _ = decode_frame_file(log.capture.image_files[k])
        motion = motion_between(first, grey)
        if motion is not None and np.hypot(*motion) >= MOTION_TOLERANCE_PX:  # as the scan's frames are moved
            base, shadow = base - motion, shadow - motion
    return heading_from_gnomon(log.camera, pose, plane, base, shadow, times[k:k + 1], site, g.frame,
                               where=f"{log.path}: [gnomon]")


def _sun_clock(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> SunClock:
    """Frame times, the heading of the world frame ([site] or a gnomon), and the sun over the capture."""
    from gnomon.light.sun import SunClock

    assert log.site is not None  # the field log requires [site] for the sun
    site = _site(log)
    times = _capture_times(log, n_frames)
    heading, source, sigma, est = log.site.heading_deg, "[site] heading_deg", None, None
    if log.gnomon is not None:
        est = _gnomon_heading(log, log.gnomon, pose, times, site)
        if heading is None:
            heading, source, sigma = est.heading_deg, f"gnomon in {est.frame}", est.sigma_deg
        else:
            diff = (est.heading_deg - heading + 180.0) % 360.0 - 180.0
            if abs(diff) > max(3 * est.sigma_deg, 0.5):
                warnings.append(f"the gnomon gives a heading of {est.heading_deg:.2f}° ± {est.sigma_deg:.2f}°, "
                                f"[site] heading_deg says {heading:.2f}°")
    assert heading is not None  # the field log requires heading_deg or [gnomon]
    clock = SunClock(site, times, float(heading), source, sigma, est)
    if np.all(clock.night):
        raise GnomonError(f"{log.path}: the sun is below the horizon at every frame "
                          f"({times[0].isoformat()} … {times[-1].isoformat()}); check [site] and the timestamps")
    return clock


def _nothing_more(s: LightSections) -> None:
    """A kind that needs nothing but its own [light] table."""


#: Every kind of light, by its ``[light] kind``.
LIGHTS: dict[str, LightKind] = {
    "lamp": LightKind("lamp", "a point lamp at a known position", _parse_lamp, _nothing_more, _lamp),
    "two-plane": LightKind("two-plane", "any point light; the shadow planes from two reference planes",
                           _parse_kind_only("two-plane"), _check_two_planes, _two_plane),
    "sun": LightKind("sun", "the sun, from the site and each frame's time", _parse_kind_only("sun"), _check_sun, _sun,
                     dip_width="sun", register=True),
}


def light_kind(t: Table) -> LightKind:
    """The kind a ``[light]`` table names (its ``kind`` key taken), or a one-line error naming the key."""
    kind = t.string("kind")
    if kind not in LIGHTS:
        raise t.error("kind", f"expected one of {', '.join(map(repr, LIGHTS))}, got {kind!r}")
    return LIGHTS[kind]


def registers(log: FieldLog) -> bool:
    """Whether a scan of ``log`` registers its frames (:mod:`gnomon.capture.registration`): ``[capture]
    register`` ``"on"`` or ``"off"``, or with ``"auto"`` (the default) its light's kind (on for the sun)."""
    mode = log.capture.register
    if mode != "auto":
        return mode == "on"
    kind = LIGHTS.get(log.light.kind)
    return kind is not None and kind.register


def light_model(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> LightModel:
    """The light model of a field log; ``pose`` world → camera, ``n_frames`` frames in the capture.

    Appends to ``warnings`` what the user should know (a gnomon disagreeing with ``[site] heading_deg``).
    """
    kind = LIGHTS.get(log.light.kind)
    if kind is None:
        raise GnomonError(f"{log.path}: [light] kind {log.light.kind!r} is not supported by this version")
    return kind.build(log, pose, n_frames, warnings)
