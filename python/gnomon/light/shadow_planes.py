"""Shadow planes Π(t), one per frame, in the camera frame.

Every plane is returned as a row ``[nx, ny, nz, d]`` with a unit normal and
``n·X = d`` (camera frame, world units); a row of NaN marks a frame without a
plane (no reference line, or a degenerate geometry). The kernel interpolates
between consecutive rows at each pixel's sub-frame shadow time, so the
normals are oriented consistently from frame to frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.geometry.validity import light_point_or_line
from gnomon.util.fitting import fit_plane_robust

__all__ = ["MIN_LAMP_LINE_ANGLE_DEG", "CompletionLight", "complete_from_light", "completing_lines",
           "completion_light", "lamp_shadow_planes", "sun_shadow_planes", "two_plane_shadow_planes"]

# When the line, seen from the lamp, shrinks to an angle below this (S almost
# on the line's own axis), the plane through S and the line is ill-defined.
MIN_LAMP_LINE_ANGLE_DEG = 2.0


def _orient(planes: np.ndarray) -> np.ndarray:
    """Flip rows so each normal agrees with the previous valid one (stable interpolation)."""
    previous = None
    for i in range(len(planes)):
        if not np.isfinite(planes[i, 0]):
            continue
        if previous is not None and planes[i, :3] @ previous < 0:
            planes[i] = -planes[i]
        previous = planes[i, :3]
    return planes


def lamp_shadow_planes(lines: list[ReferenceLines], lamp_cam: np.ndarray) -> tuple[np.ndarray, int]:
    """Planes through the lamp centre S and each frame's shadow line(s).

    With one reference plane the plane is exactly the one through S and its
    line. With several, it is the least-squares plane through S closest to
    points sampled along every plane's line (each line weighted equally).
    Returns the (N, 4) planes and the number of frames dropped as degenerate
    (S within ``MIN_LAMP_LINE_ANGLE_DEG`` of a line's direction as seen from it).
    """
    n_frames = len(lines[0].point)
    planes = np.full((n_frames, 4), np.nan)
    degenerate = 0
    sin_min = np.sin(np.radians(MIN_LAMP_LINE_ANGLE_DEG))
    found_on = np.stack([np.isfinite(ln.point[:, 0]) for ln in lines])
    # The frames with one line: the crosses of all of them at once (row for row numpy's cross).
    single = np.flatnonzero(found_on.sum(axis=0) == 1)
    point, direction = np.zeros((n_frames, 3)), np.zeros((n_frames, 3))
    for ln, on in zip(lines, found_on, strict=True):
        point[on], direction[on] = ln.point[on], ln.direction[on]
    to_lines = point[single] - lamp_cam
    crosses = dict(zip(single.tolist(), zip(np.cross(direction[single], to_lines), to_lines, strict=True),
                       strict=True))
    for t in np.flatnonzero(found_on.any(axis=0)).tolist():
        if t in crosses:
            normal, to_line = crosses[t]
            if np.linalg.norm(normal) < sin_min * np.linalg.norm(to_line):
                degenerate += 1
                continue
        else:
            found = [ln for ln in lines if np.isfinite(ln.point[t, 0])]
            samples = []
            for ln in found:
                extent = np.linalg.norm(ln.point[t] - lamp_cam) * 0.25
                for s in (-1.0, 0.0, 1.0):
                    samples.append(ln.point[t] + s * extent * ln.direction[t] - lamp_cam)
            _, sv, vt = np.linalg.svd(np.asarray(samples), full_matrices=False)
            normal = vt[2]
            if sv[1] < sin_min * sv[0]:
                degenerate += 1
                continue
        normal = normal / np.linalg.norm(normal)
        planes[t, :3] = normal
        planes[t, 3] = normal @ lamp_cam
    return _orient(planes), degenerate


def sun_shadow_planes(lines: list[ReferenceLines], sun_dir_cam: np.ndarray) -> tuple[np.ndarray, int]:
    """Planes containing each frame's shadow line and the direction towards the sun.

    ``sun_dir_cam``: (N, 3) unit directions towards the sun in the camera
    frame, one per frame (the sun moves during a time-lapse). The normal is
    ``direction × d``; with several reference planes the line of the plane
    with the most inliers is used. Frames where the sun lies within
    ``MIN_LAMP_LINE_ANGLE_DEG`` of the line's direction are dropped as degenerate.
    """
    n_frames = len(lines[0].point)
    planes = np.full((n_frames, 4), np.nan)
    degenerate = 0
    sin_min = np.sin(np.radians(MIN_LAMP_LINE_ANGLE_DEG))
    for t in range(n_frames):
        found = [ln for ln in lines if np.isfinite(ln.point[t, 0])]
        if not found or not np.all(np.isfinite(sun_dir_cam[t])):
            continue
        best = max(found, key=lambda ln: ln.count[t])
        normal = np.cross(best.direction[t], sun_dir_cam[t])
        if np.linalg.norm(normal) < sin_min:
            degenerate += 1
            continue
        normal /= np.linalg.norm(normal)
        planes[t, :3] = normal
        planes[t, 3] = normal @ best.point[t]
    return _orient(planes), degenerate


def two_plane_shadow_planes(lines: list[ReferenceLines], min_angle_deg: float = 2.0,
                            min_points: int = 10) -> tuple[np.ndarray, int]:
    """Planes through the shadow's crossings on two (or more) reference planes: no light needed.

    Bouguet & Perona's two-plane mode: at each frame the shadow plane contains
    the shadow line on the desk and the one on the wall, so it is the
    least-squares plane through their points (docs/method.md §3) — here the 3-D
    crossings themselves, so a plane whose line is seen in one short region
    still contributes its points (the other plane's line fixes the rest).
    A frame needs ``min_points`` crossings on at least two planes; it is
    dropped as degenerate when the points do not span a plane (all nearly on
    one line) or do not lie on one (the lines do not meet in a plane).
    """
    if len(lines) < 2:
        raise ValueError("the two-plane mode needs lines on two reference planes")
    n_frames = len(lines[0].point)
    planes = np.full((n_frames, 4), np.nan)
    degenerate = 0
    sin_min = np.sin(np.radians(min_angle_deg))
    for t in range(n_frames):
        sets = [ln.points[t] for ln in lines if len(ln.points[t]) >= min_points]
        if len(sets) < 2:
            continue
        pts = np.concatenate(sets)
        centre, normal, inl = fit_plane_robust(pts)
        _, sv, _ = np.linalg.svd(pts[inl] - centre, full_matrices=False)
        enough = all(np.count_nonzero(inl[a:b]) >= min_points
                     for a, b in zip(np.cumsum([0] + [len(x) for x in sets[:-1]]), np.cumsum([len(x) for x in sets]),
                                     strict=True))
        if not enough or sv[1] < sin_min * sv[0] or sv[2] > sin_min * sv[1]:
            degenerate += 1
            continue
        planes[t, :3] = normal
        planes[t, 3] = normal @ centre
    return _orient(planes), degenerate


def _plane_through_light(p: np.ndarray, d: np.ndarray, point: np.ndarray, direction: np.ndarray | None,
                         sin_min: float) -> np.ndarray | None:
    """Unit normal of the plane containing the line (``p``, ``d``) and the light (a point, or the line through
    ``point`` along ``direction``), least squares; None when they do not fix a plane."""
    to_line = p - point
    if direction is not None:  # the light is a line: measure from its point nearest the shadow line
        to_line = to_line - (to_line @ direction) * direction
    if np.linalg.norm(to_line) == 0:
        return None
    rows = [d / np.linalg.norm(d), to_line / np.linalg.norm(to_line)]
    if direction is not None:
        rows.append(direction / np.linalg.norm(direction))
    _, sv, vt = np.linalg.svd(np.array(rows))
    if sv[1] < sin_min * sv[0]:
        return None
    normal: np.ndarray = vt[-1]
    return normal


def _completing_line(lines: list[ReferenceLines], t: int) -> ReferenceLines | None:
    """The line a one-line frame ``t`` is completed from: the best-supported one found in it."""
    found = [ln for ln in lines if np.isfinite(ln.point[t, 0])]
    return max(found, key=lambda ln: ln.count[t]) if found else None


def completing_lines(measured: np.ndarray, completed: np.ndarray,
                     lines: list[ReferenceLines]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) point and (N, 3) unit direction (camera frame) of the line each completed frame's plane was
    built from (:func:`complete_from_light`): the frames with a plane in ``completed`` but not in
    ``measured``; NaN rows elsewhere. The completed plane contains that line, so its error is a rotation
    about it (:func:`gnomon.geometry.uncertainty.completion_depth_sigma`)."""
    n = len(measured)
    point = np.full((n, 3), np.nan)
    direction = np.full((n, 3), np.nan)
    for t in np.flatnonzero(np.isfinite(completed[:, 0]) & ~np.isfinite(measured[:, 0])):
        best = _completing_line(lines, int(t))
        if best is not None:
            point[t] = best.point[t]
            direction[t] = best.direction[t] / np.linalg.norm(best.direction[t])
    return point, direction


def complete_from_light(planes: np.ndarray, lines: list[ReferenceLines], point: np.ndarray,
                        direction: np.ndarray | None,
                        min_angle_deg: float = MIN_LAMP_LINE_ANGLE_DEG) -> tuple[np.ndarray, int]:
    """Planes for the frames whose shadow crossed only one reference plane, from the light the others located.

    Two-plane scans locate the light from the frames whose shadow crossed
    both planes (:func:`gnomon.geometry.validity.light_point_or_line`): a point ``S``,
    or, when every plane contained one direction (a stick moved parallel to
    itself), the line through ``point`` along ``direction``. All shadow planes
    of that light contain it, so a frame with a line on one plane only (the
    shadow's start and end, where it is on the wall but not yet on the desk)
    still has a plane: the one containing that line and the light — the
    least-squares plane normal to the line's direction, to the direction
    from the light to the line and (a line light) to the light's direction.
    A frame is skipped when these do not fix a plane (the light within
    ``min_angle_deg`` of the line's own axis). Returns the completed (N, 4)
    planes (oriented) and the number of frames added.
    """
    out = planes.copy()
    added = 0
    sin_min = np.sin(np.radians(min_angle_deg))
    for t in range(len(out)):
        if np.isfinite(out[t, 0]):
            continue
        best = _completing_line(lines, t)
        if best is None:
            continue
        p = best.point[t]
        normal = _plane_through_light(p, best.direction[t], point, direction, sin_min)
        if normal is None:
            continue
        out[t, :3] = normal
        out[t, 3] = normal @ p
        added += 1
    return _orient(out), added


@dataclass
class CompletionLight:
    """The light that completes the one-line frames (:func:`completion_light`), camera frame.

    ``point`` and ``direction`` (None: a point light) as :func:`complete_from_light`
    takes them; ``model`` "point" or "line"; ``errors_deg`` each candidate
    model's median angle (degrees) between a two-plane frame's measured plane
    and the plane completed from one of its lines alone (the light located
    without that frame): only "point" when the planes fix a point light.
    """

    point: np.ndarray
    direction: np.ndarray | None
    model: str
    errors_deg: dict[str, float]


def _least_squares_point(planes: np.ndarray) -> np.ndarray:
    """The point closest to every valid plane, however poorly the planes fix it."""
    return np.asarray(light_point_or_line(planes, min_conditioning=0.0).point, dtype=np.float64)


def completion_light(planes: np.ndarray, lines: list[ReferenceLines],
                     min_angle_deg: float = MIN_LAMP_LINE_ANGLE_DEG, measure: bool = True) -> CompletionLight:
    """Which light completes the one-line frames best: a point, or the line the planes nearly share.

    ``planes`` (N, 4): the two-plane frames' measured planes (NaN rows elsewhere).
    When the planes fix the light as a point (:func:`gnomon.geometry.validity.light_point_or_line`
    not degenerate) it is that point. When they nearly share one direction
    (a stick moved almost parallel to itself) the light is either a point
    poorly located along that direction or a line light; which is the better
    model is measured, not assumed: every two-plane frame is completed from
    each of its lines alone, with the light located from the other frames
    (leave one out), and compared with its measured plane; the model with
    the smaller median angle wins (the line on a tie: exact for a stick moved
    parallel to itself). On the CMU frog (singular-value ratio 0.007, a
    hand-held stick whose tilt drifted) the point errs by 0.22° / 0.14°
    (entering / leaving edge) and the line by 0.26° / 0.24°. The same
    measurement gives a point light's error (for the completed planes' σ);
    ``measure=False`` skips it when only the planes are wanted (``errors_deg``
    then empty for a point light; the choice between models is always measured).
    """
    est = light_point_or_line(planes)
    if not est.degenerate and not measure:
        return CompletionLight(est.point, None, "point", {})
    sin_min = np.sin(np.radians(min_angle_deg))
    frames = np.flatnonzero(np.all(np.isfinite(planes), axis=1))
    errors: dict[str, list[float]] = {"point": [], "line": []} if est.degenerate else {"point": []}
    for t in frames:
        others = planes.copy()
        others[t] = np.nan
        if np.all(np.isfinite(others), axis=1).sum() < 3:
            continue
        if est.degenerate:
            line_est = light_point_or_line(others)
            models = {"point": (_least_squares_point(others), None),
                      "line": (line_est.point, line_est.direction)}
        else:
            models = {"point": (_least_squares_point(others), None)}
        measured = planes[t, :3] / np.linalg.norm(planes[t, :3])
        for ln in lines:
            if not np.isfinite(ln.point[t, 0]):
                continue
            for name, (point, direction) in models.items():
                normal = _plane_through_light(ln.point[t], ln.direction[t], point, direction, sin_min)
                if normal is not None:
                    errors[name].append(float(np.degrees(np.arccos(min(1.0, abs(float(normal @ measured)))))))
    median = {k: float(np.median(v)) if v else float("inf") for k, v in errors.items()}
    if not est.degenerate:
        return CompletionLight(est.point, None, "point", median)
    if median["point"] < median["line"]:
        return CompletionLight(_least_squares_point(planes), None, "point", median)
    return CompletionLight(est.point, est.direction, "line", median)
