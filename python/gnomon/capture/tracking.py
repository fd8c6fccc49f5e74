"""Per-pixel shadow times from a stream of grey frames: one shadow event (dip) per pixel.

For every pixel the tracker finds the deepest *dip* of the sequence: dark
samples with brighter ones on both sides within the dip width ``W``
(``max_width``, frames). Frames are grouped in blocks of ``W``; for frame
``k`` of block ``b`` the left context is the brightest sample from the start of
block ``b − 1`` to ``k − 1``, the right context the brightest from ``k + 1`` to
the end of block ``b + 1`` (clamped to the sequence; empty = 0), and the depth
is ``max(0, min(left, right) − I[k])`` (DN). A slow wide darkening (a cloud,
dusk) or a step that never returns (night, dawn) has no depth beyond the noise.

Depths are folded in time order into events: a frame within ``W`` frames
after the best event's frame belongs to it; a farther one counts for another
event, so ``rival`` is the depth of the deepest *other* dip. A pixel is
``ambiguous`` (no times) when ``rival ≥ ambiguity · contrast``.

Reported per pixel: the dip's lit level ``imax = min(left, right)`` and
darkest sample ``imin`` (DN of the input), ``contrast = imax − imin``, the
threshold at mid-level in *linear irradiance* ``(L(imax) + L(imin)) / 2``
where ``L`` decodes DN to irradiance (see :func:`decoding_lut`), and two
shadow times in frames (frame ``i`` is time ``i``) at sub-frame precision:

* ``enter``: the intensity falls through the threshold into the dip,
* ``leave``: it rises back through it, after ``enter``.

How: the enter and leave crossings are located in DN (the last fall through
``(imax + imin)/2`` before the dip's darkest frame, the first rise after it)
and the ``2m`` raw samples around each are kept (frames ``j−m … j+m−1``,
clamped to the sequence); at the end the crossing of the linear threshold
nearest each window's centre is interpolated linearly between the two decoded
samples around it: ``t = k + (v_k − thr) / (v_k − v_{k+1})``. The slope
``|v_k − v_{k+1}|`` (linear units per frame) at the crossing is kept for the
noise model ``σ_t = σ_I / slope``. ``clipped`` flags a dip whose levels or
interpolated samples are 0 or the type's maximum (times may be biased).

One intensity representation: the frames reach the kernel as they were
decoded from the files (DN of the input, uint8 or uint16), with the capture's
one decoding table :func:`decoding_lut`; ``min_contrast`` is in DN of the
input and the kernel applies it, in every mode. When the light changes (the
sun, ``normalize_illumination``), :class:`IlluminationNormalizer` measures
each frame's gain and the kernel divides the decoded samples by it; each dip
is then reported in the light it was seen in: ``imax``/``imin``/``contrast``
in (fractional) DN of the input, the threshold and slopes in linear units.
:func:`linear` decodes such levels.

The work is done by the Rust kernel (:class:`gnomon._kernel.TemporalTracker`,
streaming, explicit SIMD, memory independent of the number of frames).
:class:`NumpyTracker` is an independent numpy implementation of the same
definitions: the tests cross-check the two and ``gnomon bench`` uses it as the
baseline.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, fields, replace

import numpy as np

from gnomon import _kernel
from gnomon.capture.cloud_levels import HeldFrame, cloud_levels
from gnomon.capture.frames import DroppedFrame, Frame, FrameSource, frame_pass
from gnomon.capture.noise import image_noise_dn
from gnomon.capture.registration import FrameRegistrar, Registration, reference_frame, registered
from gnomon.capture.steps import StepTracker
from gnomon.errors import FrameError, KernelArrayError, KernelFramesError, KernelLutError, KernelParameterError
from gnomon.util.progress import Progress
from gnomon.util.validate import MAX_DIP_FRAMES

SUPPORTED_DTYPES = (np.dtype(np.uint8), np.dtype(np.uint16))

MIN_CONTRAST_SIGMAS = 8.0  # a dip this many σI deep (of one frame) is not noise


@dataclass
class ShadowTimes:
    """The tracker's per-pixel results; every array is (H, W).

    ``imax``, ``imin``, ``contrast``: float32, DN of the input: the deepest
    dip's lit level, darkest sample and depth (0 where there is no dip;
    fractional with illumination normalisation, in the light of the dip).
    ``threshold``: float32, linear irradiance units of the decoding LUT.
    ``enter``, ``leave``: float32 shadow times in frames, NaN = no crossing or
    invalid pixel. ``enter_slope``, ``leave_slope``: float32
    ``|ΔL|`` per frame at the crossing (linear units), NaN likewise.
    ``rival``: float32 DN, depth of the deepest other dip (0 = none).
    ``valid``: bool, a dip with ``contrast ≥ min_contrast`` that is not ambiguous.
    ``ambiguous``: bool, ``contrast ≥ min_contrast`` but ``rival ≥ ambiguity · contrast``.
    ``clipped``: bool, the dip's levels or a sample interpolated at a crossing
    is 0 or the dtype's maximum.
    """

    imax: np.ndarray
    imin: np.ndarray
    contrast: np.ndarray
    threshold: np.ndarray
    enter: np.ndarray
    leave: np.ndarray
    enter_slope: np.ndarray
    leave_slope: np.ndarray
    rival: np.ndarray
    valid: np.ndarray
    ambiguous: np.ndarray
    clipped: np.ndarray

    @classmethod
    def from_kernel(cls, result: _kernel.ShadowTimes | ShadowTimes) -> ShadowTimes:
        """The (writable) arrays of ``TemporalTracker.finish``'s result (or :meth:`NumpyTracker.finish`'s)."""
        return cls(**{f.name: np.asarray(getattr(result, f.name)) for f in fields(cls)})

    @property
    def shape(self) -> tuple[int, int]:
        return self.enter.shape

    def drop(self, pixels: np.ndarray) -> None:
        """Forget the dips of ``pixels`` ((H, W) bool), in place: no contrast, no times, not valid."""
        for name in ("contrast", "rival"):
            getattr(self, name)[pixels] = 0.0
        for name in ("enter", "leave", "enter_slope", "leave_slope"):
            getattr(self, name)[pixels] = np.nan
        for name in ("valid", "ambiguous", "clipped"):
            getattr(self, name)[pixels] = False


@dataclass
class SecondDips:
    """Every pixel's second candidate dip (the event whose depth is ``ShadowTimes.rival``), and
    the best dip's times wherever it exists; every array is (H, W) float32.

    ``imax``, ``imin``, ``contrast`` (DN of the input), ``threshold`` (linear), ``enter``,
    ``leave`` (frames), ``enter_slope``, ``leave_slope`` (linear per frame): the second dip, as
    :class:`ShadowTimes` defines them for the best (0 levels and NaN times where there is none).
    ``best_enter``, ``best_leave``, ``best_enter_slope``, ``best_leave_slope``: the best dip's
    times and slopes also where it is ambiguous or below the contrast floor. A light model
    that can tell its own shadow's dip from another chooses between the two
    (:meth:`gnomon.light.base.LightModel.choose_dips`).
    """

    imax: np.ndarray
    imin: np.ndarray
    contrast: np.ndarray
    threshold: np.ndarray
    enter: np.ndarray
    leave: np.ndarray
    enter_slope: np.ndarray
    leave_slope: np.ndarray
    best_enter: np.ndarray
    best_leave: np.ndarray
    best_enter_slope: np.ndarray
    best_leave_slope: np.ndarray

    @classmethod
    def from_kernel(cls, result: _kernel.SecondDips) -> SecondDips:
        return cls(**{f.name: np.asarray(getattr(result, f.name)) for f in fields(cls)})

    def drop(self, pixels: np.ndarray) -> None:
        """Forget both dips of ``pixels`` ((H, W) bool), in place (as :meth:`ShadowTimes.drop`)."""
        self.contrast[pixels] = 0.0
        for f in fields(self):
            if f.name.endswith(("enter", "leave", "slope")):
                getattr(self, f.name)[pixels] = np.nan


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


def contrast_floor(min_contrast: float | None, noise_dn: float | None) -> float:
    """The contrast floor in force (DN of the input): the field log's ``min_contrast`` and
    ``MIN_CONTRAST_SIGMAS`` σ of the image noise ``noise_dn`` (DN), whichever is higher (a missing
    one does not count). Random frames have a large ``imax − imin`` everywhere but never many σ
    of their own noise."""
    floors = [float(min_contrast) if min_contrast is not None else 0.0]
    if noise_dn is not None:
        floors.append(MIN_CONTRAST_SIGMAS * float(noise_dn))
    return max(floors)


def linear(values_dn: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Linear irradiance (float32) of per-pixel levels in DN of the input (``ShadowTimes.imax``,
    ``imin``: integers, or fractional with illumination normalisation), decoded by ``lut``
    (:func:`decoding_lut`), linearly between its entries; NaN → 0.

    Levels that are all whole codes within the table (the tracker's, without illumination normalisation)
    are looked up directly: ``np.interp`` returns an entry itself at its own abscissa, so the values are
    the same, without a binary search per pixel."""
    values = np.asarray(values_dn)
    fp = np.asarray(lut).astype(np.float64)
    if values.dtype == np.float32 and values.size and len(fp) < 2**31:
        with np.errstate(invalid="ignore"):
            codes = values.astype(np.int32)  # NaN and out-of-range values fail the checks below
            whole = bool(np.array_equal(codes, values)) and int(codes.min()) >= 0 and int(codes.max()) < len(fp)
        if whole:
            return fp[codes].astype(np.float32)
    dn = np.nan_to_num(np.asarray(values_dn, dtype=np.float64))
    return np.interp(dn, np.arange(len(lut), dtype=np.float64), fp).astype(np.float32)


