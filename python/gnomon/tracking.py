"""Per-pixel shadow times from a stream of grey frames (METHOD.md §3).

For every pixel, over the whole sequence: the brightest and darkest value
(``imax``, ``imin``, in DN of the input), the contrast ``imax − imin`` (DN),
the threshold at mid-level in *linear irradiance*
``(L(imax) + L(imin)) / 2`` where ``L`` decodes DN to irradiance (see
:func:`decoding_lut`), and two shadow times in frames (frame ``i`` is time
``i``) at sub-frame precision:

* ``enter``: the intensity falls through the threshold,
* ``leave``: it rises back through it.

How: per pixel, the frame ``j`` of the steepest fall (largest
``I[j-1] − I[j] > 0``, first occurrence) and of the steepest rise are kept with
the ``2m`` raw samples of frames ``j−m … j+m−1`` around each (clamped to the
sequence); at the end the threshold crossing nearest the window centre is
interpolated linearly between the two decoded samples around it:
``t = k + (v_k − thr) / (v_k − v_{k+1})``. The slope ``|v_k − v_{k+1}|``
(linear units per frame) at the crossing is kept for the noise model
``σ_t = σ_I / slope``.

The work is done by the Rust kernel (:class:`gnomon._kernel.TemporalTracker`,
streaming, memory independent of the number of frames). :class:`NumpyTracker`
is the same algorithm in numpy, frame by frame: the tests cross-check the two
and ``gnomon bench`` uses it as the baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Callable, Iterable, Mapping

import numpy as np

from gnomon import _kernel
from gnomon.errors import FrameError

SUPPORTED_DTYPES = (np.dtype(np.uint8), np.dtype(np.uint16))


@dataclass
class ShadowTimes:
    """The tracker's per-pixel results; every array is (H, W).

    ``imax``, ``imin``, ``contrast``: float32, DN of the input.
    ``threshold``: float32, linear irradiance units of the decoding LUT.
    ``enter``, ``leave``: float32 shadow times in frames, NaN = no crossing or
    invalid pixel. ``enter_slope``, ``leave_slope``: float32
    ``|ΔL|`` per frame at the crossing (linear units), NaN likewise.
    ``valid``: bool, ``contrast ≥ min_contrast``.
    """

    imax: np.ndarray
    imin: np.ndarray
    contrast: np.ndarray
    threshold: np.ndarray
    enter: np.ndarray
    leave: np.ndarray
    enter_slope: np.ndarray
    leave_slope: np.ndarray
    valid: np.ndarray

    @classmethod
    def from_kernel(cls, result: Mapping[str, np.ndarray]) -> "ShadowTimes":
        """Wrap the dict returned by ``TemporalTracker.finish`` (or :meth:`NumpyTracker.finish`)."""
        return cls(**{f.name: np.asarray(result[f.name]) for f in fields(cls)})

    @property
    def shape(self) -> tuple[int, int]:
        return self.enter.shape  # type: ignore[return-value]


def _check_dtype(dtype) -> np.dtype:
    dt = np.dtype(dtype)
    if dt not in SUPPORTED_DTYPES:
        raise ValueError(f"dtype: expected uint8 or uint16, got {dt}")
    return dt


def decoding_lut(gamma: float | str, dtype) -> np.ndarray:
    """Table mapping each DN of ``dtype`` (uint8: 256 entries, uint16: 65536)
    to linear irradiance in [0, 1], float32.

    ``gamma``: a positive number for a power law ``L = (DN / DNmax) ** gamma``
    (1.0 = linear data), or ``"srgb"`` for the IEC 61966-2-1 transfer curve.
    """
    dt = _check_dtype(dtype)
    top = np.iinfo(dt).max
    x = np.arange(top + 1, dtype=np.float64) / top
    if isinstance(gamma, str):
        if gamma.lower() != "srgb":
            raise ValueError(f"gamma: expected a positive number or 'srgb', got {gamma!r}")
        linear = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    else:
        g = float(gamma)
        if not (np.isfinite(g) and g > 0):
            raise ValueError(f"gamma: expected a positive number or 'srgb', got {gamma!r}")
        linear = x**g
    return linear.astype(np.float32)


def track(
    frames: Iterable[np.ndarray],
    *,
    min_contrast: float,
    gamma: float | str,
    window: int = 4,
    progress: Callable[[int], None] | None = None,
) -> ShadowTimes:
    """Track a sequence of grey frames with the kernel and return the shadow times.

    ``frames``: 2-D uint8 or uint16 arrays, all of the first one's shape and
    dtype. ``min_contrast`` in DN; ``gamma`` as in :func:`decoding_lut`;
    ``window`` the half-width ``m`` of the kept windows. ``progress(i)`` is
    called after frame ``i`` (0-based) has been fed.

    Raises :class:`gnomon.errors.FrameError` for a frame of another shape or
    dtype (naming it), or when there is no frame at all.
    """
    tracker = None
    dtype = None
    for i, frame in enumerate(frames):
        frame = np.asarray(frame)
        if tracker is None:
            if frame.ndim != 2 or frame.dtype not in SUPPORTED_DTYPES:
                raise FrameError(
                    f"frame 0: expected a 2-D uint8 or uint16 grey image, "
                    f"got a {frame.dtype} array of shape {frame.shape}"
                )
            dtype = frame.dtype
            tracker = _kernel.TemporalTracker(
                frame.shape[0], frame.shape[1], dtype=dtype.name, window=window
            )
        try:
            tracker.update(frame)
        except ValueError as exc:
            raise FrameError(f"frame {i}: {exc}") from None
        if progress is not None:
            progress(i)
    if tracker is None:
        raise FrameError("no frames to track")
    lut = decoding_lut(gamma, dtype)
    return ShadowTimes.from_kernel(tracker.finish(float(min_contrast), lut))


@dataclass
class _State:
    """NumpyTracker's folded state: frames ``0 … next_j − 1`` of the steepest
    steps (statistics ``imax``/``imin`` cover every frame seen)."""

    best_fall: np.ndarray  # (H*W,) wide int, max(0, steepest fall)
    best_rise: np.ndarray
    fall_at: np.ndarray  # (H*W,) int64 frame of the steepest fall, -1 = none
    rise_at: np.ndarray
    fall_window: np.ndarray  # (H*W, 2m) raw samples around fall_at
    rise_window: np.ndarray
    next_j: int
    prev: np.ndarray | None  # frame next_j − 1, widened (cache)

    def copy(self) -> "_State":
        return _State(
            self.best_fall.copy(),
            self.best_rise.copy(),
            self.fall_at.copy(),
            self.rise_at.copy(),
            self.fall_window.copy(),
            self.rise_window.copy(),
            self.next_j,
            self.prev,
        )


class NumpyTracker:
    """The kernel tracker's algorithm, vectorised with numpy frame by frame.

    Same constructor, ``update``, ``frames_seen`` and ``finish`` as
    :class:`gnomon._kernel.TemporalTracker` and the same results. The steepest
    steps are updated ``m`` frames late, from a ring of the last ``2m + 1``
    frames, so each new best's window (frames ``j−m … j+m−1``) is complete
    when it is captured; ``finish`` processes the last ``m`` frames on a copy
    of the state, clamping the windows to the last frame.
    """

    def __init__(self, height: int, width: int, dtype: str = "uint8", window: int = 4):
        self._dtype = _check_dtype(dtype)
        if window < 1:
            raise ValueError(f"window: must be ≥ 1, got {window}")
        self._shape = (int(height), int(width))
        self._m = int(window)
        self._wide = np.int16 if self._dtype == np.uint8 else np.int32
        n = self._shape[0] * self._shape[1]
        self._ring = np.zeros((2 * self._m + 1, n), self._dtype)
        self._imax = np.zeros(n, self._dtype)
        self._imin = np.full(n, np.iinfo(self._dtype).max, self._dtype)
        self._state = _State(
            np.zeros(n, self._wide),
            np.zeros(n, self._wide),
            np.full(n, -1, np.int64),
            np.full(n, -1, np.int64),
            np.zeros((n, 2 * self._m), self._dtype),
            np.zeros((n, 2 * self._m), self._dtype),
            0,
            None,
        )
        self.frames_seen = 0

    def update(self, frame: np.ndarray) -> None:
        """Add the next frame: a 2-D array of the tracker's dtype and shape."""
        frame = np.asarray(frame)
        if frame.dtype != self._dtype or frame.shape != self._shape:
            raise ValueError(
                f"frame: expected a {self._dtype} array of shape {self._shape}, "
                f"got a {frame.dtype} array of shape {frame.shape}"
            )
        flat = frame.reshape(-1)
        self._ring[self.frames_seen % len(self._ring)] = flat
        np.maximum(self._imax, flat, out=self._imax)
        np.minimum(self._imin, flat, out=self._imin)
        self.frames_seen += 1
        # Frame j = F − 1 − m: its window reaches frame F − 2 ≤ last.
        while self._state.next_j <= self.frames_seen - 1 - self._m:
            self._step(self._state, self.frames_seen - 1)

    def _step(self, s: _State, last: int) -> None:
        """Fold the step into frame ``s.next_j`` (windows clamped to ``last``)."""
        j = s.next_j
        ring = self._ring
        cur = ring[j % len(ring)].astype(self._wide)
        if j > 0:
            prev = s.prev if s.prev is not None else ring[(j - 1) % len(ring)].astype(self._wide)
            fall = prev - cur
            self._fold(j, last, s.best_fall, s.fall_at, s.fall_window, fall)
            rise = np.negative(fall, out=fall)
            self._fold(j, last, s.best_rise, s.rise_at, s.rise_window, rise)
        s.prev = cur
        s.next_j = j + 1

    def _fold(self, j, last, best, at, window, step) -> None:
        """Where ``step`` beats ``best`` strictly: new best at frame ``j``, window captured."""
        steeper = np.flatnonzero(step > best)
        if steeper.size:
            best[steeper] = step[steeper]
            at[steeper] = j
            frames = np.clip(np.arange(j - self._m, j + self._m), 0, last) % len(self._ring)
            window[steeper] = self._ring[frames[:, None], steeper[None, :]].T

    def finish(self, min_contrast: float, lut: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-pixel results for the frames seen so far, as the kernel's ``finish``."""
        if self.frames_seen == 0:
            raise ValueError("no frames were given to the tracker")
        top = np.iinfo(self._dtype).max
        if lut is None:
            lut = np.arange(top + 1, dtype=np.float32)
        lut = np.asarray(lut)
        if lut.dtype != np.float32 or lut.shape != (top + 1,):
            raise ValueError(
                f"lut: expected a float32 array of shape ({top + 1},), "
                f"got a {lut.dtype} array of shape {lut.shape}"
            )
        if not np.all(np.isfinite(lut)) or np.any(np.diff(lut) < 0):
            raise ValueError("invalid decoding LUT: must be finite and non-decreasing")
        s = self._state.copy()
        last = self.frames_seen - 1
        while s.next_j <= last:
            self._step(s, last)

        imax, imin = self._imax, self._imin
        contrast = imax.astype(np.float32) - imin.astype(np.float32)
        threshold = (lut[imax] + lut[imin]) * np.float32(0.5)
        valid = contrast >= np.float32(min_contrast)
        enter, enter_slope = self._solve(s.fall_at, s.fall_window, threshold, valid, lut, True)
        leave, leave_slope = self._solve(s.rise_at, s.rise_window, threshold, valid, lut, False)
        image = lambda a: a.reshape(self._shape)  # noqa: E731
        return {
            "imax": image(imax.astype(np.float32)),
            "imin": image(imin.astype(np.float32)),
            "contrast": image(contrast),
            "threshold": image(threshold),
            "enter": image(enter),
            "leave": image(leave),
            "enter_slope": image(enter_slope),
            "leave_slope": image(leave_slope),
            "valid": image(valid),
        }

    def _solve(self, at, window, threshold, valid, lut, falling: bool):
        """Crossing nearest the window centre: time (frames) and slope, NaN if none."""
        n = at.shape[0]
        time = np.full(n, np.nan, np.float32)
        slope = np.full(n, np.nan, np.float32)
        idx = np.flatnonzero(valid & (at >= 0))
        if idx.size == 0:
            return time, slope
        v = lut[window[idx]]  # (n, 2m) float32
        thr = threshold[idx][:, None]
        a, b = v[:, :-1], v[:, 1:]
        cross = (a >= thr) & (thr > b) if falling else (a < thr) & (thr <= b)
        centre = self._m - 1
        order = [centre]
        for d in range(1, self._m):
            order += [centre - d, centre + d]
        ordered = cross[:, order]
        found = ordered.any(axis=1)
        k = np.asarray(order)[ordered.argmax(axis=1)][found]
        rows = np.flatnonzero(found)
        a_k, b_k, t_k = a[rows, k], b[rows, k], thr[rows, 0]
        fraction = (a_k - t_k) / (a_k - b_k)
        frame = at[idx][found] - self._m + k
        time[idx[found]] = (frame.astype(np.float64) + fraction.astype(np.float64)).astype(np.float32)
        slope[idx[found]] = np.abs(a_k - b_k)
        return time, slope
