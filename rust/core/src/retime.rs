//! Shadow times between the isochrones, row by row (`gnomon.reconstruct.retiming`, whose
//! numpy definition this reproduces element for element; the tests compare both).
//!
//! The map arrives oriented by the caller: the sweep runs along the rows, with
//! times increasing to the right. Per row, *runs* are the maximal stretches of
//! pixels whose consecutive pairs are finite and never go back by more than
//! `backstep` frames. A rising pair `(j, j+1)` of a run owns the crossings of
//! the integer frames `k` with `a < k ≤ b`, at `u = j + (k − a)/(b − a)`
//! (times `a`, `b`; `k` clipped to `[−1, n_frames]` as a key). A pixel with a
//! non-integer time `t` in a run takes `⌊t⌋ + (u − u₀)/(u₁ − u₀)` from the
//! run's first crossings of `⌊t⌋` and `⌊t⌋ + 1` when they are `min_gap` to
//! `max_gap` pixels apart and the pixel lies between them. Rows are
//! independent: processed in parallel, results concatenated in row order.

use rayon::prelude::*;

use crate::error::KernelError;

/// A crossing of an integer frame between two pixels of a row.
#[derive(Clone, Copy)]
struct Crossing {
    run: usize,
    key: i64,
    u: f64,
    phase: f64,
    left: i64,
    right: i64,
    rise: f64,
}

/// The re-timed map (oriented as given) and, per re-timed pixel in row-major
/// order, what its time was made of (see `gnomon.reconstruct.retiming.RetimedTimes`).
#[derive(Default)]
pub struct Retimed {
    /// `H·W` times (f32, the input's where not re-timed).
    pub times: Vec<f32>,
    /// `H·W`, 1 = re-timed.
    pub done: Vec<u8>,
    /// Per re-timed pixel: its `index` value.
    pub pixel: Vec<i64>,
    /// The `index` values of the pixels each crossing (of `⌊t⌋`, of `⌊t⌋ + 1`) lies between.
    pub left: Vec<[i64; 2]>,
    pub right: Vec<[i64; 2]>,
    /// Where each crossing lies between its two pixels (0 at the left one).
    pub phase: Vec<[f64; 2]>,
    /// How fast the time rises across each crossing's pair (frames per pixel).
    pub rise: Vec<[f64; 2]>,
    /// The two crossings' distance (pixels) and the pixel's fraction of it.
    pub gap: Vec<f64>,
    pub f: Vec<f64>,
}

/// Parameters of [`retime_rows`].
#[derive(Clone, Copy, Debug)]
pub struct RetimeParams {
    pub n_frames: i64,
    pub max_gap: f64,
    pub min_gap: f64,
    pub backstep: f64,
}

/// The checks [`retime_rows`] and [`retime_rows_sigma`] share: one index and
/// one flag per pixel, whole rows of `width`, and `n_frames ≥ 0`.
fn check_rows(
    times: &[f64],
    index: &[i64],
    wanted: &[u8],
    width: usize,
    params: RetimeParams,
) -> Result<(), KernelError> {
    let n = times.len();
    KernelError::check_image(
        n,
        width,
        &[
            ("index (one per pixel)", n, index.len()),
            ("wanted (one per pixel)", n, wanted.len()),
        ],
    )?;
    if params.n_frames < 0 {
        return Err(KernelError::parameter("n_frames", "must be ≥ 0"));
    }
    Ok(())
}

