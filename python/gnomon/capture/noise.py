"""The image noise σI of a capture, from pairs of consecutive frames.

Two frames of a static scene differ by noise alone where nothing moved: the
clipped spread of their difference, as a function of the level, gives the
sensor's noise in DN. The tracker estimates it from the first frame pairs
while it tracks (:mod:`gnomon.capture.tracking`); the uncertainty of each
depth (:mod:`gnomon.geometry.uncertainty`) and the contrast floor of a dip
follow from it.
"""

from __future__ import annotations

import numpy as np

from gnomon import _kernel

# Pixels a step of the noise estimate's clipped fit needs: with fewer it stops.
MIN_FIT_PIXELS = 16


def image_noise_dn(frame_a: np.ndarray, frame_b: np.ndarray, *, clip_sigmas: float = 4.0,
                   iterations: int = 6) -> float:
    """Per-frame image noise σI (DN) from two consecutive frames, without quantisation.

    The difference of two frames is noise (σ√2) except where the shadow moved
    or the scene changed (a small part of the image). Its spread is measured
    as a *standard deviation* with iterative ``clip_sigmas``·σ clipping, not
    as a median of absolute deviations: on 8-bit data the differences are
    integers, so a MAD is an integer too (1.4826·1/√2 = 1.048 DN whatever the
    true noise between ≈0.7 and ≈2 DN), while the clipped standard deviation
    of integer differences is continuous (quantisation adds 1/12 DN² per
    frame, which is part of the noise a threshold crossing sees).

    A slow global change between the frames (exposure drift, passing haze) is
    removed first as an offset and a gain, fitted on the unclipped pixels.
    Samples at the ends of the range (0 or the dtype's maximum: clipped or
    saturated) are excluded: their noise is hidden by the clipping.
    Returns ≥ 1/√12 DN (the quantisation floor).

    uint8/uint16 frames (a scan's) are read in the kernel: the samples inside the range, their
    differences, centred levels and starting median and MAD in one pass (``_kernel.noise_samples``);
    and each step of the clipped fit runs there (``_kernel.clipped_fit_step``: the kept pixels gathered
    in one pass, then their means), instead of ≈ 20 passes of numpy temporaries over the frame per
    step. Equal to the last bit to :func:`_image_noise_dn_numpy`, the definition.
    """
    a = np.asarray(frame_a)
    b = np.asarray(frame_b)
    if a.shape != b.shape:
        raise ValueError(f"frames differ in shape: {a.shape} vs {b.shape}")
    floor = 1.0 / np.sqrt(12.0)
    if a.dtype == b.dtype and a.dtype in (np.uint8, np.uint16):
        # a scan's frames: the samples, their differences and the starting medians in the kernel
        samples = _kernel.noise_samples(np.ravel(a), np.ravel(b), MIN_FIT_PIXELS)
        if samples is None:
            return float(floor)
        diff, level, med, mad = samples
    else:
        top = np.iinfo(a.dtype).max if np.issubdtype(a.dtype, np.integer) else np.inf
        a = a.astype(np.float32).ravel()
        b = b.astype(np.float32).ravel()
        inside = (a > 0) & (b > 0) & (a < top) & (b < top)
        if np.count_nonzero(inside) < MIN_FIT_PIXELS:
            return float(floor)
        a, b = a[inside], b[inside]
        diff = a - b
        level = 0.5 * (a + b)
        level = level - float(level.mean())
        # Starting scale: the MAD, at least one quantisation step.
        med = float(np.median(diff))
        mad = float(np.median(np.abs(diff - med)))
    scale = max(1.4826 * mad, 1.0)
    offset, gain = med, 0.0
    for _ in range(iterations):
        # Keep the pixels within clip_sigmas·scale of the line, refit it on them, their residuals' RMS:
        # in the kernel, one pass over the pixels, the same float32 arithmetic and sums as numpy's.
        step = _kernel.clipped_fit_step(diff, level, offset, gain, clip_sigmas * scale, MIN_FIT_PIXELS)
        if step is None:
            break
        _, offset, gain, new_scale = step
        scale, converged = _clipped_scale(scale, new_scale, clip_sigmas)
        if converged:
            break
    return float(max(scale / np.sqrt(2.0), floor))


