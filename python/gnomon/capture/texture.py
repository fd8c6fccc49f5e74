"""The scan's colours: per pixel, the median of a few frames in which that pixel is lit.

The first frame is not a good colour image: in a sun scan with a fixed pole it
already holds the pole's shadow, and in a desk scan the stick or the hand may
be in it. :class:`LitColour` keeps ``samples`` frames spread evenly over the
capture while the tracker streams them (a handful of frame copies, nothing
per frame otherwise), and once each pixel's shadow interval is known takes,
per pixel and channel, the median of the kept frames in which the pixel is
outside its shadow. A pixel in shadow in every kept frame (or never swept)
takes the median of all of them.
"""

from __future__ import annotations

import numpy as np

from gnomon import _kernel

__all__ = ["LitColour", "sample_indices"]


def sample_indices(eligible: np.ndarray, samples: int) -> np.ndarray:
    """``samples`` capture indices spread evenly over the ``eligible`` ones (sorted, unique)."""
    idx = np.asarray(eligible, dtype=np.int64)
    if len(idx) == 0:
        return idx
    picks = np.unique(np.rint(np.linspace(0, len(idx) - 1, min(samples, len(idx)))).astype(np.int64))
    return idx[picks]


class LitColour:
    """Colour frames kept during tracking, combined once the shadow times are known.

    ``indices`` the capture frames to keep (see :func:`sample_indices`).
    Feed every frame to :meth:`add` (only the chosen ones are copied), then
    call :meth:`finish`.
    """

    def __init__(self, indices: np.ndarray):
        self.indices = np.asarray(indices, dtype=np.int64)
        self._wanted = set(int(i) for i in self.indices)
        self._frames: dict[int, np.ndarray] = {}

    def wants(self, index: int) -> bool:
        return int(index) in self._wanted

    def add(self, index: int, image: np.ndarray) -> None:
        """Frame ``index``: (H, W, 3) RGB or (H, W) grey, uint8 or uint16; kept if chosen."""
        if self.wants(index):
            self._frames[int(index)] = np.array(image, copy=True)

    def finish(self, shadow_start: np.ndarray, shadow_end: np.ndarray, margin: float = 1.0, *,
               kernel: bool = True) -> np.ndarray:
        """(H, W, 3) uint8 RGB: per pixel the median of the kept frames it is lit in.

        The kernel takes the medians (``_kernel.lit_median``); ``kernel=False`` takes them in numpy (the
        definition, the tests' reference).

        ``shadow_start``/``shadow_end`` (H, W) the capture frames (sub-frame)
        when the pixel enters and leaves the shadow, NaN = unknown; a kept
        frame within ``margin`` frames of the interval counts as shadowed. With
        only one of the two times known, the frames within ``margin`` of it
        count as shadowed.
        """
        if not self._frames:
            raise ValueError("no colour frame was kept")
        keys = sorted(self._frames)
        stack = np.stack([self._frames[k] for k in keys])  # (K, H, W[, 3])
        if stack.ndim == 3 and kernel:  # grey: each pixel's median once, as the three equal channels' medians
            grey = self._lit_median_kernel(stack[..., None], keys, shadow_start, shadow_end, margin)
            return np.repeat(grey, 3, axis=2)
        if stack.ndim == 3:
            stack = np.repeat(stack[..., None], 3, axis=3)
        if kernel:
            return self._lit_median_kernel(stack, keys, shadow_start, shadow_end, margin)
        lit = self._lit(keys, shadow_start, shadow_end, margin)
        stack = self._u8(stack)
        lit[:, ~lit.any(axis=0)] = True  # shadowed in every kept frame: use them all
        n = lit.sum(axis=0)  # (H, W), ≥ 1
        # Median of the lit samples: shadowed ones sort last, take the middle of the first n.
        values = np.where(lit[..., None], stack.astype(np.int16), 256)
        values.sort(axis=0)
        lo = ((n - 1) // 2)[None, ..., None]
        hi = (n // 2)[None, ..., None]
        a = np.take_along_axis(values, np.broadcast_to(lo, (1,) + values.shape[1:]), axis=0)[0]
        b = np.take_along_axis(values, np.broadcast_to(hi, (1,) + values.shape[1:]), axis=0)[0]
        return ((a + b + 1) // 2).astype(np.uint8)

    def _lit_median_kernel(self, stack: np.ndarray, keys: list[int], shadow_start: np.ndarray,
                           shadow_end: np.ndarray, margin: float) -> np.ndarray:
        """(H, W, C) uint8: :meth:`finish`'s medians of a (K, H, W, C) stack, C 1 or 3, in the kernel (each pixel's
        lit frames there too, as :meth:`_lit` finds them)."""
        return _kernel.lit_median_between(np.ascontiguousarray(self._u8(stack)), np.asarray(keys, dtype=np.float64),
                                          np.ascontiguousarray(shadow_start, dtype=np.float64),
                                          np.ascontiguousarray(shadow_end, dtype=np.float64), float(margin))

    @staticmethod
    def _u8(stack: np.ndarray) -> np.ndarray:
        """The samples as uint8 (uint16 by their high byte)."""
        if stack.dtype == np.uint16:
            stack = (stack >> 8).astype(np.uint8)
        return stack.astype(np.uint8, copy=False)

    @staticmethod
    def _lit(keys: list[int], shadow_start: np.ndarray, shadow_end: np.ndarray, margin: float) -> np.ndarray:
        """(K, H, W) bool: whether each pixel is lit in each kept frame (see :meth:`finish`)."""
        start = np.asarray(shadow_start, dtype=np.float64)
        end = np.asarray(shadow_end, dtype=np.float64)
        start, end = np.where(np.isnan(start), end, start), np.where(np.isnan(end), start, end)
        t = np.asarray(keys, dtype=np.float64)[:, None, None]
        with np.errstate(invalid="ignore"):
            shadowed = (t >= np.minimum(start, end) - margin) & (t <= np.maximum(start, end) + margin)
        return ~shadowed
