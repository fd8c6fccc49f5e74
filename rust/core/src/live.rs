//! Live watch: pixels whose shadow has passed, as soon as it has passed.
//!
//! The block tracker ([`crate::TemporalTracker`]) settles a pixel's deepest
//! dip only `2W + m − 1` frames after it, and only for the whole sequence at
//! [`finish`](crate::TemporalTracker::finish). A live view needs each pixel
//! as soon as the shadow has left it. The watch is a small per-pixel state
//! machine fed with every frame (the tracker's samples `v`, frame `f`: the
//! input's DN, or normalised codes, see [`crate::intensity`]):
//!
//! * **lit**: `lit` is the brightest sample so far (the lit level before the
//!   dip). A sample at least `min_contrast` below it opens a dip: `lo = v`,
//!   `k_min = f`. (`min_contrast` is given in DN of the input; for normalised
//!   codes it is the step it spans at the input's mid-grey.)
//! * **dip**: a darker sample moves the minimum (`lo`, `k_min`) and resets
//!   the recovery count; a sample at or above the DN mid-level,
//!   `2·v ≥ lit + lo`, counts one frame of recovery (a sample below it
//!   resets the count). After `recover` consecutive frames of recovery the
//!   pixel is **finished**, at the current frame.
//! * **finished**: one dip per pixel; the state no longer changes.
//!
//! A finished pixel's provisional times are those of the block tracker's
//! definitions applied to this dip, from the frames still in the tracker's
//! ring: enter is the frame after the last bright sample (`2·v ≥ lit + lo`)
//! before `k_min`, leave the first bright one after it; the `2m` samples
//! around each (clamped to the frames in the ring) are decoded with the LUT
//! and the crossing of the linear threshold `(L(lit) + L(lo)) / 2` nearest
//! the window's centre is interpolated ([`find_crossing`]). A dip whose
//! enter has left the ring (wider than the ring) gets NaN times. Levels,
//! threshold and slopes are reported as [`finish`] reports them: DN of the
//! input and linear values in the light of the dip.
//!
//! The watch does not change the tracker's results: [`finish`] remains the
//! final word (its lit level is the brighter context on both sides, its dip
//! the deepest one), and a live view refines to it when the capture ends.
//!
//! [`finish`]: crate::TemporalTracker::finish

use crate::crossing::{find_crossing, Edge};
use crate::error::KernelError;
use crate::intensity::Intensity;
use crate::ring::FrameRing;
use crate::sample::Sample;
use crate::simd::{Portable, SimdPath, Vector};

/// Per-pixel phase of the watch (stored in the sample type, so that a
/// row's whole state is in one lane width and the update vectorises).
const LIT: usize = 0;
const DIP: usize = 1;
const DONE: usize = 2;

/// Tuning of the live watch.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchParams {
    /// A sample this many DN of the input below the lit level opens a dip (`> 0`).
    pub min_contrast: f32,
    /// Consecutive frames at or above the mid-level that end a dip (`1..=255`).
    pub recover: usize,
}

/// One pixel whose dip ended: provisional levels and times.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinishedPixel {
    /// Row-major pixel index `y · width + x`.
    pub index: u32,
    /// The frame at which the recovery was confirmed.
    pub frame: u32,
    /// The lit level before the dip and the dip's minimum (DN of the input).
    pub imax: f32,
    pub imin: f32,
    /// `(L(imax) + L(imin)) / 2` (linear units).
    pub threshold: f32,
    /// Sub-frame times (frames; NaN when the crossing is not in the ring).
    pub enter: f32,
    pub leave: f32,
    /// `|ΔL|` per frame at each crossing (linear units; NaN likewise).
    pub enter_slope: f32,
    pub leave_slope: f32,
}

