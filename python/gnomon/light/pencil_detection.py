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

from collections.abc import Callable
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


@dataclass(frozen=True)
class PencilBase:
    """Where a pencil stands in a photo, found from its image and its shadow's together.

    ``base_px``: its foot (on its shadow's axis); ``top_px``: where its top projects from that foot;
    ``fit``: how much of what changed against the empty desk the pencil and its shadow explain, as an
    intersection over union (1 = all of it and nothing else); ``changed_px``: the pixels that changed.
    """

    base_px: np.ndarray
    top_px: np.ndarray
    fit: float
    changed_px: int


FOUND_FOOT_SIGMA_PX = 1.5
"""1σ (pixels, each coordinate) of a foot found by :func:`find_pencil_base`: on the simulator's pale and
dark pencils (12 feet, 800×600) the found feet lie 0.7–3.7 px from the truth, 2.0 px RMS in distance."""

BASE_FIT_MIN = 0.5
"""Below this intersection over union, what changed against the empty desk is not one pencil and its shadow."""


def _changed(ratio: np.ndarray) -> np.ndarray:
    """The largest connected piece of what is much darker or brighter (by 30 %, 40 %) than the empty desk
    (bool mask)."""
    # a thin pale pencil is a bright strip beside a dark one: closed into one piece
    changed = cv2.morphologyEx(((ratio < 0.7) | (ratio > 1.4)).astype(np.uint8), cv2.MORPH_CLOSE,
                               np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(changed)
    if n < 2:
        return np.zeros(ratio.shape, dtype=bool)
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def _segment_distance(pts: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = b - a
    s = np.clip(((pts - a) @ d) / max(float(d @ d), 1e-9), 0.0, 1.0)
    return np.linalg.norm(pts - (a + s[:, None] * d), axis=1)


def _two_arm_fit(pts: np.ndarray, cell: float, size: tuple[int, int], base: np.ndarray, top: np.ndarray,
                 half_width: float) -> float:
    """Intersection over union of the changed points ``pts`` (each standing for ``cell`` px²) with a pencil
    (``base`` → ``top``) and a shadow leaving ``base`` to the farthest changed point the pencil does not
    hold, each ``half_width`` px wide; the pencil counted inside the image (``size``: width, height) only.
    0 when that shadow is shorter than 4 half-widths (what changed is a blob, not a pencil's shadow)."""
    pencil = _segment_distance(pts, base, top) <= half_width
    rest = pts[~pencil]
    tip = rest[np.argmax(np.linalg.norm(rest - base, axis=1))] if len(rest) else base
    if np.linalg.norm(tip - base) < 4.0 * half_width:  # a shadow is long and thin; a blob is not one
        return 0.0
    held = pencil | (_segment_distance(pts, base, tip) <= half_width)
    seen, a, b = cv2.clipLine((0, 0, size[0], size[1]), tuple(int(x) for x in np.round(base)),
                              tuple(int(x) for x in np.round(np.clip(top, -1e6, 1e6))))
    pencil_length = float(np.hypot(b[0] - a[0], b[1] - a[1])) if seen else 0.0
    arms = 2.0 * half_width * (pencil_length + float(np.linalg.norm(tip - base))) + np.pi * half_width ** 2
    covered = float(held.sum()) * cell
    return covered / (len(pts) * cell + max(arms - covered, 0.0))


def find_pencil_base(photo_linear: np.ndarray, empty_linear: np.ndarray,
                     tops_px: Callable[[np.ndarray], np.ndarray], *, source: str = "photo",
                     step_px: int = 4) -> PencilBase:
    """The foot of a pencil standing somewhere in ``photo_linear``, no pixel given.

    What changed against the empty desk (``empty_linear``; both grey, linear irradiance) is the pencil's
    own image and its shadow, two arms meeting at the foot. ``tops_px`` maps candidate feet (N, 2) to where
    the pencil's top then projects (the camera, the desk's pose and the pencil's length: the pencil's arm
    is predicted whole from its foot). Every changed pixel (every ``step_px``-th) whose predicted pencil
    lies 80 % inside the changed region (of what is inside the image) is a candidate; the one whose pencil
    and shadow (to the farthest changed pixel the pencil does not hold) best explain the changed region
    wins, then every pixel around the best three. Refuses (naming
    ``source``) when nothing changed, when no candidate's pencil fits, or when the best explains less than
    :data:`BASE_FIT_MIN` of it (two pencils, a hand, a moved object: click the base instead).
    """
    ratio = photo_linear / np.maximum(empty_linear, 1e-4)
    changed = _changed(ratio)
    n_changed = int(changed.sum())
    if n_changed < 50:
        raise GnomonError(f"{source}: nothing differs from the empty desk (no pencil found): give its base")
    half_width = float(np.percentile(cv2.distanceTransform(changed.astype(np.uint8), cv2.DIST_L2, 5)[changed],
                                     95))
    held = cv2.dilate(changed.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    vs, us = np.nonzero(changed[::step_px, ::step_px])
    candidates = np.stack([us, vs], axis=1).astype(np.float64) * step_px
    tops = np.asarray(tops_px(candidates), dtype=np.float64)
    s = np.linspace(0.0, 1.0, 40)
    along = candidates[:, None, :] + s[None, :, None] * (tops - candidates)[:, None, :]
    h, w = changed.shape
    u = np.round(along[..., 0]).astype(np.int64)
    v = np.round(along[..., 1]).astype(np.int64)
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h) & np.isfinite(along).all(axis=-1)
    on = np.zeros(inside.shape, dtype=bool)
    on[inside] = held[v[inside], u[inside]]
    seen = inside.sum(axis=1)  # a pencil may stand partly outside the image: judged on what is seen of it
    fits = (seen >= 0.2 * len(s)) & (on.sum(axis=1) >= 0.8 * np.maximum(seen, 1))
    if not fits.any():
        raise GnomonError(f"{source}: no standing pencil's image fits what differs from the empty desk "
                          "(a pale pencil on a pale desk, or the wrong length?): give its base")
    stride = 2 if n_changed > 4000 else 1
    ys, xs = np.nonzero(changed[::stride, ::stride])
    pts = np.stack([xs, ys], axis=1).astype(np.float64) * stride
    arm = half_width + 1.0  # a pixel's worth of slack on each side of the arms

    def fit(feet: np.ndarray, tops: np.ndarray) -> np.ndarray:
        return np.array([_two_arm_fit(pts, stride ** 2, (w, h), b, t, arm) for b, t in zip(feet, tops, strict=True)])

    candidates, tops = candidates[fits], tops[fits]
    scores = fit(candidates, tops)
    # then every pixel around the best few of the coarse grid
    offsets = np.stack(np.meshgrid(np.arange(-step_px, step_px + 1), np.arange(-step_px, step_px + 1)),
                       axis=-1).reshape(-1, 2)
    best = candidates[np.argsort(scores)[-3:]]
    fine = np.unique((best[:, None, :] + offsets[None]).reshape(-1, 2), axis=0)
    fine_tops = np.asarray(tops_px(fine), dtype=np.float64)
    ok = np.isfinite(fine_tops).all(axis=1)
    fine, fine_tops = fine[ok], fine_tops[ok]
    fine_scores = fit(fine, fine_tops)
    k = int(np.argmax(fine_scores))
    if fine_scores[k] < BASE_FIT_MIN:
        raise GnomonError(f"{source}: what differs from the empty desk is not one pencil and its shadow (the best "
                          f"fit explains {fine_scores[k]:.0%} of its {n_changed} pixels): give its base")
    return PencilBase(fine[k], fine_tops[k], float(fine_scores[k]), n_changed)