# A frame whose global level falls below the level its recent trend predicts by more than
# DIP_SIGMAS times the trend's own scatter (log units; at least MIN_DIP, at most log(1/CLOUD_DROP))
# darkened suddenly and together: a dip (a cloud, a flicker).
CLOUD_DROP = 0.85
MIN_DIP = 0.05
DIP_SIGMAS = 6.0
# Accepted frames whose level steps (log per frame) give the trend, and whose residuals its scatter.
GAIN_HISTORY = 5
SCATTER_HISTORY = 15
# Frame pairs at the start of a sequence used to estimate the image noise.
NOISE_PAIRS = 4
# Linear irradiance below which a pixel of the reference frame does not take part in the gain.
GAIN_FLOOR = 0.02


class IlluminationNormalizer:
    """Per-frame gain (the light's level) and cloud detection (streaming).

    ``gain(frame)`` returns the frame's gain, its global linear irradiance
    relative to the first frame's (the kernel divides the decoded samples by
    it), or None for a frame to skip.

    The reference is the last *accepted* frame (subsampled every ``step``
    pixels), so it follows the day's slow change (dawn, the sun's course,
    dusk) and never sits inside a cloud. A frame's gain relative to it is the
    interquartile mean of the per-pixel log ratios over the pixels lit in the
    reference (robust to the sweeping shadow's band and the sky brightening
    under a cloud, and free of 8-bit quantisation, which a median rounds to
    0). The gains chain up to the first frame.

    The level a frame should have is the reference's carried forward by the
    trend (the median per-frame step of the last ``GAIN_HISTORY`` accepted
    frames). How far accepted frames fall from that prediction measures how
    smooth the light is (the scatter: 1.4826 × their median absolute
    residual); a frame below it (and below the reference) by more than
    ``DIP_SIGMAS`` scatters per frame since the reference (at least
    ``MIN_DIP``, at most ``log(1/CLOUD_DROP)``) darkened suddenly and
    together — a cloud, a flicker — and is skipped. A slow change (dawn,
    dusk) follows the trend and is divided out. A darkening that lasts
    ``max_run`` frames is no dip but a new level (the weather changed, the
    exposure): the frame is accepted and the trend restarts from it; so does
    a dip whose level came back up and stopped rising below the trend (the
    light went on changing meanwhile: dusk after a cloud).
    """

    def __init__(self, lut: np.ndarray, step: int = 4, max_run: int = 32):
        self.lut = lut.astype(np.float32)
        self.step = step
        self.max_run = max_run
        self.reference: np.ndarray | None = None
        self.reference_log_gain = 0.0
        self.frames = 0  # frames seen
        self.reference_frame = -1  # index of the reference among the frames seen
        self.steps: list[float] = []  # per-frame log-gain steps between accepted frames
        self.residuals: list[float] = []  # accepted frames' log level minus the trend's prediction
        self.gains: list[float] = []  # every frame's gain (relative to the first frame)
        self.accepted_gains: list[float] = []  # the gain of each frame returned (fed to the tracker)
        self.skipped: list[int] = []  # indices (among the frames seen) refused as dips
        self._previous = 0.0  # the previous frame's log level
        self._run_min = np.inf  # the lowest log level of the current run of skipped frames

    def log_gain(self, sub: np.ndarray) -> float:
        """log of the frame's global level relative to the first frame (the reference's chain), from
        the frame's linear irradiance at every ``step``-th pixel."""
        if self.reference is None:
            return 0.0
        ok = self.reference > GAIN_FLOOR
        if np.count_nonzero(ok) < 16:
            return self.reference_log_gain
        ratio = np.log(np.maximum(sub[ok], 1e-6) / self.reference[ok])
        lo, hi = np.percentile(ratio, [25.0, 75.0])
        core = ratio[(ratio >= lo) & (ratio <= hi)]
        return self.reference_log_gain + float(core.mean())

    def tolerance(self, gap: int) -> float:
        """How far (log) below the trend a frame ``gap`` frames after the reference may fall before
        it is a dip (the prediction's error grows with the gap)."""
        if len(self.residuals) < 3:
            return -float(np.log(CLOUD_DROP))
        scatter = 1.4826 * float(np.median(np.abs(self.residuals[-SCATTER_HISTORY:])))
        return float(np.clip(DIP_SIGMAS * scatter * gap, MIN_DIP, -np.log(CLOUD_DROP)))

    def gain(self, frame: np.ndarray) -> float | None:
        """The frame's gain (> 0), or None for a frame in a sudden dip of the light."""
        # Only the pixels the gain needs are decoded here.
        sub = self.lut[frame[:: self.step, :: self.step]]
        index = self.frames
        self.frames += 1
        lg = self.log_gain(sub)
        self.gains.append(float(np.exp(lg)))
        previous, self._previous = self._previous, lg
        if self.reference is not None:
            gap = index - self.reference_frame
            trend = float(np.median(self.steps[-GAIN_HISTORY:])) if self.steps else 0.0
            expected = self.reference_log_gain + trend * gap
            restart = gap > self.max_run
            # (never a dip: a frame at least as bright as the reference)
            if lg < expected - self.tolerance(gap) and lg < self.reference_log_gain and not restart:
                # The level came back up from the dip's bottom and has stopped rising: the dip is over,
                # it only ended below the trend (dusk went on meanwhile): a new level from here.
                recovered = previous > self._run_min + self.tolerance(1) and lg - previous <= trend + self.tolerance(1)
                self._run_min = min(self._run_min, lg)
                if not recovered:
                    self.skipped.append(index)
                    return None
                restart = True
            self._run_min = np.inf
            if restart:  # a lasting new level: start the trend again from here
                self.steps, self.residuals = [], []
            else:
                self.steps.append((lg - self.reference_log_gain) / gap)
                self.residuals.append(lg - expected)
        self.reference = sub
        self.reference_log_gain = lg
        self.reference_frame = index
        gain = max(float(np.exp(lg)), 1e-6)
        self.accepted_gains.append(gain)
        return gain


