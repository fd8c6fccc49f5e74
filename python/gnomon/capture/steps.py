"""Per-pixel shadow *steps*: a pixel that goes into shadow (or out of it) once and stays.

The kernel tracker (:mod:`gnomon.capture.tracking`) finds each pixel's deepest *dip*: dark samples with
lit ones on both sides within the dip width ``W``. A straight edge of a building under the sun (a roof
line) casts a shadow whose boundary moves monotonically over the day: a pixel it passes falls into
shadow and stays there (or comes out of it for good) — a *step*, which has no lit samples on its far
side and so no depth as a dip. :class:`StepTracker` finds, per pixel, the strongest lasting step in
each direction, streaming, with memory ``O(pixels · W)`` independent of the number of frames.

Definitions, in the tracker's linear irradiance ``v_i`` of frame ``i`` (the decoded sample, divided by
the frame's global gain; a frame of a cloud dip by its own measured gain, not the kernel's per-pixel levels):

* the step at ``k`` (between frames ``k − 1`` and ``k``) has the means ``a_k`` of the ``W`` frames before
  (``k − W … k − 1``) and ``b_k`` of the ``W`` frames from ``k`` on (``k … k + W − 1``), both clamped to the
  sequence with at least ``MIN_SIDE`` frames each; its strength is ``a_k − b_k`` into the shadow
  (*entering*), ``b_k − a_k`` out of it (*leaving*). A dip of ``w`` frames shifts a mean by at most
  ``w/W`` of its depth; a transition spread over a few frames (the sun's penumbra) still is a step, at
  its centre. A step is kept only where it is ``STEP_SPREADS`` times the scatter of the samples about
  their side's mean: a passing shadow (a pole's, a cloud's) inside one side's frames scatters them;
* steps are folded in time order, per direction, as the kernel folds dips: a candidate within ``W``
  frames after the best belongs to it, a farther one counts for another event, whose strength is the
  direction's ``rival``; a direction is *ambiguous* when ``rival ≥ ambiguity · strength``;
* the step's levels are the two means at its best ``k`` (lit and shadowed), its threshold their
  mid-level, and its time the crossing of that threshold nearest the centre of the ``2m`` samples
  ``k − m … k + m − 1`` kept when the best moved, interpolated linearly between the two samples around
  it, ``t = j + (v_j − thr) / (v_j − v_{j+1})`` (as the kernel's crossings); the slope
  ``|v_j − v_{j+1}|`` is kept for the time's σ.

The result is reported in the kernel's units (:class:`gnomon.capture.tracking.ShadowTimes`): ``enter``
the entering step's time, ``leave`` the leaving step's, each only where that step is at least the
contrast floor deep and not ambiguous — the two are independent events, not the two sides of one dip;
``imax``/``imin``/``contrast`` the stronger valid step's levels in DN of the input, in the light of its
frame (the gain carried back), ``threshold`` and slopes in linear units in the same light.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_SIDE", "STEP_SPREADS", "StepTracker"]

#: The fewest frames either side of a step (at the sequence's ends the means are over fewer than W).
MIN_SIDE = 8
#: A step is at least this many times the scatter of the samples about its two sides' means (pooled): a dip
#: of w frames inside one side's W frames makes a "step" of only sqrt(2·(w/W)/(1 − w/W)) times it (1.4 for
#: a dip of W/2), a sharp step none; the sun's penumbra spread over p frames leaves about 9 at p = W/4.
STEP_SPREADS = 5.0


class _Direction:
    """The best step of one direction so far, per pixel (see the module docstring)."""

    def __init__(self, shape: tuple[int, int], half: int):
        self.best = np.zeros(shape, np.float32)
        self.at = np.full(shape, -(10**9), np.int64)
        self.rival = np.zeros(shape, np.float32)
        self.before = np.zeros(shape, np.float32)  # the mean of the frames before the step
        self.after = np.zeros(shape, np.float32)  # the mean of the frames from the step on
        self.spread = np.zeros(shape, np.float32)  # the scatter of the samples about the two means
        self.samples = np.zeros((2 * half,) + shape, np.float32)  # v[k − m … k + m − 1] at the best k

    def fold(self, k: int, strength: np.ndarray, before: np.ndarray, after: np.ndarray, spread: np.ndarray,
             width: int, ring: np.ndarray, slots: np.ndarray) -> None:
        """Candidate ``k`` of this direction's strength; ``ring[slots]`` the frames ``k − m … k + m − 1``."""
        far = (k - self.at) > width
        better = strength > self.best
        self.rival = np.where(far & better, np.maximum(self.rival, self.best), self.rival)
        self.rival = np.where(far & ~better, np.maximum(self.rival, strength), self.rival)
        if not better.any():
            return
        idx = np.nonzero(better)
        self.best[idx] = strength[idx]
        self.at[idx] = k
        self.before[idx] = before[idx]
        self.after[idx] = after[idx]
        self.spread[idx] = spread[idx]
        self.samples[:, idx[0], idx[1]] = ring[slots[:, None], idx[0][None, :], idx[1][None, :]]