def _image_noise_dn_numpy(frame_a: np.ndarray, frame_b: np.ndarray, *, clip_sigmas: float = 4.0,
                          iterations: int = 6) -> float:
    """:func:`image_noise_dn` with its fit in numpy (the definition: the tests' reference)."""
    a = np.asarray(frame_a)
    b = np.asarray(frame_b)
    if a.shape != b.shape:
        raise ValueError(f"frames differ in shape: {a.shape} vs {b.shape}")
    top = np.iinfo(a.dtype).max if np.issubdtype(a.dtype, np.integer) else np.inf
    # uint8/uint16 frames (a scan's): the samples are selected on the integers and the starting medians
    # taken from histograms, giving exactly what the float32 path gives, in less time.
    integers = a.dtype == b.dtype and a.dtype in (np.uint8, np.uint16)
    if integers:
        a, b = a.ravel(), b.ravel()
    else:
        a = a.astype(np.float32).ravel()
        b = b.astype(np.float32).ravel()
    inside = (a > 0) & (b > 0) & (a < top) & (b < top)
    floor = 1.0 / np.sqrt(12.0)
    if np.count_nonzero(inside) < 16:
        return float(floor)
    a, b = a[inside], b[inside]
    if integers:
        whole = a.astype(np.int32) - b.astype(np.int32)
        a, b = a.astype(np.float32), b.astype(np.float32)
    diff = a - b
    level = 0.5 * (a + b)
    level = level - float(level.mean())
    # Starting scale: the MAD (integer on 8-bit data, only a start), at least one quantisation step.
    if integers:
        med = _median_of_integers(whole)
        mad = _median_of_integers(np.abs(2 * whole - round(2 * med))) / 2  # |diff − med|, counted in half DN
    else:
        med = float(np.median(diff))
        mad = float(np.median(np.abs(diff - med)))
    scale = max(1.4826 * mad, 1.0)
    offset, gain = med, 0.0
    for _ in range(iterations):
        resid = diff - offset - gain * level
        keep = np.abs(resid) <= clip_sigmas * scale
        if np.count_nonzero(keep) < 16:
            break
        x, y = level[keep], diff[keep]
        x_mean, y_mean = x.mean(), y.mean()
        dx = x - x_mean
        var_x = float(np.mean(dx**2))
        gain = float(np.mean(dx * (y - y_mean)) / var_x) if var_x > 0 else 0.0
        offset = float(y_mean - gain * x_mean)
        resid = y - offset - gain * x
        new_scale = float(np.sqrt(np.mean(resid**2)))
        scale, converged = _clipped_scale(scale, new_scale, clip_sigmas)
        if converged:
            break
    return float(max(scale / np.sqrt(2.0), floor))


def _clipped_scale(scale: float, clipped_rms: float, clip_sigmas: float) -> tuple[float, bool]:
    """The next scale of the clipped fit from its inliers' residual RMS (DN): unbiased for a Gaussian
    clipped at ``clip_sigmas`` times the current ``scale``, and whether it moved by at most 0.1 %."""
    # A Gaussian clipped at k·σ has a std smaller by this factor.
    k = clip_sigmas * scale / max(clipped_rms, 1e-12)
    new_scale = clipped_rms / _clipped_std_factor(min(k, 10.0))
    return max(new_scale, 1e-6), abs(new_scale - scale) <= 1e-3 * scale


def _median_of_integers(values: np.ndarray) -> float:
    """``np.median`` of an integer array (its middle value, or the mean of the two middle ones), from
    its histogram: the same value, in time linear in its size."""
    low = int(values.min())
    cumulative = np.cumsum(np.bincount(values - low))
    n = values.size
    below = int(np.searchsorted(cumulative, (n - 1) // 2, side="right"))  # sorted element (n − 1) // 2
    above = int(np.searchsorted(cumulative, n // 2, side="right"))  # sorted element n // 2
    return (below + above) / 2 + low


def _clipped_std_factor(k: float) -> float:
    """std of a unit Gaussian truncated to ±k (k in σ of the untruncated one)."""
    from math import erf, exp, pi, sqrt

    mass = erf(k / sqrt(2.0))
    if mass <= 0:
        return 1.0
    pdf = exp(-0.5 * k * k) / sqrt(2.0 * pi)
    return float(np.sqrt(max(1.0 - 2.0 * k * pdf / mass, 1e-6)))
