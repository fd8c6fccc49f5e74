//! Streaming temporal shadow tracker (Bouguet & Perona 1998, §3 of METHOD.md).
//!
//! Per pixel, over a stream of grey frames `I_0 … I_{N-1}`, the tracker ends
//! with `Imax`, `Imin`, the contrast `Imax − Imin` (DN) and two shadow times
//! at sub-frame precision:
//!
//! * **enter**: the intensity falls through the threshold,
//! * **leave**: the intensity rises back through it,
//!
//! with the threshold at mid-level in *linear irradiance*,
//! `thr = (L(Imax) + L(Imin)) / 2`, `L` a decoding LUT (identity if absent).
//!
//! # Algorithm
//! The threshold is known only at the end of the stream, so the tracker keeps,
//! per pixel, the frame `j` of the steepest fall (the largest
//! `I_{j−1} − I_j > 0`, first occurrence) and of the steepest rise (largest
//! `I_j − I_{j−1} > 0`, first occurrence), and the `2m` raw samples around each,
//! frames `j−m … j+m−1` (`m` = [`TrackerParams::window`]), clamped to the first
//! and last frame. [`TemporalTracker::finish`] decodes the two windows with `L`,
//! looks for the threshold crossing nearest the window centre (see
//! [`find_crossing`]) and interpolates linearly between the two samples around
//! it. Memory is `O(pixels)`, independent of the number of frames.
//!
//! # Speed
//! Frames are copied into a ring and folded into the per-pixel state in
//! temporal blocks of `K` frames ([`TrackerParams::block`]), as soon as the
//! block is complete (its frames still in the last-level cache). A block is
//! folded row by row (rayon over rows), 64 pixels at a time whose state stays
//! in SIMD registers across the `K` frames: per pixel and frame, one load and
//! a few branch-free vector operations in the sample's own lane width (see
//! [`crate::sample`]); the state goes to memory once per block.
//! Windows are copied only for pixels whose best fall or rise moved inside a
//! block, and only once every frame of the window is in the ring: with a lag,
//! just before the next block is folded (or by [`TemporalTracker::finish`],
//! which clamps to the last frame).

use std::borrow::Cow;
use std::ops::Range;

use rayon::prelude::*;

use crate::error::KernelError;
use crate::sample::Sample;
use crate::simd::{Portable, SimdPath, Vector};

/// Pixels tested together for "any window to capture" before a scalar scan.
const GROUP: usize = 64;

/// Samples per parallel piece of a frame copied into the ring.
const STORE_PIECE: usize = 1 << 18;

/// Marks "no steepest fall/rise yet" in the per-pixel frame indices.
const NO_FRAME: u32 = u32::MAX;

/// Bits of [`RowState::moved`]: the fall/rise window is not yet captured.
const FELL: u8 = 1;
const ROSE: u8 = 2;

/// Tuning of [`TemporalTracker`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrackerParams {
    /// `m`: half-width of the window kept around the steepest fall and rise
    /// (`2m` samples, frames `j−m … j+m−1`). `1 ≤ m ≤ 64`.
    pub window: usize,
    /// `K`: frames folded together per pass over the state. `1 ≤ K ≤ 128`.
    /// Results do not depend on it; speed and the ring's size (`2K + m` frames
    /// and a little more) do.
    pub block: usize,
}

impl Default for TrackerParams {
    fn default() -> Self {
        TrackerParams {
            window: 4,
            block: 16,
        }
    }
}

impl TrackerParams {
    const MAX_WINDOW: usize = 64;
    /// Keeps every block-local offset (`< K + lag ≤ 191`) below `u8::MAX`.
    const MAX_BLOCK: usize = 128;

    fn validate(&self) -> Result<(), KernelError> {
        if !(1..=Self::MAX_WINDOW).contains(&self.window) {
            return Err(KernelError::parameter(
                "window",
                format!("must be in 1..={}, got {}", Self::MAX_WINDOW, self.window),
            ));
        }
        if !(1..=Self::MAX_BLOCK).contains(&self.block) {
            return Err(KernelError::parameter(
                "block",
                format!("must be in 1..={}, got {}", Self::MAX_BLOCK, self.block),
            ));
        }
        Ok(())
    }

