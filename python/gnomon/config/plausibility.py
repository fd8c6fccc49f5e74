"""A parsed field log's numbers and geometry checked together, before anything is computed.

Each key is checked where it is read (:mod:`gnomon.config.fieldlog`, with the
validators of :mod:`gnomon.util.validate`); what needs several keys at once is
checked here: the tracker's window and widest dip, the gamma, a time zone that
exists, a pole not within 20° of horizontal, a lamp neither at the camera's
centre nor absurdly far. Every failure is a :class:`~gnomon.errors.FieldLogError`
naming the file and key.
"""

from __future__ import annotations

import math

import numpy as np

from gnomon.config.specs import RELATIVE
from gnomon.errors import FieldLogError, GnomonError
from gnomon.util.validate import (
    MAX_DIP_FRAMES,
    MAX_FPS,
    MAX_WINDOW,
    MIN_CHESSBOARD,
    MIN_FPS,
    MIN_POLE_ELEVATION_DEG,
    check_camera,
)


def _zone_exists(name: str) -> bool:
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    try:
        ZoneInfo(name)
        return True
    except (ZoneInfoNotFoundError, ValueError, OSError):
        pass
    try:  # offsets such as "UTC+02:00", "+02:00"
        from gnomon.light.ephemeris import Site  # pandas: loaded only for a site's time zone

        Site(0.0, 0.0, 0.0, None, None, name)
        return True
    except Exception:
        return False


def check_field_log(log) -> None:
    """Plausibility of a parsed field log's numbers and geometry (see the module's list)."""
    p = log.path
    if log.scan.window > MAX_WINDOW:
        raise FieldLogError(f"{p}: [scan] window: must be ≤ {MAX_WINDOW} frames, got {log.scan.window}")
    dip = log.scan.max_dip_frames
    if dip is not None and not max(2, log.scan.window) <= dip <= MAX_DIP_FRAMES:
        raise FieldLogError(f"{p}: [scan] max_dip_frames: must be in {max(2, log.scan.window)}..{MAX_DIP_FRAMES} "
                            f"frames (window to the widest dip the tracker finds), got {dip}")
    gamma = log.capture.gamma
    if not isinstance(gamma, str) and not 0.1 <= gamma <= 10.0:
        raise FieldLogError(f"{p}: [capture] gamma: {gamma:g} is not a camera gamma (0.1 … 10, or 'srgb')")
    fps = log.capture.fps
    if fps is not None and not MIN_FPS <= fps <= MAX_FPS:
        raise FieldLogError(f"{p}: [capture] fps: {fps:g} frames/s is not plausible "
                            f"(one a day … {MAX_FPS:g} a second)")
    where = f"{log.camera_file}: [camera]" if log.camera_file else f"{p}: [camera]"
    try:
        check_camera(log.camera, where)
    except FieldLogError:
        raise
    except GnomonError as exc:
        raise FieldLogError(str(exc)) from None
    names: dict[str, int] = {}
    for i, plane in enumerate(log.planes):
        if plane.name in names:
            raise FieldLogError(f"{p}: [[planes]] name {plane.name!r} is used by planes {names[plane.name]} and {i}; "
                                "give each plane its own name")
        names[plane.name] = i
        if plane.chessboard is not None and min(plane.chessboard) < MIN_CHESSBOARD:
            cols, rows = plane.chessboard
            raise FieldLogError(f"{p}: [planes.{i}] chessboard: {cols}x{rows} inner corners; "
                                f"a chessboard needs at least {MIN_CHESSBOARD}x{MIN_CHESSBOARD}")
    _check_scale(log)
    if log.pose is not None:
        _check_lamp(log, log.pose)
    if log.site is not None and log.site.timezone is not None and not _zone_exists(log.site.timezone):
        raise FieldLogError(f"{p}: [site] timezone: unknown time zone {log.site.timezone!r} "
                            "(an IANA name such as 'Europe/Zurich', or an offset such as 'UTC+02:00')")
    if log.pole is not None:
        axis = log.pole.top - log.pole.base
        elevation = math.degrees(math.asin(min(1.0, abs(axis[2]) / float(np.linalg.norm(axis)))))
        if elevation < MIN_POLE_ELEVATION_DEG:
            raise FieldLogError(f"{p}: [pole] base → top rises {elevation:.1f}° above the horizontal; a pole "
                                f"stands (≥ {MIN_POLE_ELEVATION_DEG:g}°; world z is up). Are base and top swapped "
                                "with another axis?")


