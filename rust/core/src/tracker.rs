//! Streaming temporal shadow tracker: one shadow event (dip) per pixel.
//!
//! Per pixel, over a stream of grey frames `I_0 … I_{N−1}`, the tracker finds
//! the deepest *dip*: a run of dark samples with brighter samples on both
//! sides within the dip width `W` ([`TrackerParams::max_width`]), and reports
//! the dip's levels, its contrast and two shadow times at sub-frame precision:
//!
//! * **enter**: the intensity falls through the threshold into the dip,
//! * **leave**: it rises back through it, after enter,
//!
//! with the threshold at mid-level in *linear irradiance*,
//! `thr = (L(hi) + L(lo)) / 2`, `L` the capture's decoding table (identity
//! if absent). The samples are the input's DN, or in normalised mode (a
//! changing light) each frame's normalised irradiance: see
//! [`crate::intensity`] for what is compared, decoded and reported where.
//!
//! # The dip
//! Frames are grouped in blocks of `W` (block `b` = frames `bW … bW+W−1`).
//! For frame `k` of block `b`, the left context is the brightest sample from
//! the start of block `b − 1` to `k − 1`, the right context the brightest
//! from `k + 1` to the end of block `b + 1` (both clamped to the frames that
//! exist; an empty context is 0), and the **depth** of frame `k` is
//! `d_k = max(0, min(left, right) − I_k)` (DN): how far the sample lies below
//! the lit level on both sides within `W` to `2W − 1` frames. A dip up to `W`
//! frames wide always has a frame whose two contexts reach out of it; a slow
//! wide darkening (a cloud, dusk) or a step that never comes back (night) has
//! no depth beyond the noise.
//!
//! Depths are folded frame by frame into *events*: the best event
//! (`d1`, at frame `k1`) and the best other event (`d2`): a frame within `W`
//! frames after `k1` belongs to the best event (it may deepen it); a frame
//! farther away counts for another one. So `d2` is the deepest dip apart from
//! the best one. A pixel is **ambiguous** when `d2 ≥ ambiguity · d1`
//! ([`TrackerParams::ambiguity`]): two comparable dips (the stick seen
//! directly, an interreflection, a cloud), no times.
//!
//! The event whose depth is `d2` is kept too, as a *second candidate*
//! ([`SecondState`], [`TemporalTracker::finish_second`]): a far frame deeper
//! than the best makes the best the second (its windows are copied), a far
//! frame deeper than the second (not the best) becomes it (its windows
//! captured as the best's are). A caller that can tell its own shadow's dip
//! from another's (a pole's from a lamp post's) chooses between the two.
//!
//! The best dip's levels are `hi = min(left, right)` and `lo = I_{k1}`. Its
//! enter is the last fall through the DN mid-level `(hi + lo)/2` before `k1`
//! (within the left context), its leave the first rise through it after `k1`
//! (within the right context): so enter < leave, and both bound the same dip.
//! The `2m` raw samples around each (`m` = [`TrackerParams::window`]) are kept;
//! [`TemporalTracker::finish`] decodes them with `L`, finds the crossing of
//! the linear threshold nearest each window's centre ([`find_crossing`]) and
//! interpolates linearly. Memory is `O(pixels)`, independent of the number of
//! frames.
//!
//! # Speed
//! Each frame is copied into a ring of the last `3W + 2m` frames (in
//! parallel pieces; a normalised frame through its code table, a frame with
//! per-pixel levels through a vectorised division). The ring's slots are
//! skewed by a quarter page so that one pixel of many frames does not fall in
//! one cache set ([`FrameRing`]), and backed by huge pages where Linux allows
//! (faulting it in by 4 KiB pages cost as much as the normalised store). When block `b + 1` is complete (and `m − 1` frames
//! more), block `b` is evaluated row by row (rayon over rows), one SIMD
//! vector of pixels at a time ([`crate::simd`], chosen at run time): block
//! `b + 1`'s maximum, a backward pass for the right contexts (and block `b`'s
//! maximum, kept for the next block's left contexts), a forward pass for the
//! left contexts, the depths and the events, all in the sample's lane width
//! and in registers (masks of `≤`, which x86 computes in two operations, and
//! AVX2's one-instruction blends). Windows are captured (a scalar look into the ring) only for
//! pixels whose best dip moved, which is rare once the sweep is under way.

use rayon::prelude::*;

use crate::error::KernelError;
use crate::intensity::Intensity;
use crate::live::{FinishedPixel, Watch, WatchParams};
use crate::ring::FrameRing;
use crate::sample::Sample;
use crate::simd::{Portable, SimdPath, Vector};

// Defined in `crossing` (which `live` shares); public here as before.
pub use crate::crossing::{find_crossing, Crossing, Edge};

/// Samples copied into the ring per parallel task.
const STORE_PIECE: usize = 1 << 18;

/// Marks "no dip" in the per-pixel frame indices.
const NO_FRAME: u32 = u32::MAX;

/// The most lanes of any [`Vector`].
const MAX_LANES: usize = 64;

/// Samples ahead of the current vector to prefetch in each of a block's rows.
const PREFETCH_AHEAD: usize = 256;

/// Tuning of [`TemporalTracker`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerParams {
    /// `m`: half-width of the windows kept around the enter and leave
    /// crossings (`2m` samples). `1 ≤ m ≤ min(64, W)`.
    pub window: usize,
    /// `W` (frames): the widest dip always found, and the separation beyond
    /// which two dips are distinct events. `2 ≤ W ≤ 128`. The ring holds
    /// `3W + 2m` frames.
    pub max_width: usize,
    /// A pixel whose second-deepest dip is at least this fraction of the
    /// deepest is ambiguous (no times). `0 < ambiguity ≤ 1`.
    pub ambiguity: f32,
    /// Keep every pixel's second candidate dip (its levels and windows) for
    /// [`TemporalTracker::finish_second`]. Off (the default), the block pass
    /// is compiled without it (the rival depth `d2` is still tracked) and
    /// `finish_second` is refused.
    pub second_dips: bool,
}

impl Default for TrackerParams {
    fn default() -> Self {
        TrackerParams {
            window: 4,
            max_width: 32,
            ambiguity: 0.6,
            second_dips: false,
        }
    }
}

impl TrackerParams {
    const MAX_WINDOW: usize = 64;
    /// Keeps block-local offsets (`< W`) below `u8::MAX` and the event age
    /// (saturating at `MAX`) able to exceed `W`.
    const MAX_WIDTH: usize = 128;

    fn validate(&self) -> Result<(), KernelError> {
        if !(2..=Self::MAX_WIDTH).contains(&self.max_width) {
            return Err(KernelError::parameter(
                "max_width",
                format!("must be in 2..={}, got {}", Self::MAX_WIDTH, self.max_width),
            ));
        }
        let top = Self::MAX_WINDOW.min(self.max_width);
        if !(1..=top).contains(&self.window) {
            return Err(KernelError::parameter(
                "window",
                format!(
                    "must be in 1..={top} (at most 64 and max_width), got {}",
                    self.window
                ),
            ));
        }
        if !(self.ambiguity > 0.0 && self.ambiguity <= 1.0) {
            return Err(KernelError::parameter(
                "ambiguity",
                format!("must be in (0, 1], got {}", self.ambiguity),
            ));
        }
        Ok(())
    }