/// The watch's state of one image row.
#[derive(Debug, Clone)]
///
/// Per pixel: `lit` the brightest sample before the dip, `lo` the dip's
/// minimum, `age` frames since `lo` was first reached (saturating at
/// `T::MAX`: unknown), `phase` ([`LIT`], [`DIP`], [`DONE`]), `count`
/// consecutive frames of recovery (`T::MAX` marks a pixel finished by the
/// frame being folded, until it is collected).
pub(crate) struct WatchRow<T: Sample> {
    lit: Vec<T>,
    lo: Vec<T>,
    age: Vec<T>,
    phase: Vec<T>,
    count: Vec<T>,
    finished: Vec<FinishedPixel>,
}

/// What every row of the watch shares.
#[derive(Debug, Clone)]
pub(crate) struct WatchConfig {
    pub(crate) path: SimdPath,
    min_contrast: usize,
    recover: u8,
    half: usize,
}

/// The live watch of a whole frame (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct Watch<T: Sample> {
    pub(crate) config: WatchConfig,
    pub(crate) rows: Vec<WatchRow<T>>,
}

impl<T: Sample> Watch<T> {
    /// A watch for `height × width` frames; `half` is the tracker's window `m`.
    pub(crate) fn new(
        height: usize,
        width: usize,
        half: usize,
        path: SimdPath,
        params: &WatchParams,
        intensity: &Intensity,
    ) -> Result<Self, KernelError> {
        if !(params.min_contrast.is_finite() && params.min_contrast > 0.0) {
            return Err(KernelError::parameter(
                "min_contrast",
                format!(
                    "must be a positive number of DN, got {}",
                    params.min_contrast
                ),
            ));
        }
        if !(1..=255).contains(&params.recover) {
            return Err(KernelError::parameter(
                "recover",
                format!("must be in 1..=255 frames, got {}", params.recover),
            ));
        }
        let contrast = intensity.contrast_in_samples(params.min_contrast);
        let row = WatchRow {
            lit: vec![T::MIN; width],
            lo: vec![T::MIN; width],
            age: vec![T::MAX; width],
            phase: vec![T::MIN; width],
            count: vec![T::MIN; width],
            finished: Vec::new(),
        };
        Ok(Watch {
            config: WatchConfig {
                path,
                // A dip opens when lit − v ≥ ceil(contrast) (integers).
                min_contrast: contrast.ceil().min(1e9) as usize,
                recover: params.recover as u8,
                half,
            },
            rows: vec![row; height],
        })
    }

    /// The pixels finished since the last call, in row-major order of rows
    /// (within a row, in the order they finished).
    pub(crate) fn take_finished(&mut self) -> Vec<FinishedPixel> {
        let mut out = Vec::new();
        for row in &mut self.rows {
            out.append(&mut row.finished);
        }
        out
    }

    /// Pixels in each phase: (lit, in a dip, finished).
    pub(crate) fn counts(&self) -> (usize, usize, usize) {
        let mut c = (0, 0, 0);
        for row in &self.rows {
            for &p in &row.phase {
                match p {
                    p if p.index() == LIT => c.0 += 1,
                    p if p.index() == DIP => c.1 += 1,
                    _ => c.2 += 1,
                }
            }
        }
        c
    }
}

impl WatchConfig {
    /// Fold the newest frame `frame` (already in `ring`, which holds the
    /// frames `oldest … frame`) into row `row`'s state.
    pub(crate) fn update_row<T: Sample>(
        &self,
        state: &mut WatchRow<T>,
        ring: &FrameRing<T>,
        intensity: &Intensity,
        row: usize,
        frame: usize,
        oldest: usize,
    ) {
        let samples = ring.row(frame, row);
        let width = samples.len();
        let constant = |k: usize| {
            if k >= T::MAX.index() {
                T::MAX
            } else {
                T::from_offset(k)
            }
        };
        let consts = Constants {
            contrast: constant(self.min_contrast),
            recover: constant(self.recover.into()),
            lit: constant(LIT),
            dip: constant(DIP),
            done: constant(DONE),
        };
        let any_done = fold_row(self.path, state, samples, consts);
        if !any_done {
            return;
        }
        for x in 0..width {
            if state.phase[x] == consts.done && state.count[x] == T::MAX {
                state.count[x] = T::MIN;
                let pixel = self.solve(state, ring, intensity, row, x, frame, oldest);
                state.finished.push(FinishedPixel {
                    index: (row * width + x) as u32,
                    ..pixel
                });
            }
        }
    }

