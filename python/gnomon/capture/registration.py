"""Frame registration: each frame's motion against the reference frame, measured and undone.

A camera on a tripod for hours moves by a pixel or two (the tripod settles, warms up, is touched),
and a pixel then no longer sees one point: its shadow time mixes its neighbours'. With
``[capture] register`` a scan registers every frame it tracks against its reference frame
(:func:`reference_frame`: the first frame lit like most of the capture, so not dawn's; the scan's
pixel grid is its grid):

* **Where.** Small patches (``PATCH_PX`` square) of the reference where the image is textured in
  both directions (the smaller eigenvalue of the structure tensor over the patch, the best
  ``PER_CELL`` per cell of a ``GRID`` over the image): a few hundred patches, a few per cent of the
  pixels, most of them holding one edge between two surfaces.
* **What.** One translation ``m`` (pixels, x right and y down; a point at ``p`` in the reference is
  at ``p + m`` in the frame), and for every patch its own gain and offset (the light changes: the
  sun, clouds, the exposure): frame ≈ ``a·R(x − m) + b`` patch by patch, both images smoothed by a
  Gaussian (σ ``SMOOTH_PX``), the frame read at whole pixels, the reference interpolated at ``x − m``
  by Keys' cubic with its exact derivative. Gauss–Newton with the gain and offset eliminated per
  patch, from the previous frame's motion.
* **What does not change.** Each iteration weighs a pixel by Tukey's biweight of its residual, cut
  at ``TUKEY`` times the noise's scale read from the smaller residuals (their ``SCALE_PERCENTILE``-th
  percentile: the changed pixels are the tail, and a median would follow them once most patches hold
  some change); a patch with more than ``MAX_OUTLIER_SHARE`` of its pixels cut is left out whole.
  So the sweeping shadow, the shadows turning with the sun inside the window recesses, the pole's
  shading and a cloud's uneven dimming carry no weight. When the iterations from the previous
  motion do not converge on enough patches (a sudden shift, a cloud), they start again with the
  cut annealed from 4× its width, then from a phase correlation of the whole frame (high-passed,
  4× smaller) against the reference.
* **How well.** ``sigma_px``: the noise's σ of the motion (the residuals through the normal
  equations), scaled up by how much more the patches' own shifts disagree than their noise allows
  (a reduced χ² between patches). ``non_translation_px``: what a translation leaves of the motion,
  the largest distance at the image's corners between it and a linearised homography (8
  parameters: a rotation, a zoom, a shear, a pan's perspective) fitted the same way, every
  ``FIELD_EVERY`` frames and whenever the motion moved on by ``FIELD_MOVE_PX``: the median of the last
  ``FIELD_RUNS`` such measurements.

Measured on the simulated facade (``benchmarks/camera_drift.py``; 2 px of drift and a 1 px knock):
the motion per frame within 0.026 px of the truth at 800×600 and 0.023 px at 400×300; with a still
camera it reads at most 0.036 px. Measuring costs 5–8 ms of CPU per frame, resampling 0.4–1.2 ms.

A frame that moved by ``MOTION_TOLERANCE_PX`` or more, and by more than what a translation leaves
(the last reading: a smaller motion cannot be told from the scene's own changes), is resampled onto
the reference grid before tracking (Keys' cubic, separable, at the exact fraction; its colour image
too), and the pixels at the image border that the moved frames do not see whole get no dip; a frame
that moved less is tracked as it was read, so a still camera's scan is the same with or without
registration. The motion is a translation: a turn or zoom is measured, warned about beyond
``NON_TRANSLATION_WARN_PX`` and refused beyond ``MAX_NON_TRANSLATION_PX``, not undone.

Over a whole day the sun turns so far that the shadows in the window recesses no longer resemble the
reference's (a translation then leaves more than ``NON_TRANSLATION_WARN_PX`` unexplained, and the
translation itself drifts by tenths of a pixel): the frames are then measured against the last frame
a translation explained (its motion known: an anchor, in ``Registration.anchors``), and the frames
measured before a reading says a translation explains them again keep the last credible motion. A
frame much dimmer than the reference (``DIM``: dawn, dusk) is not measured and keeps the last motion.

Refused (:class:`~gnomon.errors.FrameError`, naming the frame): a camera that moved by more than
``MAX_MOTION_PX``, or whose motion departs from a translation by more than
``MAX_NON_TRANSLATION_PX``, or with more than ``MAX_UNREGISTERED_SHARE`` of its frames whose motion
could not be measured (too few patches agree). Fewer such frames are left out of the tracking and
warned about; so are frames registered to no better than ``MOTION_TOLERANCE_PX``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from statistics import NormalDist

import cv2
import numpy as np

from gnomon.capture.frames import Frame, FrameSource, decode_frame_file
from gnomon.errors import FrameError
from gnomon.util.threads import ahead

__all__ = ["MAX_MOTION_PX", "MAX_NON_TRANSLATION_PX", "MOTION_TOLERANCE_PX", "NON_TRANSLATION_WARN_PX",
           "REGISTER_MODES", "FrameRegistrar", "Registration", "border_band", "motion_between", "reference_frame",
           "registered", "shift_image"]

REGISTER_MODES = ("auto", "on", "off")
"""``[capture] register``: ``"auto"`` (on for a light whose capture lasts hours, the sun), ``"on"``, ``"off"``."""

MOTION_TOLERANCE_PX = 0.05
"""Pixels. A frame that moved less is tracked as read; a motion measured to no better than this warns."""
MAX_MOTION_PX = 16.0
"""Pixels. A camera that moved farther is refused: re-aim it, or split the capture where it moved."""
NON_TRANSLATION_WARN_PX = 0.25
"""Pixels. What a translation leaves of a frame's motion beyond this warns. Below it the measure cannot
tell a turn from the scene's own changes: on pure translations it reads up to 0.10 px on the simulated
facade and 0.19 px on the desk, whose stick sweeps one side of the image after the other (the median of
three measurements; single ones up to 0.12 and 0.36 px); a turn of 0.3 px at the corners reads 0.31 px."""
MAX_NON_TRANSLATION_PX = 0.5
"""Pixels. A motion that departs from a translation by more (the camera turned or zoomed) is refused."""
DIM = 0.4
"""A frame whose mean level (DN, over the patches) is below this × the reference's is not measured (dawn,
dusk, night: the flat patches of a dark frame agree with any motion, and sky light alone casts other
shadows): it is moved as the last measured frame was."""
REFERENCE_LEVEL = 0.5
"""The reference is the first frame at least this × as bright as the capture's brightest (sampled) …"""
REFERENCE_SAMPLES = 40
"""… of this many frames spread over the capture."""
MAX_UNREGISTERED_SHARE = 0.1
"""A capture with more of its tracked frames unregistrable is refused; fewer are left out."""