    /// Ring slots: evaluating the block from frame `d` happens when the newest
    /// frame is `d + 2W + m − 2` and needs frames back to `d − W − m + 1`.
    fn ring_slots(&self) -> usize {
        3 * self.max_width + 2 * self.window
    }

    /// Frames seen when the block from frame `d` is evaluated.
    fn evaluate_at(&self, d: usize) -> usize {
        d + 2 * self.max_width + self.window - 1
    }
}

/// The tracker's per-pixel results, row-major `(height, width)` arrays.
///
/// Intensities are in DN of the input (fractional in normalised mode: see
/// [`crate::intensity`]); the threshold and the slopes in the linear units of
/// the decoding table, in the light the dip was seen in; times in frames
/// (frame `i` is time `i`).
#[derive(Debug, Clone, PartialEq)]
pub struct ShadowTimes {
    pub height: usize,
    pub width: usize,
    /// `hi`: the lit level around the deepest dip (DN); 0 where there is no dip.
    pub imax: Vec<f32>,
    /// `lo`: the darkest sample of the deepest dip (DN); 0 where there is no dip.
    pub imin: Vec<f32>,
    /// `imax − imin`: the depth of the deepest dip (DN), which `min_contrast` bounds.
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
    /// Depth of the deepest dip apart from the best one (DN), 0 if none.
    pub rival: Vec<f32>,
    /// 1 where a dip exists, `contrast ≥ min_contrast` and it is not ambiguous, else 0.
    pub valid: Vec<u8>,
    /// 1 where `contrast ≥ min_contrast` but `rival ≥ ambiguity · contrast`.
    pub ambiguous: Vec<u8>,
    /// 1 where the dip's levels or a sample interpolated at a crossing is
    /// clipped (`0` or the type's maximum): the times may be biased.
    pub clipped: Vec<u8>,
}

/// The state of one image row.
///
/// Invariants, for the frames `0 … D−1` evaluated so far (`D` a multiple of `W`):
/// * `prev_max[x]`: the brightest sample of the last evaluated block
///   (frames `D−W … D−1`; 0 before any);
/// * `d1[x]`: the deepest depth of frames `< D` (0 = none), reached first at
///   frame `k1`; `age[x] = min(D − 1 − k1, MAX)` (`MAX` before any dip);
///   `d2[x]`: the deepest depth among the frames that were farther than `W`
///   after the best event when folded, and of the best events they replaced;
/// * `hi`, `lo`: the levels of the dip at `k1` (`min(left, right)` and
///   `I_{k1}`; 0 while `d1 = 0`); `enter_at`/`leave_at`: the
///   centres `j` of its windows (`NO_FRAME` while `d1 = 0`);
///   `enter_window[x·2m .. x·2m+2m]`: the samples of frames `j−m … j+m−1`
///   around `j = enter_at[x]`, clamped to `[0, last]` (`last` the newest frame
///   when captured); likewise `leave_window`.
#[derive(Debug, Clone)]
struct RowState<T: Sample> {
    prev_max: Vec<T>,
    d1: Vec<T>,
    d2: Vec<T>,
    age: Vec<T>,
    hi: Vec<T>,
    lo: Vec<T>,
    enter_at: Vec<u32>,
    leave_at: Vec<u32>,
    enter_window: Vec<T>,
    leave_window: Vec<T>,
    /// The second candidate: the event whose depth is `d2` (see [`SecondDips`]).
    second: SecondState<T>,
}

/// The state of one row's second candidate dips.
///
/// Invariants (frames `0 … D−1`): where `d2[x] > 0`, the event that set it
/// has its darkest sample at some frame `k2`, `hi2 − lo2 = d2` (its lit level
/// and that sample), `enter_at2`/`leave_at2` the centres of its enter and
/// leave windows and `enter_window2`/`leave_window2` the samples around them,
/// found exactly as the best dip's ([`capture_dip`]); elsewhere `hi2 = lo2 = 0`
/// and the centres are `NO_FRAME`.
#[derive(Debug, Clone)]
struct SecondState<T: Sample> {
    hi2: Vec<T>,
    lo2: Vec<T>,
    enter_at2: Vec<u32>,
    leave_at2: Vec<u32>,
    enter_window2: Vec<T>,
    leave_window2: Vec<T>,
}

impl<T: Sample> SecondState<T> {
    /// Empty vectors when the tracker keeps no second candidates (never read then).
    fn new(width: usize, half: usize, keep: bool) -> Self {
        let width = if keep { width } else { 0 };
        SecondState {
            hi2: vec![T::MIN; width],
            lo2: vec![T::MIN; width],
            enter_at2: vec![NO_FRAME; width],
            leave_at2: vec![NO_FRAME; width],
            enter_window2: vec![T::MIN; width * 2 * half],
            leave_window2: vec![T::MIN; width * 2 * half],
        }
    }
}

impl<T: Sample> RowState<T> {
    fn new(width: usize, half: usize, second: bool) -> Self {
        RowState {
            prev_max: vec![T::MIN; width],
            d1: vec![T::MIN; width],
            d2: vec![T::MIN; width],
            age: vec![T::MAX; width],
            hi: vec![T::MIN; width],
            lo: vec![T::MIN; width],
            enter_at: vec![NO_FRAME; width],
            leave_at: vec![NO_FRAME; width],
            enter_window: vec![T::MIN; width * 2 * half],
            leave_window: vec![T::MIN; width * 2 * half],
            second: SecondState::new(width, half, second),
        }
    }
}

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

/// What evaluating one block of one row needs besides the row's state.
#[derive(Clone, Copy)]
struct BlockJob {
    /// First frame of the block (a multiple of `W`).
    start: usize,
    /// Newest frame available (the contexts and windows are clamped to it).
    last: usize,
    max_width: usize,
    half: usize,
}

impl BlockJob {
    /// One past the block's last available frame.
    fn end(&self) -> usize {
        (self.start + self.max_width).min(self.last + 1)
    }
    /// The frames of block `b + 1` that exist.
    fn next(&self) -> std::ops::Range<usize> {
        self.end()..(self.start + 2 * self.max_width).min(self.last + 1)
    }
}

