"""Finding a pencil's shadow tip (and refining its base) against a photo of the empty desk.

`gnomon calibrate lamp` needs, per photo, the pencil's base and the tip of
its shadow. Given a photo of the same desk without the pencil (same camera,
same lamp) and a rough pixel of the base, both are measured:

* The shadow is where the pencil photo is darker than the empty desk *in
  irradiance*: their ratio drops from 1 (lit) towards ambient/(ambient +
  direct). The shadow leaves the base in the direction (scanned every 0.5°
  around the hint) that stays in shadow longest — not the pencil's own image,
  which rises towards the projection of its top (that direction is left out,
  and a pencil seen from above, a blob at its foot, is looked past). On real
  photos (a thick pen, a soft lamp) the shadow is tens of pixels wide at the
  base, so the slices across it are as wide as it is.
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


def _slices(ratio: np.ndarray, hint: np.ndarray, axis: np.ndarray, normal: np.ndarray, source: str,
            half_width: float = HALF_WIDTH_PX):
    """Deficit and centre of slices (``half_width`` px each side) across the shadow along ``axis``; where it
    ends; its centre line."""
    h, w = ratio.shape
    s = np.arange(0.0, float(np.hypot(w, h)), STEP_PX)
    s = s[_inside(hint + s[:, None] * axis, w, h)]
    t = np.arange(-half_width, half_width + 1e-9, STEP_PX)
    deficit = np.clip(1.0 - _sample(ratio, hint + s[:, None, None] * axis + t[None, :, None] * normal), 0, None)
    area = deficit.sum(axis=1) * STEP_PX
    # the centre within HALF_WIDTH_PX of the axis: a wider slice near the base also holds the pencil's own
    # image (a dark pen's pulls the centre line, and with it the base, towards itself)
    core = np.abs(t) <= HALF_WIDTH_PX + 1e-9
    centre = (deficit[:, core] * t[core]).sum(axis=1) / np.maximum(deficit[:, core].sum(axis=1), 1e-9)
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


def _shadow_direction(ratio: np.ndarray, hint: np.ndarray, dirs: np.ndarray, away: np.ndarray, body_px: float,
                      source: str) -> tuple[np.ndarray, float]:
    """The shadow's direction from the base hint, and the half-width (px) of the slices that hold it.

    Of the rays leaving the hint in the directions ``away`` from the pencil's own image, the one that stays
    in shadow longest: its deficit (1 − ratio) above half the shadow's, with gaps of at most 4 px. The
    darkest ray over the first ``NEAR_PX`` does not do: on real photos (a soft lamp) the shadow is tens of
    px wide there, so every ray within ±30° of its axis is as dark, and a pencil seen from above is a dark
    blob around its foot (``body_px``: how far its top's image lies from the hint; the shadow is then read
    from past it). The half-width: 0.75 of the shadow's width across that ray near the base, at least
    ``HALF_WIDTH_PX``.
    """
    h, w = ratio.shape
    r = np.arange(NEAR_PX[0], float(np.hypot(w, h)), STEP_PX)
    deficit = np.clip(1.0 - _sample(ratio, hint + r[None, :, None] * dirs[:, None, :]), 0, None)  # (dirs, r)
    # past a pencil seen from above (its image a blob around its foot); one seen from the side is left out
    # by its direction (``away``)
    start = body_px + 4.0 if body_px < NEAR_PX[1] else NEAR_PX[0]
    beyond_body = (r >= start) & (r < start + NEAR_PX[1] - NEAR_PX[0])
    reference = float(np.max(np.where(away, deficit[:, beyond_body].mean(axis=1), 0.0)))
    if reference < 0.15:
        raise GnomonError(f"{source}: no pencil shadow leaves the base hint {hint.round(1).tolist()} "
                          "(the photo is not darker than the empty desk there)")
    lit = deficit < 0.5 * reference
    gap = int(round(4.0 / STEP_PX))
    # the first run of `gap` lit samples past the body ends a ray's shadow
    runs = cv2.boxFilter(lit.astype(np.float32), -1, (gap, 1), anchor=(0, 0), normalize=False,
                         borderType=cv2.BORDER_CONSTANT) >= gap - 0.5
    runs &= r[None, :] >= start
    length = np.where(runs.any(axis=1), r[np.argmax(runs, axis=1)], r[-1])
    k = int(np.argmax(np.where(away, length, -1.0)))
    axis = dirs[k]
    normal = np.array([-axis[1], axis[0]])
    s = r[beyond_body][:, None]
    t = np.arange(-80.0, 80.0 + 1e-9, STEP_PX)
    across = np.clip(1.0 - _sample(ratio, hint + s[..., None] * axis + t[None, :, None] * normal), 0, None)
    width = float(np.median((across > 0.5 * reference).sum(axis=1))) * STEP_PX
    return axis, float(np.clip(0.75 * width, HALF_WIDTH_PX, 80.0))


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
    body = np.arctan2(top_px[1] - hint[1], top_px[0] - hint[0])
    away = np.abs((theta - body + np.pi) % (2 * np.pi) - np.pi) > np.radians(BODY_EXCLUSION_DEG)
    axis, half_width = _shadow_direction(ratio, hint, dirs, away, float(np.hypot(*(top_px - hint))), source)
    # Refine the direction: the slices' centres give the axis' tilt; re-slice along it.
    for _ in range(3):
        normal = np.array([-axis[1], axis[0]])
        s, area, centre, end, line, plateau, deficit, near = _slices(ratio, hint, axis, normal, source, half_width)
        tilt = np.arctan(line[0])
        axis = np.cos(tilt) * axis + np.sin(tilt) * normal
        if abs(tilt) < 1e-4:
            break
    normal = np.array([-axis[1], axis[0]])
    s, area, centre, end, line, plateau, deficit, near = _slices(ratio, hint, axis, normal, source, half_width)
    idx = np.arange(len(s))
    # the shadow's own level, half-way along it (near the base the slices may also hold the pencil's image)
    middle = (s >= 0.3 * s[end]) & (s <= 0.6 * s[end])
    level = float(np.median(area[middle])) if middle.any() else plateau
    falling = (idx <= end + 4) & (s > 0.5 * s[end]) & (area < 0.75 * level) & (area > 0.15 * level)
    if falling.sum() >= 3:
        slope, intercept = np.polyfit(s[falling], area[falling], 1)
        s_tip = -intercept / slope if slope < 0 else s[end]
    else:
        s_tip = s[end]
    base = hint + np.polyval(line, 0.0) * normal
    tip = hint + s_tip * axis + np.polyval(line, s_tip) * normal
    shadow_ratio = float(1.0 - np.median(deficit[near].max(axis=1)))
    return PencilDetection(base, tip, float(np.degrees(np.arctan2(axis[1], axis[0]))), shadow_ratio)
