//! The clipped line fit of the image-noise estimate (`gnomon.capture.noise.image_noise_dn`), equal
//! bit for bit to its numpy definition (`_image_noise_dn_numpy`).
//!
//! The estimate fits, over the pixels of two frames, the difference `y = a − b` against the
//! centred level `x = ½(a + b) − mean`, keeping the pixels whose residual is within a limit,
//! and measures the residuals' RMS; it repeats with the new limit until that settles. numpy
//! evaluates each step as a string of float32 array operations and float32 means; one
//! [`clipped_fit_step`] does the same arithmetic in one pass over the pixels (gathering the
//! kept ones) and a few over the kept, with the sums taken in numpy's order
//! ([`pairwise_sum`]), so that every float32 it produces is numpy's.

use crate::error::KernelError;
use crate::sample::Sample;

/// Elements summed by 8 running accumulators before numpy's sum splits in halves.
const PAIRWISE_BLOCK: usize = 128;

/// The float32 sum of `a` in numpy's order (`np.add.reduce` of a contiguous float32 array):
/// fewer than 8 in turn from zero; up to 128 over 8 accumulators (element `i` into
/// accumulator `i mod 8`, eight lanes a vector add), combined as
/// `((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))`, then the last `n mod 8` in turn;
/// more: the two halves summed apart (the first half a multiple of 8 long) and added.
pub fn pairwise_sum(a: &[f32]) -> f32 {
    let n = a.len();
    if n < 8 {
        a.iter().fold(0.0f32, |sum, &v| sum + v)
    } else if n <= PAIRWISE_BLOCK {
        let whole = n - n % 8;
        let mut r = [0.0f32; 8];
        r.copy_from_slice(&a[..8]);
        for block in a[8..whole].chunks_exact(8) {
            for (acc, &v) in r.iter_mut().zip(block) {
                *acc += v;
            }
        }
        let sum = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        a[whole..].iter().fold(sum, |sum, &v| sum + v)
    } else {
        let half = n / 2 - (n / 2) % 8;
        pairwise_sum(&a[..half]) + pairwise_sum(&a[half..])
    }
}

/// numpy's float32 mean of `a` (not empty): its [`pairwise_sum`] over the count, divided in
/// float64 (numpy divides the float32 sum by an integer scalar) and rounded to float32.
fn mean(a: &[f32]) -> f32 {
    (f64::from(pairwise_sum(a)) / a.len() as f64) as f32
}

/// [`pairwise_sum`] of `f(start), …, f(start + n − 1)`, each block of up to 128 terms
/// computed into a local array and summed there (the same splits, so the same sum as over
/// the terms written out).
fn pairwise_sum_of(start: usize, n: usize, f: &impl Fn(usize) -> f32) -> f32 {
    if n <= PAIRWISE_BLOCK {
        let mut block = [0.0f32; PAIRWISE_BLOCK];
        for (k, term) in block[..n].iter_mut().enumerate() {
            *term = f(start + k);
        }
        pairwise_sum(&block[..n])
    } else {
        let half = n / 2 - (n / 2) % 8;
        pairwise_sum_of(start, half, f) + pairwise_sum_of(start + half, n - half, f)
    }
}

/// numpy's float32 mean of `f(x[i], y[i])` over the pairs (not empty; `x`, `y` of one length).
fn mean_of(x: &[f32], y: &[f32], f: impl Fn(f32, f32) -> f32) -> f32 {
    let sum = pairwise_sum_of(0, x.len(), &|i| f(x[i], y[i]));
    (f64::from(sum) / x.len() as f64) as f32
}

/// One step of the clipped fit: the pixels kept, the new offset and gain, and the RMS of the
/// kept pixels' residuals about them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipFit {
    pub kept: usize,
    pub offset: f32,
    pub gain: f32,
    pub rms: f32,
}