/// Evaluate the block of `job` for the `V::LANES` pixels from `x0`: depths,
/// events, and the windows of pixels whose best dip moved.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn evaluate_span<'a, T: Sample, V: Vector<T>, const SECOND: bool>(
    state: &mut RowState<T>,
    ring: &'a FrameRing<T>,
    row: usize,
    ctx: &mut Option<Context<'a, T>>,
    rows: &[&[T]],
    next: &[&[T]],
    right: &mut [V],
    job: BlockJob,
    x0: usize,
) {
    let zero = V::splat(T::MIN);
    // Block b − 1's maximum (0 for block 0) and block b + 1's (0 if absent).
    let mprev: V = load(&state.prev_max, x0);
    let mut mnext = zero;
    for r in next {
        prefetch(r, x0 + PREFETCH_AHEAD);
        mnext = mnext.max(load(r, x0));
    }
    // Backward: right[i] = max(I[i+1 .. end), block b + 1); block b's maximum.
    let mut acc = mnext;
    let mut block_max = zero;
    for (i, r) in rows.iter().enumerate().rev() {
        right[i] = acc;
        let cur: V = load(r, x0);
        acc = acc.max(cur);
        block_max = block_max.max(cur);
    }
    store(block_max, &mut state.prev_max, x0);
    // Forward: left = max(block b − 1, I[start .. k−1]); depths; events.
    let mut left = mprev;
    let mut d1: V = load(&state.d1, x0);
    let mut d2: V = load(&state.d2, x0);
    let mut age: V = load(&state.age, x0);
    let none = V::splat(T::NO_OFFSET);
    let one = V::splat(T::from_offset(1));
    let far_after = V::splat(T::from_offset(job.max_width));
    let mut hi: V = load(&state.hi, x0);
    let mut lo: V = load(&state.lo, x0);
    let mut moved = none;
    // The second candidate: the best event's state at the block's start moves
    // there when a far frame beats it (FROM_BEST), a far frame deeper than the
    // second (not the best) becomes it (its offset).
    // Without SECOND these lanes are never loaded, updated nor stored.
    let (mut hi2, mut lo2): (V, V) = if SECOND {
        (load(&state.second.hi2, x0), load(&state.second.lo2, x0))
    } else {
        (zero, zero)
    };
    let mut moved2 = none;
    let from_best = V::splat(T::from_offset(FROM_BEST));
    // The frame's block-local offset in every lane.
    let mut offset = zero;
    // Masks are of the cheaper `≤` (`notbetter` = not a new best, `near` =
    // within W after it), the selects' operands ordered accordingly.
    for (i, r) in rows.iter().enumerate() {
        let cur: V = load(r, x0);
        let lit = left.min(right[i]);
        let depth = lit.sub_sat(cur);
        age = age.add_sat(one);
        let notbetter = depth.le(d1);
        let near = age.le(far_after);
        if SECOND {
            // far and better: the best becomes the second (promote); far, not better and
            // deeper than the second: this frame becomes it; else the second stays.
            let keep2 = near.or(notbetter.and(depth.le(d2)));
            hi2 = V::select(keep2, hi2, V::select(notbetter, lit, hi));
            lo2 = V::select(keep2, lo2, V::select(notbetter, cur, lo));
            moved2 = V::select(keep2, moved2, V::select(notbetter, offset, from_best));
        }
        d2 = V::select(near, d2, d2.max(depth.min(d1)));
        d1 = d1.max(depth);
        age = V::select(notbetter, age, zero);
        hi = V::select(notbetter, hi, lit);
        lo = V::select(notbetter, lo, cur);
        moved = V::select(notbetter, moved, offset);
        left = left.max(cur);
        offset = offset.add_sat(one);
    }
    store(d1, &mut state.d1, x0);
    store(d2, &mut state.d2, x0);
    store(age, &mut state.age, x0);
    store(hi, &mut state.hi, x0);
    store(lo, &mut state.lo, x0);
    if SECOND {
        store(hi2, &mut state.second.hi2, x0);
        store(lo2, &mut state.second.lo2, x0);
    }
    if SECOND && moved2.ne(none).any() {
        // Before the best dip's own capture: FROM_BEST copies its windows of the block's start.
        let mut offsets = [T::NO_OFFSET; MAX_LANES];
        store(moved2, &mut offsets, 0);
        for (i, &offset) in offsets[..V::LANES].iter().enumerate() {
            if offset == T::NO_OFFSET {
                continue;
            }
            if offset.index() == FROM_BEST {
                promote_best(state, x0 + i, job.half);
            } else {
                let ctx = ctx.get_or_insert_with(|| Context::new(ring, row, job.context()));
                capture_second(state, ctx, x0 + i, job.start + offset.index(), job);
            }
        }
    }
    if !moved.ne(none).any() {
        return;
    }
    let mut offsets = [T::NO_OFFSET; MAX_LANES];
    store(moved, &mut offsets, 0);
    let ctx = ctx.get_or_insert_with(|| Context::new(ring, row, job.context()));
    for (i, &offset) in offsets[..V::LANES].iter().enumerate() {
        if offset != T::NO_OFFSET {
            capture_dip(state, ctx, x0 + i, job.start + offset.index(), job);
        }
    }
}

/// The rows of one image row in every frame a capture may read: frames
/// `first … end−1`, [`BlockJob::context`].
struct Context<'a, T> {
    first: usize,
    rows: Vec<&'a [T]>,
}

impl<'a, T: Sample> Context<'a, T> {
    fn new(ring: &'a FrameRing<T>, row: usize, frames: std::ops::Range<usize>) -> Self {
        Context {
            first: frames.start,
            rows: frames.map(|f| ring.row(f, row)).collect(),
        }
    }

    #[inline(always)]
    fn at(&self, frame: usize, x: usize) -> T {
        self.rows[frame - self.first][x]
    }
}

impl BlockJob {
    /// Frames a capture in this block may read: the left context's start
    /// (block `b − 1`) less `m`, to the right context's end (block `b + 1`)
    /// plus `m − 1`, clamped to the frames that exist.
    fn context(&self) -> std::ops::Range<usize> {
        let first = self.start.saturating_sub(self.max_width + self.half);
        let end = (self.start + 2 * self.max_width + self.half).min(self.last + 1);
        first..end
    }
}

/// Marks, among the second candidate's block-local offsets, "the best dip of
/// the block's start became the second" (offsets are `< W ≤ 128`).
const FROM_BEST: usize = TrackerParams::MAX_WIDTH + 1;

/// Pixel `x`'s best dip (as captured before this block) became its second candidate.
fn promote_best<T: Sample>(state: &mut RowState<T>, x: usize, half: usize) {
    let span = 2 * half;
    let s = &mut state.second;
    s.enter_at2[x] = state.enter_at[x];
    s.leave_at2[x] = state.leave_at[x];
    s.enter_window2[x * span..(x + 1) * span]
        .copy_from_slice(&state.enter_window[x * span..(x + 1) * span]);
    s.leave_window2[x * span..(x + 1) * span]
        .copy_from_slice(&state.leave_window[x * span..(x + 1) * span]);
}