PATCH_PX = 8  # a patch's side
GRID = (16, 12)  # cells (columns, rows) over the reference, each giving …
PER_CELL = 3  # … its most textured patches, not overlapping
MIN_TEXTURE = 0.25  # the smaller eigenvalue of a patch's mean structure tensor ((DN of 8 bits / px)²)
MIN_PATCHES = 24  # patches a reference and a frame's motion need
SMOOTH_PX = 1.0  # σ of the Gaussian both images are smoothed with
TUKEY = 2.0  # the biweight's cut, in units of the noise's scale …
SCALE_PERCENTILE = 25  # … read from this percentile of the residuals' magnitudes …
SCALE_STRIDE = 5  # … of every 5th pixel
MAX_OUTLIER_SHARE = 0.3  # a patch with more of its pixels cut is left out
MAX_ITERATIONS = 20
CONVERGED_PX = 5e-3  # the last step moves no patch by more
RELINEARISE_PX = 0.05  # the reference is interpolated again once the motion moved this far from where it was
PHASE_CHECK_PX = 3.0  # a frame's motion is measured again from the phase correlation's when they differ by more
COARSE_SIDE = 256  # the phase correlation's frames (4× smaller, or as many times as bring them to this wide)
FIELD_EVERY = 10  # frames between measurements of what a translation leaves …
FIELD_MOVE_PX = 0.25  # … or once the motion moved on by this much; what is reported is the median …
FIELD_RUNS = 3  # … of the last this many
_SMOOTH_RADIUS = 3
_GAUSS = np.exp(-0.5 * (np.arange(-_SMOOTH_RADIUS, _SMOOTH_RADIUS + 1) / SMOOTH_PX) ** 2)
_GAUSS = (_GAUSS / _GAUSS.sum()).astype(np.float32)
_A = -0.5  # Keys' cubic


def _keys(t: np.ndarray) -> np.ndarray:
    t = np.abs(t)
    return np.where(t <= 1, (_A + 2) * t**3 - (_A + 3) * t**2 + 1,
                    np.where(t < 2, _A * t**3 - 5 * _A * t**2 + 8 * _A * t - 4 * _A, 0.0))


def _keys_slope(t: np.ndarray) -> np.ndarray:
    s, t = np.sign(t), np.abs(t)
    return s * np.where(t <= 1, 3 * (_A + 2) * t**2 - 2 * (_A + 3) * t,
                        np.where(t < 2, 3 * _A * t**2 - 10 * _A * t + 8 * _A, 0.0))


