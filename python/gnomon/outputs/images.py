"""A picture of a scan without a viewer: ``preview.png`` = colour | depth | σ | coverage.

Four panels side by side at the same (downscaled) size, each captioned: the
colour image the points take their colours from, the depth map (camera Z,
viridis, range in the caption), the predicted σ of the depth (inferno), and
the coverage map (one colour per class of :data:`COVERAGE_CLASSES`, the
legend under the panel). Pixels without a value are black.

:func:`coverage_map` computes the classes; the recording shows the same map
(``maps/coverage``).
"""

from __future__ import annotations

import os

import cv2
import numpy as np

__all__ = ["COVERAGE_CLASSES", "coverage_map", "preview_image", "write_preview"]

#: Coverage class → (name, RGB colour). One uint8 class per pixel.
COVERAGE_CLASSES: dict[int, tuple[str, tuple[int, int, int]]] = {
    0: ("no shadow seen", (40, 40, 40)),
    1: ("point", (60, 180, 75)),
    2: ("shadow seen, no depth", (230, 25, 75)),
    3: ("under-sampled point", (255, 200, 20)),
    4: ("cropped", (0, 130, 200)),
    5: ("ambiguous: two comparable dips", (145, 30, 180)),
    6: ("edges disagree", (245, 130, 48)),
    7: ("no neighbour at its depth", (70, 240, 240)),
    8: ("no direct light", (150, 100, 40)),
}
(NO_SHADOW, POINT, NO_DEPTH, UNDERSAMPLED, CROPPED, AMBIGUOUS, EDGES_DISAGREE, NO_NEIGHBOUR,
 NO_DIRECT_LIGHT) = range(9)


def coverage_map(contrast_ok: np.ndarray, valid: np.ndarray, undersampled: np.ndarray | None = None,
                 cropped: np.ndarray | None = None, *, ambiguous: np.ndarray | None = None,
                 conflict: np.ndarray | None = None, unsupported: np.ndarray | None = None,
                 no_direct_light: np.ndarray | None = None) -> np.ndarray:
    """Class per pixel (H, W) uint8: see :data:`COVERAGE_CLASSES`.

    ``contrast_ok`` the shadow was seen (enough contrast), ``valid`` a point
    was kept, ``undersampled`` kept points the edge crossed in fewer than 2
    frames, ``cropped`` points removed by ``[output] crop``. Why a pixel has
    no point, where known: ``ambiguous`` two comparable dips (no time),
    ``conflict`` the entering and leaving edges gave incompatible depths,
    ``unsupported`` a depth no neighbour shares, ``no_direct_light`` a dip the
    light's own shadow did not make (bounced light, the edge of the light). All (H, W) bool; a pixel
    with a shadow time and none of these reasons is "shadow seen, no depth"
    (no shadow plane near its time, or the light refused it).
    """
    c = np.where(contrast_ok, NO_DEPTH, NO_SHADOW).astype(np.uint8)
    if ambiguous is not None:
        c[ambiguous & ~contrast_ok] = AMBIGUOUS
    if unsupported is not None:
        c[unsupported & contrast_ok] = NO_NEIGHBOUR
    if conflict is not None:
        c[conflict & contrast_ok] = EDGES_DISAGREE
    if no_direct_light is not None:
        c[no_direct_light & contrast_ok] = NO_DIRECT_LIGHT
    c[valid] = POINT
    if undersampled is not None:
        c[valid & undersampled] = UNDERSAMPLED
    if cropped is not None:
        c[cropped & ~valid] = CROPPED
    return c


def _colourise(values: np.ndarray, cmap: int) -> tuple[np.ndarray, tuple[float, float] | None]:
    finite = np.isfinite(values)
    if not finite.any():
        return np.zeros(values.shape + (3,), np.uint8), None
    lo, hi = np.percentile(values[finite], [1, 99])
    hi = hi if hi > lo else lo + 1.0
    scaled = np.clip((np.nan_to_num(values, nan=lo) - lo) / (hi - lo), 0, 1)
    bgr = cv2.applyColorMap((scaled * 255).astype(np.uint8), cmap)
    bgr[~finite] = 0
    return bgr[:, :, ::-1], (float(lo), float(hi))


def _caption(panel: np.ndarray, text: str, bar: int) -> np.ndarray:
    out = np.zeros((panel.shape[0] + bar, panel.shape[1], 3), np.uint8)
    out[:panel.shape[0]] = panel
    scale = bar / 40
    while scale > 0.2 and cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > panel.shape[1] - 8:
        scale *= 0.9
    cv2.putText(out, text, (6, panel.shape[0] + int(bar * 0.68)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (235, 235, 235), 1, cv2.LINE_AA)
    return out


def preview_image(rgb: np.ndarray, depth: np.ndarray, sigma: np.ndarray, coverage: np.ndarray, *,
                  units: str = "", max_panel_width: int = 480) -> np.ndarray:
    """The preview (H', 4·W', 3) uint8 RGB: colour | depth | σ | coverage, captioned.

    ``rgb`` (H, W, 3) uint8; ``depth``, ``sigma`` (H, W) float, NaN = none;
    ``coverage`` (H, W) uint8 classes. Panels are downscaled to at most
    ``max_panel_width`` pixels wide (area average; nearest for the classes).
    """
    h, w = depth.shape
    scale = min(1.0, max_panel_width / w)
    size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))

    def fit(a: np.ndarray, nearest: bool = False) -> np.ndarray:
        if size == (w, h):
            return a
        return cv2.resize(a, size, interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)

    colour = fit(np.ascontiguousarray(rgb, dtype=np.uint8))
    d, drange = _colourise(fit(np.asarray(depth, np.float32), nearest=True), cv2.COLORMAP_VIRIDIS)
    s, srange = _colourise(fit(np.asarray(sigma, np.float32), nearest=True), cv2.COLORMAP_INFERNO)
    lut = np.zeros((256, 3), np.uint8)
    for k, (_, c) in COVERAGE_CLASSES.items():
        lut[k] = c
    cov = lut[fit(np.asarray(coverage, np.uint8), nearest=True)]
    u = f" {units}" if units else ""
    share = {k: float(np.mean(coverage == k)) for k in COVERAGE_CLASSES}
    short = {POINT: "points", NO_DEPTH: "no depth", UNDERSAMPLED: "under-sampled", CROPPED: "cropped",
             AMBIGUOUS: "ambiguous", EDGES_DISAGREE: "edges disagree", NO_NEIGHBOUR: "no neighbour"}
    legend = ", ".join(f"{short[k]} {100 * share[k]:.0f}%" for k in short if share[k] > 0)
    bar = max(18, size[1] // 12)
    panels = [
        _caption(colour, "colour", bar),
        _caption(d, "depth" + (f" {drange[0]:.4g}-{drange[1]:.4g}{u}" if drange else ": none"), bar),
        _caption(s, "sigma" + (f" {srange[0]:.2g}-{srange[1]:.2g}{u}" if srange else ": none"), bar),
        _caption(cov, legend or "coverage", bar),
    ]
    return np.concatenate(panels, axis=1)


def write_preview(path: str | os.PathLike, rgb: np.ndarray, depth: np.ndarray, sigma: np.ndarray,
                  coverage: np.ndarray, *, units: str = "") -> None:
    """Write :func:`preview_image` as PNG, atomically."""
    from gnomon.util import atomic

    img = preview_image(rgb, depth, sigma, coverage, units=units)
    ok, png = cv2.imencode(".png", img[:, :, ::-1])
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    atomic.write_bytes(path, png.tobytes())