def _lengths(log) -> list[str]:
    """Where the field log gives a length (so its units are not "relative")."""
    out = []
    for plane in log.planes:
        where = f"[[planes]] {plane.name}"
        if plane.markers and not plane.unmeasured_marks:
            out.append(f"{where}: its marks' plane_xy")
        if plane.chessboard is not None or plane.aruco is not None or plane.charuco is not None:
            out.append(f"{where}: its board's or markers' size")
        if plane.mark_distance is not None:
            out.append(f"{where}: mark_distance")
    if log.pose is not None:
        out.append("[camera.pose] tvec")
    if log.light.kind in ("lamp", "sun"):
        out.append(f"[light] kind = {log.light.kind!r}")
    return out


def _check_scale(log) -> None:
    """What fixes the lengths when a plane's marks were not measured (no ``plane_xy``): the first plane
    placed by marks (the world frame) needs a known length (``mark_distance``), else ``[capture] units =
    "relative"``; a plane after it without one has its distance from where it meets the first (measured
    after tracking). A declared ``[camera.pose]`` cannot be checked by such marks."""
    p = log.path
    marked = [pl for pl in log.planes if pl.markers or pl.chessboard or pl.aruco or pl.charuco]
    unmeasured = [pl for pl in marked if pl.unmeasured_marks]
    if log.capture.units == RELATIVE:
        given = _lengths(log)
        if given:
            raise FieldLogError(f"{p}: [capture] units = \"relative\" says no length is known, but {given[0]} "
                                "gives one: set units to its unit (\"mm\" or \"m\")")
        if not unmeasured or marked[0] is not unmeasured[0]:
            raise FieldLogError(f"{p}: [capture] units = \"relative\": the unit is the first marked plane's "
                                "distance from the camera, so that plane needs marks without plane_xy")
    if not unmeasured:
        return
    if log.pose is not None:
        raise FieldLogError(f"{p}: [camera.pose] declares the planes, and the marks of [[planes]] "
                            f"{unmeasured[0].name} have no plane_xy: such marks give a plane's orientation, not "
                            "a pose to check; remove [camera.pose] (the marks then place the planes) or give "
                            "plane_xy")
    first = marked[0]
    if first.unmeasured_marks and first.mark_distance is None and log.capture.units != RELATIVE:
        raise FieldLogError(
            f"{p}: [[planes]] {first.name}: its marks have no plane_xy, so nothing fixes the lengths: give "
            "mark_distance = { between = [id, id], length = L } (two of its marks' distance, measured, in "
            f"[capture] units), or [capture] units = \"relative\" (lengths in units of the {first.name}'s "
            "distance from the camera)")


def _check_lamp(log, pose) -> None:
    """A lamp neither at the camera's centre nor absurdly far, relative to the camera's distance to the scene."""
    if log.light.kind != "lamp" or log.light.position is None:
        return
    centre = pose.camera_centre_world
    plane = log.planes[0]
    with np.errstate(all="ignore"):
        scene = abs(float(np.dot(centre - plane.point, plane.normal)))
        gap = float(np.linalg.norm(np.asarray(log.light.position, dtype=np.float64) - centre))
    if not scene > 0:
        return
    if gap < 0.01 * scene:
        raise FieldLogError(f"{log.path}: [light] position {log.light.position.tolist()} is at the camera's centre "
                            f"({gap:.3g} from it, the scene is {scene:.3g} away): its shadow planes would pass "
                            "through the camera and be seen edge-on")
    if not gap <= 1e4 * scene:
        raise FieldLogError(f"{log.path}: [light] position is {gap:.3g} from the camera, the scene {scene:.3g}: "
                            "not a lamp (for the sun, use kind = 'sun')")