    /// Provisional times of pixel `x` of `row`, finished at frame `last`,
    /// from the frames `oldest … last` in the ring.
    #[allow(clippy::too_many_arguments)]
    fn solve<T: Sample>(
        &self,
        state: &WatchRow<T>,
        ring: &FrameRing<T>,
        intensity: &Intensity,
        row: usize,
        x: usize,
        last: usize,
        oldest: usize,
    ) -> FinishedPixel {
        let (hi, lo) = (state.lit[x], state.lo[x]);
        // The dip's minimum was first reached `age` frames ago (unknown when saturated).
        let age = state.age[x];
        let k_min = if age == T::MAX {
            None
        } else {
            last.checked_sub(age.index())
        };
        let at = |f: usize| ring.row(f, row)[x];
        let sum = hi.index() + lo.index();
        let bright = |f: usize| 2 * at(f).index() >= sum;
        let lut = intensity.decode();
        let threshold = (lut[hi.index()] + lut[lo.index()]) * 0.5;
        let enter = k_min.and_then(|k| (oldest..k).rev().find(|&c| bright(c)).map(|c| c + 1));
        let leave = k_min.and_then(|k| ((k + 1).max(oldest)..=last).find(|&c| bright(c)));
        let span = 2 * self.half;
        // span = 2m ≤ 128 (TrackerParams): on the stack
        let mut buffer = [0.0f32; 128];
        let linear = &mut buffer[..span];
        let mut cross = |centre: Option<usize>, edge: Edge| -> (f32, f32) {
            let Some(j) = centre else {
                return (f32::NAN, f32::NAN);
            };
            for (i, l) in linear.iter_mut().enumerate() {
                let f = (j + i).saturating_sub(self.half).clamp(oldest, last);
                *l = lut[at(f).index()];
            }
            match find_crossing(linear, threshold, edge) {
                Some(c) => {
                    let frame = j as i64 - self.half as i64 + c.index as i64;
                    ((frame as f64 + f64::from(c.fraction)) as f32, c.slope)
                }
                None => (f32::NAN, f32::NAN),
            }
        };
        let (enter, enter_slope) = cross(enter, Edge::Enter);
        let (leave, leave_slope) = cross(leave, Edge::Leave);
        // the light of the dip: at the middle of its times (at the newest frame without)
        let centre = Intensity::dip_time(enter, leave);
        let gain = intensity.gain_at(centre, intensity.gain_at(last as f32, 1.0));
        let r = intensity.report(hi, lo, T::MIN, gain);
        FinishedPixel {
            index: 0,
            frame: last as u32,
            imax: r.imax,
            imin: r.imin,
            threshold: threshold * r.gain,
            enter,
            leave,
            enter_slope: enter_slope * r.gain,
            leave_slope: leave_slope * r.gain,
        }
    }
}

/// The watch's constants in the sample type.
#[derive(Clone, Copy)]
struct Constants<T> {
    contrast: T,
    recover: T,
    lit: T,
    dip: T,
    done: T,
}