/// Re-time the rows of an oriented `H × width` shadow-time map (see the module).
///
/// `times` `H·W` frames (NaN = none); `index` `H·W` each pixel's flat index in
/// the caller's image (carried into the outputs); `wanted` `H·W` non-zero =
/// may be re-timed (crossings are taken from every pixel).
pub fn retime_rows(
    times: &[f64],
    index: &[i64],
    wanted: &[u8],
    width: usize,
    params: RetimeParams,
) -> Result<Retimed, KernelError> {
    let n = times.len();
    check_rows(times, index, wanted, width, params)?;
    let rows: Vec<Retimed> = times
        .par_chunks(width)
        .zip(index.par_chunks(width))
        .zip(wanted.par_chunks(width))
        .map(|((t, idx), want)| retime_row(t, idx, want, params))
        .collect();
    let mut out = Retimed::default();
    let count: usize = rows.iter().map(|r| r.pixel.len()).sum();
    out.times.reserve(n);
    out.done.reserve(n);
    out.pixel.reserve(count);
    for r in rows {
        out.times.extend(r.times);
        out.done.extend(r.done);
        out.pixel.extend(r.pixel);
        out.left.extend(r.left);
        out.right.extend(r.right);
        out.phase.extend(r.phase);
        out.rise.extend(r.rise);
        out.gap.extend(r.gap);
        out.f.extend(r.f);
    }
    Ok(out)
}

/// The re-timed map, its mask and every pixel's time σ (frames), oriented as given.
#[derive(Default)]
pub struct RetimedSigma {
    /// `H·W` times (f32, the input's where not re-timed).
    pub times: Vec<f32>,
    /// `H·W`, 1 = re-timed.
    pub done: Vec<u8>,
    /// `H·W` σ of each time (f32): the pixel's own where not re-timed.
    pub sigma: Vec<f32>,
}

/// [`retime_rows`] and the σ of each pixel's time in one pass, as
/// `gnomon.reconstruct.retiming.RetimedTimes.sigma` defines it from the crossings' details
/// (which are not kept): a crossing at phase φ between pixels a and b whose
/// times rise by g per pixel is off by `((1 − φ)·σa + φ·σb)/g` pixels; the
/// re-timed pixel at fraction f of the gap D between its two crossings takes
/// `(1 − f)/D` and `f/D` of their errors, added linearly, and in quadrature
/// the part `(1 − 1/g)/√12` of a pixel each crossing is blind to. All in f64,
/// rounded to f32 at the end.
///
/// `sigma`: the σ (frames) of every pixel's own time in the caller's image,
/// indexed by the values of `index` (each must lie in `0..sigma.len()`).
/// Rows are processed in parallel; each row's outputs depend on that row only.
pub fn retime_rows_sigma(
    times: &[f64],
    index: &[i64],
    wanted: &[u8],
    sigma: &[f64],
    width: usize,
    params: RetimeParams,
) -> Result<RetimedSigma, KernelError> {
    let n = times.len();
    check_rows(times, index, wanted, width, params)?;
    if index.iter().any(|&i| i < 0 || i as usize >= sigma.len()) {
        return Err(KernelError::parameter(
            "index",
            format!("values must index sigma's {} pixels", sigma.len()),
        ));
    }
    let mut out = RetimedSigma {
        times: vec![0.0; n],
        done: vec![0; n],
        sigma: vec![0.0; n],
    };
    out.times
        .par_chunks_mut(width)
        .zip(out.done.par_chunks_mut(width))
        .zip(out.sigma.par_chunks_mut(width))
        .zip(times.par_chunks(width))
        .zip(index.par_chunks(width))
        .zip(wanted.par_chunks(width))
        .for_each(|(((((t_out, d_out), s_out), t), idx), want)| {
            let row = retime_row(t, idx, want, params);
            t_out.copy_from_slice(&row.times);
            d_out.copy_from_slice(&row.done);
            // the row's re-timed pixels, in row order, are its entries in order
            let mut k = 0;
            for j in 0..t.len() {
                let own = sigma[idx[j] as usize];
                s_out[j] = if row.done[j] == 0 {
                    own as f32
                } else {
                    k += 1;
                    retimed_sigma(&row, k - 1, sigma) as f32
                };
            }
        });
    Ok(out)
}