/// Record the new second candidate of pixel `x` at frame `k2` of `job`'s
/// block (levels already set by the vector pass), as [`capture_dip`] does the best.
fn capture_second<T: Sample>(
    state: &mut RowState<T>,
    ctx: &Context<'_, T>,
    x: usize,
    k2: usize,
    job: BlockJob,
) {
    let s = &mut state.second;
    let span = 2 * job.half;
    let (enter, leave) = dip_crossings(ctx, x, k2, s.hi2[x], s.lo2[x], job);
    fill_window(
        ctx,
        x,
        job,
        &mut s.enter_window2[x * span..(x + 1) * span],
        enter,
    );
    fill_window(
        ctx,
        x,
        job,
        &mut s.leave_window2[x * span..(x + 1) * span],
        leave,
    );
    s.enter_at2[x] = enter as u32;
    s.leave_at2[x] = leave as u32;
}

/// The centres of the enter and leave crossings (in DN, through the mid-level
/// of `hi` and `lo`) of pixel `x`'s dip whose darkest sample is at frame `k`.
fn dip_crossings<T: Sample>(
    ctx: &Context<'_, T>,
    x: usize,
    k: usize,
    hi: T,
    lo: T,
    job: BlockJob,
) -> (usize, usize) {
    let at = |frame: usize| ctx.at(frame, x);
    let sum = hi.index() + lo.index();
    let bright = |frame: usize| 2 * at(frame).index() >= sum;
    let first = job.start.saturating_sub(job.max_width);
    let enter = (first..k)
        .rev()
        .find(|&c| bright(c))
        .map_or(first, |c| c + 1);
    let stop = (job.start + 2 * job.max_width).min(job.last + 1);
    let leave = (k + 1..stop).find(|&c| bright(c)).unwrap_or(stop - 1);
    (enter, leave)
}

/// The `2m` samples of pixel `x` around centre `j` (frames `j−m … j+m−1`, clamped).
fn fill_window<T: Sample>(ctx: &Context<'_, T>, x: usize, job: BlockJob, dst: &mut [T], j: usize) {
    for (i, d) in dst.iter_mut().enumerate() {
        *d = ctx.at((j + i).saturating_sub(job.half).min(job.last), x);
    }
}

/// Record the new best dip of pixel `x` at frame `k1` of `job`'s block: its
/// levels, the centres of its enter and leave crossings in DN and the
/// windows around them (every frame needed is in `ctx`).
fn capture_dip<T: Sample>(
    state: &mut RowState<T>,
    ctx: &Context<'_, T>,
    x: usize,
    k1: usize,
    job: BlockJob,
) {
    let at = |frame: usize| ctx.at(frame, x);
    // Set by the vector pass: the lit level min(left, right) and I_{k1}.
    let (hi, lo) = (state.hi[x], state.lo[x]);
    debug_assert!(hi > lo);
    // Mid-level in DN, exactly: 2·v ≥ hi + lo.
    let sum = hi.index() + lo.index();
    let bright = |frame: usize| 2 * at(frame).index() >= sum;
    // The left context holds a sample ≥ hi, so a bright frame exists back to
    // the start of block b − 1; likewise forward to the end of block b + 1.
    let first = job.start.saturating_sub(job.max_width);
    let enter = (first..k1)
        .rev()
        .find(|&c| bright(c))
        .map_or(first, |c| c + 1);
    let stop = (job.start + 2 * job.max_width).min(job.last + 1);
    let leave = (k1 + 1..stop).find(|&c| bright(c)).unwrap_or(stop - 1);
    let span = 2 * job.half;
    let window = |dst: &mut [T], j: usize| {
        for (i, d) in dst.iter_mut().enumerate() {
            *d = at((j + i).saturating_sub(job.half).min(job.last));
        }
    };
    window(&mut state.enter_window[x * span..(x + 1) * span], enter);
    window(&mut state.leave_window[x * span..(x + 1) * span], leave);
    state.enter_at[x] = enter as u32;
    state.leave_at[x] = leave as u32;
}

/// Evaluate `job`'s block of one row with vectors `V`.
#[inline(always)]
fn evaluate_row_with<T: Sample, V: Vector<T>, const SECOND: bool>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    job: BlockJob,
) {
    debug_assert!(V::LANES <= MAX_LANES);
    let width = state.d1.len();
    let rows: Vec<&[T]> = (job.start..job.end()).map(|j| ring.row(j, row)).collect();
    let next: Vec<&[T]> = job.next().map(|j| ring.row(j, row)).collect();
    let mut right = vec![V::splat(T::MIN); rows.len()];
    // The rows a capture reads, gathered on the first capture in this row.
    let mut ctx = None;
    let split = width - width % V::LANES;
    for x0 in (0..split).step_by(V::LANES) {
        evaluate_span::<T, V, SECOND>(
            state, ring, row, &mut ctx, &rows, &next, &mut right, job, x0,
        );
    }
    let mut right = vec![Portable::<T, 1>::splat(T::MIN); rows.len()];
    for x0 in split..width {
        evaluate_span::<T, Portable<T, 1>, SECOND>(
            state, ring, row, &mut ctx, &rows, &next, &mut right, job, x0,
        );
    }
}

/// [`evaluate_row_with`] compiled for AVX2.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn evaluate_row_avx2<T: Sample, const SECOND: bool>(
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    job: BlockJob,
) {
    evaluate_row_with::<T, T::Avx2, SECOND>(state, ring, row, job)
}

/// Evaluate `job`'s block of one row on the instruction set `path` (which
/// the CPU must support: checked when it is set), keeping the second
/// candidates when `second` (the tracker's [`TrackerParams::second_dips`];
/// the row's state was allocated for it).
fn evaluate_row<T: Sample>(
    path: SimdPath,
    second: bool,
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    job: BlockJob,
) {
    if second {
        evaluate_row_on::<T, true>(path, state, ring, row, job)
    } else {
        evaluate_row_on::<T, false>(path, state, ring, row, job)
    }
}

/// [`evaluate_row`] with the second candidates' choice made at compile time.
fn evaluate_row_on<T: Sample, const SECOND: bool>(
    path: SimdPath,
    state: &mut RowState<T>,
    ring: &FrameRing<T>,
    row: usize,
    job: BlockJob,
) {
    match path {
        #[cfg(target_arch = "x86_64")]
        SimdPath::Avx2 => {
            debug_assert!(path.is_supported());
            // SAFETY: the tracker only holds a path the CPU supports.
            unsafe { evaluate_row_avx2::<T, SECOND>(state, ring, row, job) }
        }
        #[cfg(target_arch = "x86_64")]
        SimdPath::Sse2 => evaluate_row_with::<T, T::Sse2, SECOND>(state, ring, row, job),
        _ => evaluate_row_with::<T, T::Portable, SECOND>(state, ring, row, job),
    }
}