@dataclass(frozen=True)
class TrackerSettings:
    """How frames become shadow times: plain values, resolved from the field log.

    ``gamma``: the frames' encoding (:func:`decoding_lut`, the one decoding table); ``min_contrast``:
    DN of the input (None: no floor here; the scan keeps the dips that stand
    ``MIN_CONTRAST_SIGMAS`` σ of the measured image noise out of it); ``window``: the half-width
    ``m`` of the kept windows;
    ``normalize_illumination``: the kernel divides every frame's decoded samples by its global
    gain, and sudden dips are skipped (:class:`IlluminationNormalizer`); ``max_width`` (frames): the
    widest dip always found; ``ambiguity``: the rival/contrast ratio from which
    a pixel is ambiguous; ``second_dips``: also report every pixel's second
    candidate dip (:class:`SecondDips`, for a light model that chooses between
    the two; the kernel keeps them only then: its block pass is about a third
    cheaper per frame without, and :meth:`ShadowTracker.second_dips` needs it); ``register``: measure
    every tracked frame's motion against the first and resample the frames that moved onto its grid
    (:mod:`gnomon.capture.registration`); ``steps``: report each pixel's strongest lasting step into and
    out of the shadow instead of its dip (:mod:`gnomon.capture.steps`: a straight edge's shadow under the
    sun, which passes each pixel once and does not come back), over the same frames, the dip width
    ``max_width`` the steps' sides.
    """

    gamma: float | str = "srgb"
    min_contrast: float | None = 20.0
    window: int = 4
    normalize_illumination: bool = False
    max_width: int = 32
    ambiguity: float = 0.6
    second_dips: bool = False
    register: bool = False
    steps: bool = False


