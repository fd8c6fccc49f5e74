"""Check a field log before scanning: one picture of what the scan will assume.

:func:`setup_preview` draws on the capture's first frame (BGR, uint8):

* each plane's reference regions, tinted in the plane's colour;
* each marker as found (a circle) with its reprojection residual in pixels,
  and its hint (a small magenta cross) when it was refined from one;
* each measured plane's grid (its own 2-D frame, lines every ``step`` world
  units over its markers' extent and a margin), reprojected through the
  camera model, so a wrong coordinate or a swapped marker shows as a grid
  that misses the marks;
* the line where two planes meet (desk and wall: the corner), in yellow;
* the pencil's base and tip pixels of a ``[pencil]`` table, if any.

Inputs are plain values (the image, the camera, the pose, plane frames,
marker pixels); :mod:`gnomon.commands.preview` reads the field log.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from gnomon.camera.models import CameraModel, Pose

__all__ = ["MarkerMark", "PlaneDrawing", "nice_step", "plane_intersection", "setup_preview"]

COLOURS = ((60, 60, 255), (255, 120, 40), (60, 200, 60), (200, 60, 200))  # BGR, one per plane


@dataclass
class MarkerMark:
    """One marker as the scan sees it: found pixel, hint (or None when exact) and residual (pixels)."""

    name: str
    pixel: np.ndarray
    hint: np.ndarray | None
    residual_px: float


@dataclass
class PlaneDrawing:
    """One plane for the preview: its frame in the world (origin, x and y axes, unit normal), regions, marks.

    ``extent``: (x0, x1, y0, y1) in the plane's frame, where to draw its grid
    (None: no grid).
    """

    name: str
    origin: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    normal: np.ndarray
    mask: np.ndarray | None = None
    markers: list[MarkerMark] = field(default_factory=list)
    extent: tuple[float, float, float, float] | None = None


def nice_step(length: float, lines: int = 8) -> float:
    """A round grid step (1, 2 or 5 × 10^k) giving about ``lines`` lines over ``length``."""
    raw = max(length, 1e-12) / lines
    k = np.floor(np.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10**k >= raw:
            return float(m * 10**k)
    return float(10 ** (k + 1))  # pragma: no cover


def plane_intersection(n1: np.ndarray, d1: float, n2: np.ndarray, d2: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The line where planes ``n1·X = d1`` and ``n2·X = d2`` meet: (a point, unit direction); None if parallel."""
    direction = np.cross(n1, n2)
    s = np.linalg.norm(direction)
    if s < 1e-6:
        return None
    direction /= s
    A = np.stack([n1, n2, direction])
    point = np.linalg.solve(A, np.array([d1, d2, 0.0]))
    return point, direction


def _polyline(img: np.ndarray, camera: CameraModel, pose: Pose, pts_world: np.ndarray, colour, thickness=1) -> None:
    cam = pose.world_to_camera(pts_world)
    h, w = img.shape[:2]
    # Only directions inside the image's field of view: a polynomial lens model
    # folds far-off directions back into the image.
    border = np.concatenate([np.stack([np.linspace(0, w - 1, 32), np.zeros(32)], axis=1),
                             np.stack([np.linspace(0, w - 1, 32), np.full(32, h - 1.0)], axis=1),
                             np.stack([np.zeros(32), np.linspace(0, h - 1, 32)], axis=1),
                             np.stack([np.full(32, w - 1.0), np.linspace(0, h - 1, 32)], axis=1)])
    rays = camera.rays(border)
    nx, ny = rays[:, 0] / rays[:, 2], rays[:, 1] / rays[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        px, py = cam[:, 0] / cam[:, 2], cam[:, 1] / cam[:, 2]
    front = (cam[:, 2] > 1e-9) & (px >= np.nanmin(nx)) & (px <= np.nanmax(nx)) & (py >= np.nanmin(ny)) \
        & (py <= np.nanmax(ny))
    if not front.any():
        return
    pix = np.full((len(cam), 2), np.nan)
    pix[front] = camera.project(cam[front])
    ok = np.isfinite(pix).all(axis=1)
    # draw each run of consecutive good points
    run: list[np.ndarray] = []
    for p, good in zip(pix, ok, strict=True):
        if good:
            run.append(p)
        elif run:
            _draw_run(img, run, colour, thickness)
            run = []
    if run:
        _draw_run(img, run, colour, thickness)


def _draw_run(img, run, colour, thickness) -> None:
    if len(run) < 2:
        return
    pts = np.round(np.array(run) * 16).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(img, [pts], False, colour, thickness, cv2.LINE_AA, shift=4)


def _text(img: np.ndarray, text: str, at: tuple[float, float], colour) -> None:
    org = (int(at[0]), int(at[1]))
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1, cv2.LINE_AA)