/// Streaming per-pixel shadow tracker over frames of `T` (`u8` or `u16`).
///
/// Invariants between calls (`F` = frames seen, `D` = frames evaluated,
/// `W` = max width, `m` = window):
/// * the ring has `S = 3W + 2m` slots and holds frames `max(0, F−S) … F−1`;
/// * `D` is a multiple of `W` and `F < D + 2W + m − 1`: the block from `D` is
///   evaluated as soon as `F = D + 2W + m − 1`, when its right contexts and
///   windows (to frame `D + 2W + m − 2`) are in the ring, and its left ones
///   (back to `D − W − m + 1`) still are;
/// * every row state satisfies [`RowState`]'s invariants for frames `0 … D−1`.
///
/// [`finish`](Self::finish) works on a copy of each row's state and evaluates
/// the pending blocks with the contexts and windows clamped to `F − 1`, so it
/// can be called at any time for a preview.
#[derive(Debug, Clone)]
pub struct TemporalTracker<T: Sample> {
    height: usize,
    width: usize,
    params: TrackerParams,
    ring: FrameRing<T>,
    rows: Vec<RowState<T>>,
    frames_seen: usize,
    frames_evaluated: usize,
    path: SimdPath,
    /// What the samples are: the decoding table, and in normalised mode the
    /// frames' gains.
    intensity: Intensity,
    /// The live watch, once [`watch`](Self::watch) was called.
    watch: Option<Watch<T>>,
}

impl<T: Sample> TemporalTracker<T> {
    /// A tracker for frames of `height × width` samples, DN decoded as
    /// themselves (linear data).
    pub fn new(height: usize, width: usize, params: TrackerParams) -> Result<Self, KernelError> {
        Self::build(height, width, params, Intensity::dn::<T>(None)?)
    }

    /// A tracker for frames of `height × width` DN decoded by the capture's
    /// `table` (`T::LUT_LEN` finite, non-decreasing values: DN → linear).
    pub fn with_table(
        height: usize,
        width: usize,
        params: TrackerParams,
        table: &[f32],
    ) -> Result<Self, KernelError> {
        Self::build(height, width, params, Intensity::dn::<T>(Some(table))?)
    }

    fn build(
        height: usize,
        width: usize,
        params: TrackerParams,
        intensity: Intensity,
    ) -> Result<Self, KernelError> {
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
                .map(|_| RowState::new(width, params.window, params.second_dips))
                .collect(),
            frames_seen: 0,
            frames_evaluated: 0,
            path: SimdPath::active(),
            intensity,
            watch: None,
        })
    }

    /// Whether the frames come with a gain ([`TemporalTracker::normalised`]).
    pub fn is_normalised(&self) -> bool {
        self.intensity.is_normalised()
    }

    /// The decoding table of the input's DN (256 or 65536 entries).
    pub fn input_len(&self) -> usize {
        self.intensity.input_len()
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
        if let Some(watch) = &mut self.watch {
            watch.config.path = path;
        }
        Ok(())
    }

    /// Number of frames given to [`update`](Self::update) so far.
    pub fn frames_seen(&self) -> usize {
        self.frames_seen
    }

    /// Check that `frame` (of any sample type) can be the next frame.
    fn check_frame<I>(&self, frame: &[I]) -> Result<(), KernelError> {
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
        Ok(())
    }

    /// Add the next frame (row-major, `height × width` DN). An error for a
    /// normalised tracker, whose frames come with a gain
    /// ([`update_with_gain`](TemporalTracker::update_with_gain)).
    pub fn update(&mut self, frame: &[T]) -> Result<(), KernelError> {
        self.check_frame(frame)?;
        if self.intensity.is_normalised() {
            return Err(KernelError::parameter(
                "gain",
                "a normalised tracker needs each frame's gain",
            ));
        }
        // In parallel pieces: one core does not saturate the memory bus.
        self.ring
            .slot_mut(self.frames_seen)
            .par_chunks_mut(STORE_PIECE)
            .zip(frame.par_chunks(STORE_PIECE))
            .for_each(|(dst, src)| dst.copy_from_slice(src));
        self.stored();
        Ok(())
    }

    /// The frame just stored in the ring is the next one: fold it into the
    /// watch, and evaluate a block when one is due.
    fn stored(&mut self) {
        let max_width = self.params.max_width;
        self.frames_seen += 1;
        if let Some(watch) = &mut self.watch {
            let (ring, config) = (&self.ring, &watch.config);
            let newest = self.frames_seen - 1;
            let oldest = self.frames_seen.saturating_sub(ring.slots());
            watch
                .rows
                .par_iter_mut()
                .enumerate()
                .for_each(|(row, state)| {
                    config.update_row(state, ring, &self.intensity, row, newest, oldest)
                });
        }
        if self.frames_seen == self.params.evaluate_at(self.frames_evaluated) {
            let job = BlockJob {
                start: self.frames_evaluated,
                last: self.frames_seen - 1,
                max_width,
                half: self.params.window,
            };
            let (ring, path, second) = (&self.ring, self.path, self.params.second_dips);
            self.rows
                .par_iter_mut()
                .enumerate()
                .for_each(|(row, state)| evaluate_row(path, second, state, ring, row, job));
            self.frames_evaluated += max_width;
        }
    }

    /// Start the live watch ([`crate::live`]) from the next frame on, with
    /// the settings `params` (its provisional times decoded as in
    /// [`finish`](Self::finish)). Replaces an earlier watch.
    pub fn watch(&mut self, params: WatchParams) -> Result<(), KernelError> {
        self.watch = Some(Watch::new(
            self.height,
            self.width,
            self.params.window,
            self.path,
            &params,
            &self.intensity,
        )?);
        Ok(())
    }

    /// The pixels whose dip ended since the last call, with their provisional
    /// levels and times (row by row; see [`crate::live`]). An error before
    /// [`watch`](Self::watch).
    pub fn take_finished(&mut self) -> Result<Vec<FinishedPixel>, KernelError> {
        match &mut self.watch {
            Some(watch) => Ok(watch.take_finished()),
            None => Err(KernelError::parameter(
                "watch",
                "the live watch was not started",
            )),
        }
    }

    /// Pixels of the live watch that are lit (no dip yet), in a dip, and
    /// finished; `None` before [`watch`](Self::watch).
    pub fn watch_counts(&self) -> Option<(usize, usize, usize)> {
        self.watch.as_ref().map(Watch::counts)
    }

    /// The per-pixel results for the frames seen so far; does not change the
    /// tracker.
    ///
    /// `min_contrast` (DN of the input, in every mode): pixels whose deepest
    /// dip is shallower are invalid (times NaN). Thresholds, interpolation
    /// and slopes use the decoded values (see [`crate::intensity`]).
    pub fn finish(&self, min_contrast: f32) -> Result<ShadowTimes, KernelError> {
        if self.frames_seen == 0 {
            return Err(KernelError::NoFrames);
        }
        if !min_contrast.is_finite() {
            return Err(KernelError::parameter(
                "min_contrast",
                format!("must be finite, got {min_contrast}"),
            ));
        }
        let last = self.frames_seen - 1;
        // the light of a dip without times
        let fallback = self.intensity.median_gain();
        let params = self.params;
        let pending: Vec<BlockJob> = (self.frames_evaluated..=last)
            .step_by(params.max_width)
            .map(|start| BlockJob {
                start,
                last,
                max_width: params.max_width,
                half: params.window,
            })
            .collect();
        let mut times = ShadowTimes::empty(self.height, self.width);
        let out_rows = times.rows_mut();
        out_rows
            .into_par_iter()
            .zip(self.rows.par_iter())
            .enumerate()
            .for_each(|(row, (mut out, evaluated))| {
                let mut state = evaluated.clone();
                for &job in &pending {
                    evaluate_row(
                        self.path,
                        self.params.second_dips,
                        &mut state,
                        &self.ring,
                        row,
                        job,
                    );
                }
                let light = Light {
                    intensity: &self.intensity,
                    min_contrast,
                    fallback,
                };
                resolve_row(&state, light, &params, &mut out);
            });
        Ok(times)
    }
}