class ShadowTracker:
    """The kernel tracker fed with one capture's grey frames: the one place that drives it.

    ``shape`` (H, W) and ``dtype`` (uint8 or uint16) of the frames, which the
    kernel receives unchanged with the decoding table ``lut``. With
    ``settings.normalize_illumination`` each frame goes with its gain and
    :meth:`update` refuses frames in a sudden dip.
    """

    def __init__(self, settings: TrackerSettings, shape: tuple[int, int], dtype: np.dtype,
                 crop: tuple[slice, slice] | None = None):
        self.settings = settings
        self.lut = decoding_lut(settings.gamma, dtype)
        self.normalizer = (IlluminationNormalizer(self.lut, max_run=settings.max_width)
                           if settings.normalize_illumination else None)
        # ``crop`` (rows, columns): track only this part of each frame; the normalisation still sees the
        # whole frame, so a tile's shadow times equal the same pixels' in an untiled pass.
        self.crop = crop
        h, w = np.empty(shape, dtype=bool)[crop].shape if crop is not None else shape
        self._tracker = _kernel.TemporalTracker(h, w, dtype="uint8" if _check_dtype(dtype) == np.uint8 else "uint16",
                                                window=settings.window, max_width=settings.max_width,
                                                ambiguity=settings.ambiguity, lut=self.lut,
                                                normalise=self.normalizer is not None,
                                                second_dips=settings.second_dips)
        # The steps (a straight edge's shadow), over exactly the frames and levels the kernel sees.
        self._steps = (StepTracker((h, w), self.lut, settings.max_width, min(settings.window, 4),
                                   settings.ambiguity) if settings.steps else None)
        self.fed: list[int] = []  # capture index of every frame the kernel saw, in order
        self.refused: list[int] = []  # capture index of every frame it did not see (illumination dips)
        self.levelled: list[int] = []  # capture index of every frame fed levelled pixel by pixel (a cloud's)
        self._given = 0
        self._held: list[tuple[int, HeldFrame]] = []  # a dip's frames waiting for its end
        self._clear: tuple[np.ndarray, float] | None = None  # the last frame fed with one gain, and its gain

    def update(self, grey: np.ndarray, index: int | None = None) -> bool:
        """Feed one frame (DN; ``index``: its capture index, default the count of frames given);
        False when nothing reached the kernel now: the frame is held as part of an illumination
        dip (a cloud), to be levelled pixel by pixel (:mod:`gnomon.capture.cloud_levels`) and fed once the
        dip is over, before the frame that ends it. :attr:`fed` and :attr:`refused` say, after
        :meth:`flush`, which frames the kernel saw (in order) and which it did not."""
        index = self._given if index is None else int(index)
        self._given += 1
        if self.normalizer is None:
            self._feed(grey, None, None)
            self.fed.append(index)
            return True
        gain = self.normalizer.gain(grey)
        if gain is None:
            if self._clear is None or len(self._held) >= self.settings.max_width:
                self.refused.append(index)
            else:
                self._held.append((index, HeldFrame(grey, self.normalizer.gains[-1])))
            return False
        if self._held and self._clear is not None:
            before, gain_before = self._clear
            held = [h for _, h in self._held]
            for (i, _), (clear_gain, levels), h in zip(self._held, cloud_levels(self.lut, before, gain_before, grey,
                                                                                gain, held), held, strict=True):
                self._feed(h.grey, clear_gain, levels, h.gain)
                self.fed.append(i)
                self.levelled.append(i)
            self._held = []
        self._feed(grey, gain, None)
        self.fed.append(index)
        self._clear = (grey, gain)
        return True

    def _feed(self, grey: np.ndarray, gain: float | None, levels: np.ndarray | None,
              measured_gain: float | None = None) -> None:
        """One frame to the kernel (and the steps); a frame levelled pixel by pixel comes with its
        ``measured_gain`` (its own global level), which the steps take instead of the levels: these are fitted
        for a thin passing shadow, and would move a step made under the cloud."""
        if self.crop is not None:
            grey = np.ascontiguousarray(grey[self.crop])
            levels = None if levels is None else np.ascontiguousarray(levels[self.crop])
        if levels is None:
            self._tracker.update(grey, gain)
        else:
            self._tracker.update(grey, gain, levels)
        if self._steps is not None:
            self._steps.update(grey, gain if levels is None else measured_gain)

    def flush(self) -> None:
        """The frames still held at the end (a dip the capture ends in) are refused."""
        self.refused += [i for i, _ in self._held]
        self._held = []

    def watch(self, min_contrast: float, recover: int = 3) -> None:
        """Start the kernel's live watch (:meth:`gnomon._kernel.TemporalTracker.watch`) from the next frame.

        ``min_contrast`` (DN of the input) opens a dip; ``recover`` frames back above the
        mid-level end it. The provisional levels, threshold and slopes are in :meth:`finish`'s
        units.
        """
        self._tracker.watch(float(min_contrast), int(recover))

    def take_finished(self) -> _kernel.FinishedPixels:
        """The pixels whose dip ended since the last call (:meth:`watch` first); indices are
        row-major in the tracked frame (the crop, when there is one)."""
        return self._tracker.take_finished()

    @property
    def watch_counts(self) -> tuple[int, int, int] | None:
        """Pixels of the live watch lit, in a dip and finished (None before :meth:`watch`)."""
        return self._tracker.watch_counts

    def second_dips(self) -> SecondDips:
        """The second candidate dips (:class:`SecondDips`), in the units :meth:`finish` reports
        (each dip in its own light); ``KernelParameterError`` unless ``settings.second_dips``."""
        return SecondDips.from_kernel(self._tracker.finish_second())

    def finish(self, noise_dn: float | None = None) -> ShadowTimes:
        """The shadow times so far: the kernel keeps the dips at least :func:`contrast_floor` deep
        (``settings.min_contrast`` and, given the image noise ``noise_dn`` (DN), its multiple). With
        ``settings.steps``, the steps instead (:class:`~gnomon.capture.steps.StepTracker`, the same floor)."""
        floor = contrast_floor(self.settings.min_contrast, noise_dn)
        if self._steps is not None:
            return ShadowTimes(**self._steps.finish(floor))
        return ShadowTimes.from_kernel(self._tracker.finish(floor))