    /// Frames a block is folded late, so that the previous block's windows
    /// (reaching `m − 1` frames past it) are complete when it is folded:
    /// `max(0, m − 1 − K)`.
    fn lag(&self) -> usize {
        (self.window - 1).saturating_sub(self.block)
    }

    /// Ring slots: the previous block's windows reach back `K + m` frames
    /// from the block being folded, which ends `lag` frames before the newest.
    fn ring_slots(&self) -> usize {
        2 * self.block + self.lag() + self.window
    }
}

/// The tracker's per-pixel results, row-major `(height, width)` arrays.
///
/// Intensities are in DN of the input; the threshold and the slopes in the
/// linear units of the decoding LUT; times in frames (frame `i` is time `i`).
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowTimes {
    pub height: usize,
    pub width: usize,
    /// Brightest sample (DN).
    pub imax: Vec<f32>,
    /// Darkest sample (DN).
    pub imin: Vec<f32>,
    /// `imax − imin` (DN).
    pub contrast: Vec<f32>,
    /// `(L(imax) + L(imin)) / 2` (linear units).
    pub threshold: Vec<f32>,
    /// Time the intensity falls through the threshold (frames); NaN = none or invalid.
    pub enter: Vec<f32>,
    /// Time the intensity rises back through it (frames); NaN = none or invalid.
    pub leave: Vec<f32>,
    /// `|L(v_k) − L(v_{k+1})|` at the enter crossing (linear units per frame); NaN = none.
    pub enter_slope: Vec<f32>,
    /// Same at the leave crossing.
    pub leave_slope: Vec<f32>,
    /// 1 where `contrast ≥ min_contrast`, else 0.
    pub valid: Vec<u8>,
}

/// One threshold crossing in a window of samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// The crossing lies between samples `index` and `index + 1`.
    pub index: usize,
    /// `(v_k − thr) / (v_k − v_{k+1})`: in `[0, 1)` for a fall, `(0, 1]` for a rise.
    pub fraction: f32,
    /// `|v_k − v_{k+1}|` (units of the samples per frame).
    pub slope: f32,
}

/// Which way the intensity crosses the threshold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    /// Falling into the shadow: `v_k ≥ thr > v_{k+1}`.
    Enter,
    /// Rising out of it: `v_k < thr ≤ v_{k+1}`.
    Leave,
}

/// The crossing of `threshold` in `values` nearest the centre of the window.
///
/// `values` are `2m` consecutive samples whose centre pair is `(m−1, m)`;
/// candidate pairs are tried at growing distance `d` from it, the earlier pair
/// (`m−1−d`) before the later (`m−1+d`). Pairs of equal samples (as produced by
/// clamping at the ends of the sequence) never cross. `None` if no pair crosses.
pub fn find_crossing(values: &[f32], threshold: f32, edge: Edge) -> Option<Crossing> {
    if values.len() < 2 {
        return None;
    }
    let pairs = values.len() - 1;
    let centre = (values.len() / 2).saturating_sub(1);
    let crosses = |k: usize| {
        let (a, b) = (values[k], values[k + 1]);
        match edge {
            Edge::Enter => a >= threshold && threshold > b,
            Edge::Leave => a < threshold && threshold <= b,
        }
    };
    let reach = centre.max(pairs - 1 - centre);
    (0..=reach)
        .flat_map(|d| [centre.checked_sub(d), Some(centre + d).filter(|_| d > 0)])
        .flatten()
        .filter(|&k| k < pairs)
        .find(|&k| crosses(k))
        .map(|k| {
            let (a, b) = (values[k], values[k + 1]);
            Crossing {
                index: k,
                fraction: (a - threshold) / (a - b),
                slope: (a - b).abs(),
            }
        })
}

/// The last `slots` frames, frame `j` in slot `j % slots`.
#[derive(Debug, Clone)]
struct FrameRing<T> {
    samples: Vec<T>,
    width: usize,
    frame_len: usize,
    slots: usize,
}

impl<T: Sample> FrameRing<T> {
    fn new(height: usize, width: usize, slots: usize) -> Self {
        FrameRing {
            samples: vec![T::MIN; height * width * slots],
            width,
            frame_len: height * width,
            slots,
        }
    }