impl<T: Sample> TemporalTracker<T> {
    /// Every pixel's second candidate dip for the frames seen so far (the
    /// event whose depth is [`ShadowTimes::rival`]); does not change the
    /// tracker. Decoded and reported as in [`finish`](Self::finish) (each
    /// dip in its own light). No contrast floor: the caller compares
    /// [`SecondDips::contrast`] with its own.
    pub fn finish_second(&self) -> Result<SecondDips, KernelError> {
        if !self.params.second_dips {
            return Err(KernelError::parameter(
                "second_dips",
                "finish_second needs a tracker built with second_dips = true \
                 (it keeps no second candidates otherwise)",
            ));
        }
        if self.frames_seen == 0 {
            return Err(KernelError::NoFrames);
        }
        let fallback = self.intensity.median_gain();
        let last = self.frames_seen - 1;
        let params = self.params;
        let pending: Vec<BlockJob> = (self.frames_evaluated..=last)
            .step_by(params.max_width)
            .map(|start| BlockJob {
                start,
                last,
                max_width: params.max_width,
                half: params.window,
            })
            .collect();
        let (h, w) = (self.height, self.width);
        let mut out = SecondDips::empty(h, w);
        let rows: Vec<SecondRow> = self
            .rows
            .par_iter()
            .enumerate()
            .map(|(row, evaluated)| {
                let mut state = evaluated.clone();
                for &job in &pending {
                    evaluate_row(
                        self.path,
                        self.params.second_dips,
                        &mut state,
                        &self.ring,
                        row,
                        job,
                    );
                }
                resolve_second_row(&state, &self.intensity, fallback, params.window)
            })
            .collect();
        for (y, r) in rows.into_iter().enumerate() {
            let at = y * w..(y + 1) * w;
            out.imax[at.clone()].copy_from_slice(&r.imax);
            out.imin[at.clone()].copy_from_slice(&r.imin);
            out.contrast[at.clone()].copy_from_slice(&r.contrast);
            out.threshold[at.clone()].copy_from_slice(&r.threshold);
            out.enter[at.clone()].copy_from_slice(&r.enter);
            out.leave[at.clone()].copy_from_slice(&r.leave);
            out.enter_slope[at.clone()].copy_from_slice(&r.enter_slope);
            out.leave_slope[at.clone()].copy_from_slice(&r.leave_slope);
            out.best_enter[at.clone()].copy_from_slice(&r.best_enter);
            out.best_leave[at.clone()].copy_from_slice(&r.best_leave);
            out.best_enter_slope[at.clone()].copy_from_slice(&r.best_enter_slope);
            out.best_leave_slope[at].copy_from_slice(&r.best_leave_slope);
        }
        Ok(out)
    }
}

/// Every pixel's second candidate dip ([`TemporalTracker::finish_second`]):
/// the deepest dip apart from the best one, with the same definitions as the
/// best's in [`ShadowTimes`] (levels in DN, threshold and slopes linear,
/// times in frames; NaN times and 0 levels where there is none). Row-major
/// `(height, width)` arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct SecondDips {
    pub height: usize,
    pub width: usize,
    pub imax: Vec<f32>,
    pub imin: Vec<f32>,
    /// `imax − imin` = [`ShadowTimes::rival`] (DN); 0 = none.
    pub contrast: Vec<f32>,
    pub threshold: Vec<f32>,
    pub enter: Vec<f32>,
    pub leave: Vec<f32>,
    pub enter_slope: Vec<f32>,
    pub leave_slope: Vec<f32>,
    /// The best dip's times and slopes as in [`ShadowTimes`], but wherever it
    /// exists (also where it is ambiguous or below the contrast floor): what
    /// a caller choosing between the two candidates needs.
    pub best_enter: Vec<f32>,
    pub best_leave: Vec<f32>,
    pub best_enter_slope: Vec<f32>,
    pub best_leave_slope: Vec<f32>,
}

impl SecondDips {
    fn empty(height: usize, width: usize) -> Self {
        let n = height * width;
        SecondDips {
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
            best_enter: vec![f32::NAN; n],
            best_leave: vec![f32::NAN; n],
            best_enter_slope: vec![f32::NAN; n],
            best_leave_slope: vec![f32::NAN; n],
        }
    }
}

/// One row of [`SecondDips`].
struct SecondRow {
    imax: Vec<f32>,
    imin: Vec<f32>,
    contrast: Vec<f32>,
    threshold: Vec<f32>,
    enter: Vec<f32>,
    leave: Vec<f32>,
    enter_slope: Vec<f32>,
    leave_slope: Vec<f32>,
    best_enter: Vec<f32>,
    best_leave: Vec<f32>,
    best_enter_slope: Vec<f32>,
    best_leave_slope: Vec<f32>,
}