/// Fold one frame's row `samples` into `state` for the `V::LANES` pixels
/// from `x0` (branch-free); whether one of them finished.
#[inline(always)]
fn fold_span<T: Sample, V: Vector<T>>(
    state: &mut WatchRow<T>,
    samples: &[T],
    c: Constants<T>,
    x0: usize,
) -> bool {
    let load = |s: &[T]| -> V {
        assert!(x0 + V::LANES <= s.len());
        // SAFETY: in bounds (checked above); `V` is only used on CPUs that have it.
        unsafe { V::load(s.as_ptr().add(x0)) }
    };
    let (zero, ones, one) = (
        V::splat(T::MIN),
        V::splat(T::MAX),
        V::splat(T::from_offset(1)),
    );
    let not = |m: V| V::select(m, zero, ones);
    let and = |a: V, b: V| V::select(a, b, zero);
    let (v, lit, lo, age, phase, count): (V, V, V, V, V, V) = (
        load(samples),
        load(&state.lit),
        load(&state.lo),
        load(&state.age),
        load(&state.phase),
        load(&state.count),
    );
    let in_lit = not(phase.ne(V::splat(c.lit)));
    let in_dip = not(phase.ne(V::splat(c.dip)));
    // lit − v ≥ contrast
    let opens = and(in_lit, not(V::splat(c.contrast).gt(lit.sub_sat(v))));
    let darker = and(in_dip, lo.gt(v));
    // 2·v ≥ lit + lo ⇔ v − lo ≥ lit − v (for v ≥ lo), without overflow
    let up = and(
        and(in_dip, not(darker)),
        not(lit.sub_sat(v).gt(v.sub_sat(lo))),
    );
    let next = count.add_sat(one);
    let done = and(up, not(V::splat(c.recover).gt(next)));
    let reset = opens.or(darker);
    let stores = [
        (&mut state.lit, V::select(in_lit, lit.max(v), lit)),
        (&mut state.lo, V::select(reset, v, lo)),
        (&mut state.age, V::select(reset, zero, age.add_sat(one))),
        (
            &mut state.count,
            V::select(
                done,
                ones,
                V::select(up, next, V::select(in_dip, zero, count)),
            ),
        ),
        (
            &mut state.phase,
            V::select(
                opens,
                V::splat(c.dip),
                V::select(done, V::splat(c.done), phase),
            ),
        ),
    ];
    for (dst, value) in stores {
        assert!(x0 + V::LANES <= dst.len());
        // SAFETY: as for the loads.
        unsafe { value.store(dst.as_mut_ptr().add(x0)) };
    }
    done.any()
}

/// [`fold_span`] over a whole row with vectors `V` (the tail one pixel at a time).
#[inline(always)]
fn fold_row_with<T: Sample, V: Vector<T>>(
    state: &mut WatchRow<T>,
    samples: &[T],
    c: Constants<T>,
) -> bool {
    let width = samples.len();
    let split = width - width % V::LANES;
    let mut any = false;
    for x0 in (0..split).step_by(V::LANES) {
        any |= fold_span::<T, V>(state, samples, c, x0);
    }
    for x0 in split..width {
        any |= fold_span::<T, Portable<T, 1>>(state, samples, c, x0);
    }
    any
}

/// [`fold_row_with`] compiled for AVX2.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fold_row_avx2<T: Sample>(
    state: &mut WatchRow<T>,
    samples: &[T],
    c: Constants<T>,
) -> bool {
    fold_row_with::<T, T::Avx2>(state, samples, c)
}

/// Fold one row on the instruction set `path` (one the CPU supports: the
/// tracker only holds such a path).
fn fold_row<T: Sample>(
    path: SimdPath,
    state: &mut WatchRow<T>,
    samples: &[T],
    c: Constants<T>,
) -> bool {
    match path {
        #[cfg(target_arch = "x86_64")]
        SimdPath::Avx2 => {
            debug_assert!(path.is_supported());
            // SAFETY: the tracker only holds a path the CPU supports.
            unsafe { fold_row_avx2(state, samples, c) }
        }
        #[cfg(target_arch = "x86_64")]
        SimdPath::Sse2 => fold_row_with::<T, T::Sse2>(state, samples, c),
        _ => fold_row_with::<T, T::Portable>(state, samples, c),
    }
}