    /// Copy `frame` into the slot of frame `index`, in parallel pieces (a
    /// single core does not saturate the memory bus).
    fn store(&mut self, index: usize, frame: &[T]) {
        let start = (index % self.slots) * self.frame_len;
        self.samples[start..start + self.frame_len]
            .par_chunks_mut(STORE_PIECE)
            .zip(frame.par_chunks(STORE_PIECE))
            .for_each(|(dst, src)| dst.copy_from_slice(src));
    }

    #[inline(always)]
    fn row(&self, frame: usize, row: usize) -> &[T] {
        let start = (frame % self.slots) * self.frame_len + row * self.width;
        &self.samples[start..start + self.width]
    }
}

/// The folded state of one image row.
///
/// Invariants, for the frames `0 … D−1` folded so far:
/// * `imax`/`imin`: max/min sample (`T::MIN`/`T::MAX` before any frame);
/// * `best_fall[x]`: `max(0, max_{1≤j<D} I_{j−1} − I_j)`; `fall_at[x]` the first
///   `j` reaching it, `NO_FRAME` while it is 0 (so only real falls count);
///   likewise `best_rise`/`rise_at` for `I_j − I_{j−1}`;
/// * `fall_window[x·2m .. x·2m+2m]`: the samples of frames `j−m … j+m−1`
///   around `j = fall_at[x]`, clamped to `[0, last]` with `last` the newest
///   frame when they were captured (while streaming, the whole window is in
///   the ring when it is captured, so only the clamp at 0 applies) — unless
///   `moved[x]` has the bit `FELL`: then `fall_at` moved in the last folded
///   block and its window is still to be captured. Likewise `rise_window`,
///   `ROSE`.
#[derive(Debug, Clone)]
struct RowState<T: Sample> {
    imax: Vec<T>,
    imin: Vec<T>,
    best_fall: Vec<T>,
    best_rise: Vec<T>,
    fall_at: Vec<u32>,
    rise_at: Vec<u32>,
    moved: Vec<u8>,
    fall_window: Vec<T>,
    rise_window: Vec<T>,
}

impl<T: Sample> RowState<T> {
    fn new(width: usize, half: usize) -> Self {
        RowState {
            imax: vec![T::MIN; width],
            imin: vec![T::MAX; width],
            best_fall: vec![T::MIN; width],
            best_rise: vec![T::MIN; width],
            fall_at: vec![NO_FRAME; width],
            rise_at: vec![NO_FRAME; width],
            moved: vec![0; width],
            fall_window: vec![T::MIN; width * 2 * half],
            rise_window: vec![T::MIN; width * 2 * half],
        }
    }
}

/// Samples ahead of the current vector to prefetch in each of a block's rows.
const PREFETCH_AHEAD: usize = 256;

/// Hint the cache to fetch `slice[at]` (no effect past the end).
#[inline(always)]
fn prefetch<T>(slice: &[T], at: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(item) = slice.get(at) {
        // SAFETY: a prefetch only hints the cache; the address is in bounds.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                (item as *const T).cast::<i8>(),
            )
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (slice, at);
}

/// Load `V::LANES` samples of `slice` from `x0`.
#[inline(always)]
fn load<T: Sample, V: Vector<T>>(slice: &[T], x0: usize) -> V {
    assert!(x0 + V::LANES <= slice.len());
    // SAFETY: in bounds (checked above); `V` is only used on CPUs that have it.
    unsafe { V::load(slice.as_ptr().add(x0)) }
}

/// Store `v` into `V::LANES` samples of `slice` from `x0`.
#[inline(always)]
fn store<T: Sample, V: Vector<T>>(v: V, slice: &mut [T], x0: usize) {
    assert!(x0 + V::LANES <= slice.len());
    // SAFETY: as in `load`.
    unsafe { v.store(slice.as_mut_ptr().add(x0)) }
}