@dataclass
class TrackedSequence:
    """One tracking pass over a capture.

    ``used``: capture index of each frame the tracker saw (its frame ``i`` is
    capture frame ``used[i]``); ``skipped_dips``: capture frames refused as
    illumination dips; ``first_grey``/``first_color``: the first frame (grey,
    and BGR when the capture is in colour); ``noise_dn``: image noise (DN of
    the input); ``lut``: the capture's decoding table (DN of the input →
    linear, :func:`linear` for the times' levels); ``info``: how the pass ran
    when that is worth reporting (a tiled pass: tiles, workers, memory);
    ``dropped``: the corrupt frames the source left out (``[capture] on_corrupt_frame = "drop"``).
    ``registration``: each frame's motion against the first, when the pass
    registered the frames (:class:`~gnomon.capture.registration.Registration`;
    its border pixels have no dip).
    """

    times: ShadowTimes
    used: np.ndarray
    skipped_dips: list[int]
    first_grey: np.ndarray
    first_color: np.ndarray | None
    noise_dn: float
    lut: np.ndarray
    info: dict = field(default_factory=dict)
    second: SecondDips | None = None  # the second candidate dips, when the pass kept them
    levelled: list[int] = field(default_factory=list)  # capture frames of illumination dips levelled per pixel
    dropped: list[DroppedFrame] = field(default_factory=list)
    registration: Registration | None = None

    @property
    def n_frames(self) -> int:
        """Frames fed to the tracker."""
        return len(self.used)

    @property
    def levelled_frames(self) -> np.ndarray:
        """The tracker frames (indices into ``used``) that were levelled pixel by pixel (int64)."""
        return np.flatnonzero(np.isin(self.used, self.levelled)).astype(np.int64)


def track_source(
    source: FrameSource,
    settings: TrackerSettings,
    shape: tuple[int, int],
    *,
    skip: np.ndarray | None = None,
    on_frame: Callable[[Frame], None] | None = None,
    progress: bool = False,
    where: str = "[camera]",
    crop: tuple[slice, slice] | None = None,
    on_update: Callable[[Frame, ShadowTracker], None] | None = None,
) -> TrackedSequence:
    """One streaming pass over a capture's frames through the kernel tracker.

    ``shape``: the (H, W) every frame must have (``where`` names its origin in
    errors); ``skip``: (N,) bool, capture frames the tracker must not see;
    ``crop``: (rows, columns) slices, track only that tile (the shadow times
    are then the tile's; everything per frame is still measured on the whole
    frame, see :class:`ShadowTracker`);
    ``on_frame(frame)`` is called for every frame (skipped ones too), e.g. to
    record it; ``on_update(frame, tracker)`` after each frame the tracker took
    (a live view reads the tracker's watch there, :mod:`gnomon.runs.live`).
    With ``settings.register`` every frame the tracker takes is first registered against a reference
    frame (:func:`~gnomon.capture.registration.reference_frame`, :class:`~gnomon.capture.registration.FrameRegistrar`):
    ``on_frame``, ``on_update`` and the tracker see it on the reference's grid, a frame whose motion
    cannot be measured is left out, and the pixels at the border the moved frames do not see get no dip.
    Raises :class:`FrameError` for a frame of another size, a
    source with fewer frames than expected, fewer than two usable frames, or a camera that moved more
    than the registration follows.
    """
    tracker: ShadowTracker | None = None
    registrar = None
    if settings.register:
        registrar = FrameRegistrar(shape, source.count)
        reference = reference_frame(source, skip)
        if reference is not None and reference.grey.shape == shape:
            registrar.set_reference(reference)
    first: Frame | None = None
    previous: np.ndarray | None = None
    noise: list[Future[float]] = []
    seen = 0
    # The noise estimate (first frame pairs) runs on a worker thread while the tracker goes on.
    # With registration, the frames are registered on a thread of their own a few frames ahead.
    with Progress("tracking", source.count, enabled=progress) as bar, \
            ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-noise") as pool, \
            frame_pass(source) as frames, registered(frames, registrar, skip) as stream:
        for read, frame, skipped in stream:
            seen += 1
            if first is None:
                _check_first(read, shape, where)
                first, tracker = read, ShadowTracker(settings, shape, read.grey.dtype, crop)
            if not skipped:
                if previous is not None and len(noise) < NOISE_PAIRS:
                    # the first frames the tracker sees (not the night's, clipped at black), before any
                    # illumination drift has accumulated
                    noise.append(pool.submit(image_noise_dn, previous, frame.grey))
                previous = frame.grey
            if on_frame is not None:
                on_frame(frame)
            bar.update(frame.index + 1)
            if skipped:
                continue
            assert tracker is not None
            if tracker.update(frame.grey, frame.index) and on_update is not None:
                on_update(frame, tracker)
    if tracker is None or first is None:
        raise FrameError(f"{source.name}: no frames")
    tracker.flush()
    used, dips = tracker.fed, sorted(tracker.refused)
    dropped = list(getattr(source, "dropped", ()))  # a drop-in source may not drop frames
    if source.expected_count is not None and seen + len(dropped) < source.expected_count:
        raise FrameError(f"{source.name}: only {seen + len(dropped)} frames, expected {source.expected_count}")
    if len(used) < 2:
        raise FrameError(f"{source.name}: fewer than two usable frames (sun below the horizon or clouds)")
    noise_dn = float(np.median([n.result() for n in noise])) if noise else 1.0
    times = tracker.finish(noise_dn)
    second = tracker.second_dips() if settings.second_dips else None
    registration = None if registrar is None else registrar.result(source.name)
    if registration is not None and registration.border.any():
        border = registration.border if crop is None else registration.border[crop]
        times.drop(border)
        if second is not None:
            second.drop(border)
    return TrackedSequence(times, np.asarray(used), dips, first.grey, first.color, noise_dn, tracker.lut,
                           second=second, levelled=list(tracker.levelled), dropped=dropped,
                           registration=registration)