def setup_preview(first: np.ndarray, camera: CameraModel, pose: Pose, planes: list[PlaneDrawing],
                  pencil_pixels: list[tuple[str, np.ndarray]] | None = None) -> np.ndarray:
    """The first frame with regions, markers, grids, the planes' common lines and pencil points (BGR uint8)."""
    img = first
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    for k, p in enumerate(planes):
        colour = COLOURS[k % len(COLOURS)]
        if p.mask is not None and p.mask.any():
            img[p.mask] = (0.6 * img[p.mask] + 0.4 * np.array(colour)).astype(np.uint8)
    # the grids
    for k, p in enumerate(planes):
        if p.extent is None:
            continue
        colour = COLOURS[k % len(COLOURS)]
        x0, x1, y0, y1 = p.extent
        step = nice_step(max(x1 - x0, y1 - y0))
        samples = np.linspace(0.0, 1.0, 60)[:, None]
        for x in np.arange(np.ceil(x0 / step) * step, x1 + 1e-9, step):
            line = p.origin + x * p.x_axis + (y0 + samples * (y1 - y0)) * p.y_axis
            _polyline(img, camera, pose, line, colour)
        for y in np.arange(np.ceil(y0 / step) * step, y1 + 1e-9, step):
            line = p.origin + (x0 + samples * (x1 - x0)) * p.x_axis + y * p.y_axis
            _polyline(img, camera, pose, line, colour)
        # the plane's axes from its origin, thicker
        _polyline(img, camera, pose, p.origin + samples * step * p.x_axis, (0, 0, 255), 2)
        _polyline(img, camera, pose, p.origin + samples * step * p.y_axis, (0, 200, 0), 2)
        _text(img, f"{p.name} (grid {step:g})", camera.project(pose.world_to_camera(p.origin[None]))[0] + [4, -6],
              colour)
    # where two planes meet
    for i in range(len(planes)):
        for j in range(i + 1, len(planes)):
            a, b = planes[i], planes[j]
            hit = plane_intersection(a.normal, float(a.normal @ a.origin), b.normal, float(b.normal @ b.origin))
            if hit is None:
                continue
            point, direction = hit
            span = (max((e[1] - e[0]) for e in (a.extent, b.extent) if e is not None)
                    if (a.extent or b.extent) else 1000.0)
            centre = point + direction * float(direction @ (a.origin - point))
            line = centre + np.linspace(-1.5 * span, 1.5 * span, 200)[:, None] * direction
            _polyline(img, camera, pose, line, (0, 255, 255), 1)
    # the markers, on top
    for k, p in enumerate(planes):
        colour = COLOURS[k % len(COLOURS)]
        for m in p.markers:
            u, v = m.pixel
            if m.hint is not None:
                cv2.drawMarker(img, (int(np.rint(m.hint[0])), int(np.rint(m.hint[1]))), (255, 0, 255),
                               cv2.MARKER_CROSS, 8, 1)
            cv2.circle(img, (int(np.rint(u * 16)), int(np.rint(v * 16))), 6 * 16, colour, 2, cv2.LINE_AA, shift=4)
            _text(img, f"{m.name} {m.residual_px:.2f}px", (u + 8, v - 8), (255, 255, 255))
    for label, pix in pencil_pixels or []:
        cv2.drawMarker(img, (int(np.rint(pix[0])), int(np.rint(pix[1]))), (0, 255, 0), cv2.MARKER_TILTED_CROSS, 12, 2)
        _text(img, label, (pix[0] + 8, pix[1] + 14), (0, 255, 0))
    return img