/// Fold the block `rows` (one row of each frame, `prev` the row of the
/// frame before the first) into the `V::LANES` pixels from `x0` of a row's
/// state. The pixels' state stays in registers across the block's frames:
/// per pixel and frame one load and a few branch-free vector operations.
#[inline(always)]
fn fold_span<T: Sample, V: Vector<T>>(
    state: &mut RowState<T>,
    prev: &[T],
    rows: &[&[T]],
    first: usize,
    x0: usize,
) {
    let mut imax: V = load(&state.imax, x0);
    let mut imin: V = load(&state.imin, x0);
    let mut best_fall: V = load(&state.best_fall, x0);
    let mut best_rise: V = load(&state.best_rise, x0);
    let none = V::splat(T::NO_OFFSET);
    let (mut fall_offset, mut rise_offset) = (none, none);
    let mut before: V = load(prev, x0);
    for (k, row) in rows.iter().enumerate() {
        prefetch(row, x0 + PREFETCH_AHEAD);
        let cur: V = load(row, x0);
        imax = imax.max(cur);
        imin = imin.min(cur);
        // Saturated to 0 when not a fall (rise): never beats the best (≥ 0).
        let fall = before.sub_sat(cur);
        let rise = cur.sub_sat(before);
        let offset = V::splat(T::from_offset(k));
        fall_offset = V::select(fall.gt(best_fall), offset, fall_offset);
        rise_offset = V::select(rise.gt(best_rise), offset, rise_offset);
        best_fall = best_fall.max(fall);
        best_rise = best_rise.max(rise);
        before = cur;
    }
    store(imax, &mut state.imax, x0);
    store(imin, &mut state.imin, x0);
    store(best_fall, &mut state.best_fall, x0);
    store(best_rise, &mut state.best_rise, x0);
    // Moves are rare once the sweep is under way: a vectorised test first.
    if !fall_offset.ne(none).or(rise_offset.ne(none)).any() {
        return;
    }
    let mut offsets = [T::NO_OFFSET; 2 * MAX_LANES];
    store(fall_offset, &mut offsets, 0);
    store(rise_offset, &mut offsets, MAX_LANES);
    for i in 0..V::LANES {
        let x = x0 + i;
        let (f, r) = (offsets[i], offsets[MAX_LANES + i]);
        if f != T::NO_OFFSET {
            state.fall_at[x] = (first + f.index()) as u32;
            state.moved[x] |= FELL;
        }
        if r != T::NO_OFFSET {
            state.rise_at[x] = (first + r.index()) as u32;
            state.moved[x] |= ROSE;
        }
    }
}

/// The most lanes of any [`Vector`].
const MAX_LANES: usize = 64;

/// Fold the frames `frames` (present in `ring` with their predecessors) into
/// one row's state with vectors `V`: statistics, `fall_at`/`rise_at` and the
/// `moved` bits. Windows are not captured here.
#[inline(always)]
fn fold_row_with<T: Sample, V: Vector<T>>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    frames: Range<usize>,
) {
    debug_assert!(frames.len() < T::NO_OFFSET.index());
    debug_assert!(V::LANES <= MAX_LANES);
    let width = state.imax.len();
    let prev = ring.row(frames.start.saturating_sub(1), row);
    let rows: Vec<&[T]> = frames.clone().map(|j| ring.row(j, row)).collect();
    let split = width - width % V::LANES;
    for x0 in (0..split).step_by(V::LANES) {
        fold_span::<T, V>(state, prev, &rows, frames.start, x0);
    }
    for x0 in split..width {
        fold_span::<T, Portable<T, 1>>(state, prev, &rows, frames.start, x0);
    }
}

/// [`fold_row_with`] compiled for AVX2.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fold_row_avx2<T: Sample>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    frames: Range<usize>,
) {
    fold_row_with::<T, T::Avx2>(state, ring, row, frames)
}

/// Fold `frames` into one row's state on the instruction set `path`
/// (which the CPU must support: checked when the tracker is made).
fn fold_row<T: Sample>(
    path: SimdPath,
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    frames: Range<usize>,
) {
    match path {
        #[cfg(target_arch = "x86_64")]
        SimdPath::Avx2 => {
            debug_assert!(path.is_supported());
            // SAFETY: the tracker only holds a path the CPU supports.
            unsafe { fold_row_avx2(state, ring, row, frames) }
        }
        #[cfg(target_arch = "x86_64")]
        SimdPath::Sse2 => fold_row_with::<T, T::Sse2>(state, ring, row, frames),
        _ => fold_row_with::<T, T::Portable>(state, ring, row, frames),
    }
}
/// Copy the `2m` samples of frames `j−m … j+m−1` (clamped to `[0, last]`) of
/// pixel `(row, col)` into `dst`.
fn capture_window<T: Sample>(
    dst: &mut [T],
    ring: &FrameRing<T>,
    row: usize,
    col: usize,
    j: usize,
    last: usize,
) {
    let half = dst.len() / 2;
    for (i, d) in dst.iter_mut().enumerate() {
        let frame = (j + i).saturating_sub(half).min(last);
        *d = ring.row(frame, row)[col];
    }
}