class StepTracker:
    """Streaming per-pixel step finder over the frames the kernel tracker sees (see the module docstring).

    ``shape`` (H, W) of the tracked frames; ``lut`` the capture's decoding table (DN → linear);
    ``width`` ``W`` (frames); ``half`` ``m`` (the kept samples either side); ``ambiguity`` as the kernel's.
    """

    def __init__(self, shape: tuple[int, int], lut: np.ndarray, width: int, half: int, ambiguity: float):
        if width < MIN_SIDE or not 1 <= half <= MIN_SIDE:
            raise ValueError(f"StepTracker: width {width} must be ≥ {MIN_SIDE}, half {half} in 1..{MIN_SIDE}")
        self.shape, self.lut = shape, np.asarray(lut, np.float32)
        self.width, self.half, self.ambiguity = int(width), int(half), float(ambiguity)
        self.slots = 2 * self.width + 1
        self.ring = np.zeros((self.slots,) + shape, np.float32)
        self.right = np.zeros(shape, np.float64)  # Σ v over the W frames from the candidate on (clamped)
        self.left = np.zeros(shape, np.float64)  # Σ v over the W frames before it (clamped)
        self.right2 = np.zeros(shape, np.float64)  # and Σ v² over each
        self.left2 = np.zeros(shape, np.float64)
        self.gains: list[float] = []
        self.frames = 0
        self.enter = _Direction(shape, self.half)
        self.leave = _Direction(shape, self.half)
        self._ended = False

    def update(self, grey: np.ndarray, gain: float | None = None) -> None:
        """One tracked frame (DN of the input) and its global gain (a frame of a cloud dip: its own measured
        gain, not the kernel's per-pixel levels, which are fitted for a thin passing shadow and would move a
        step made under the cloud)."""
        if self._ended:
            raise RuntimeError("StepTracker: no frame may follow finish()")
        v = self.lut[grey]
        g = 1.0 if gain is None else float(gain)
        f = self.frames
        self.ring[f % self.slots] = v / g
        self.gains.append(g)
        self.frames += 1
        self._add_right(self.ring[f % self.slots], 1.0)
        if f >= self.width:
            self._add_right(self.ring[(f - self.width) % self.slots], -1.0)
        self._advance(f - self.width + 1, self.width)

    def _advance(self, k: int, n_after: int) -> None:
        """Candidate ``k`` (its later side ``n_after`` frames long): bring the left sums to it, and evaluate it
        when both sides are long enough."""
        if k < 1:
            return
        v = self.ring[(k - 1) % self.slots].astype(np.float64)
        self.left += v
        self.left2 += v * v
        if k - 1 - self.width >= 0:
            v = self.ring[(k - 1 - self.width) % self.slots].astype(np.float64)
            self.left -= v
            self.left2 -= v * v
        n_before = min(k, self.width)
        if n_before < MIN_SIDE or n_after < MIN_SIDE:
            return
        before, after = self.left / n_before, self.right / n_after
        # the samples' scatter about their side's mean, both sides pooled
        var = (np.maximum(self.left2 / n_before - before**2, 0.0)
               + np.maximum(self.right2 / n_after - after**2, 0.0)) / 2
        spread = np.sqrt(var).astype(np.float32)
        before, after = before.astype(np.float32), after.astype(np.float32)
        m = self.half
        slots = np.arange(k - m, k + m) % self.slots
        self.enter.fold(k, before - after, before, after, spread, self.width, self.ring, slots)
        self.leave.fold(k, after - before, before, after, spread, self.width, self.ring, slots)

    def _add_right(self, v: np.ndarray, sign: float) -> None:
        v64 = v.astype(np.float64)
        self.right += sign * v64
        self.right2 += sign * v64 * v64

    def finish(self, min_contrast_dn: float) -> dict[str, np.ndarray]:
        """The steps as :class:`~gnomon.capture.tracking.ShadowTimes`'s fields (a dict of (H, W) arrays);
        the candidates whose later side the sequence's end shortens are evaluated here (once: no frame
        may follow)."""
        n = self.frames
        if not self._ended:
            self._ended = True
            for k in range(max(n - self.width + 1, 1), n - MIN_SIDE + 1):
                if k - 1 >= n - self.width:  # the frame k − 1 leaves the later side
                    self._add_right(self.ring[(k - 1) % self.slots], -1.0)
                self._advance(k, n - k)
        top = len(self.lut) - 1
        lut64 = self.lut.astype(np.float64)
        gains = np.asarray(self.gains, np.float64)
        out: dict[str, dict[str, np.ndarray]] = {}
        for name, d, falling in (("enter", self.enter, True), ("leave", self.leave, False)):
            found = d.at >= 0
            at = np.clip(d.at, 0, max(n - 1, 0))
            g = gains[at] if n else np.ones(self.shape)
            lit = np.where(falling, d.before, d.after).astype(np.float64)
            dark = np.where(falling, d.after, d.before).astype(np.float64)
            thr = 0.5 * (lit + dark)
            time, slope = _crossing(d.samples, thr, d.at - self.half, falling)
            # levels in DN of the input, in the light of the step's frame
            hi = np.interp(lit * g, lut64, np.arange(top + 1.0))
            lo = np.interp(dark * g, lut64, np.arange(top + 1.0))
            contrast = hi - lo
            ambiguous = found & (d.rival >= self.ambiguity * d.best) & (contrast >= min_contrast_dn)
            steady = d.best >= STEP_SPREADS * d.spread  # a step, not a dip inside one side's frames
            valid = found & (contrast >= min_contrast_dn) & ~ambiguous & np.isfinite(time) & (d.best > 0) & steady
            clipped = (hi <= 0) | (hi >= top) | (lo <= 0)
            out[name] = {"time": np.where(valid, time, np.nan), "slope": np.where(valid, slope * g, np.nan),
                         "hi": hi, "lo": lo, "contrast": np.where(found, contrast, 0.0),
                         "thr": thr * g, "valid": valid, "ambiguous": ambiguous & ~valid, "clipped": clipped,
                         "rival": np.where(d.best > 0, d.rival / np.maximum(d.best, 1e-12), 0.0) * contrast}
        e, lv = out["enter"], out["leave"]
        # the levels of the stronger valid step (either, where neither is valid)
        use_e = np.where(e["valid"] == lv["valid"], e["contrast"] >= lv["contrast"], e["valid"])

        def pick(key: str) -> np.ndarray:
            return np.where(use_e, e[key], lv[key])

        valid = e["valid"] | lv["valid"]
        f32 = np.float32
        return {
            "imax": pick("hi").astype(f32), "imin": pick("lo").astype(f32),
            "contrast": pick("contrast").astype(f32), "threshold": pick("thr").astype(f32),
            "enter": e["time"].astype(f32), "leave": lv["time"].astype(f32),
            "enter_slope": e["slope"].astype(f32), "leave_slope": lv["slope"].astype(f32),
            "rival": pick("rival").astype(f32), "valid": valid,
            "ambiguous": (e["ambiguous"] | lv["ambiguous"]) & ~valid, "clipped": pick("clipped") & valid,
        }


def _crossing(samples: np.ndarray, thr: np.ndarray, first: np.ndarray,
              falling: bool) -> tuple[np.ndarray, np.ndarray]:
    """The crossing of ``thr`` nearest the centre of each pixel's ``2m`` samples (frames ``first …``),
    falling or rising, interpolated linearly: (time in frames, |Δv| per frame); NaN where none."""
    two_m = samples.shape[0]
    centre = two_m / 2 - 1  # the crossing between samples m − 1 and m sits at the window's centre
    time = np.full(thr.shape, np.nan)
    slope = np.full(thr.shape, np.nan)
    best = np.full(thr.shape, np.inf)
    s = samples.astype(np.float64)
    for j in range(two_m - 1):
        a, b = s[j], s[j + 1]
        hit = (a >= thr) & (b < thr) if falling else (a < thr) & (b >= thr)
        near = np.abs(j - centre)
        take = hit & (near < best)
        if take.any():
            with np.errstate(invalid="ignore", divide="ignore"):
                t = first + j + (a - thr) / (a - b)
            time = np.where(take, t, time)
            slope = np.where(take, np.abs(a - b), slope)
            best = np.where(take, near, best)
    return time, slope
