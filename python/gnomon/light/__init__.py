"""Light models: one class per kind of light, one small interface (:class:`LightModel`).

* :class:`LampLight`: a point lamp at a known position;
* :class:`TwoPlaneLight`: any point light, the planes from two reference planes;
* :class:`SunWithLines`: the sun, the planes through the reference lines;
* :class:`SunWithPole`: the sun and a vertical pole of known axis.

:func:`light_from_field_log` resolves a field log's ``[light]`` (with
``[site]``, ``[pole]``, ``[gnomon]`` for the sun) into one of them, once, at
the edge; the scan then only talks to the interface. The lamp's own
calibration from pencil photos lives in :mod:`gnomon.light.lamp_calibration`.

The sun's names (:class:`SunClock`, :class:`SunWithLines`, :class:`SunWithPole`, ...) are
loaded on first use: they need pandas and pvlib, which a lamp or two-plane scan never loads.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

import numpy as np

from gnomon.camera import Pose
from gnomon.errors import FrameError, GnomonError
from gnomon.fieldlog import FieldLog, GnomonSpec
from gnomon.light.base import EdgePlanes, EdgeTimes, LightModel, ReferenceGeometry, Screening
from gnomon.light.lamp import LampLight
from gnomon.light.lamp_calibration import (
    LampCalibration,
    PencilLog,
    calibrate_lamp_cli,
    calibrate_lamp_from_pencil,
    detect_missing_tips,
    load_pencil_log,
)
from gnomon.light.two_plane import TwoPlaneLight
from gnomon.reference_lines import PlaneInCamera

if TYPE_CHECKING:
    import pandas as pd

    from gnomon.light.sun import HeadingEstimate as HeadingEstimate
    from gnomon.light.sun import SunClock as SunClock
    from gnomon.light.sun import SunWithLines as SunWithLines
    from gnomon.light.sun import SunWithPole as SunWithPole
    from gnomon.light.sun import heading_from_gnomon as heading_from_gnomon
    from gnomon.sun import Site

__all__ = [
    "EdgePlanes", "EdgeTimes", "LampCalibration", "LampLight", "LightModel", "PencilLog", "ReferenceGeometry",
    "Screening", "SunClock", "SunWithLines", "SunWithPole", "TwoPlaneLight", "calibrate_lamp_cli",
    "calibrate_lamp_from_pencil",
    "detect_missing_tips", "light_from_field_log", "load_pencil_log",
]

#: Names of :mod:`gnomon.light.sun` this package gives, imported on first use (pandas, pvlib).
_SUN_NAMES = ("HeadingEstimate", "SunClock", "SunWithLines", "SunWithPole", "heading_from_gnomon")


def __getattr__(name: str):
    if name in _SUN_NAMES:
        return getattr(importlib.import_module("gnomon.light.sun"), name)
    raise AttributeError(f"module 'gnomon.light' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUN_NAMES))


def light_from_field_log(log: FieldLog, pose: Pose, n_frames: int, warnings: list[str]) -> LightModel:
    """The light model of a field log; ``pose`` world → camera, ``n_frames`` frames in the capture.

    Appends to ``warnings`` what the user should know (a gnomon disagreeing
    with ``[site] heading_deg``).
    """
    kind = log.light.kind
    if kind == "lamp":
        assert log.light.position is not None  # the field log requires it
        return LampLight(log.light.position, pose)
    if kind == "two-plane":
        return TwoPlaneLight(pose)
    if kind == "sun":
        from gnomon.light.sun import SunWithLines, SunWithPole

        clock = _sun_clock(log, pose, n_frames, warnings)
        if log.pole is not None:
            return SunWithPole(clock, pose, log.pole.base, log.pole.top, log.pole.radius)
        return SunWithLines(clock, pose)
    raise GnomonError(f"{log.path}: [light] kind {kind!r} is not supported by this version")


#: The field log's [site] key of each :class:`Site` field.
SITE_KEYS = {"latitude_deg": "latitude", "longitude_deg": "longitude", "altitude_m": "altitude",
             "pressure_pa": "pressure_pa", "temperature_c": "temperature_c", "timezone": "timezone"}


def _site(log: FieldLog) -> Site:
    from gnomon.sun import Site, SiteError

    s = log.site
    assert s is not None
    try:
        return Site(s.latitude_deg, s.longitude_deg, s.altitude_m, s.pressure_pa, s.temperature_c, s.timezone)
    except SiteError as exc:
        raise exc.named(SITE_KEYS, prefix=f"{log.path}: [site] ") from None


def _capture_times(log: FieldLog, n_frames: int) -> pd.DatetimeIndex:
    """UTC time of every frame of the capture."""
    from gnomon.timestamps import frame_times

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
    return heading_from_gnomon(log.camera, pose, plane, g.base_px, g.shadow_px, times[k:k + 1], site, g.frame,
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