/// Capture the windows of one row's `moved` pixels (frames up to `last`,
/// back to the window starts, all in `ring`) and clear the bits.
fn capture_row<T: Sample>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    last: usize,
    half: usize,
) {
    let span = 2 * half;
    for g0 in (0..state.moved.len()).step_by(GROUP) {
        let g1 = (g0 + GROUP).min(state.moved.len());
        if state.moved[g0..g1].iter().fold(0, |any, &m| any | m) == 0 {
            continue;
        }
        for x in g0..g1 {
            let moved = std::mem::take(&mut state.moved[x]);
            if moved & FELL != 0 {
                let dst = &mut state.fall_window[x * span..(x + 1) * span];
                capture_window(dst, ring, row, x, state.fall_at[x] as usize, last);
            }
            if moved & ROSE != 0 {
                let dst = &mut state.rise_window[x * span..(x + 1) * span];
                capture_window(dst, ring, row, x, state.rise_at[x] as usize, last);
            }
        }
    }
}

/// Streaming per-pixel shadow tracker over frames of `T` (`u8` or `u16`).
///
/// Invariants between calls (`F` = frames seen, `D` = frames folded,
/// `K` = block, `m` = window, `L` = lag `= max(0, m − 1 − K)`):
/// * the ring has `S = 2K + L + m` slots and holds frames `max(0, F−S) … F−1`;
/// * `D` is a multiple of `K` and `0 ≤ F − D < K + L`: block `D … D+K−1` is
///   folded as soon as `F = D + K + L`, right after the windows of the
///   previous block `D−K … D−1` are captured. Those reach from `D − K − m =
///   F − S` to `D + m − 2 ≤ F − 1`: all in the ring, none clamped at the end;
///   the block itself needs frames `D − 1 … D + K − 1`;
/// * every row state satisfies [`RowState`]'s invariants for frames `0 … D−1`,
///   with `moved` bits only for moves in block `D−K … D−1`.
///
/// [`finish`](Self::finish) works on a copy of each row's state: captures the
/// pending windows, folds the pending frames `D … F−1` and captures theirs
/// (everything back to `D − K − m` is in the ring), clamping at `F − 1`. So it
/// can be called at any time for a preview.
#[derive(Debug, Clone)]
pub struct TemporalTracker<T: Sample> {
    height: usize,
    width: usize,
    params: TrackerParams,
    ring: FrameRing<T>,
    rows: Vec<RowState<T>>,
    frames_seen: usize,
    frames_folded: usize,
    path: SimdPath,
}

