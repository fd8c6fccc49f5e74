"""Shadow times between the isochrones: a fast sweep's times from where the edge was, not from how dark it got.

A pixel's shadow time is interpolated linearly between the two frames whose
samples bracket the threshold (:mod:`gnomon.capture.tracking`). That is exact while
the edge's penumbra spans a frame's motion or more. When the shadow moves
several pixels per frame (a hand-swept stick filmed at a few frames per
second: most pixels of the CMU frog capture are crossed within one frame), a
pixel is fully lit in frame ``k`` and fully dark in ``k + 1``, so every pixel
between the edge's positions at frames ``k`` and ``k + 1`` gets the same time
``≈ k + 0.5``: the time map is a staircase, and the points triangulated from
it a saw-tooth around the surface (on the frog's desk, ±3 mm).

The edge's *positions* are still measured well: where the time map crosses
the integer frame ``k`` is where the pixel's penumbra straddles the
threshold in frame ``k``, to a fraction of a pixel (the reference lines are
measured there, :mod:`gnomon.geometry.reference_lines`). Between the crossings of
``k`` and ``k + 1`` the edge moved at a steady pace over a smooth surface,
so the pixel's time is the fraction of that distance it lies along:

    t = k + (u − u_k) / (u_{k+1} − u_k)

along the sweep's axis (rows or columns, whichever the times change fastest
along). The crossings are taken within *runs*: consecutive pixels of one row
(or column) whose times never go back against the sweep by more than
``BACKSTEP`` frames (a depth edge, a missing time or a wrong one ends a run),
where each integer frame is crossed once. A pixel keeps its own time when a bracketing crossing is
missing in its run, or when they are more than ``max_gap`` pixels apart, or
less than ``MIN_GAP_PX`` (a slow sweep, which the tracker times well).
The map's integer isochrones are unchanged (it passes through the same
crossings), so the reference lines, and the shadow planes, are the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel

__all__ = ["ACROSS_BEND_FRAMES", "ACROSS_HALF_ROWS", "MAX_GAP_PX", "RetimedTimes", "RowRetiming",
           "average_across_sweep", "retime_between_isochrones", "retime_rows", "retime_with_sigma"]

# Crossings of consecutive frames farther apart than this (pixels) are not interpolated between.
MAX_GAP_PX = 40.0
# Nor closer than this: an edge that moved less than three pixels in a frame is sampled finely enough
# in time (its penumbra spans the step) for the tracker's own interpolation.
MIN_GAP_PX = 3.0
# A run tolerates times going back by this much (frames): the noise of a staircase's plateau.
BACKSTEP = 0.25
# The scan averages each re-timed time with the re-timed rows this far on either side across the sweep
# (:func:`average_across_sweep`): less than the MIN_GAP_PX a re-timed time already spans along it.
ACROSS_HALF_ROWS = 2
# ... taking a pair of rows only when the time bends across them by at most this (frames): half the
# staircase's step, which a depth edge between the rows exceeds.
ACROSS_BEND_FRAMES = 0.5


def _sweep_axis(times: np.ndarray) -> tuple[bool, float]:
    """(along rows?, sense) of the sweep: the axis where neighbouring times differ most, and its sign."""
    steps = []
    for axis in (1, 0):
        d = np.diff(times, axis=axis) if times.shape[axis] > 1 else np.zeros(0)
        d = d[np.isfinite(d) & (d != 0)]
        steps.append(float(np.median(d)) if d.size else 0.0)
    along_rows = not abs(steps[1]) > abs(steps[0])
    return along_rows, float(np.sign(steps[0] if along_rows else steps[1]))


@dataclass(frozen=True)
class RetimedTimes:
    """A re-timed shadow-time map and what its times were made of.

    ``times`` (H, W) float32 frames (NaN = none); ``retimed`` (H, W) bool the
    pixels whose time comes from the crossings around them (the others kept
    the tracker's). For each re-timed pixel (``pixel``, flat indices), the two
    crossings it lies between: the pixels each crossing was interpolated
    between (``left``, ``right``: (P, 2) flat indices, crossing of ``⌊t⌋``
    then of ``⌊t⌋ + 1``), where between them (``phase`` (P, 2), 0 at the
    left pixel) and how fast the time rises there (``rise`` (P, 2), frames
    per pixel); the crossings' distance ``gap`` (P,) pixels and the pixel's
    fraction ``f`` (P,) of it.
    """

    times: np.ndarray
    retimed: np.ndarray
    pixel: np.ndarray
    left: np.ndarray
    right: np.ndarray
    phase: np.ndarray
    rise: np.ndarray
    gap: np.ndarray
    f: np.ndarray

    def sigma(self, sigma_t: np.ndarray) -> np.ndarray:
        """Each pixel's time σ (frames) given the tracker's σ of every pixel's own time (H, W).

        A crossing at phase φ between pixels a and b whose times rise by g per
        pixel is off by ``((1 − φ) σa + φ σb) / g`` pixels (neighbours' errors
        taken as fully correlated: the sampling phase, which dominates, is
        nearly the same for adjacent pixels); the
        re-timed ``t = ⌊t⌋ + (u − u₀)/(u₁ − u₀)`` is off by ``(1 − f)/D`` and
        ``f/D`` of the two crossings' errors (D the gap), added linearly too:
        where the sweep is steady the crossings of consecutive frames fall at
        the same sampling phase, so their errors are alike (on the simulated
        two-plane capture, adding them in quadrature under-predicts the error
        by 1.7×); and, in quadrature, a crossing whose penumbra is narrower
        than a pixel (the time rises by g > 1 frame per pixel there) is known
        only to ``(1 − 1/g)/√12`` px. Pixels not re-timed keep
        their own σ.
        """
        out = np.asarray(sigma_t, dtype=np.float64).copy()
        if self.pixel.size == 0:
            return out.astype(np.float32)
        flat = out.ravel()
        sa, sb = flat[self.left], flat[self.right]
        su = ((1.0 - self.phase) * sa + self.phase * sb) / self.rise  # (P, 2) px
        weights = np.stack([1.0 - self.f, self.f], axis=1) / self.gap[:, None]
        # A penumbra narrower than a pixel (the time rises by g > 1 frame per pixel across it) is
        # located only within its pixel: uniform over the part 1 − 1/g it does not span, independent
        # between the two crossings.
        blind = np.clip(1.0 - 1.0 / self.rise, 0.0, 1.0) / np.sqrt(12.0)  # (P, 2) px
        quantised = np.sqrt(np.sum((weights * blind) ** 2, axis=1))
        new = np.hypot(np.sum(weights * su, axis=1), quantised)
        flat = flat.copy()
        flat[self.pixel] = new
        return flat.reshape(out.shape).astype(np.float32)


def retime_between_isochrones(times: np.ndarray, n_frames: int, max_gap: float = MAX_GAP_PX,
                              where: np.ndarray | None = None) -> RetimedTimes:
    """The shadow-time map (H, W, frames, NaN = none) re-timed between its integer isochrones (see the module).

    ``where`` (H, W) bool: re-time only these pixels (e.g. the under-sampled
    ones, :func:`gnomon.geometry.uncertainty.undersampled`: where the edge is sampled
    by two frames or more, the tracker's own time is already right); the
    crossings are still taken from every pixel.

    The rows (oriented along the sweep here) are re-timed by the kernel
    (``_kernel.retime_rows``, rows in parallel); :func:`_retime_numpy` is the
    same in numpy, element for element (the tests' reference).
    """
    t = np.asarray(times, dtype=np.float64)
    z2 = np.zeros((0, 2))
    if t.ndim != 2 or t.size == 0:
        return RetimedTimes(t.astype(np.float32), np.zeros(t.shape, dtype=bool), np.zeros(0, dtype=np.int64),
                            z2.astype(np.int64), z2.astype(np.int64), z2, z2, np.zeros(0), np.zeros(0))
    along_rows, sense = _sweep_axis(t)
    index = np.arange(t.size).reshape(t.shape)
    if sense == 0 or (t.shape[1] if along_rows else t.shape[0]) < 2:
        return RetimedTimes(t.astype(np.float32), np.zeros(t.shape, dtype=bool), np.zeros(0, dtype=np.int64),
                            z2.astype(np.int64), z2.astype(np.int64), z2, z2, np.zeros(0), np.zeros(0))
    wanted = np.ones(t.shape, dtype=np.uint8) if where is None else np.asarray(where, dtype=np.uint8)

    def orient(a: np.ndarray) -> np.ndarray:
        a = a if along_rows else a.T
        return np.ascontiguousarray(a[:, ::-1] if sense < 0 else a)

    new, done, pixel, left, right, phase, rise, gap, f = _kernel.retime_rows(
        orient(t), orient(index), orient(wanted), int(n_frames), float(max_gap), MIN_GAP_PX, BACKSTEP)
    if sense < 0:
        new, done = new[:, ::-1], done[:, ::-1]
    if not along_rows:
        new, done = new.T, done.T
    return RetimedTimes(np.ascontiguousarray(new), np.ascontiguousarray(done), pixel, left, right, phase, rise,
                        gap, f)


def retime_with_sigma(times: np.ndarray, n_frames: int, sigma_t: np.ndarray, max_gap: float = MAX_GAP_PX,
                      where: np.ndarray | None = None, across: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(times, σ)`` (H, W) float32: ``retime_between_isochrones(...).times`` and
    ``.sigma(sigma_t)`` in one kernel pass (``_kernel.retime_rows_sigma``, rows in parallel), without
    the per-pixel details of the crossings. ``sigma_t`` (H, W) the σ (frames) of every pixel's own time.

    ``across`` > 0: the re-timed times then averaged across the sweep over ``±across`` rows
    (:func:`average_across_sweep`); their σ is left as it was (an upper bound: the rows' crossing
    errors are partly shared, by the codec's blocks and the occluder's own edge).
    """
    r = retime_rows(times, n_frames, sigma_t, max_gap, where)
    if across > 0 and r.retimed is not None:
        return average_across_sweep(r.times, r.retimed, r.along_rows, across), r.sigma
    return r.times, r.sigma


@dataclass(frozen=True)
class RowRetiming:
    """:func:`retime_rows`' result: ``times`` and ``sigma`` (H, W) float32 (frames), ``retimed`` (H, W) bool
    the pixels re-timed (None when the map has no sweep to re-time along: ``times`` are the input's),
    ``along_rows`` the sweep's axis (:func:`_sweep_axis`)."""

    times: np.ndarray
    sigma: np.ndarray
    retimed: np.ndarray | None
    along_rows: bool


def retime_rows(times: np.ndarray, n_frames: int, sigma_t: np.ndarray, max_gap: float = MAX_GAP_PX,
                where: np.ndarray | None = None) -> RowRetiming:
    """:func:`retime_with_sigma` before the averaging across the sweep, with what that averaging needs:
    a caller that wants the times both with and without it (``gnomon.reconstruct.edges``) re-times once."""
    t = np.asarray(times, dtype=np.float64)
    s = np.asarray(sigma_t, dtype=np.float64)
    if t.ndim != 2 or t.size == 0:
        return RowRetiming(t.astype(np.float32), s.astype(np.float32), None, True)
    if s.shape != t.shape:
        raise ValueError(f"sigma_t has shape {s.shape}, the times {t.shape}")
    along_rows, sense = _sweep_axis(t)
    if sense == 0 or (t.shape[1] if along_rows else t.shape[0]) < 2:
        return RowRetiming(t.astype(np.float32), s.astype(np.float32), None, along_rows)
    index = np.arange(t.size).reshape(t.shape)
    wanted = np.ones(t.shape, dtype=np.uint8) if where is None else np.asarray(where, dtype=np.uint8)

    def orient(a: np.ndarray) -> np.ndarray:
        a = a if along_rows else a.T
        return np.ascontiguousarray(a[:, ::-1] if sense < 0 else a)

    def back(a: np.ndarray) -> np.ndarray:
        a = a[:, ::-1] if sense < 0 else a
        return np.ascontiguousarray(a if along_rows else a.T)

    new, done, sigma = _kernel.retime_rows_sigma(orient(t), orient(index), orient(wanted), s.ravel(), int(n_frames),
                                                 float(max_gap), MIN_GAP_PX, BACKSTEP)
    return RowRetiming(back(new), back(sigma), back(done), along_rows)


def average_across_sweep(times: np.ndarray, retimed: np.ndarray, along_rows: bool, half: int = ACROSS_HALF_ROWS,
                         bend: float = ACROSS_BEND_FRAMES) -> np.ndarray:
    """(H, W) float32: each re-timed pixel's time averaged with re-timed pixels across the sweep.

    Along the sweep a re-timed time is interpolated between two crossings found
    in that pixel's row alone (column, for a sweep along the columns), so each
    row carries its own crossing errors: on a dim surface the map breaks into
    streaks along the sweep. The isochrones run across the sweep and are
    continuous there except at a depth edge, so the rows ``v ± d`` (``d = 1 …
    half``) estimate the same smooth time. They are taken in symmetric pairs (a
    time that changes linearly across the rows keeps its value) and only when
    both are re-timed and the pair bends by at most ``bend`` frames
    (``|t(v−d) + t(v+d) − 2 t(v)|``; a depth edge between the rows shifts the
    staircase by a frame or more). ``times`` (H, W) frames (NaN = none),
    ``retimed`` (H, W) bool; ``along_rows``: the sweep runs along the rows
    (:func:`_sweep_axis`). Pixels not re-timed keep their time.

    float32 times (the re-timed maps) are averaged by the kernel (``_kernel.average_across``, rows in
    parallel, the same f64 arithmetic); :func:`_average_across_sweep_numpy` is the definition.
    """
    if isinstance(times, np.ndarray) and times.dtype == np.float32 and times.ndim == 2 and times.size:
        done = np.ascontiguousarray(retimed, dtype=bool).view(np.uint8)
        return _kernel.average_across(np.ascontiguousarray(times), done, bool(along_rows), int(half), float(bend))
    return _average_across_sweep_numpy(times, retimed, along_rows, half, bend)


def _average_across_sweep_numpy(times: np.ndarray, retimed: np.ndarray, along_rows: bool,
                                half: int = ACROSS_HALF_ROWS, bend: float = ACROSS_BEND_FRAMES) -> np.ndarray:
    """:func:`average_across_sweep` in numpy (the kernel's ``average_across`` gives the same on float32 times)."""
    t = np.asarray(times, dtype=np.float64)
    ok = np.asarray(retimed, dtype=bool) & np.isfinite(t)
    if not along_rows:
        t, ok = t.T, ok.T
    h = t.shape[0]
    total = np.where(ok, t, 0.0)
    count = ok.astype(np.float64)
    for d in range(1, half + 1):
        if h <= 2 * d:
            break
        centre, up, down = t[d:h - d], t[:h - 2 * d], t[2 * d:]
        with np.errstate(invalid="ignore"):
            pair = (ok[d:h - d] & ok[:h - 2 * d] & ok[2 * d:]
                    & (np.abs(up + down - 2.0 * centre) <= bend))
        total[d:h - d] += np.where(pair, up + down, 0.0)
        count[d:h - d] += 2.0 * pair
    out = np.where(ok, total / np.maximum(count, 1.0), t)
    return np.ascontiguousarray((out if along_rows else out.T).astype(np.float32))


def _retime_numpy(times: np.ndarray, n_frames: int, max_gap: float = MAX_GAP_PX,
                  where: np.ndarray | None = None) -> RetimedTimes:
    """:func:`retime_between_isochrones` in numpy (the kernel's ``retime_rows`` gives the same)."""
    t = np.asarray(times, dtype=np.float64)
    empty = np.zeros(0, dtype=np.int64)

    def unchanged() -> RetimedTimes:
        z2 = np.zeros((0, 2))
        return RetimedTimes(t.astype(np.float32), np.zeros(t.shape, dtype=bool), empty, z2.astype(np.int64),
                            z2.astype(np.int64), z2, z2, np.zeros(0), np.zeros(0))

    if t.ndim != 2 or t.size == 0:
        return unchanged()
    along_rows, sense = _sweep_axis(t)
    if sense == 0:
        return unchanged()
    # Work along rows, with times increasing to the right; ``index`` keeps each pixel's flat index in the image.
    index = np.arange(t.size).reshape(t.shape)
    m, index = (t, index) if along_rows else (t.T, index.T)
    if sense < 0:
        m, index = m[:, ::-1], index[:, ::-1]
    h, w = m.shape
    if w < 2:
        return unchanged()
    a, b = m[:, :-1], m[:, 1:]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(a) & np.isfinite(b) & (b >= a - BACKSTEP)
    # Run ids: a new run at each row start and after each pair that is not ok.
    start = np.ones((h, w), dtype=np.int64)
    start[:, 1:] = ~ok
    run = np.cumsum(start.ravel()).reshape(h, w)
    # Crossings: pair (j, j+1) of a run owns the integer frames k with a < k ≤ b, at u = j + (k − a)/(b − a).
    rise = ok & (b > a)
    lo = np.where(rise, np.floor(a) + 1, 0).astype(np.int64)
    hi = np.where(rise, np.floor(b), -1).astype(np.int64)
    count = np.where(rise, np.maximum(hi - lo + 1, 0), 0)
    rows, cols = np.nonzero(count)
    if rows.size == 0:
        return unchanged()
    reps = count[rows, cols]
    rows, cols = np.repeat(rows, reps), np.repeat(cols, reps)
    k = lo[rows, cols] + (np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps))
    ta, tb = a[rows, cols], b[rows, cols]
    phase = (k - ta) / (tb - ta)
    u = cols + phase
    stride = n_frames + 2
    key = run[rows, cols] * stride + np.clip(k, -1, n_frames) + 1
    order = np.argsort(key, kind="stable")
    key, u, phase = key[order], u[order], phase[order]
    c_left, c_right, c_rise = index[rows, cols][order], index[rows, cols + 1][order], (tb - ta)[order]
    # Every finite pixel that is not on an integer frame: look up its run's crossings of ⌊t⌋ and ⌊t⌋ + 1.
    wanted = np.isfinite(m)
    if where is not None:
        wm = np.asarray(where, dtype=bool)
        wm = wm if along_rows else wm.T
        wanted &= wm[:, ::-1] if sense < 0 else wm
    pr, pc = np.nonzero(wanted)
    tp = m[pr, pc]
    kf = np.floor(tp)
    inner = tp > kf
    pr, pc, kf = pr[inner], pc[inner], kf[inner].astype(np.int64)
    rid = run[pr, pc]
    k0 = rid * stride + np.clip(kf, -1, n_frames) + 1
    k1 = rid * stride + np.clip(kf + 1, -1, n_frames) + 1
    i0 = np.clip(np.searchsorted(key, k0), 0, len(key) - 1)
    i1 = np.clip(np.searchsorted(key, k1), 0, len(key) - 1)
    have = (key[i0] == k0) & (key[i1] == k1)
    u0, u1 = u[i0], u[i1]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = (pc - u0) / (u1 - u0)
        good = have & (u1 - u0 >= MIN_GAP_PX) & (u1 - u0 <= max_gap) & (frac >= 0) & (frac <= 1)
    new = m.astype(np.float32, copy=True)
    new[pr[good], pc[good]] = (kf[good] + frac[good]).astype(np.float32)
    done = np.zeros(m.shape, dtype=bool)
    done[pr[good], pc[good]] = True
    if sense < 0:
        new, done = new[:, ::-1], done[:, ::-1]
    if not along_rows:
        new, done = new.T, done.T
    j0, j1 = i0[good], i1[good]
    return RetimedTimes(np.ascontiguousarray(new), np.ascontiguousarray(done), index[pr[good], pc[good]],
                        np.stack([c_left[j0], c_left[j1]], axis=1), np.stack([c_right[j0], c_right[j1]], axis=1),
                        np.stack([phase[j0], phase[j1]], axis=1), np.stack([c_rise[j0], c_rise[j1]], axis=1),
                        (u1 - u0)[good], frac[good])