def _taps(fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Keys' weights of the samples at offsets −1, 0, 1, 2 for a point ``fraction`` past the second,
    and their derivatives with respect to the point's position."""
    t = np.arange(-1.0, 3.0) - fraction
    return _keys(t).astype(np.float32), (-_keys_slope(t)).astype(np.float32)


def shift_image(image: np.ndarray, motion: tuple[float, float]) -> np.ndarray:
    """``image`` (H, W) or (H, W, C), uint8 or uint16, resampled onto the reference grid:
    ``out(x) = image(x + motion)`` (Keys' cubic, separable, at the exact fraction, rounded to the
    image's type; beyond the image its edge is repeated)."""
    mx, my = float(motion[0]), float(motion[1])
    nx, ny = math.floor(mx), math.floor(my)
    kx, _ = _taps(mx - nx)
    ky, _ = _taps(my - ny)
    depth = cv2.CV_8U if image.dtype == np.uint8 else cv2.CV_16U
    # out(x + n) = Σ_t k(t − f) image(x + n + t), t = −1 … 2: a correlation anchored at the second tap,
    # then the whole pixels by moving the result, its edge repeated.
    fine = cv2.sepFilter2D(image, depth, kx, ky, anchor=(1, 1), borderType=cv2.BORDER_REPLICATE)
    h, w = image.shape[:2]
    if abs(nx) >= w or abs(ny) >= h:
        raise ValueError(f"a motion of ({mx:.1f}, {my:.1f}) px moves the frame out of the image")
    part = fine[max(ny, 0):h + min(ny, 0), max(nx, 0):w + min(nx, 0)]
    return cv2.copyMakeBorder(part, max(-ny, 0), max(ny, 0), max(-nx, 0), max(nx, 0), cv2.BORDER_REPLICATE)


def border_band(shape: tuple[int, int], motion: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels some frame moved by ``motion`` ((M, 2) px, the resampled frames') does
    not see with the whole interpolation kernel inside the image."""
    out = np.zeros(shape, dtype=bool)
    if len(motion) == 0:
        return out
    h, w = shape
    lo = np.minimum(motion.min(axis=0), 0.0)
    hi = np.maximum(motion.max(axis=0), 0.0)
    left, top = int(math.ceil(-lo[0])) + 1, int(math.ceil(-lo[1])) + 1
    right, bottom = int(math.ceil(hi[0])) + 2, int(math.ceil(hi[1])) + 2
    out[:top] = out[h - bottom:] = True
    out[:, :left] = out[:, w - right:] = True
    return out


def _as_8bit(grey: np.ndarray) -> np.ndarray:
    f = grey.astype(np.float32)
    return f / np.float32(257.0) if grey.dtype == np.uint16 else f


def _smooth(image: np.ndarray) -> np.ndarray:
    """The Gaussian (σ ``SMOOTH_PX``) both the reference and the frames' patches are smoothed with."""
    return cv2.sepFilter2D(image, cv2.CV_32F, _GAUSS, _GAUSS, borderType=cv2.BORDER_REFLECT)


def _select_patches(ref: np.ndarray, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """Top-left corners (K, 2) (row, column) of the reference's most textured patches, the best
    ``PER_CELL`` per cell of ``GRID``, not overlapping, at least ``margin`` inside the image, and their
    texture (K,): the smaller eigenvalue of the patch's mean structure tensor."""
    p = PATCH_PX
    gx = cv2.Sobel(ref, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(ref, cv2.CV_32F, 0, 1, ksize=3) / 8
    sxx = cv2.boxFilter(gx * gx, -1, (p, p), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    syy = cv2.boxFilter(gy * gy, -1, (p, p), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    sxy = cv2.boxFilter(gx * gy, -1, (p, p), anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    weakest = (sxx + syy) / 2 - np.sqrt(((sxx - syy) / 2) ** 2 + sxy**2)  # at each top-left corner
    h, w = ref.shape
    usable = np.full((h, w), -1.0, np.float32)
    usable[margin:h - margin - p + 1, margin:w - margin - p + 1] = weakest[margin:h - margin - p + 1,
                                                                          margin:w - margin - p + 1]
    corners: list[tuple[int, int]] = []
    texture: list[float] = []
    rows = np.linspace(margin, h - margin - p + 1, GRID[1] + 1).astype(int)
    cols = np.linspace(margin, w - margin - p + 1, GRID[0] + 1).astype(int)
    for r0, r1 in zip(rows[:-1], rows[1:], strict=True):
        for c0, c1 in zip(cols[:-1], cols[1:], strict=True):
            cell = usable[r0:r1, c0:c1].copy()
            for _ in range(PER_CELL):
                if cell.size == 0:
                    break
                k = int(np.argmax(cell))
                v, u = divmod(k, cell.shape[1])
                if not cell[v, u] >= MIN_TEXTURE:
                    break
                corners.append((r0 + v, c0 + u))
                texture.append(float(cell[v, u]))
                cell[max(0, v - p + 1):v + p, max(0, u - p + 1):u + p] = -1.0
    return np.array(corners, dtype=np.int64).reshape(-1, 2), np.array(texture)


@dataclass(frozen=True)
class _Solution:
    q: np.ndarray  # the parameters (px)
    covariance: np.ndarray  # their covariance (px²)
    patches: int  # patches that agreed
    converged: bool
    texture: float  # the share of the reference's texture in the patches that agreed
    halves: float  # px, how far apart the image's halves' motions are


@dataclass(frozen=True)
class _Estimate:
    motion: np.ndarray  # (2,) px
    sigma: float  # px
    patches: int  # patches that agreed
    non_translation: float  # px
    converged: bool
    texture: float  # the share of the reference's texture in the patches that agreed


@dataclass
class Registration:
    """A capture's registration: per capture frame (N entries; NaN / 0 / False where not registered).

    ``motion_px`` (N, 2): the frame's motion against the reference frame, x right and y down
    (a point at ``p`` in the reference is at ``p + motion`` in the frame); ``sigma_px``: its σ;
    ``non_translation_px``: what a translation leaves of the frame's motion (px, across the image);
    ``patches``: the patches that agreed; ``compensated``: the frame was resampled onto the
    reference grid (it moved by ``MOTION_TOLERANCE_PX`` or more); ``applied_px`` (N, 2): the motion it
    was moved back by (NaN where it was not: a held frame's is the last one's); ``unregistered``: capture frames
    whose motion could not be measured (left out of the tracking); ``dim``: capture frames too dim to
    measure (``DIM``), moved as the last measured frame was; ``doubtful``: capture frames measured while
    the last reading of what a translation leaves exceeded ``NON_TRANSLATION_WARN_PX``, moved as the
    last frame before them; ``border``: the (H, W) pixels
    the resampled frames do not see (left out of the scan); ``patch_count``: the reference's
    patches; ``measure_s``, ``resample_s``: the CPU time spent measuring and resampling (the
    tracking thread's, which does both).
    """

    reference_frame: int
    names: list[str]
    motion_px: np.ndarray
    sigma_px: np.ndarray
    non_translation_px: np.ndarray
    patches: np.ndarray
    compensated: np.ndarray
    applied_px: np.ndarray
    unregistered: list[int]
    dim: list[int]
    doubtful: list[int]
    anchors: list[tuple[int, list[float]]]
    border: np.ndarray
    patch_count: int
    measure_s: float = 0.0
    resample_s: float = 0.0

    @property
    def measured(self) -> np.ndarray:
        """(N,) bool: frames whose motion was measured."""
        return np.isfinite(self.motion_px[:, 0])

    def moved(self, frame: Frame) -> Frame:
        """``frame`` (grey and colour) on the reference grid as the tracker saw it (itself where it was
        not resampled), e.g. a frame decoded again for the recording or the colours."""
        if not self.compensated[frame.index]:
            return frame
        m = self.applied_px[frame.index]
        return replace(frame, grey=shift_image(frame.grey, (m[0], m[1])),
                       color=None if frame.color is None else shift_image(frame.color, (m[0], m[1])))

    def report(self) -> dict:
        """report.json's ``registration``: the motion per frame and its summary."""
        m = self.measured
        n = int(m.sum())
        size = np.hypot(self.motion_px[:, 0], self.motion_px[:, 1])
        worst = int(np.nanargmax(size)) if n else None

        def per_frame(values: np.ndarray, digits: int) -> list:
            return [None if not np.all(np.isfinite(v)) else np.round(v, digits).tolist() for v in values]

        return {
            "reference_frame": self.reference_frame,
            "frames_measured": n,
            "frames_compensated": int(self.compensated.sum()),
            "unregistered_frames": list(self.unregistered),
            # the frames measured against in turn (the reference first) and their motion against it
            "anchors": [{"frame": i, "motion_px": m} for i, m in self.anchors],
            "dim_frames": list(self.dim),  # too dim to measure: moved as the last measured frame
            "doubtful_frames": list(self.doubtful),  # not a translation: moved as the last frame that was
            "max_motion_px": None if worst is None else float(round(size[worst], 4)),
            "max_motion_frame": worst,
            "max_sigma_px": float(round(np.nanmax(self.sigma_px), 4)) if n else None,
            "max_non_translation_px": float(round(np.nanmax(self.non_translation_px), 4)) if n else None,
            "tolerance_px": MOTION_TOLERANCE_PX,
            "border_pixels_left_out": int(self.border.sum()),
            "patches": self.patch_count,
            # CPU milliseconds per frame measured, and per frame resampled
            "ms_per_frame": {"measure": round(1000 * self.measure_s / max(n, 1), 3),
                             "resample": round(1000 * self.resample_s / max(int(self.compensated.sum()), 1), 3)},
            "motion_px": per_frame(self.motion_px, 4),
            "sigma_px": per_frame(self.sigma_px, 4),
            "non_translation_px": per_frame(self.non_translation_px, 4),
        }

    def warnings(self) -> list[str]:
        """What the user should know: the camera moved (and was followed), frames registered to no
        better than the tolerance, frames whose motion a translation does not describe, frames left out."""
        out: list[str] = []
        m = self.measured
        if self.compensated.any():
            size = np.hypot(self.applied_px[:, 0], self.applied_px[:, 1])  # what the frames were moved back by
            worst = int(np.nanargmax(size))
            out.append(f"the camera moved: up to {size[worst]:.2f} px by frame {worst} ({self.names[worst]}) against "
                       f"frame {self.reference_frame}; {int(self.compensated.sum())} frames resampled onto frame "
                       f"{self.reference_frame}'s grid (report.json registration), "
                       f"{int(self.border.sum())} pixels at the image border left out")
        loose = np.flatnonzero(m & (self.sigma_px > MOTION_TOLERANCE_PX))
        if len(loose):
            k = int(loose[np.argmax(self.sigma_px[loose])])
            out.append(f"{len(loose)} frames registered to no better than ±{MOTION_TOLERANCE_PX} px (worst ±"
                       f"{self.sigma_px[k]:.3f} px, frame {k}, {self.names[k]}; {_frames(loose)}): too little "
                       "texture that stays unchanged; their shadow times may be off by that much of a pixel's "
                       "sweep; a capture with more fixed texture in view (or a steadier mount) avoids it")
        bent = np.flatnonzero(m & (self.non_translation_px > NON_TRANSLATION_WARN_PX))
        if len(bent) or self.doubtful:
            most = float(np.nanmax(self.non_translation_px))
            out.append(f"the frames' motion is not a translation alone (up to {most:.2f} px across the image "
                       f"beyond one, {_frames(bent)}): the camera turned or zoomed, or the scene's shadows "
                       f"changed too much to tell; {len(self.doubtful)} frames measured meanwhile were moved "
                       f"as the last frame a translation explained ({_frames(np.asarray(self.doubtful))}); "
                       "if the camera turned, fix its mount")
        if len(self.anchors) > 1:
            later = [str(i) for i, _ in self.anchors[1:]]
            out.append(f"the scene's shadows changed too much to measure every frame against frame "
                       f"{self.reference_frame}: from where a translation no longer explained the motion, the "
                       f"frames were measured against frame{'s' if len(later) > 1 else ''} {', '.join(later)} "
                       "(in turn), whose own motion adds its error to theirs: the camera's motion is known less "
                       "well there (on the simulated whole day, to 0.2 px)")
        held = [i for i in self.dim if self.compensated[i]]
        if held:
            out.append(f"{len(held)} frames too dim to register against frame {self.reference_frame} (dawn, dusk, "
                       f"under a cloud; {_frames(np.asarray(held))}) were moved as the last registered frame was")
        if self.unregistered:
            out.append(f"{len(self.unregistered)} frames whose motion could not be measured left out of the scan "
                       f"({_frames(np.asarray(self.unregistered))}): too few parts of the image matched the "
                       f"reference frame {self.reference_frame} (fog, something in front of the camera, a large "
                       "jump of the camera)")
        return out


def reference_frame(source: FrameSource | object, skip: np.ndarray | None = None) -> Frame | None:
    """The frame a capture is registered against: the first (not in ``skip``) at least ``REFERENCE_LEVEL``
    × as bright as the brightest of ``REFERENCE_SAMPLES`` frames spread over the capture (their mean
    level, decoded 4× smaller), decoded as a scan decodes it: a day's first frames are dawn's, lit by
    the sky alone, which shadow the scene otherwise than the sun (registered against one, the facade
    lit by the sun reads motions of up to 0.8 px). None for a video or a live source (their first frame
    tracked is the reference) and when there is no frame to sample."""
    files = tuple(getattr(source, "image_files", ()))  # a live source (a camera, a stream) has none
    if getattr(source, "video", None) is not None or not files:
        return None
    usable = [i for i in range(len(files)) if skip is None or not skip[i]]
    if not usable:
        return None
    sample = usable[::max(1, len(usable) // REFERENCE_SAMPLES)]
    levels = []
    for i in sample:
        small = cv2.imread(str(files[i]), cv2.IMREAD_REDUCED_GRAYSCALE_4)
        levels.append(float(small.mean()) if small is not None else 0.0)
    top = max(levels)
    first = next(i for i, level in zip(sample, levels, strict=True) if level >= REFERENCE_LEVEL * top)
    grey, _, _ = decode_frame_file(files[first])
    return Frame(first, grey, None, files[first].name)


AHEAD = 4
"""Frames :func:`registered` registers ahead of the tracker, at most."""


@contextmanager
def registered(frames: Iterator[Frame], registrar: FrameRegistrar | None,
               skip: np.ndarray | None = None) -> Iterator[Iterator[tuple[Frame, Frame, bool]]]:
    """``frames`` as ``(frame as read, frame on the reference grid, left out)``, registered on a thread of
    their own up to ``AHEAD`` frames ahead (numpy and OpenCV release the interpreter for the arrays, the
    kernel for the tracker: the two overlap), in order; without ``registrar`` as read, on this thread.
    ``skip``: frames not registered (and left out). An error on the thread (a camera moved more than a
    scan follows) is raised here; leaving the block stops and joins the thread."""
    if registrar is None:
        yield ((f, f, skip is not None and bool(skip[f.index])) for f in frames)
        return

    def each() -> Iterator[tuple[Frame, Frame, bool]]:
        for frame in frames:
            if skip is not None and skip[frame.index]:
                yield frame, frame, True
            else:
                moved = registrar.register(frame)
                yield frame, frame if moved is None else moved, moved is None

    stream = ahead(each(), AHEAD, "gnomon-registration")
    try:
        yield stream
    finally:
        stream.close()


def motion_between(reference: np.ndarray, grey: np.ndarray) -> np.ndarray | None:
    """One frame's motion against a reference frame ((2,) px, as :class:`Registration`'s), or None when
    the reference has too little texture or the motion cannot be measured (grey images of one size)."""
    registrar = FrameRegistrar(reference.shape, 2)
    registrar.register(Frame(0, reference, None, "reference"))
    try:
        registrar.register(Frame(1, grey, None, "frame"))
    except FrameError:
        return None
    motion = registrar.result("").motion_px[1]
    return motion if np.isfinite(motion).all() else None


def _frames(indices: np.ndarray) -> str:
    listed = ", ".join(str(int(i)) for i in indices[:8])
    return f"frames {listed}{' …' if len(indices) > 8 else ''}"


@dataclass
class FrameRegistrar:
    """Registers a capture's frames, one at a time, against its first (:meth:`register`), then
    summarises (:meth:`result`). ``shape``: (H, W) of the frames; ``count``: frames in the capture."""

    shape: tuple[int, int]
    count: int
    reference_frame: int = -1
    _ref: np.ndarray | None = None  # the smoothed reference, 8-bit scale, float32
    _corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    _texture: np.ndarray = field(default_factory=lambda: np.zeros(0))  # each patch's (its structure tensor's)
    _coarse_ref: np.ndarray | None = None
    _window_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # the frame's patch windows
    _reference_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # the reference's, at m = 0
    _centres: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))  # patches' x, y (centred, / half the size)
    _corner_xy: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))  # the image corners', likewise
    _last: np.ndarray = field(default_factory=lambda: np.zeros(2))  # the last motion the frames were moved by
    _start: np.ndarray = field(default_factory=lambda: np.zeros(2))  # the last motion measured (the next start)
    _credible: bool = True  # the last reading of what a translation leaves was within NON_TRANSLATION_WARN_PX
    _unexplained: float = 0.0  # what a translation leaves (the median of the last readings): a smaller motion
    # cannot be told from the scene's own changes, and the frame is tracked as read
    _offset: np.ndarray = field(default_factory=lambda: np.zeros(2))  # the frame measured against: its motion
    _anchors: list[tuple[int, list[float]]] = field(default_factory=list)  # the frames measured against, in turn
    _kept: tuple[Frame, np.ndarray] | None = None  # the last frame a translation explained, and its motion
    _doubtful: list[int] = field(default_factory=list)  # frames measured while it was not
    _linear: tuple | None = None  # (m0, the reference about m0: values, gradients, patches inside)
    _field_at: np.ndarray | None = None  # the motion where the non-translation was last measured
    _coarse_scale: int = 4  # the phase correlation's frames are this many times smaller
    _since_field: int = 0  # frames since
    _fields: list[float] = field(default_factory=list)  # every measurement of what a translation leaves
    _names: list[str] = field(default_factory=list)
    _motion: np.ndarray | None = None
    _sigma: np.ndarray | None = None
    _bent: np.ndarray | None = None
    _patches: np.ndarray | None = None
    _compensated: np.ndarray | None = None
    _unregistered: list[int] = field(default_factory=list)
    _dim: list[int] = field(default_factory=list)  # frames too dim to measure
    _held_motion: dict[int, np.ndarray] = field(default_factory=dict)  # their motion, the last measured one's
    _ref_level: float = 0.0  # the reference's mean level over the patches' windows (DN of 8 bits)
    _level_scale: float = 1.0
    _tracked: int = 0
    _measure_s: float = 0.0
    _resample_s: float = 0.0

    def __post_init__(self) -> None:
        n = self.count
        self._names = [""] * n
        self._motion = np.full((n, 2), np.nan)
        self._sigma = np.full(n, np.nan)
        self._bent = np.full(n, np.nan)
        self._patches = np.zeros(n, dtype=np.int64)
        self._compensated = np.zeros(n, dtype=bool)

    # ------------------------------------------------------------------ per frame
    def register(self, frame: Frame) -> Frame | None:
        """``frame`` on the reference grid (itself when it moved less than ``MOTION_TOLERANCE_PX``), or
        None when its motion cannot be measured (leave it out). Without a reference (:meth:`set_reference`)
        the first frame with enough texture becomes it; frames before it pass as read. A frame much
        dimmer than the reference (``DIM``: dawn, dusk, night) is not measured: it is moved as the last
        measured frame was (as read before any). Raises :class:`FrameError` naming the frame when the
        camera moved more than Gnomon follows."""
        assert self._motion is not None and self._compensated is not None
        if frame.grey.shape[:2] != self.shape:
            return frame  # the pass refuses it, naming the frame
        i = frame.index
        self._names[i] = frame.name
        self._tracked += 1
        t0 = time.thread_time()
        if self._ref is None:
            self.set_reference(frame)
            self._measure_s += time.thread_time() - t0
            return frame
        if i == self.reference_frame:
            return frame
        level = float(frame.grey.ravel().take(self._window_index).mean()) / self._level_scale
        if level < DIM * self._ref_level:
            self._dim.append(i)
            self._measure_s += time.thread_time() - t0
            return self._moved(frame, self._last, held=True)
        estimate = self._measure(frame.grey)
        if estimate is not None and not self._credible and self._kept is not None \
                and self._kept[0].index != self._anchors[-1][0]:
            # What a translation leaves grew beyond the tolerable: the scene's shadows changed too much
            # since the frame measured against (a day's sun turning); measure against the last frame a
            # translation explained, whose motion is known, from now on.
            kept, offset = self._kept
            if self._anchor(kept, offset):
                estimate = self._measure(frame.grey)
        self._measure_s += time.thread_time() - t0
        if estimate is None:
            self._unregistered.append(i)
            return None
        self._start = estimate.motion
        m = estimate.motion + self._offset
        size = float(np.hypot(*m))
        if size > MAX_MOTION_PX:
            raise FrameError(f"frame {i} ({frame.name}): the camera moved by {size:.1f} px since frame "
                             f"{self.reference_frame}, more than the {MAX_MOTION_PX:g} px a scan follows; keep the "
                             "camera still, or scan the frames before and after the move apart")
        if estimate.non_translation > MAX_NON_TRANSLATION_PX:
            raise FrameError(f"frame {i} ({frame.name}): the camera turned or zoomed since frame "
                             f"{self.reference_frame} (its motion departs from a translation by "
                             f"{estimate.non_translation:.2f} px across the image, more than the "
                             f"{MAX_NON_TRANSLATION_PX:g} px a scan accepts); fix the camera's mount")
        self._motion[i] = m
        assert self._sigma is not None and self._bent is not None and self._patches is not None
        self._sigma[i] = estimate.sigma
        self._bent[i] = estimate.non_translation
        self._patches[i] = estimate.patches
        if not self._credible:
            self._doubtful.append(i)
            return self._moved(frame, self._last, held=True)
        self._last, self._kept = m, (frame, m)
        return self._moved(frame, m)

    def _moved(self, frame: Frame, m: np.ndarray, held: bool = False) -> Frame:
        """``frame`` resampled onto the reference grid for the motion ``m`` (itself below the tolerance)."""
        if float(np.hypot(*m)) < max(MOTION_TOLERANCE_PX, self._unexplained):
            return frame
        assert self._compensated is not None
        t1 = time.thread_time()
        self._compensated[frame.index] = True
        moved = replace(frame, grey=shift_image(frame.grey, (m[0], m[1])),
                        color=None if frame.color is None else shift_image(frame.color, (m[0], m[1])))
        self._resample_s += time.thread_time() - t1
        if held:
            self._held_motion[frame.index] = m
        return moved

    def set_reference(self, frame: Frame) -> None:
        """Take ``frame`` as the reference when it has texture enough (its motion is 0 by definition); a
        scan gives the first frame lit like most of the capture (:func:`reference_frame`) before its pass."""
        assert self._motion is not None and self._sigma is not None and self._bent is not None
        if not self._anchor(frame, np.zeros(2)):
            return
        self.reference_frame = frame.index
        self._motion[frame.index] = 0.0
        self._sigma[frame.index] = 0.0
        self._bent[frame.index] = 0.0
        assert self._patches is not None
        self._patches[frame.index] = len(self._corners)

    def _anchor(self, frame: Frame, offset: np.ndarray) -> bool:
        """Measure the frames against ``frame`` from now on, whose motion against the reference is
        ``offset`` (px); False (nothing changed) when it has too little texture."""
        ref = _smooth(_as_8bit(frame.grey))
        margin = _SMOOTH_RADIUS + 8
        corners, texture = _select_patches(ref, margin)
        if len(corners) < MIN_PATCHES:
            return False
        self._ref, self._corners, self._texture = ref, corners, texture
        self._offset, self._start, self._linear = np.array(offset, dtype=np.float64), np.zeros(2), None
        self._field_at, self._fields, self._since_field, self._credible = None, [], 0, True
        self._anchors.append((frame.index, [float(x) for x in offset]))
        h, w = self.shape
        r = np.arange(-_SMOOTH_RADIUS, PATCH_PX + _SMOOTH_RADIUS)
        self._window_index = ((corners[:, 0][:, None, None] + r[None, :, None]) * w
                              + corners[:, 1][:, None, None] + r[None, None, :]).ravel()
        r = np.arange(PATCH_PX + 3)
        self._reference_index = ((corners[:, 0][:, None, None] - 1 + r[None, :, None]) * w
                                 + corners[:, 1][:, None, None] - 1 + r[None, None, :]).ravel()
        half = max(w, h) / 2
        centre = (PATCH_PX - 1) / 2
        self._centres = ((corners[:, 1] + centre - (w - 1) / 2) / half, (corners[:, 0] + centre - (h - 1) / 2) / half)
        self._corner_xy = (np.array([-1.0, 1.0, -1.0, 1.0]) * (w - 1) / 2 / half,
                           np.array([-1.0, -1.0, 1.0, 1.0]) * (h - 1) / 2 / half)
        self._coarse_scale = max(4, math.ceil(max(w, h) / COARSE_SIDE))
        self._coarse_ref = _coarse(frame.grey, self._coarse_scale)
        self._level_scale = 257.0 if frame.grey.dtype == np.uint16 else 1.0
        self._ref_level = float(frame.grey.ravel().take(self._window_index).mean()) / self._level_scale
        return True

    def _frame_patches(self, grey: np.ndarray) -> np.ndarray:
        """The frame's patches (K, P·P), smoothed as the reference, read at whole pixels."""
        p, s = PATCH_PX, _SMOOTH_RADIUS
        k = len(self._corners)
        windows = _as_8bit(grey.ravel().take(self._window_index)).reshape(k, p + 2 * s, p + 2 * s)
        # One tall image: a smoothed window's centre sees only its own window (its margin is the radius).
        smooth = _smooth(windows.reshape(k * (p + 2 * s), p + 2 * s)).reshape(k, p + 2 * s, p + 2 * s)
        return np.ascontiguousarray(smooth[:, s:s + p, s:s + p]).reshape(k, p * p)

    def _reference(self, m: np.ndarray):
        """The reference at ``x − m`` over the patches (K, P·P), its gradient (x, y), and which patches
        it holds whole."""
        assert self._ref is not None
        p = PATCH_PX
        n0, n1 = math.floor(-m[0]), math.floor(-m[1])
        wx, dwx = _taps(-m[0] - n0)
        wy, dwy = _taps(-m[1] - n1)
        h, w = self._ref.shape
        k = len(self._corners)
        top = self._corners[:, 0] + n1 - 1
        left = self._corners[:, 1] + n0 - 1
        inside = (top >= 0) & (left >= 0) & (top + p + 3 <= h) & (left + p + 3 <= w)
        index = self._reference_index + (n1 * w + n0)
        if not inside.all():  # the windows that leave the image are read anywhere inside and not used
            index = index.reshape(k, -1)
            index[~inside] = self._reference_index.reshape(k, -1)[~inside]
        mosaic = self._ref.ravel().take(index).reshape(k * (p + 3), p + 3)
        # Each window's first P rows and columns see only its own pixels (the kernel reaches 3 further).
        out = [cv2.sepFilter2D(mosaic, cv2.CV_32F, kx, ky, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
               .reshape(k, p + 3, p + 3)[:, :p, :p] for kx, ky in ((wx, wy), (dwx, wy), (wx, dwy))]
        values, gx, gy = (np.ascontiguousarray(o) for o in out)
        return values.reshape(k, -1), gx.reshape(k, -1), gy.reshape(k, -1), inside

    def _measure(self, grey: np.ndarray) -> _Estimate | None:
        frame = self._frame_patches(grey)
        enough = max(MIN_PATCHES, len(self._corners) // 3)

        def fine(e: _Estimate | None) -> bool:
            return e is not None and e.converged and e.patches >= enough

        # From the previous frame's motion (the camera moves slowly: a few iterations).
        best = self._translation(frame, self._start, anneal=False)
        if not fine(best):
            # A wrong start, or the light changed (a cloud): the weights annealed from 4× the cut.
            best = self._translation(frame, self._start, anneal=True)
        # A jump beyond the iterations' reach can leave the flat patches agreeing with a wrong motion: the
        # whole frame's phase correlation (coarse, a few px) is a second opinion; where it differs, the
        # iterations start again from it, and the motion whose agreeing patches hold more of the
        # reference's texture wins.
        start = _phase_shift(self._coarse_ref, _coarse(grey, self._coarse_scale), self._coarse_scale)
        if best is None or np.abs(start - best.motion).max() > PHASE_CHECK_PX * self._coarse_scale / 4:
            other = self._translation(frame, start, anneal=True)
            if other is not None and other.converged and other.patches >= MIN_PATCHES and (
                    best is None or not best.converged or other.texture > best.texture):
                best = other
        if best is None or not best.converged or best.patches < MIN_PATCHES:
            return None
        # Whether the motion is a translation: every FIELD_EVERY frames, and whenever it moved on by
        # FIELD_MOVE_PX since (a rotation or zoom grows with the motion).
        self._since_field += 1
        if (self._field_at is None or self._since_field >= FIELD_EVERY
                or np.abs(best.motion - self._field_at).max() >= FIELD_MOVE_PX):
            self._field_at, self._since_field = best.motion, 0
            # The scene's own changes (a shadow over one side of the image) read as a small turn now and
            # then; a turned camera stays turned: the median of the last FIELD_RUNS measurements.
            reading = self._non_translation(frame, best.motion)
            self._fields.append(reading)
            # A translation that leaves this much unexplained is not the camera's motion alone: until a
            # reading says otherwise, the frames keep the last motion a translation explained.
            self._credible = not reading > NON_TRANSLATION_WARN_PX
            best = replace(best, non_translation=float(np.nanmedian(self._fields[-FIELD_RUNS:])))
            if math.isfinite(best.non_translation):
                self._unexplained = best.non_translation
        return best

    def _solve(self, frame: np.ndarray, start: np.ndarray, *, anneal: bool,
               design: np.ndarray | None = None) -> _Solution | None:
        """Iteratively reweighted Gauss–Newton for the motion, with per-patch gain and offset and Tukey's
        weights, from ``start``.

        The parameters ``q`` move patch ``p`` by ``design[p] @ q`` (px; ``design`` (K, 2, Q); None: the
        identity, ``q`` the translation). The reference is interpolated at one point ``m0`` and taken to
        first order about it, ``R(x − d) ≈ R(x − m0) − ∇R(x − m0)·(d − m0)``, again from wherever the
        patches' mean motion moved by more than ``RELINEARISE_PX``. Each iteration weighs the pixels by
        their residuals at the current motion (the robust scale annealed from 4× down to 1× over the
        first two with ``anneal``), fits every patch's gain and offset and solves for the step, all from
        the weighted sums of the pixels' 1, R, F, ∇R products (one batched matrix product): the gain
        and offset eliminated, a patch's normal matrix is ``a²·(C_GG − C_GR·C_RG / C_RR)`` and its
        right-hand side ``−a·(C_GF − a·C_GR)`` (C the weighted covariances over the patch). It stops
        when the step moves no patch by ``CONVERGED_PX`` and the patches kept are the last iteration's."""
        q = np.array(start, dtype=np.float64)
        k, n = frame.shape
        if design is None:
            design = np.broadcast_to(np.eye(2), (k, 2, 2))
        translation = design.shape[2] == 2
        columns = np.empty((k, 5, n), np.float32)  # 1, R, F, ∂R/∂x, ∂R/∂y per pixel
        columns[:, 0] = 1.0
        columns[:, 2] = frame
        w = np.ones((k, n), np.float32)
        good = np.ones(k, dtype=bool)
        schedule = (4.0, 2.0) if anneal else ()
        converged = False
        a = np.zeros(k, np.float32)
        about = None
        for it in range(MAX_ITERATIONS + 1):
            moved = design @ q  # (K, 2) each patch's motion
            m0, (ref0, gx, gy, inside) = self._linearised(moved.mean(axis=0))
            if about is not m0:
                about = m0
                columns[:, 3] = gx
                columns[:, 4] = gy
            d = (moved - m0).astype(np.float32)
            columns[:, 1] = ref0 - gx * d[:, :1] - gy * d[:, 1:]
            if it == 0:  # the first weights: the residuals of the unweighted fit
                cov, _ = _covariances(columns, w * inside[:, None])
                a = cov[:, 1, 2] / np.maximum(cov[:, 1, 1], 1e-6)
            e = frame - columns[:, 1] * a.astype(np.float32)[:, None]
            e -= ((e * w).sum(axis=1) / np.maximum(w.sum(axis=1), np.float32(1e-6)))[:, None]
            scale = _robust_scale(e[inside].ravel()[::SCALE_STRIDE]) if inside.any() else 0.0
            u = e / np.float32((schedule[it] if it < len(schedule) else 1.0) * TUKEY * max(scale, 0.25))
            w = np.maximum(1.0 - u * u, 0.0) ** 2 * inside[:, None]
            kept = (w > 0).mean(axis=1) >= 1.0 - MAX_OUTLIER_SHARE
            w *= kept[:, None]
            settled = bool(np.array_equal(kept, good))
            good = kept
            if it == MAX_ITERATIONS:
                break
            cov, total = _covariances(columns, w)
            crr = np.maximum(cov[:, 1, 1], 1e-6)
            a = cov[:, 1, 2] / crr
            # per patch: H = a²·(C_GG − C_GR C_RG / C_RR), b = −a·(C_GF − a·C_GR)
            h = np.empty((k, 2, 2))
            h[:, 0, 0] = a * a * (cov[:, 3, 3] - cov[:, 1, 3] ** 2 / crr)
            h[:, 1, 1] = a * a * (cov[:, 4, 4] - cov[:, 1, 4] ** 2 / crr)
            h[:, 0, 1] = h[:, 1, 0] = a * a * (cov[:, 3, 4] - cov[:, 1, 3] * cov[:, 1, 4] / crr)
            b = np.stack([-a * (cov[:, 2, 3] - a * cov[:, 1, 3]), -a * (cov[:, 2, 4] - a * cov[:, 1, 4])], axis=1)
            h[~good] = 0.0
            b[~good] = 0.0
            if translation:
                normal, rhs = h.sum(axis=0), b.sum(axis=0)
            else:
                normal, rhs = np.einsum("kia,kij,kjb->ab", design, h, design), np.einsum("kia,ki->a", design, b)
            if int(good.sum()) < MIN_PATCHES or not np.linalg.cond(normal) < 1e8:
                return None
            step = np.linalg.solve(normal, rhs)
            q = q + step
            shift = np.abs(design @ step).max()
            if np.abs(design @ q - design @ np.asarray(start)).max() > MAX_MOTION_PX + 4:
                return None
            if it >= len(schedule) and settled and shift < CONVERGED_PX:
                converged = True
                break
        # σ: the residuals through the normal equations, scaled by how much more than their noise the
        # good patches' own shifts (H_p⁻¹ b_p) disagree with the common motion (a reduced χ² between patches).
        residual = np.where(good, cov[:, 2, 2] - a * cov[:, 1, 2], 0.0)
        noise2 = float(residual.sum()) / max(float(total[good].sum()) - 2.0 * int(good.sum()) - len(q), 1.0)
        det = h[:, 0, 0] * h[:, 1, 1] - h[:, 0, 1] ** 2
        ok = good & (det > 1e-6 * (h[:, 0, 0] + h[:, 1, 1]) ** 2)
        own = np.zeros((k, 2))
        own[ok] = np.linalg.solve(h[ok], b[ok][:, :, None])[:, :, 0]
        chi2 = float(np.einsum("ki,kij,kj->", own[ok], h[ok], own[ok]))
        spread = chi2 / max(noise2, 1e-12) / max(2.0 * int(ok.sum()) - len(q), 1.0)
        covariance = noise2 * max(spread, 1.0) * np.linalg.inv(normal)
        texture = float(self._texture[good].sum() / max(self._texture.sum(), 1e-12))
        return _Solution(q, covariance, int(good.sum()), converged, texture, self._halves(h, b))

    def _halves(self, h: np.ndarray, b: np.ndarray) -> float:
        """How far apart the motions of the image's halves are (px): top and bottom, left and right, each
        half's motion one Gauss–Newton step from the common one over its own patches. The camera moves
        the whole image alike; the scene's changes seldom do (half of what they pull apart is a σ)."""
        x, y = self._centres
        worst = 0.0
        for first in (x < 0, y < 0):
            steps = []
            for half in (first, ~first):
                normal, rhs = h[half].sum(axis=0), b[half].sum(axis=0)
                if not np.linalg.cond(normal) < 1e8:
                    return float("nan")
                steps.append(np.linalg.solve(normal, rhs))
            worst = max(worst, float(np.hypot(*(steps[0] - steps[1]))))
        return worst

    def _translation(self, frame: np.ndarray, start: np.ndarray, *, anneal: bool) -> _Estimate | None:
        """:meth:`_solve` for a translation: the motion and its σ (the larger axis of its covariance)."""
        solution = self._solve(frame, start, anneal=anneal)
        if solution is None:
            return None
        noise = float(math.sqrt(max(float(np.linalg.eigvalsh(solution.covariance).max()), 0.0)))
        sigma = max(noise, solution.halves / 2) if math.isfinite(solution.halves) else noise
        return _Estimate(solution.q, sigma, solution.patches, float("nan"), solution.converged, solution.texture)

    def _non_translation(self, frame: np.ndarray, motion: np.ndarray) -> float:
        """What a translation leaves of the frame's motion (px): the largest distance over the image's
        corners between ``motion`` and a linearised homography (8 parameters: the translation, a
        rotation, a zoom, a shear and a pan's perspective) fitted as the translation is, from it."""
        x, y = self._centres
        one, zero = np.ones_like(x), np.zeros_like(x)
        # Δx = t_x + a1 x + a2 y + g1 x² + g2 xy;  Δy = t_y + b1 x + b2 y + g1 xy + g2 y²
        design = np.stack([np.stack([one, zero, x, y, zero, zero, x * x, x * y], axis=1),
                           np.stack([zero, one, zero, zero, x, y, x * y, y * y], axis=1)], axis=1)
        solution = self._solve(frame, np.concatenate([motion, np.zeros(6)]), anneal=False, design=design)
        if solution is None or not solution.converged:
            return float("nan")
        q = solution.q
        cx, cy = self._corner_xy
        dx = q[0] + q[2] * cx + q[3] * cy + q[6] * cx * cx + q[7] * cx * cy - motion[0]
        dy = q[1] + q[4] * cx + q[5] * cy + q[6] * cx * cy + q[7] * cy * cy - motion[1]
        return float(np.hypot(dx, dy).max())

    def _linearised(self, m: np.ndarray):
        """The point the reference is taken to first order about for the motion ``m`` (the last one,
        unless ``m`` moved by more than ``RELINEARISE_PX`` from it) and :meth:`_reference` there."""
        if self._linear is None or np.abs(m - self._linear[0]).max() > RELINEARISE_PX:
            self._linear = (m.copy(), self._reference(m))
        return self._linear

    # ------------------------------------------------------------------ the capture
    def result(self, source_name: str) -> Registration:
        """The capture's :class:`Registration`; :class:`FrameError` when too many of its tracked frames
        could not be registered."""
        assert self._motion is not None and self._sigma is not None and self._bent is not None
        assert self._patches is not None and self._compensated is not None
        lost = len(self._unregistered)
        if lost and lost > MAX_UNREGISTERED_SHARE * max(self._tracked, 1):
            k = self._unregistered[0]
            raise FrameError(f"{source_name}: the motion of {lost} of {self._tracked} frames could not be measured "
                             f"against frame {self.reference_frame} (the first: frame {k}, {self._names[k]}): the "
                             "camera moved more than a scan follows, or the view changed; keep the camera still, "
                             "or set [capture] register = \"off\" for a camera that did not move")
        applied = np.where(self._compensated[:, None], self._motion, np.nan)
        for i, held in self._held_motion.items():
            applied[i] = held
        return Registration(self.reference_frame, list(self._names), self._motion, self._sigma, self._bent,
                            self._patches, self._compensated, applied, list(self._unregistered), list(self._dim),
                            list(self._doubtful), list(self._anchors),
                            border_band(self.shape, applied[self._compensated]), len(self._corners),
                            self._measure_s, self._resample_s)


def _robust_scale(residuals: np.ndarray) -> float:
    """The noise's σ from the ``SCALE_PERCENTILE``-th percentile of the residuals' magnitudes (the lower
    part: the changed pixels are the tail)."""
    magnitude = np.abs(residuals)
    k = int(len(magnitude) * SCALE_PERCENTILE / 100)
    half_normal = NormalDist().inv_cdf(0.5 + SCALE_PERCENTILE / 200)  # that percentile of |N(0, 1)|
    return float(np.partition(magnitude, k)[k]) / half_normal


def _covariances(columns: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per patch, the weighted covariances (K, 5, 5) of ``columns`` (K, 5, n; the first is 1) under the
    weights ``w`` (K, n) (sums about the weighted means, not divided), and the weights' sums (K,)."""
    gram = np.matmul(columns * w[:, None, :], columns.transpose(0, 2, 1)).astype(np.float64)
    total = np.maximum(gram[:, 0, 0], 1e-9)
    return gram - gram[:, 0, :, None] * gram[:, 0, None, :] / total[:, None, None], total


# ---------------------------------------------------------------------- coarse: phase correlation
def _coarse(grey: np.ndarray, scale: int) -> np.ndarray:
    """The frame ``scale`` times smaller, high-passed (minus its blur) and windowed, for the phase correlation."""
    small = cv2.resize(_as_8bit(grey), None, fx=1 / scale, fy=1 / scale, interpolation=cv2.INTER_AREA)
    high = small - cv2.GaussianBlur(small, (0, 0), 4.0)
    window = cv2.createHanningWindow((small.shape[1], small.shape[0]), cv2.CV_32F)
    return (high * window).astype(np.float32)


def _phase_shift(ref: np.ndarray | None, frame: np.ndarray, scale: int) -> np.ndarray:
    """The frame's motion against the reference by phase correlation (px, full scale)."""
    if ref is None:
        return np.zeros(2)
    (dx, dy), _ = cv2.phaseCorrelate(ref, frame)
    return np.array([dx, dy]) * scale