impl<T: Sample> TemporalTracker<T> {
    /// A tracker for frames of `height × width` samples.
    pub fn new(height: usize, width: usize, params: TrackerParams) -> Result<Self, KernelError> {
        params.validate()?;
        if height == 0 || width == 0 {
            return Err(KernelError::parameter(
                "shape",
                format!("frames must not be empty, got {height} × {width}"),
            ));
        }
        Ok(TemporalTracker {
            height,
            width,
            params,
            ring: FrameRing::new(height, width, params.ring_slots()),
            rows: (0..height)
                .map(|_| RowState::new(width, params.window))
                .collect(),
            frames_seen: 0,
            frames_folded: 0,
            path: SimdPath::active(),
        })
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn params(&self) -> TrackerParams {
        self.params
    }

    /// The instruction set the hot loops run on ([`SimdPath::active`] when made).
    pub fn simd_path(&self) -> SimdPath {
        self.path
    }

    /// Run the hot loops on `path` from now on (results do not depend on it).
    pub fn set_simd_path(&mut self, path: SimdPath) -> Result<(), KernelError> {
        if !path.is_supported() {
            return Err(KernelError::parameter(
                "simd_path",
                format!("{} is not supported by this CPU", path.name()),
            ));
        }
        self.path = path;
        Ok(())
    }

    /// Number of frames given to [`update`](Self::update) so far.
    pub fn frames_seen(&self) -> usize {
        self.frames_seen
    }

    /// Add the next frame (row-major, `height × width` samples).
    pub fn update(&mut self, frame: &[T]) -> Result<(), KernelError> {
        if frame.len() != self.height * self.width {
            return Err(KernelError::LengthMismatch {
                what: "frame",
                expected: self.height * self.width,
                got: frame.len(),
            });
        }
        if self.frames_seen >= (NO_FRAME - 1) as usize {
            return Err(KernelError::TooManyFrames);
        }
        self.ring.store(self.frames_seen, frame);
        self.frames_seen += 1;
        let (block, half) = (self.params.block, self.params.window);
        if self.frames_seen == self.frames_folded + block + self.params.lag() {
            let frames = self.frames_folded..self.frames_folded + block;
            let last = self.frames_seen - 1;
            let (ring, path) = (&self.ring, self.path);
            self.rows
                .par_iter_mut()
                .enumerate()
                .for_each(|(row, state)| {
                    capture_row(state, ring, row, last, half);
                    fold_row(path, state, ring, row, frames.clone());
                });
            self.frames_folded += block;
        }
        Ok(())
    }

    /// The per-pixel results for the frames seen so far; does not change the
    /// tracker.
    ///
    /// `min_contrast` (DN): pixels with `imax − imin < min_contrast` are
    /// invalid (times NaN). `lut`: decoding table from DN to linear
    /// irradiance, `T::LUT_LEN` finite non-decreasing values (`None` =
    /// identity); thresholds, interpolation and slopes use decoded values.
    pub fn finish(
        &self,
        min_contrast: f32,
        lut: Option<&[f32]>,
    ) -> Result<ShadowTimes, KernelError> {
        if self.frames_seen == 0 {
            return Err(KernelError::NoFrames);
        }
        if !min_contrast.is_finite() {
            return Err(KernelError::parameter(
                "min_contrast",
                format!("must be finite, got {min_contrast}"),
            ));
        }
        let lut = decoding_lut::<T>(lut)?;
        let (half, last) = (self.params.window, self.frames_seen - 1);
        let pending = self.frames_folded..self.frames_seen;
        let mut times = ShadowTimes::empty(self.height, self.width);
        let out_rows = times.rows_mut();
        out_rows
            .into_par_iter()
            .zip(self.rows.par_iter())
            .enumerate()
            .for_each(|(row, (mut out, folded))| {
                let mut state = folded.clone();
                capture_row(&mut state, &self.ring, row, last, half);
                if !pending.is_empty() {
                    fold_row(self.path, &mut state, &self.ring, row, pending.clone());
                    capture_row(&mut state, &self.ring, row, last, half);
                }
                resolve_row(&state, &lut, min_contrast, half, &mut out);
            });
        Ok(times)
    }
}

/// The decoding table to use: the caller's after validation, or the identity.
fn decoding_lut<T: Sample>(lut: Option<&[f32]>) -> Result<Cow<'_, [f32]>, KernelError> {
    let Some(lut) = lut else {
        return Ok(Cow::Owned((0..T::LUT_LEN).map(|v| v as f32).collect()));
    };
    if lut.len() != T::LUT_LEN {
        return Err(KernelError::InvalidLut {
            reason: format!(
                "a {} LUT needs {} entries, got {}",
                T::DTYPE,
                T::LUT_LEN,
                lut.len()
            ),
        });
    }
    if let Some(i) = lut.iter().position(|v| !v.is_finite()) {
        return Err(KernelError::InvalidLut {
            reason: format!("entry {i} is {}", lut[i]),
        });
    }
    if let Some(i) = lut.windows(2).position(|w| w[1] < w[0]) {
        return Err(KernelError::InvalidLut {
            reason: format!(
                "must be non-decreasing, but entry {} ({}) < entry {i} ({})",
                i + 1,
                lut[i + 1],
                lut[i]
            ),
        });
    }
    Ok(Cow::Borrowed(lut))
}