/// Re-timed times averaged across the sweep (`gnomon.reconstruct.retiming.average_across_sweep`, whose numpy
/// definition this reproduces value for value).
///
/// `times` `H·W` frames (f32, NaN = none), `retimed` `H·W` (non-zero = re-timed), rows of `width`.
/// `across_rows`: the pixels `v ± d` of a column are averaged (the sweep runs along the rows), else
/// the pixels `u ± d` of a row. A re-timed pixel with a finite time `t` takes the mean of `t` and of
/// every symmetric pair `d = 1 … half` (while the map is longer than `2d` along that axis) whose
/// two pixels are re-timed and finite and which bends by at most `bend` frames
/// (`|t₋ + t₊ − 2t| ≤ bend`); the other pixels keep their time. In f64 in numpy's order (the
/// pair's sum added to the running total, 0 for a pair not taken), rounded to f32 at the end.
/// Rows of the output in parallel.
pub fn average_across(
    times: &[f32],
    retimed: &[u8],
    width: usize,
    across_rows: bool,
    half: usize,
    bend: f64,
) -> Result<Vec<f32>, KernelError> {
    let n = times.len();
    KernelError::check_image(n, width, &[("retimed (one per pixel)", n, retimed.len())])?;
    let height = n / width.max(1);
    let ok = |i: usize| retimed[i] != 0 && times[i].is_finite();
    // the length of the averaging axis, and the flat offset of one step along it
    let (length, step) = if across_rows {
        (height, width)
    } else {
        (width, 1)
    };
    let mut out = vec![0f32; n];
    out.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(v, row)| {
            for (u, o) in row.iter_mut().enumerate() {
                let i = v * width + u;
                let t = f64::from(times[i]);
                if !ok(i) {
                    *o = times[i];
                    continue;
                }
                let p = if across_rows { v } else { u };
                let (mut total, mut count) = (t, 1.0f64);
                for d in 1..=half {
                    if length <= 2 * d {
                        break;
                    }
                    if p < d || p >= length - d {
                        continue;
                    }
                    let (a, b) = (i - d * step, i + d * step);
                    let (up, down) = (f64::from(times[a]), f64::from(times[b]));
                    let pair = ok(a) && ok(b) && (up + down - 2.0 * t).abs() <= bend;
                    total += if pair { up + down } else { 0.0 };
                    count += if pair { 2.0 } else { 0.0 };
                }
                *o = (total / count.max(1.0)) as f32;
            }
        });
    Ok(out)
}

/// The σ of a row's `k`-th re-timed pixel (see [`retime_rows_sigma`]).
fn retimed_sigma(row: &Retimed, k: usize, sigma: &[f64]) -> f64 {
    let (w0, w1) = ((1.0 - row.f[k]) / row.gap[k], row.f[k] / row.gap[k]);
    let crossing = |c: usize| {
        let (sa, sb) = (
            sigma[row.left[k][c] as usize],
            sigma[row.right[k][c] as usize],
        );
        let (phase, rise) = (row.phase[k][c], row.rise[k][c]);
        let error = ((1.0 - phase) * sa + phase * sb) / rise;
        let blind = (1.0 - 1.0 / rise).clamp(0.0, 1.0) / 12f64.sqrt();
        (error, blind)
    };
    let ((e0, b0), (e1, b1)) = (crossing(0), crossing(1));
    let (q0, q1) = (w0 * b0, w1 * b1);
    let quantised = (q0 * q0 + q1 * q1).sqrt();
    (w0 * e0 + w1 * e1).hypot(quantised)
}

