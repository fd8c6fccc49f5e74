"""Shadow planes Π(t), one per frame, in the camera frame.

Every plane is returned as a row ``[nx, ny, nz, d]`` with a unit normal and
``n·X = d`` (camera frame, world units); a row of NaN marks a frame without a
plane (no reference line, or a degenerate geometry). The kernel interpolates
between consecutive rows at each pixel's sub-frame shadow time, so the
normals are oriented consistently from frame to frame.
"""

from __future__ import annotations

import numpy as np

from gnomon.reference_lines import ReferenceLines

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
    for t in range(n_frames):
        found = [ln for ln in lines if np.isfinite(ln.point[t, 0])]
        if not found:
            continue
        if len(found) == 1:
            p, d = found[0].point[t], found[0].direction[t]
            to_line = p - lamp_cam
            normal = np.cross(d, to_line)
            if np.linalg.norm(normal) < sin_min * np.linalg.norm(to_line):
                degenerate += 1
                continue
        else:
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


def two_plane_shadow_planes(lines: list[ReferenceLines], min_angle_deg: float = 2.0) -> tuple[np.ndarray, int]:
    """Planes through the shadow lines on two (or more) reference planes: no light needed.

    Bouguet & Perona's two-plane mode: at each frame the shadow plane contains
    the line on the desk and the line on the wall, so it is the least-squares
    plane through points sampled along both. A frame is dropped when a line is
    missing on one plane or the two lines do not span a plane (nearly
    parallel and far apart, or nearly the same line): measured by the
    smallest singular value of the sampled points against the others.
    """
    if len(lines) < 2:
        raise ValueError("the two-plane mode needs lines on two reference planes")
    n_frames = len(lines[0].point)
    planes = np.full((n_frames, 4), np.nan)
    degenerate = 0
    sin_min = np.sin(np.radians(min_angle_deg))
    for t in range(n_frames):
        found = [ln for ln in lines if np.isfinite(ln.point[t, 0])]
        if len(found) < 2:
            continue
        samples = []
        scale = np.mean([np.linalg.norm(ln.point[t]) for ln in found]) * 0.1
        for ln in found:
            for s in (-1.0, 0.0, 1.0):
                samples.append(ln.point[t] + s * scale * ln.direction[t])
        pts = np.asarray(samples)
        centre = pts.mean(axis=0)
        _, sv, vt = np.linalg.svd(pts - centre, full_matrices=False)
        # Coplanar lines: the third singular value is ~0 while the second is not.
        if sv[1] < sin_min * sv[0] or sv[2] > sin_min * sv[1]:
            degenerate += 1
            continue
        normal = vt[2]
        planes[t, :3] = normal
        planes[t, 3] = normal @ centre
    return _orient(planes), degenerate


def light_point_from_planes(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point closest (least squares) to every valid plane: the lamp, as a by-product.

    All shadow planes of a point source pass through it. Returns the point
    (camera frame) and the RMS distance of the planes from it.
    """
    valid = planes[np.isfinite(planes[:, 0])]
    if len(valid) < 3:
        raise ValueError("need at least three shadow planes to locate the light")
    n, d = valid[:, :3], valid[:, 3]
    point, *_ = np.linalg.lstsq(n, d, rcond=None)
    rms = float(np.sqrt(np.mean((n @ point - d) ** 2)))
    return point, np.asarray(rms)