/// Turn one row's folded state into results.
fn resolve_row<T: Sample>(
    state: &RowState<T>,
    lut: &[f32],
    min_contrast: f32,
    half: usize,
    out: &mut RowTimesMut<'_>,
) {
    let span = 2 * half;
    let mut linear = vec![0.0f32; span];
    let mut solve = |at: u32, window: &[T], threshold: f32, edge: Edge| -> (f32, f32) {
        if at == NO_FRAME {
            return (f32::NAN, f32::NAN);
        }
        for (l, v) in linear.iter_mut().zip(window) {
            *l = lut[v.index()];
        }
        match find_crossing(&linear, threshold, edge) {
            Some(c) => {
                let frame = at as i64 - half as i64 + c.index as i64;
                ((frame as f64 + f64::from(c.fraction)) as f32, c.slope)
            }
            None => (f32::NAN, f32::NAN),
        }
    };
    for x in 0..state.imax.len() {
        let (hi, lo) = (state.imax[x], state.imin[x]);
        let contrast = hi.to_f32() - lo.to_f32();
        let threshold = (lut[hi.index()] + lut[lo.index()]) * 0.5;
        let valid = contrast >= min_contrast;
        out.imax[x] = hi.to_f32();
        out.imin[x] = lo.to_f32();
        out.contrast[x] = contrast;
        out.threshold[x] = threshold;
        out.valid[x] = u8::from(valid);
        if valid {
            let window = &state.fall_window[x * span..(x + 1) * span];
            (out.enter[x], out.enter_slope[x]) =
                solve(state.fall_at[x], window, threshold, Edge::Enter);
            let window = &state.rise_window[x * span..(x + 1) * span];
            (out.leave[x], out.leave_slope[x]) =
                solve(state.rise_at[x], window, threshold, Edge::Leave);
        }
    }
}

/// Mutable views of one row of every [`ShadowTimes`] array.
struct RowTimesMut<'a> {
    imax: &'a mut [f32],
    imin: &'a mut [f32],
    contrast: &'a mut [f32],
    threshold: &'a mut [f32],
    enter: &'a mut [f32],
    leave: &'a mut [f32],
    enter_slope: &'a mut [f32],
    leave_slope: &'a mut [f32],
    valid: &'a mut [u8],
}

impl<'a> RowTimesMut<'a> {
    fn split_at(self, mid: usize) -> (Self, Self) {
        let (imax, imax_rest) = self.imax.split_at_mut(mid);
        let (imin, imin_rest) = self.imin.split_at_mut(mid);
        let (contrast, contrast_rest) = self.contrast.split_at_mut(mid);
        let (threshold, threshold_rest) = self.threshold.split_at_mut(mid);
        let (enter, enter_rest) = self.enter.split_at_mut(mid);
        let (leave, leave_rest) = self.leave.split_at_mut(mid);
        let (enter_slope, enter_slope_rest) = self.enter_slope.split_at_mut(mid);
        let (leave_slope, leave_slope_rest) = self.leave_slope.split_at_mut(mid);
        let (valid, valid_rest) = self.valid.split_at_mut(mid);
        (
            RowTimesMut {
                imax,
                imin,
                contrast,
                threshold,
                enter,
                leave,
                enter_slope,
                leave_slope,
                valid,
            },
            RowTimesMut {
                imax: imax_rest,
                imin: imin_rest,
                contrast: contrast_rest,
                threshold: threshold_rest,
                enter: enter_rest,
                leave: leave_rest,
                enter_slope: enter_slope_rest,
                leave_slope: leave_slope_rest,
                valid: valid_rest,
            },
        )
    }
}

impl ShadowTimes {
    /// All times and slopes NaN, everything else zero.
    fn empty(height: usize, width: usize) -> Self {
        let n = height * width;
        ShadowTimes {
            height,
            width,
            imax: vec![0.0; n],
            imin: vec![0.0; n],
            contrast: vec![0.0; n],
            threshold: vec![0.0; n],
            enter: vec![f32::NAN; n],
            leave: vec![f32::NAN; n],
            enter_slope: vec![f32::NAN; n],
            leave_slope: vec![f32::NAN; n],
            valid: vec![0; n],
        }
    }

    fn rows_mut(&mut self) -> Vec<RowTimesMut<'_>> {
        let mut rest = RowTimesMut {
            imax: &mut self.imax,
            imin: &mut self.imin,
            contrast: &mut self.contrast,
            threshold: &mut self.threshold,
            enter: &mut self.enter,
            leave: &mut self.leave,
            enter_slope: &mut self.enter_slope,
            leave_slope: &mut self.leave_slope,
            valid: &mut self.valid,
        };
        let mut rows = Vec::with_capacity(self.height);
        for _ in 0..self.height {
            let (row, tail) = rest.split_at(self.width);
            rows.push(row);
            rest = tail;
        }
        rows
    }
}