# The width (TrackerSettings.max_width, frames) a scan starts from; the kernel's widest is MAX_DIP_FRAMES.
DEFAULT_DIP_FRAMES = 32
# A pass's dips are at its width's limit when more than LONG_DWELL_SHARE of its tracked pixels stayed in
# shadow (leave − enter) longer than LONG_DWELL times the width: a shadow that stays longer than the width
# is cut in two events, and its pixel is left out as ambiguous (two comparable dips) or gets no time.
LONG_DWELL = 0.75
LONG_DWELL_SHARE = 0.02
# Passes of one capture at most (the first, then each wider one).
WIDENING_PASSES = 3


@dataclass(frozen=True)
class Dwell:
    """How long a pass's tracked pixels stayed in shadow (``leave − enter``, frames), against its dip width.

    ``width``: the pass's widest dip (frames); ``pixels``: tracked pixels with both times;
    ``p99``: the 99th percentile of their dwell (frames; NaN without pixels); ``long_share``: the share of
    them that stayed longer than ``LONG_DWELL · width``.
    """

    width: int
    pixels: int
    p99: float
    long_share: float

    @property
    def at_limit(self) -> bool:
        """The pass's dips reach its width: longer shadows were cut in two (see ``LONG_DWELL_SHARE``)."""
        return self.long_share > LONG_DWELL_SHARE

    def wider(self) -> int | None:
        """The width to track again with when the dips are at the limit (at least double, and 1.5 times the
        99th percentile dwell, a multiple of 16, at most ``MAX_DIP_FRAMES``); None when they are not, or the
        width is already the widest."""
        if not self.at_limit or self.width >= MAX_DIP_FRAMES:
            return None
        want = max(2.0 * self.width, 1.5 * self.p99 if np.isfinite(self.p99) else 0.0)
        return int(min(MAX_DIP_FRAMES, 16 * np.ceil(want / 16.0)))

    def describe(self) -> str:
        return (f"{self.long_share:.0%} of the tracked pixels stayed in shadow longer than "
                f"{LONG_DWELL * self.width:.0f} of the {self.width} frames a dip may last "
                f"(99th percentile {self.p99:.0f} frames)")


def dwell(times: ShadowTimes, width: int) -> Dwell:
    """:class:`Dwell` of ``times`` (a pass of widest dip ``width`` frames) over its valid pixels."""
    both = times.valid & np.isfinite(times.enter) & np.isfinite(times.leave)
    d = (times.leave[both] - times.enter[both]).astype(np.float64)
    if d.size == 0:
        return Dwell(int(width), 0, float("nan"), 0.0)
    return Dwell(int(width), int(d.size), float(np.percentile(d, 99)), float(np.mean(d > LONG_DWELL * width)))


def track_widening(
    track_pass: Callable[..., TrackedSequence],
    source: FrameSource,
    settings: TrackerSettings,
    shape: tuple[int, int],
    *,
    dip_width: str,
    **kwargs: object,
) -> tuple[TrackedSequence, TrackerSettings, list[str]]:
    """``track_pass(source, settings, shape, **kwargs)`` (:func:`track_source` or a drop-in), then, when the
    shadow stayed on many pixels nearly as long as the widest dip (:class:`Dwell`) and ``dip_width`` is
    ``"auto"``, again with a wider one (at most ``WIDENING_PASSES`` passes, ``MAX_DIP_FRAMES`` frames): the
    source is read again, without ``on_frame`` (the first pass saw every frame) and without colour.

    ``dip_width``: who set the width (:func:`gnomon.config.setup.dip_width_policy`): ``"auto"`` widens;
    ``"field log"`` and ``"live"`` keep it; ``"sun"`` keeps it and is not checked (there the width is what
    tells a shadow from a cloud or dusk). Returns the last pass, its settings and what to tell the user: a
    note for each widening, a warning when the dips are still at the limit (the width was kept, or the
    widest reached), except under the sun.
    """
    widen = dip_width == "auto"
    tracked = track_pass(source, settings, shape, **kwargs)
    d = dwell(tracked.times, settings.max_width)
    notes: list[str] = []
    again = {**kwargs, "on_frame": None}
    for _ in range(WIDENING_PASSES - 1):
        wider = d.wider() if widen else None
        if wider is None:
            break
        notes.append(f"{d.describe()}: longer shadows are cut in two; tracked again with dips of up to {wider} "
                     f"frames ([scan] max_dip_frames = {wider} skips the first pass)")
        settings = replace(settings, max_width=wider)
        colour = getattr(source, "color_frames", None)
        if colour is not None:
            source.color_frames = frozenset()  # the colour samples came with the first pass
        try:
            tracked = track_pass(source, settings, shape, **again)
        finally:
            if colour is not None:
                source.color_frames = colour
        d = dwell(tracked.times, settings.max_width)
    if dip_width != "sun" and d.at_limit:
        if settings.max_width >= MAX_DIP_FRAMES:
            fix = (f"the tracker finds no dip wider than {MAX_DIP_FRAMES} frames: keep fewer frames (every second "
                   "one) or sweep faster")
        elif not widen:
            fix = f"set [scan] max_dip_frames = {d.wider()}"
        else:
            fix = "the last pass was the widest this scan tracks"
        notes.append(f"{d.describe()}: longer shadows are cut in two and left out as ambiguous; {fix}")
    return tracked, settings, notes


def _check_first(frame: Frame, shape: tuple[int, int], where: str) -> None:
    if frame.grey.shape != shape:
        g = frame.grey
        raise FrameError(f"frame 0 ({frame.name}): size {g.shape[1]}x{g.shape[0]} differs from the "
                         f"camera's {shape[1]}x{shape[0]} ({where})")