/// One row's second candidates, resolved like the best dips in [`resolve_row`]
/// (`fallback`: the gain of a dip without times).
fn resolve_second_row<T: Sample>(
    state: &RowState<T>,
    intensity: &Intensity,
    fallback: f64,
    half: usize,
) -> SecondRow {
    let lut = intensity.decode();
    let s = &state.second;
    let width = s.hi2.len();
    let span = 2 * half;
    let mut row = SecondRow {
        imax: vec![0.0; width],
        imin: vec![0.0; width],
        contrast: vec![0.0; width],
        threshold: vec![0.0; width],
        enter: vec![f32::NAN; width],
        leave: vec![f32::NAN; width],
        enter_slope: vec![f32::NAN; width],
        leave_slope: vec![f32::NAN; width],
        best_enter: vec![f32::NAN; width],
        best_leave: vec![f32::NAN; width],
        best_enter_slope: vec![f32::NAN; width],
        best_leave_slope: vec![f32::NAN; width],
    };
    let mut linear = vec![0.0f32; span];
    let mut solve = |at: u32, window: &[T], threshold: f32, edge: Edge| -> (f32, f32) {
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
    for x in 0..width {
        let (hi, lo) = (state.hi[x], state.lo[x]);
        if state.enter_at[x] != NO_FRAME && hi > lo {
            let threshold = (lut[hi.index()] + lut[lo.index()]) * 0.5;
            let window = &state.enter_window[x * span..(x + 1) * span];
            (row.best_enter[x], row.best_enter_slope[x]) =
                solve(state.enter_at[x], window, threshold, Edge::Enter);
            let window = &state.leave_window[x * span..(x + 1) * span];
            (row.best_leave[x], row.best_leave_slope[x]) =
                solve(state.leave_at[x], window, threshold, Edge::Leave);
            // slopes in the light of the best dip, as in `finish`
            let centre = Intensity::dip_time(row.best_enter[x], row.best_leave[x]);
            let gain = intensity.gain_at(centre, fallback) as f32;
            row.best_enter_slope[x] *= gain;
            row.best_leave_slope[x] *= gain;
        }
        let (hi, lo) = (s.hi2[x], s.lo2[x]);
        if s.enter_at2[x] == NO_FRAME || hi <= lo {
            continue;
        }
        let threshold = (lut[hi.index()] + lut[lo.index()]) * 0.5;
        let window = &s.enter_window2[x * span..(x + 1) * span];
        let (enter, enter_slope) = solve(s.enter_at2[x], window, threshold, Edge::Enter);
        let window = &s.leave_window2[x * span..(x + 1) * span];
        let (leave, leave_slope) = solve(s.leave_at2[x], window, threshold, Edge::Leave);
        // reported in its own light, as the best dip in `finish`
        let gain = intensity.gain_at(Intensity::dip_time(enter, leave), fallback);
        let r = intensity.report(hi, lo, T::MIN, gain);
        row.imax[x] = r.imax;
        row.imin[x] = r.imin;
        row.contrast[x] = r.imax - r.imin;
        row.threshold[x] = threshold * r.gain;
        (row.enter[x], row.enter_slope[x]) = (enter, enter_slope * r.gain);
        (row.leave[x], row.leave_slope[x]) = (leave, leave_slope * r.gain);
    }
    row
}

impl TemporalTracker<u16> {
    /// A tracker for frames whose light changes (the sun through a day):
    /// each frame of `height × width` DN comes with its gain
    /// ([`update_with_gain`](Self::update_with_gain)). `table` decodes the
    /// input's DN (256 entries for `u8` frames, 65536 for `u16`). The samples
    /// are normalised codes ([`crate::intensity`]).
    pub fn normalised(
        height: usize,
        width: usize,
        params: TrackerParams,
        table: &[f32],
    ) -> Result<Self, KernelError> {
        Self::build(height, width, params, Intensity::normalised(table)?)
    }

    /// Add the next frame of a normalised tracker: `frame` the input's DN
    /// (row-major; `I` the input's type, matching the table), `gain` (> 0)
    /// its light relative to the first frame's. The kernel decodes each
    /// sample and divides it by the gain.
    pub fn update_with_gain<I: Sample>(
        &mut self,
        frame: &[I],
        gain: f64,
    ) -> Result<(), KernelError> {
        self.check_frame(frame)?;
        if self.intensity.is_normalised() && self.intensity.input_len() != I::LUT_LEN {
            return Err(KernelError::parameter(
                "frame",
                format!(
                    "a {} frame for a tracker whose decoding table has {} entries",
                    I::DTYPE,
                    self.intensity.input_len()
                ),
            ));
        }
        let code = self.intensity.encoder(gain)?;
        // (the table has I::LUT_LEN entries, checked above: sliced to that
        // length, every sample indexes it without a bounds check)
        let code = &code[..I::LUT_LEN];
        self.ring
            .slot_mut(self.frames_seen)
            .par_chunks_mut(STORE_PIECE)
            .zip(frame.par_chunks(STORE_PIECE))
            .for_each(|(dst, src)| encode(dst, src, code));
        self.stored();
        Ok(())
    }

    /// Add the next frame of a normalised tracker whose light is not one gain
    /// for every pixel (a cloud frame: the direct sun dims, the sky
    /// brightens, so each pixel's level changes by its own factor): `gain`
    /// (> 0) is the frame's light as in
    /// [`update_with_gain`](Self::update_with_gain) and `levels` (one per
    /// pixel, row-major, finite and > 0) each pixel's own factor on top of it,
    /// so a sample is stored as `L(DN) · S / (gain · level)`. A sample at the
    /// input's largest DN is stored as the largest code (so it stays flagged
    /// as clipped, whatever its level). The per-pixel factors are not kept:
    /// a dip is reported in the light `gain` (the frame's light levelled).
    pub fn update_with_levels<I: Sample>(
        &mut self,
        frame: &[I],
        gain: f64,
        levels: &[f32],
    ) -> Result<(), KernelError> {
        self.check_frame(frame)?;
        if levels.len() != frame.len() {
            return Err(KernelError::LengthMismatch {
                what: "levels",
                expected: frame.len(),
                got: levels.len(),
            });
        }
        // (a fold over the whole frame, which vectorises; the position only on error)
        let ok = |l: f32| l > 0.0 && l < f32::INFINITY;
        let all_ok = levels.iter().fold(true, |all, &l| all & ok(l));
        if let Some(i) = levels.iter().position(|&l| !all_ok && !ok(l)) {
            return Err(KernelError::parameter(
                "levels",
                format!("must be finite and > 0, got {} at pixel {i}", levels[i]),
            ));
        }
        if !self.intensity.is_normalised() || self.intensity.input_len() != I::LUT_LEN {
            return Err(KernelError::parameter(
                "levels",
                "only a normalised tracker, with frames of its table's type, takes per-pixel levels",
            ));
        }
        // L(DN) · (S / gain) per DN of the input, then divided per pixel
        let factor = (f64::from(crate::intensity::NORMALISED_SCALE) / gain) as f32;
        let scaled: Vec<f32> = self.intensity.input_table()[..I::LUT_LEN]
            .iter()
            .map(|&l| l * factor)
            .collect();
        // (the frame's code table is only used for its gain and clipping code here)
        self.intensity.encoder_levelled(gain)?;
        self.ring
            .slot_mut(self.frames_seen)
            .par_chunks_mut(STORE_PIECE)
            .zip(frame.par_chunks(STORE_PIECE))
            .zip(levels.par_chunks(STORE_PIECE))
            .for_each(|((dst, src), lev)| encode_levelled(dst, src, lev, &scaled));
        self.stored();
        Ok(())
    }
}

/// `dst[i] = code[src[i]]`: a frame's samples through its code table
/// (`code.len() == I::LUT_LEN`, so no index is out of bounds).
#[inline(always)]
fn encode<I: Sample>(dst: &mut [u16], src: &[I], code: &[u16]) {
    debug_assert_eq!(code.len(), I::LUT_LEN);
    // Four independent lookups per step: the loads overlap.
    let mut d4 = dst.chunks_exact_mut(4);
    let mut s4 = src.chunks_exact(4);
    for (d, s) in (&mut d4).zip(&mut s4) {
        let (a, b, c, e) = (
            code[s[0].index()],
            code[s[1].index()],
            code[s[2].index()],
            code[s[3].index()],
        );
        d[0] = a;
        d[1] = b;
        d[2] = c;
        d[3] = e;
    }
    for (d, s) in d4.into_remainder().iter_mut().zip(s4.remainder()) {
        *d = code[s.index()];
    }
}

/// `dst[i]`: the code of sample `src[i]` divided by its level `lev[i]`,
/// `min(⌊scaled[src[i]] / lev[i]⌋, 65534)`, or 65535 for the input's largest
/// DN (`scaled.len() == I::LUT_LEN`: `L(DN) · S / gain`). The table look-ups
/// go into a small buffer first, so that the divisions, clamps and
/// conversions run as one loop the compiler vectorises.
#[inline(always)]
fn encode_levelled<I: Sample>(dst: &mut [u16], src: &[I], lev: &[f32], scaled: &[f32]) {
    const PIECE: usize = 256;
    let scaled = &scaled[..I::LUT_LEN];
    let top = I::LUT_LEN - 1;
    const CAPPED: f32 = (u16::MAX - 1) as f32;
    let mut linear = [0.0f32; PIECE];
    for ((d, s), l) in dst
        .chunks_mut(PIECE)
        .zip(src.chunks(PIECE))
        .zip(lev.chunks(PIECE))
    {
        let linear = &mut linear[..d.len()];
        for (x, v) in linear.iter_mut().zip(s) {
            *x = scaled[v.index()];
        }
        for (((d, &x), &l), v) in d.iter_mut().zip(linear.iter()).zip(l).zip(s) {
            // (never NaN, the table being finite and the level finite and > 0: clamped by
            // compares and selects, then truncated towards zero through i32, which vectorise)
            let q = x / l;
            let q = if q < CAPPED { q } else { CAPPED };
            let code = (if q > 0.0 { q } else { 0.0 }) as i32 as u16;
            *d = if v.index() >= top { u16::MAX } else { code };
        }
    }
}

/// What turning a row's state into results needs besides the state.
#[derive(Clone, Copy)]
struct Light<'a> {
    intensity: &'a Intensity,
    /// DN of the input.
    min_contrast: f32,
    /// The gain of a dip without times (normalised mode).
    fallback: f64,
}

