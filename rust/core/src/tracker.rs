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
//! temporal blocks of `K` frames ([`TrackerParams::block`]). A block is folded
//! row by row (rayon over rows), chunk of pixels by chunk, so a chunk's state
//! stays in L1 across the `K` frames; the inner loop over pixels is
//! branch-free and auto-vectorises (for `u8` in `i16` lanes, for `u16` in
//! `i32`). The windows are copied after the block, only for pixels whose best
//! fall or rise moved inside it. A block is folded `m` frames late so that
//! every window it needs is already in the ring.

use std::borrow::Cow;
use std::ops::Range;

use rayon::prelude::*;

use crate::error::KernelError;
use crate::sample::{Lane, Sample};

/// Pixels per chunk of a row in the block fold: the chunk's state
/// (`≤ 14 B/pixel` for `u8`) stays in L1 while the block's frames stream by.
const CHUNK: usize = 512;

/// Marks "no steepest fall/rise yet" in the per-pixel frame indices.
const NO_FRAME: u32 = u32::MAX;

/// Tuning of [`TemporalTracker`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrackerParams {
    /// `m`: half-width of the window kept around the steepest fall and rise
    /// (`2m` samples, frames `j−m … j+m−1`). `1 ≤ m ≤ 64`.
    pub window: usize,
    /// `K`: frames folded together per pass over the state. `1 ≤ K ≤ 4096`.
    /// Results do not depend on it; speed does.
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
    const MAX_BLOCK: usize = 4096;

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

    fn store(&mut self, index: usize, frame: &[T]) {
        let start = (index % self.slots) * self.frame_len;
        self.samples[start..start + self.frame_len].copy_from_slice(frame);
    }

    #[inline(always)]
    fn row(&self, frame: usize, row: usize) -> &[T] {
        let start = (frame % self.slots) * self.frame_len + row * self.width;
        &self.samples[start..start + self.width]
    }
}

/// The folded state of one image row.
///
/// Invariants, for the frames `0 … F−1` folded so far:
/// * `imax`/`imin`: max/min sample (`T::MIN`/`T::MAX` before any frame);
/// * `best_fall[x]`: `max(0, max_{1≤j<F} I_{j−1} − I_j)`; `fall_at[x]` the first
///   `j` reaching it, `NO_FRAME` while it is 0 (so only real falls count);
///   likewise `best_rise`/`rise_at` for `I_j − I_{j−1}`;
/// * `fall_window[x·2m .. x·2m+2m]`: samples of frames `j−m … j+m−1` around
///   `j = fall_at[x]`, clamped to `[0, last]` where `last` is the last frame
///   present when it was captured (during streaming every frame of the window
///   is present, so only the clamp at 0 ever applies); meaningless while
///   `fall_at[x] == NO_FRAME`. Likewise `rise_window`.
#[derive(Debug, Clone)]
struct RowState<T: Sample> {
    imax: Vec<T>,
    imin: Vec<T>,
    best_fall: Vec<T::Lane>,
    best_rise: Vec<T::Lane>,
    fall_at: Vec<u32>,
    rise_at: Vec<u32>,
    fall_window: Vec<T>,
    rise_window: Vec<T>,
}

impl<T: Sample> RowState<T> {
    fn new(width: usize, half: usize) -> Self {
        RowState {
            imax: vec![T::MIN; width],
            imin: vec![T::MAX; width],
            best_fall: vec![T::Lane::ZERO; width],
            best_rise: vec![T::Lane::ZERO; width],
            fall_at: vec![NO_FRAME; width],
            rise_at: vec![NO_FRAME; width],
            fall_window: vec![T::MIN; width * 2 * half],
            rise_window: vec![T::MIN; width * 2 * half],
        }
    }
}