/// One step of the clipped fit of `diff` against `level` (float32, one per pixel), from the
/// line `offset + gain·level`: the pixels whose residual `(diff − offset) − level·gain` is within
/// `limit` in magnitude (the three cast to float32, as numpy casts a Python float against a
/// float32 array) are kept; with their `x` (level) and `y` (diff), the new line is
/// `gain' = mean(dx·(y − ȳ)) / var_x` (0 unless `var_x = mean(dx²) > 0`, `dx = x − x̄`) and
/// `offset' = ȳ − gain'·x̄`, and `rms = √mean(((y − offset') − x·gain')²)`, every operation in
/// float32 in numpy's order. None when fewer than `min_kept` pixels are kept.
pub fn clipped_fit_step(
    diff: &[f32],
    level: &[f32],
    offset: f64,
    gain: f64,
    limit: f64,
    min_kept: usize,
) -> Result<Option<ClipFit>, KernelError> {
    if diff.len() != level.len() {
        return Err(KernelError::LengthMismatch {
            what: "level (one per difference)",
            expected: diff.len(),
            got: level.len(),
        });
    }
    let (offset, gain, limit) = (offset as f32, gain as f32, limit as f32);
    // The kept pixels' level and difference, in order: every pixel written at the next place,
    // which only a kept one takes (no branch).
    let n = diff.len();
    let (mut x, mut y) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut kept = 0;
    for (&d, &l) in diff.iter().zip(level) {
        x[kept] = l;
        y[kept] = d;
        kept += usize::from(((d - offset) - l * gain).abs() <= limit);
    }
    if kept < min_kept.max(1) {
        return Ok(None);
    }
    let (x, y) = (&x[..kept], &y[..kept]);
    let (x_mean, y_mean) = (mean(x), mean(y));
    let var_x = mean_of(x, y, |a, _| {
        let dx = a - x_mean;
        dx * dx
    });
    let gain = if var_x > 0.0 {
        mean_of(x, y, |a, b| (a - x_mean) * (b - y_mean)) / var_x
    } else {
        0.0
    };
    let offset = y_mean - gain * x_mean;
    let rms = mean_of(x, y, |a, b| {
        let r = (b - offset) - a * gain;
        r * r
    })
    .sqrt();
    Ok(Some(ClipFit {
        kept,
        offset,
        gain,
        rms,
    }))
}

/// The samples of a frame pair the noise estimate fits, with its starting line: for the pixels
/// where both frames are strictly inside their range (neither 0 nor the type's maximum), in
/// order, `diff = a − b` and `level = ½(a + b) − mean` (float32, numpy's arithmetic and mean),
/// and the median of the differences and of their distances from it (the MAD).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseSamples {
    pub diff: Vec<f32>,
    pub level: Vec<f32>,
    pub median: f64,
    pub mad: f64,
}

/// numpy's median of integers given by their histogram (`counts[v]` of the value `low + v`,
/// `n` in all, `n > 0`): the mean of its sorted elements `(n − 1) / 2` and `n / 2`, as
/// `gnomon.geometry.uncertainty._median_of_integers` computes it.
fn histogram_median(counts: &[u32], low: i64, n: usize) -> f64 {
    let nth = |k: usize| {
        let mut seen = 0usize;
        for (v, &c) in counts.iter().enumerate() {
            seen += c as usize;
            if seen > k {
                return v as i64;
            }
        }
        counts.len() as i64 - 1
    };
    (nth((n - 1) / 2) + nth(n / 2)) as f64 / 2.0 + low as f64
}