/// Turn one row's state into results.
///
/// In DN mode only a dip deep enough is solved for times. In normalised mode
/// the contrast in DN depends on the light at the dip, i.e. on its times:
/// every unambiguous dip is solved, then the contrast decides.
fn resolve_row<T: Sample>(
    state: &RowState<T>,
    light: Light<'_>,
    params: &TrackerParams,
    out: &mut RowTimesMut<'_>,
) {
    let intensity = light.intensity;
    let lut = intensity.decode();
    let normalised = intensity.is_normalised();
    let top = (intensity.input_len() - 1) as f32;
    let half = params.window;
    let span = 2 * half;
    let mut linear = vec![0.0f32; span];
    // (time, slope, a sample interpolated is clipped)
    let mut solve = |at: u32, window: &[T], threshold: f32, edge: Edge| -> (f32, f32, bool) {
        for (l, v) in linear.iter_mut().zip(window) {
            *l = lut[v.index()];
        }
        match find_crossing(&linear, threshold, edge) {
            Some(c) => {
                let frame = at as i64 - half as i64 + c.index as i64;
                // the frames of the two samples (clamped as when captured)
                let of = |k: i64| k.max(0) as usize;
                let clipped = intensity.clipped(window[c.index], of(frame))
                    || intensity.clipped(window[c.index + 1], of(frame + 1));
                (
                    (frame as f64 + f64::from(c.fraction)) as f32,
                    c.slope,
                    clipped,
                )
            }
            None => (f32::NAN, f32::NAN, false),
        }
    };
    for x in 0..state.d1.len() {
        let has_dip = state.enter_at[x] != NO_FRAME;
        let (hi, lo, d2) = (state.hi[x], state.lo[x], state.d2[x]);
        // depths compared in samples
        let depth = hi.to_f32() - lo.to_f32();
        let unambiguous = has_dip && d2.to_f32() < params.ambiguity * depth;
        let threshold = (lut[hi.index()] + lut[lo.index()]) * 0.5;
        let wanted = unambiguous && (normalised || depth >= light.min_contrast);
        let nan = (f32::NAN, f32::NAN, false);
        let (enter, leave) = if wanted {
            let window = &state.enter_window[x * span..(x + 1) * span];
            let enter = solve(state.enter_at[x], window, threshold, Edge::Enter);
            let window = &state.leave_window[x * span..(x + 1) * span];
            (
                enter,
                solve(state.leave_at[x], window, threshold, Edge::Leave),
            )
        } else {
            (nan, nan)
        };
        let centre = Intensity::dip_time(enter.0, leave.0);
        let gain = intensity.gain_at(centre, light.fallback);
        let r = intensity.report(hi, lo, d2, gain);
        let contrast = r.imax - r.imin;
        let deep = has_dip && contrast >= light.min_contrast;
        let valid = deep && unambiguous;
        let (enter, leave) = if valid { (enter, leave) } else { (nan, nan) };
        out.imax[x] = r.imax;
        out.imin[x] = r.imin;
        out.contrast[x] = contrast;
        out.threshold[x] = threshold * r.gain;
        out.rival[x] = r.rival;
        out.valid[x] = u8::from(valid);
        out.ambiguous[x] = u8::from(deep && !unambiguous);
        (out.enter[x], out.enter_slope[x]) = (enter.0, enter.1 * r.gain);
        (out.leave[x], out.leave_slope[x]) = (leave.0, leave.1 * r.gain);
        let levels_clipped = r.imax >= top || r.imin <= 0.0 || hi == T::MAX;
        out.clipped[x] = u8::from(has_dip && levels_clipped || enter.2 || leave.2);
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
    rival: &'a mut [f32],
    valid: &'a mut [u8],
    ambiguous: &'a mut [u8],
    clipped: &'a mut [u8],
}

macro_rules! split_fields {
    ($self:ident, $mid:ident, $($f:ident),*) => {{
        $(let $f = $self.$f.split_at_mut($mid);)*
        (
            RowTimesMut { $($f: $f.0,)* },
            RowTimesMut { $($f: $f.1,)* },
        )
    }};
}

impl<'a> RowTimesMut<'a> {
    fn split_at(self, mid: usize) -> (Self, Self) {
        split_fields!(
            self,
            mid,
            imax,
            imin,
            contrast,
            threshold,
            enter,
            leave,
            enter_slope,
            leave_slope,
            rival,
            valid,
            ambiguous,
            clipped
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
            rival: vec![0.0; n],
            valid: vec![0; n],
            ambiguous: vec![0; n],
            clipped: vec![0; n],
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
            rival: &mut self.rival,
            valid: &mut self.valid,
            ambiguous: &mut self.ambiguous,
            clipped: &mut self.clipped,
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