/// Fold one frame into a chunk of pixels. Branch-free: the selects compile to
/// SIMD blends. All slices have the length of `cur`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fold_frame<T: Sample>(
    cur: &[T],
    prev: &[T],
    offset: T::Lane,
    imax: &mut [T],
    imin: &mut [T],
    best_fall: &mut [T::Lane],
    best_rise: &mut [T::Lane],
    fall_offset: &mut [T::Lane],
    rise_offset: &mut [T::Lane],
) {
    let n = cur.len();
    let (prev, imax, imin) = (&prev[..n], &mut imax[..n], &mut imin[..n]);
    let (best_fall, best_rise) = (&mut best_fall[..n], &mut best_rise[..n]);
    let (fall_offset, rise_offset) = (&mut fall_offset[..n], &mut rise_offset[..n]);
    for x in 0..n {
        let v = cur[x];
        imax[x] = imax[x].max(v);
        imin[x] = imin[x].min(v);
        let (w, p) = (v.widen(), prev[x].widen());
        let fall = p - w;
        let rise = w - p;
        let steeper_fall = fall > best_fall[x];
        let steeper_rise = rise > best_rise[x];
        best_fall[x] = if steeper_fall { fall } else { best_fall[x] };
        fall_offset[x] = if steeper_fall { offset } else { fall_offset[x] };
        best_rise[x] = if steeper_rise { rise } else { best_rise[x] };
        rise_offset[x] = if steeper_rise { offset } else { rise_offset[x] };
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

/// Fold `frames` (all present in `ring`, as well as the frames their windows
/// need up to `last`) into one row's state.
fn fold_row<T: Sample>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    frames: Range<usize>,
    last: usize,
    half: usize,
) {
    debug_assert!(frames.len() <= T::Lane::MAX_OFFSET);
    let width = state.imax.len();
    let span = 2 * half;
    let mut fall_offset = [T::Lane::NONE; CHUNK];
    let mut rise_offset = [T::Lane::NONE; CHUNK];
    for c0 in (0..width).step_by(CHUNK) {
        let c1 = (c0 + CHUNK).min(width);
        let fall_offset = &mut fall_offset[..c1 - c0];
        let rise_offset = &mut rise_offset[..c1 - c0];
        fall_offset.fill(T::Lane::NONE);
        rise_offset.fill(T::Lane::NONE);
        for (k, j) in frames.clone().enumerate() {
            fold_frame(
                &ring.row(j, row)[c0..c1],
                &ring.row(j.saturating_sub(1), row)[c0..c1],
                T::Lane::from_offset(k),
                &mut state.imax[c0..c1],
                &mut state.imin[c0..c1],
                &mut state.best_fall[c0..c1],
                &mut state.best_rise[c0..c1],
                fall_offset,
                rise_offset,
            );
        }
        for (i, (&f, &r)) in fall_offset.iter().zip(rise_offset.iter()).enumerate() {
            let x = c0 + i;
            if f != T::Lane::NONE {
                let j = frames.start + f.to_offset();
                state.fall_at[x] = j as u32;
                let dst = &mut state.fall_window[x * span..(x + 1) * span];
                capture_window(dst, ring, row, x, j, last);
            }
            if r != T::Lane::NONE {
                let j = frames.start + r.to_offset();
                state.rise_at[x] = j as u32;
                let dst = &mut state.rise_window[x * span..(x + 1) * span];
                capture_window(dst, ring, row, x, j, last);
            }
        }
    }
}

/// Streaming per-pixel shadow tracker over frames of `T` (`u8` or `u16`).
///
/// Invariants between calls (`F` = frames seen, `D` = frames folded,
/// `K` = block, `m` = window):
/// * the ring has `K + 2m` slots and holds frames `max(0, F−K−2m) … F−1`;
/// * `D` is a multiple of `K` and `0 ≤ F − D < K + m`: a block `D … D+K−1` is
///   folded as soon as `F = D + K + m`. Its windows then reach back to `D − m`
///   and forward to `D + K + m − 2 < F`, and its first frame's predecessor
///   is `D − 1 ≥ D − m`: all in the ring, none clamped at the end;
/// * every row state satisfies [`RowState`]'s invariants for frames `0 … D−1`.
///
/// [`finish`](Self::finish) folds the pending frames `D … F−1` into a copy of
/// each row's state (their windows, up to `D − m`, are in the ring too), so it
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
        let slots = params.block + 2 * params.window;
        Ok(TemporalTracker {
            height,
            width,
            params,
            ring: FrameRing::new(height, width, slots),
            rows: (0..height)
                .map(|_| RowState::new(width, params.window))
                .collect(),
            frames_seen: 0,
            frames_folded: 0,
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
        if self.frames_seen == self.frames_folded + block + half {
            let frames = self.frames_folded..self.frames_folded + block;
            let last = self.frames_seen - 1;
            let ring = &self.ring;
            self.rows.par_iter_mut().enumerate().for_each(|(row, state)| {
                fold_row(state, ring, row, frames.clone(), last, half);
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
    pub fn finish(&self, min_contrast: f32, lut: Option<&[f32]>) -> Result<ShadowTimes, KernelError> {
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
                let state = if pending.is_empty() {
                    Cow::Borrowed(folded)
                } else {
                    let mut state = folded.clone();
                    fold_row(&mut state, &self.ring, row, pending.clone(), last, half);
                    Cow::Owned(state)
                };
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
