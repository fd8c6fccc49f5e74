"""Finding a pencil's shadow tip (and refining its base) against a photo of the empty desk.

`gnomon calibrate lamp` needs, per photo, the pencil's base and the tip of
its shadow. Given a photo of the same desk without the pencil (same camera,
same lamp) and a rough pixel of the base, both are measured:

* The shadow is where the pencil photo is darker than the empty desk *in
  irradiance*: their ratio drops from 1 (lit) towards ambient/(ambient +
  direct). The shadow leaves the base in the direction (scanned every 0.5°
  around the hint) in which the ratio is lowest over the first 6–40 px — not
  the pencil's own image, which rises towards the projection of its top.
* Across that direction, each slice of the shadow gives its deficit
  ``∫(1 − ratio)`` and its centre; the centres fit the shadow's axis, which
  moves the base hint onto the axis (along the axis, the pencil hides its own
  foot, so the hint stays).
* The shadow's deficit shrinks linearly along the sharpened tip's shadow
  and blur does not change it, so the tip is where a line fitted to the
  falling deficit reaches zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from gnomon.errors import GnomonError

NEAR_PX = (6.0, 40.0)  # the stretch of shadow near the base that sets its direction
HALF_WIDTH_PX = 12.0  # half-width of the slices across the shadow
STEP_PX = 0.5
BODY_EXCLUSION_DEG = 15.0


@dataclass(frozen=True)
class PencilDetection:
    base_px: np.ndarray  # (2,) the hint moved onto the shadow's axis
    tip_px: np.ndarray  # (2,) the shadow's tip
    direction_deg: float  # of the shadow in the image, from +u towards +v
    shadow_ratio: float  # irradiance ratio in the shadow near the base


def _sample(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    m = pts.astype(np.float32)
    return cv2.remap(image, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)


def _inside(pts: np.ndarray, w: int, h: int) -> np.ndarray:
    return (pts[:, 0] >= 0) & (pts[:, 0] <= w - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= h - 1)


def _slices(ratio: np.ndarray, hint: np.ndarray, axis: np.ndarray, normal: np.ndarray, source: str):
    """Deficit and centre of slices across the shadow along ``axis``; where it ends; its centre line."""
    h, w = ratio.shape
    s = np.arange(0.0, float(np.hypot(w, h)), STEP_PX)
    s = s[_inside(hint + s[:, None] * axis, w, h)]
    t = np.arange(-HALF_WIDTH_PX, HALF_WIDTH_PX + 1e-9, STEP_PX)
    deficit = np.clip(1.0 - _sample(ratio, hint + s[:, None, None] * axis + t[None, :, None] * normal), 0, None)
    area = deficit.sum(axis=1) * STEP_PX
    centre = (deficit * t).sum(axis=1) / np.maximum(deficit.sum(axis=1), 1e-9)
    near = (s >= NEAR_PX[0]) & (s < NEAR_PX[1])
    plateau = float(np.median(area[near]))
    # the shadow runs from the base until its deficit vanishes
    inside = np.flatnonzero((s >= NEAR_PX[0]) & (area > 0.15 * plateau))
    if len(inside) == 0:
        raise GnomonError(f"{source}: no pencil shadow along the direction found")
    breaks = np.flatnonzero(np.diff(inside) > 4)
    end = int(inside[breaks[0]] if len(breaks) else inside[-1])
    if end + 8 >= len(s):
        raise GnomonError(f"{source}: the pencil's shadow runs out of the image")
    body_part = (np.arange(len(s)) <= end) & (s >= NEAR_PX[0]) & (area > 0.5 * plateau)
    if body_part.sum() < 5:
        raise GnomonError(f"{source}: the pencil's shadow is too short to measure")
    line = np.polyfit(s[body_part], centre[body_part], 1)
    return s, area, centre, end, line, plateau, deficit, near


def detect_pencil(photo_linear: np.ndarray, empty_linear: np.ndarray, base_hint_px: np.ndarray,
                  top_px: np.ndarray, *, source: str = "photo") -> PencilDetection:
    """The shadow tip and the refined base of a pencil standing near ``base_hint_px``.

    ``photo_linear``, ``empty_linear``: grey images in linear irradiance, same
    size; ``top_px``: where the pencil's top projects when its base is at the
    hint (its own image lies that way, and is not its shadow).
    """
    if photo_linear.shape != empty_linear.shape:
        raise GnomonError(f"{source}: size {photo_linear.shape[::-1]} differs from the empty-desk photo's "
                          f"{empty_linear.shape[::-1]}")
    ratio = (photo_linear / np.maximum(empty_linear, 1e-4)).astype(np.float32)
    hint = np.asarray(base_hint_px, dtype=np.float64)
    theta = np.radians(np.arange(0.0, 360.0, 0.5))
    dirs = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    r = np.arange(NEAR_PX[0], NEAR_PX[1], STEP_PX)
    darkness = np.clip(1.0 - _sample(ratio, hint + r[None, :, None] * dirs[:, None, :]), 0, None).mean(axis=1)
    body = np.arctan2(top_px[1] - hint[1], top_px[0] - hint[0])
    away = np.abs((theta - body + np.pi) % (2 * np.pi) - np.pi) > np.radians(BODY_EXCLUSION_DEG)
    k = int(np.argmax(np.where(away, darkness, -1.0)))
    if darkness[k] < 0.15:
        raise GnomonError(f"{source}: no pencil shadow leaves the base hint {hint.round(1).tolist()} "
                          "(the photo is not darker than the empty desk there)")
    axis = dirs[k]
    # Refine the direction: the slices' centres give the axis' tilt; re-slice along it.
    for _ in range(3):
        normal = np.array([-axis[1], axis[0]])
        s, area, centre, end, line, plateau, deficit, near = _slices(ratio, hint, axis, normal, source)
        tilt = np.arctan(line[0])
        axis = np.cos(tilt) * axis + np.sin(tilt) * normal
        if abs(tilt) < 1e-4:
            break
    normal = np.array([-axis[1], axis[0]])
    s, area, centre, end, line, plateau, deficit, near = _slices(ratio, hint, axis, normal, source)
    idx = np.arange(len(s))
    falling = (idx <= end + 4) & (s > 0.5 * s[end]) & (area < 0.75 * plateau) & (area > 0.15 * plateau)
    if falling.sum() >= 3:
        slope, intercept = np.polyfit(s[falling], area[falling], 1)
        s_tip = -intercept / slope if slope < 0 else s[end]
    else:
        s_tip = s[end]
    base = hint + np.polyval(line, 0.0) * normal
    tip = hint + s_tip * axis + np.polyval(line, s_tip) * normal
    shadow_ratio = float(1.0 - np.median(deficit[near].max(axis=1)))
    return PencilDetection(base, tip, float(np.degrees(np.arctan2(axis[1], axis[0]))), shadow_ratio)