/// The samples of frames `a` and `b` (one per pixel, the same length) that the noise estimate
/// fits ([`NoiseSamples`]); None when fewer than `min_inside` pixels are inside the range.
/// Equal to the integer path of `gnomon.capture.noise._image_noise_dn_numpy` before its fit.
pub fn noise_samples<T: Sample>(
    a: &[T],
    b: &[T],
    min_inside: usize,
) -> Result<Option<NoiseSamples>, KernelError> {
    if a.len() != b.len() {
        return Err(KernelError::LengthMismatch {
            what: "frame b (one sample per pixel of a)",
            expected: a.len(),
            got: b.len(),
        });
    }
    let inside = |p: T, q: T| p > T::MIN && q > T::MIN && p < T::MAX && q < T::MAX;
    let n = a.iter().zip(b).filter(|(&p, &q)| inside(p, q)).count();
    if n < min_inside.max(1) {
        return Ok(None);
    }
    let (mut diff, mut level) = (Vec::with_capacity(n), Vec::with_capacity(n));
    // Differences of samples inside the range: within ±(MAX − 2), counted from −MAX.
    let top = T::MAX.index() as i64;
    let mut counts = vec![0u32; 2 * top as usize + 1];
    for (&p, &q) in a.iter().zip(b).filter(|(&p, &q)| inside(p, q)) {
        let (x, y) = (p.to_f32(), q.to_f32());
        diff.push(x - y);
        level.push(0.5 * (x + y));
        counts[(p.index() as i64 - q.index() as i64 + top) as usize] += 1;
    }
    let level_mean = mean(&level);
    for l in &mut level {
        *l -= level_mean;
    }
    let median = histogram_median(&counts, -top, n);
    // |2·diff − round(2·median)|: in half DN, on the integers (2·median is one).
    let centre = (2.0 * median) as i64;
    let mut half = vec![0u32; 4 * top as usize + 1];
    for (v, &c) in counts.iter().enumerate().filter(|(_, &c)| c > 0) {
        let d = 2 * (v as i64 - top) - centre;
        half[d.unsigned_abs() as usize] += c;
    }
    let mad = histogram_median(&half, 0, n) / 2.0;
    Ok(Some(NoiseSamples {
        diff,
        level,
        median,
        mad,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_sum_follows_numpys_blocks() {
        // Fewer than 8: in turn from zero (so −0 sums to +0).
        assert_eq!(pairwise_sum(&[1.0, 2.0, 3.0]), 6.0);
        assert_eq!(pairwise_sum(&[-0.0]).to_bits(), 0.0f32.to_bits());
        // 9 values: 8 accumulators, then the ninth added last. 2^24 + 1 is not a float32, so the
        // order shows: the ones meet each other before they meet 2^24.
        let big = 16_777_216.0f32;
        let v = [big, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        let by_blocks = ((big + 1.0) + (1.0 + 1.0)) + ((1.0 + 1.0) + (1.0 + 1.0)) + 1.0;
        assert_eq!(pairwise_sum(&v), by_blocks);
        let in_turn = v.iter().fold(0.0f32, |s, &a| s + a);
        assert_ne!(pairwise_sum(&v), in_turn);
        // 300 values: halves of 144 (a multiple of 8) and 156.
        let w: Vec<f32> = (0..300).map(|i| 0.1 * i as f32 + 1e-3).collect();
        let halves = pairwise_sum(&w[..144]) + pairwise_sum(&w[144..]);
        assert_eq!(pairwise_sum(&w), halves);
    }

    #[test]
    fn sums_of_computed_terms_are_the_sums_of_the_terms_written_out() {
        for n in [0, 1, 7, 8, 9, 127, 128, 129, 136, 1000, 4099, 70_001] {
            let terms: Vec<f32> = (0..n)
                .map(|i| ((i * 7919) % 1013) as f32 * 0.37 - 150.0)
                .collect();
            let computed = pairwise_sum_of(0, n, &|i| ((i * 7919) % 1013) as f32 * 0.37 - 150.0);
            assert_eq!(computed.to_bits(), pairwise_sum(&terms).to_bits(), "{n}");
        }
    }

    #[test]
    fn histogram_median_is_the_middle_of_the_sorted_values() {
        for values in [
            vec![3i64],
            vec![5, -2],
            vec![4, 4, 9],
            vec![-7, 0, 2, 2, 8, 11],
            vec![1, 1, 1, 6],
        ] {
            let low = *values.iter().min().unwrap();
            let mut counts = vec![0u32; 30];
            for &v in &values {
                counts[(v - low) as usize] += 1;
            }
            let mut sorted = values.clone();
            sorted.sort();
            let n = sorted.len();
            let expected = (sorted[(n - 1) / 2] + sorted[n / 2]) as f64 / 2.0;
            assert_eq!(histogram_median(&counts, low, n), expected, "{values:?}");
        }
    }

    #[test]
    fn noise_samples_keep_the_pixels_inside_the_range() {
        // pixel 1 is black in a, pixel 3 saturated in b: left out
        let a: Vec<u8> = vec![10, 0, 200, 30, 7, 9];
        let b: Vec<u8> = vec![12, 5, 190, 255, 7, 10];
        let s = noise_samples(&a, &b, 1).unwrap().unwrap();
        assert_eq!(s.diff, vec![-2.0, 10.0, 0.0, -1.0]);
        let level = [11.0f32, 195.0, 7.0, 9.5];
        let centre = ((11.0f32 + 195.0) + (7.0 + 9.5)) / 4.0;
        assert_eq!(s.level, level.map(|l| l - centre).to_vec());
        // differences -2, 10, 0, -1: median -0.5; |2·d + 1| = 3, 21, 1, 1 → 2, halved 1
        assert_eq!((s.median, s.mad), (-0.5, 1.0));
        assert!(noise_samples(&a, &b, 5).unwrap().is_none());
        assert!(noise_samples(&a, &b[1..], 1).is_err());
    }

    #[test]
    fn a_clean_line_is_found_and_outliers_are_clipped() {
        // y = 0.5 + 0.25·x exactly, but for two wild pixels the limit removes.
        let level: Vec<f32> = (0..64).map(|i| i as f32 - 31.5).collect();
        let mut diff: Vec<f32> = level.iter().map(|&x| 0.5 + 0.25 * x).collect();
        diff[3] = 90.0;
        diff[40] = -70.0;
        let fit = clipped_fit_step(&diff, &level, 0.5, 0.25, 1.0, 16)
            .unwrap()
            .unwrap();
        assert_eq!(fit.kept, 62);
        assert!((fit.gain - 0.25).abs() < 1e-6 && (fit.offset - 0.5).abs() < 1e-5);
        assert!(fit.rms < 1e-5);
        assert!(clipped_fit_step(&diff, &level, 0.5, 0.25, 1.0, 63)
            .unwrap()
            .is_none());
        assert!(clipped_fit_step(&diff, &level[1..], 0.0, 0.0, 1.0, 1).is_err());
    }
}