def track(
    frames: Iterable[np.ndarray],
    *,
    min_contrast: float,
    gamma: float | str,
    window: int = 4,
    max_width: int = 32,
    ambiguity: float = 0.6,
    progress: Callable[[int], None] | None = None,
) -> ShadowTimes:
    """Track a sequence of grey frames with the kernel and return the shadow times.

    ``frames``: 2-D uint8 or uint16 arrays, all of the first one's shape and
    dtype. ``min_contrast`` in DN; ``gamma`` as in :func:`decoding_lut`;
    ``window`` the half-width ``m`` of the kept windows; ``max_width`` (frames)
    the widest dip always found; ``ambiguity`` the rival/contrast ratio from
    which a pixel is ambiguous. ``progress(i)`` is
    called after frame ``i`` (0-based) has been fed.

    Raises :class:`gnomon.errors.FrameError` for a frame of another shape or
    dtype (naming it), or when there is no frame at all.
    """
    settings = TrackerSettings(gamma, float(min_contrast), window, False, max_width, ambiguity)
    tracker: ShadowTracker | None = None
    for i, frame in enumerate(frames):
        frame = np.asarray(frame)
        if tracker is None:
            if frame.ndim != 2 or frame.dtype not in SUPPORTED_DTYPES:
                raise FrameError(
                    f"frame 0: expected a 2-D uint8 or uint16 grey image, "
                    f"got a {frame.dtype} array of shape {frame.shape}"
                )
            tracker = ShadowTracker(settings, (frame.shape[0], frame.shape[1]), frame.dtype)
        try:
            tracker.update(frame)
        except ValueError as exc:
            raise FrameError(f"frame {i}: {exc}") from None
        if progress is not None:
            progress(i)
    if tracker is None:
        raise FrameError("no frames to track")
    return tracker.finish()


@dataclass
class _State:
    """NumpyTracker's per-pixel state for the frames of the blocks evaluated so far."""

    d1: np.ndarray  # (N,) int32, deepest depth (0 = no dip)
    d2: np.ndarray  # (N,) int32, deepest other event's depth
    k1: np.ndarray  # (N,) int64, frame of d1, -1 = none
    hi: np.ndarray  # (N,) int32, lit level of the best dip
    lo: np.ndarray  # (N,) int32, its darkest sample
    enter_at: np.ndarray  # (N,) int64, window centres, -1 = none
    leave_at: np.ndarray
    enter_window: np.ndarray  # (N, 2m) raw samples
    leave_window: np.ndarray
    evaluated: int  # frames evaluated (a multiple of W)

    def copy(self) -> _State:
        return replace(self, **{f.name: getattr(self, f.name).copy() for f in fields(self) if f.name != "evaluated"})


_CAPTURE_CHUNK = 1 << 16
"""Pixels whose windows NumpyTracker captures at once (bounds its temporary arrays)."""