fn retime_row(t: &[f64], idx: &[i64], want: &[u8], p: RetimeParams) -> Retimed {
    let w = t.len();
    let clip = |k: i64| k.clamp(-1, p.n_frames);
    let mut out = Retimed {
        times: t.iter().map(|&x| x as f32).collect(),
        done: vec![0u8; w],
        ..Retimed::default()
    };
    // Run of each pixel: a new run after each pair that is not ok.
    let mut run = vec![0usize; w];
    let mut crossings: Vec<Crossing> = Vec::new();
    for j in 0..w.saturating_sub(1) {
        let (a, b) = (t[j], t[j + 1]);
        let ok = a.is_finite() && b.is_finite() && b >= a - p.backstep;
        run[j + 1] = run[j] + usize::from(!ok);
        if ok && b > a {
            let (lo, hi) = (a.floor() as i64 + 1, b.floor() as i64);
            for k in lo..=hi {
                let phase = (k as f64 - a) / (b - a);
                crossings.push(Crossing {
                    run: run[j],
                    key: clip(k),
                    u: j as f64 + phase,
                    phase,
                    left: idx[j],
                    right: idx[j + 1],
                    rise: b - a,
                });
            }
        }
    }
    if crossings.is_empty() {
        return out;
    }
    // The first crossing (in row order) of each (run, frame): a stable sort, then a binary search.
    crossings.sort_by_key(|c| (c.run, c.key));
    let find = |run: usize, key: i64| -> Option<Crossing> {
        let i = crossings.partition_point(|c| (c.run, c.key) < (run, key));
        crossings
            .get(i)
            .filter(|c| c.run == run && c.key == key)
            .copied()
    };
    for j in 0..w {
        let tp = t[j];
        if want[j] == 0 || !tp.is_finite() {
            continue;
        }
        let kf = tp.floor();
        if tp <= kf {
            continue; // on an integer frame: keeps its time
        }
        let kf = kf as i64;
        let (Some(c0), Some(c1)) = (find(run[j], clip(kf)), find(run[j], clip(kf + 1))) else {
            continue;
        };
        let gap = c1.u - c0.u;
        let frac = (j as f64 - c0.u) / gap;
        if !((p.min_gap..=p.max_gap).contains(&gap) && (0.0..=1.0).contains(&frac)) {
            continue;
        }
        out.times[j] = (kf as f64 + frac) as f32;
        out.done[j] = 1;
        out.pixel.push(idx[j]);
        out.left.push([c0.left, c1.left]);
        out.right.push([c0.right, c1.right]);
        out.phase.push([c0.phase, c1.phase]);
        out.rise.push([c0.rise, c1.rise]);
        out.gap.push(gap);
        out.f.push(frac);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: RetimeParams = RetimeParams {
        n_frames: 10,
        max_gap: 40.0,
        min_gap: 3.0,
        backstep: 0.25,
    };

    #[test]
    fn staircase_becomes_a_ramp() {
        // Frames 2 and 3 crossed 5 pixels apart (at u = 0.5 and 5.5); the plateau between gets a ramp.
        let t = [1.5, 2.5, 2.5, 2.5, 2.5, 2.5, 3.5, 3.5];
        let idx: Vec<i64> = (0..8).collect();
        let r = retime_rows(&t, &idx, &[1; 8], 8, P).unwrap();
        assert_eq!(r.pixel, vec![1, 2, 3, 4, 5]);
        for (k, &px) in r.pixel.iter().enumerate() {
            let f = (px as f64 - 0.5) / 5.0;
            assert!((f64::from(r.times[px as usize]) - (2.0 + f)).abs() < 1e-6);
            assert!((r.f[k] - f).abs() < 1e-12);
        }
        assert_eq!(r.left[0], [0, 5]);
        assert_eq!(r.right[0], [1, 6]);
        assert_eq!(r.gap, vec![5.0; 5]);
        assert_eq!(r.done, vec![0, 1, 1, 1, 1, 1, 0, 0]);
        // pixels not wanted keep their time
        let r = retime_rows(&t, &idx, &[1, 1, 0, 1, 1, 1, 1, 1], 8, P).unwrap();
        assert_eq!(r.pixel, vec![1, 3, 4, 5]);
        assert_eq!(r.times[2], 2.5);
    }

    #[test]
    fn sigma_of_a_ramp_from_its_crossings() {
        // The staircase of staircase_becomes_a_ramp: crossings at u = 0.5 (frame 2, between pixels 0
        // and 1) and u = 5.5 (frame 3, between 5 and 6), each rising by 1 frame per pixel (not blind).
        let t = [1.5, 2.5, 2.5, 2.5, 2.5, 2.5, 3.5, 3.5];
        let idx: Vec<i64> = (0..8).collect();
        let sigma: Vec<f64> = (0..8).map(|i| 0.1 + 0.01 * f64::from(i)).collect();
        let r = retime_rows_sigma(&t, &idx, &[1; 8], &sigma, 8, P).unwrap();
        let plain = retime_rows(&t, &idx, &[1; 8], 8, P).unwrap();
        assert_eq!(r.times, plain.times);
        assert_eq!(r.done, plain.done);
        // crossing errors (pixels): the mean of the pair's σ over a rise of 1
        let (e0, e1) = (0.5 * (sigma[0] + sigma[1]), 0.5 * (sigma[5] + sigma[6]));
        for px in 1..6 {
            let f = (px as f64 - 0.5) / 5.0;
            let want = ((1.0 - f) * e0 + f * e1) / 5.0;
            assert!((f64::from(r.sigma[px]) - want).abs() < 1e-7, "pixel {px}");
        }
        for px in [0, 6, 7] {
            assert_eq!(r.sigma[px], sigma[px] as f32);
        }
        // index values must address sigma
        assert!(retime_rows_sigma(&t, &idx, &[1; 8], &sigma[..7], 8, P).is_err());
    }

    #[test]
    fn averaged_across_the_sweep() {
        // 3 rows × 2 columns, averaged across the rows: the middle pixel of column 0 takes its
        // straight pair, column 1's pair bends by 1 frame (> 0.5) and is not taken.
        let t = [1.0f32, 5.0, 2.0, 6.0, 3.0, 8.0];
        let done = [1u8; 6];
        let out = average_across(&t, &done, 2, true, 2, 0.5).unwrap();
        assert_eq!(out, vec![1.0, 5.0, 2.0, 6.0, 3.0, 8.0]);
        // bends of 0.4 and 0.5 frame: both pairs taken, the mean in f64 (the pixel, then its pair)
        let t2 = [1.0f32, 5.0, 2.2, 6.0, 3.0, 7.5];
        let out = average_across(&t2, &done, 2, true, 2, 0.5).unwrap();
        assert_eq!(out[2], ((f64::from(2.2f32) + (1.0 + 3.0)) / 3.0) as f32);
        assert_eq!(out[3], ((6.0f64 + (5.0 + 7.5)) / 3.0) as f32);
        // the first and last rows have no pair
        assert_eq!(out[0], 1.0);
        // along the rows instead: a row of 3 is too short for d = 2, d = 1 is taken
        let out = average_across(&[1.0, 2.0, 3.5], &[1, 1, 1], 3, false, 2, 0.5).unwrap();
        assert_eq!(out[1], ((2.0f64 + (1.0 + 3.5)) / 3.0) as f32);
        // a pixel not re-timed keeps its time, and is no partner
        let out = average_across(&[1.0, 2.2, 3.0], &[1, 0, 1], 3, false, 2, 0.5).unwrap();
        assert_eq!(out, vec![1.0, 2.2, 3.0]);
        assert!(average_across(&t, &done[..5], 2, true, 2, 0.5).is_err());
    }

    #[test]
    fn runs_end_at_gaps_and_backsteps() {
        // A NaN splits the row: the crossings of frame 3 lie in another run.
        let t = [1.5, 2.5, 2.5, 2.5, f64::NAN, 2.5, 3.5, 3.5];
        let idx: Vec<i64> = (0..8).collect();
        let r = retime_rows(&t, &idx, &[1; 8], 8, P).unwrap();
        assert!(r.pixel.is_empty());
        assert_eq!(r.times[1], 2.5);
        assert!(r.times[4].is_nan());
        assert!(retime_rows(&t, &idx[..7], &[1; 8], 8, P).is_err());
        assert!(retime_rows(&t, &idx, &[1; 8], 3, P).is_err());
    }
}