class NumpyTracker:
    """The kernel tracker's definitions, implemented independently with numpy.

    Same constructor (without illumination normalisation), ``update``,
    ``frames_seen`` and ``finish`` as :class:`gnomon._kernel.TemporalTracker`
    and the same results. Frames are kept
    in a ring of the last ``3W + 2m``; block ``b`` (frames ``bW … bW+W−1``) is
    evaluated as a whole once frame ``(b+2)W + m − 2`` has arrived: its right
    contexts by a backward running maximum, its left contexts, depths and events
    frame by frame, and the windows of the pixels whose best dip moved by
    boolean searches over the stacked frames. ``finish`` evaluates the pending
    blocks on a copy of the state, clamped to the last frame.
    """

    def __init__(self, height: int, width: int, dtype: str = "uint8", window: int = 4,
                 max_width: int = 32, ambiguity: float = 0.6, lut: np.ndarray | None = None):
        self._dtype = _check_dtype(dtype)
        top = np.iinfo(self._dtype).max
        if lut is None:
            lut = np.arange(top + 1, dtype=np.float32)
        lut = np.asarray(lut)
        if lut.dtype != np.float32 or lut.shape != (top + 1,):
            raise KernelArrayError(
                f"lut: expected a float32 array of shape ({top + 1},), "
                f"got a {lut.dtype} array of shape {lut.shape}"
            )
        if not np.all(np.isfinite(lut)) or np.any(np.diff(lut) < 0):
            raise KernelLutError("invalid decoding LUT: must be finite and non-decreasing")
        self._lut = lut
        if not 2 <= max_width <= 128:
            raise KernelParameterError(f"max_width: must be in 2..=128, got {max_width}")
        if not 1 <= window <= min(64, max_width):
            raise KernelParameterError(f"window: must be in 1..={min(64, max_width)}, got {window}")
        if not 0 < ambiguity <= 1:
            raise KernelParameterError(f"ambiguity: must be in (0, 1], got {ambiguity}")
        self._shape = (int(height), int(width))
        self._m, self._w, self._ambiguity = int(window), int(max_width), float(ambiguity)
        n = self._shape[0] * self._shape[1]
        self._ring = np.zeros((3 * self._w + 2 * self._m, n), self._dtype)

        def i32(v: int) -> np.ndarray:
            return np.full(n, v, np.int32)

        def i64() -> np.ndarray:
            return np.full(n, -1, np.int64)

        self._state = _State(i32(0), i32(0), i64(), i32(0), i32(0), i64(), i64(),
                             np.zeros((n, 2 * self._m), self._dtype),
                             np.zeros((n, 2 * self._m), self._dtype), 0)
        self.frames_seen = 0

    def update(self, frame: np.ndarray) -> None:
        """Add the next frame: a 2-D array of the tracker's dtype and shape."""
        frame = np.asarray(frame)
        if frame.dtype != self._dtype or frame.shape != self._shape:
            raise KernelArrayError(
                f"frame: expected a {self._dtype} array of shape {self._shape}, "
                f"got a {frame.dtype} array of shape {frame.shape}"
            )
        self._ring[self.frames_seen % len(self._ring)] = frame.reshape(-1)
        self.frames_seen += 1
        s = self._state
        if self.frames_seen == s.evaluated + 2 * self._w + self._m - 1:
            self._evaluate(s, self.frames_seen - 1)

    def _frame(self, f: int) -> np.ndarray:
        return self._ring[f % len(self._ring)]

    def _evaluate(self, s: _State, last: int) -> None:
        """Evaluate the block of frames ``s.evaluated …`` (contexts clamped to ``last``)."""
        w = self._w
        start = s.evaluated
        end = min(start + w, last + 1)
        outer = min(start + 2 * w, last + 1)  # end of the right contexts (block b + 1)
        n = s.d1.shape[0]
        # Right contexts, backward: max of frames k+1 … outer−1 (0 when empty).
        acc = np.zeros(n, self._dtype)
        for f in range(outer - 1, end - 1, -1):
            np.maximum(acc, self._frame(f), out=acc)
        right = np.empty((end - start, n), self._dtype)
        for k in range(end - 1, start - 1, -1):
            right[k - start] = acc
            np.maximum(acc, self._frame(k), out=acc)
        # Left contexts, forward from the start of block b − 1.
        left = np.zeros(n, self._dtype)
        for f in range(max(0, start - w), start):
            np.maximum(left, self._frame(f), out=left)
        for k in range(start, end):
            cur = self._frame(k)
            lit = np.minimum(left, right[k - start]).astype(np.int32)
            depth = np.maximum(lit - cur, 0)
            same_event = (s.k1 >= 0) & (k - s.k1 <= w)
            better = depth > s.d1
            np.copyto(s.d2, np.maximum(s.d2, np.minimum(depth, s.d1)), where=~same_event)
            np.maximum(s.d1, depth, out=s.d1)
            s.k1[better] = k
            np.copyto(s.hi, lit, where=better)
            np.copyto(s.lo, cur, where=better, casting="unsafe")
            np.maximum(left, cur, out=left)
        s.evaluated = start + w
        moved = np.flatnonzero(s.k1 >= start)
        if moved.size:
            self._capture(s, moved, start, outer, last)

    def _capture(self, s: _State, px: np.ndarray, start: int, outer: int, last: int) -> None:
        """Enter/leave window centres and windows of the pixels ``px`` whose best dip
        (at ``s.k1``) lies in the block from ``start``, in chunks of pixels."""
        w, m = self._w, self._m
        f0 = max(0, start - w - m)
        f1 = min(last + 1, outer + m - 1)
        frames = np.arange(f0, f1)[:, None]
        offsets = np.arange(-m, m)[:, None]
        for lo in range(0, px.size, _CAPTURE_CHUNK):
            p = px[lo:lo + _CAPTURE_CHUNK]
            stack = np.stack([self._frame(f)[p] for f in range(f0, f1)])  # (F, P)
            k1 = s.k1[p][None, :]
            # 2·v ≥ hi + lo  ⇔  v ≥ ⌈(hi + lo) / 2⌉ (integers)
            bright = stack >= ((s.hi[p] + s.lo[p] + 1) // 2).astype(self._dtype)[None, :]
            before = bright & (frames >= max(0, start - w)) & (frames < k1)
            after = bright & (frames > k1) & (frames < outer)
            enter = f0 + (len(frames) - 1 - np.argmax(before[::-1], axis=0)) + 1
            leave = f0 + np.argmax(after, axis=0)
            s.enter_at[p], s.leave_at[p] = enter, leave
            cols = np.arange(p.size)[None, :]
            s.enter_window[p] = stack[np.clip(enter[None, :] + offsets, 0, last) - f0, cols].T
            s.leave_window[p] = stack[np.clip(leave[None, :] + offsets, 0, last) - f0, cols].T

    def finish(self, min_contrast: float) -> ShadowTimes:
        """Per-pixel results for the frames seen so far, as the kernel's ``finish``."""
        if self.frames_seen == 0:
            raise KernelFramesError("no frames were given to the tracker")
        top = np.iinfo(self._dtype).max
        lut = self._lut
        s = self._state.copy()
        last = self.frames_seen - 1
        while s.evaluated <= last:
            self._evaluate(s, last)

        has_dip = s.enter_at >= 0
        hi = np.where(has_dip, s.hi, 0)
        lo = np.where(has_dip, s.lo, 0)
        contrast = (hi - lo).astype(np.float32)
        threshold = (lut[hi] + lut[lo]) * np.float32(0.5)
        rival = s.d2.astype(np.float32)
        deep = has_dip & (contrast >= np.float32(min_contrast))
        ambiguous = deep & (rival >= np.float32(self._ambiguity) * contrast)
        valid = deep & ~ambiguous
        enter, enter_slope, enter_clip = self._solve(s.enter_at, s.enter_window, threshold, valid, lut, True)
        leave, leave_slope, leave_clip = self._solve(s.leave_at, s.leave_window, threshold, valid, lut, False)
        clipped = has_dip & ((hi == top) | (lo == 0)) | enter_clip | leave_clip
        shape = self._shape
        return ShadowTimes(
            imax=hi.astype(np.float32).reshape(shape),
            imin=lo.astype(np.float32).reshape(shape),
            contrast=contrast.reshape(shape),
            threshold=threshold.reshape(shape),
            enter=enter.reshape(shape),
            leave=leave.reshape(shape),
            enter_slope=enter_slope.reshape(shape),
            leave_slope=leave_slope.reshape(shape),
            rival=rival.reshape(shape),
            valid=valid.reshape(shape),
            ambiguous=ambiguous.reshape(shape),
            clipped=clipped.reshape(shape),
        )

    def _solve(self, at, window, threshold, valid, lut, falling: bool):
        """Crossing nearest the window centre: time (frames), slope (NaN if none) and
        whether a sample interpolated is clipped."""
        n = at.shape[0]
        time = np.full(n, np.nan, np.float32)
        slope = np.full(n, np.nan, np.float32)
        clipped = np.zeros(n, bool)
        idx = np.flatnonzero(valid)
        if idx.size == 0:
            return time, slope, clipped
        raw = window[idx]
        v = lut[raw]  # (n, 2m) float32
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
        top = np.iinfo(self._dtype).max
        pair = np.stack([raw[rows, k], raw[rows, k + 1]])
        clipped[idx[found]] = ((pair == 0) | (pair == top)).any(axis=0)
        return time, slope, clipped
