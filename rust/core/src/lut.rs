//! A per-code table looked up at each level's code in a sorted decoding table: numpy's
//! `table[clip(searchsorted(lut, values), 0, N − 1)]`, scaled (`gnomon.geometry.uncertainty.
//! linear_noise_at_threshold`: the image noise carried to irradiance at each pixel's threshold).

use rayon::prelude::*;

use crate::error::KernelError;

/// Values per parallel work item.
const VALUES_PER_TASK: usize = 16384;

/// numpy's `<` on floats, which sorts NaN after every number.
fn less(a: f32, b: f32) -> bool {
    a < b || (b.is_nan() && !a.is_nan())
}

/// `(scale · table[k]) as f32` for every value `v`, `k` the number of entries of `lut` that sort
/// before `v` (numpy's `searchsorted(lut, v)`, side "left", with its order: NaN last), clamped to
/// `0 … N − 1`: numpy's `(scale * table[np.searchsorted(lut, values).clip(0, N - 1)]).astype(float32)`
/// element for element, `scale · table[k]` in f64.
///
/// `lut` (N ≥ 1) must be sorted in that order (a decoding table is increasing) and `table` have
/// its length; otherwise an error. Values in parallel.
pub fn lut_lookup(
    lut: &[f32],
    table: &[f64],
    scale: f64,
    values: &[f32],
) -> Result<Vec<f32>, KernelError> {
    if lut.is_empty() {
        return Err(KernelError::parameter("lut", "needs at least one entry"));
    }
    if table.len() != lut.len() {
        return Err(KernelError::LengthMismatch {
            what: "table (one per lut entry)",
            expected: lut.len(),
            got: table.len(),
        });
    }
    if lut.windows(2).any(|w| less(w[1], w[0])) {
        return Err(KernelError::parameter(
            "lut",
            "must be sorted (increasing, NaN last)",
        ));
    }
    let last = lut.len() - 1;
    let index = CodeIndex::new(lut);
    let mut out = vec![0f32; values.len()];
    out.par_chunks_mut(VALUES_PER_TASK)
        .zip(values.par_chunks(VALUES_PER_TASK))
        .for_each(|(out, values)| {
            for (o, &v) in out.iter_mut().zip(values) {
                *o = (scale * table[index.code(lut, v).min(last)]) as f32;
            }
        });
    Ok(out)
}

/// Buckets of the sorted table's finite range (a few entries each on a decoding table).
const BUCKETS: usize = 4096;

/// Where to search a sorted table for a value: the finite entries' range cut into [`BUCKETS`]
/// equal buckets, and before each bucket's lower edge, how many entries sort.
///
/// Invariant: `lower[j]` counts the entries below `lo + j·(hi − lo)/BUCKETS` (in f64, where every
/// f32 is exact), `lower[BUCKETS]` the finite entries; so a value between the edges of buckets
/// `j` and `j + 3` has as many entries before it as some index in `lower[j] ..= lower[j + 3]`.
struct CodeIndex {
    lo: f64,
    hi: f64,
    scale: f64,
    lower: Vec<usize>,
    finite: usize,
}

impl CodeIndex {
    fn new(lut: &[f32]) -> Self {
        let finite = lut.partition_point(|x| !x.is_nan());
        let (lo, hi) = if finite > 0 {
            (f64::from(lut[0]), f64::from(lut[finite - 1]))
        } else {
            (0.0, 0.0)
        };
        let usable = finite > 0 && lo.is_finite() && hi.is_finite() && hi > lo;
        let lower = if usable {
            let width = (hi - lo) / BUCKETS as f64;
            let mut lower: Vec<usize> = (0..BUCKETS)
                .map(|j| {
                    let edge = lo + j as f64 * width;
                    lut[..finite].partition_point(|&x| f64::from(x) < edge)
                })
                .collect();
            lower.push(finite);
            lower
        } else {
            Vec::new()
        };
        let scale = if usable {
            BUCKETS as f64 / (hi - lo)
        } else {
            0.0
        };
        CodeIndex {
            lo,
            hi,
            scale,
            lower,
            finite,
        }
    }

    /// How many entries of `lut` (the table the index was made of) sort before `v` (NaN last).
    fn code(&self, lut: &[f32], v: f32) -> usize {
        if self.lower.is_empty() {
            return lut.partition_point(|&x| less(x, v));
        }
        let x = f64::from(v);
        if x.is_nan() || x > self.hi {
            return self.finite; // every number sorts before NaN and before what is above the last
        }
        if x < self.lo {
            return 0;
        }
        // the bucket of x, give or take one for rounding: search from the one before to the one after
        let b = (((x - self.lo) * self.scale) as usize).min(BUCKETS - 1);
        let (start, end) = (
            self.lower[b.saturating_sub(1)],
            self.lower[(b + 2).min(BUCKETS)],
        );
        start + lut[start..end].partition_point(|&e| e < v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_numpys_searchsorted_left_clipped() {
        let lut = [0.0f32, 0.25, 0.25, 0.5, 1.0];
        let table = [10.0, 11.0, 12.0, 13.0, 14.0];
        let values = [
            -1.0f32,
            0.0,
            0.1,
            0.25,
            0.3,
            0.5,
            1.0,
            2.0,
            f32::NAN,
            f32::INFINITY,
        ];
        // searchsorted: 0, 0, 1, 1, 3, 3, 4, 5 → 4, NaN → 5 → 4, inf → 5 → 4
        let want = [
            10.0f32, 10.0, 11.0, 11.0, 13.0, 13.0, 14.0, 14.0, 14.0, 14.0,
        ];
        assert_eq!(lut_lookup(&lut, &table, 1.0, &values).unwrap(), want);
        let scaled = lut_lookup(&lut, &table, 0.1, &[0.3]).unwrap();
        assert_eq!(scaled, [(0.1f64 * 13.0) as f32]);
    }

    #[test]
    fn a_nan_entry_sorts_last() {
        let lut = [0.0f32, 1.0, f32::NAN];
        let table = [1.0, 2.0, 3.0];
        assert_eq!(
            lut_lookup(&lut, &table, 1.0, &[5.0, f32::NAN]).unwrap(),
            [3.0, 3.0]
        );
    }

    #[test]
    fn the_index_finds_what_a_plain_search_finds() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as f32 / (1u64 << 31) as f32
        };
        let srgb: Vec<f32> = (0..256)
            .map(|i| {
                let x = f64::from(i) / 255.0;
                (if x <= 0.04045 {
                    x / 12.92
                } else {
                    ((x + 0.055) / 1.055).powf(2.4)
                }) as f32
            })
            .collect();
        let steep: Vec<f32> = (0..65536)
            .map(|i| (f64::from(i) / 65535.0).powf(2.2) as f32)
            .collect();
        let flat = vec![0.5f32; 8];
        for lut in [
            &srgb[..],
            &steep[..],
            &flat[..],
            &[1.0f32][..],
            &[0.0f32, 0.0, 1.0, 1.0, f32::NAN][..],
        ] {
            let mut values: Vec<f32> = (0..20000).map(|_| 1.2 * next() - 0.1).collect();
            values.extend(lut.iter().copied());
            values.extend(
                lut.iter()
                    .map(|&x| f32::from_bits(x.to_bits().wrapping_add(1))),
            );
            values.extend(
                lut.iter()
                    .map(|&x| f32::from_bits(x.to_bits().wrapping_sub(1))),
            );
            values.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0]);
            let index = CodeIndex::new(lut);
            for &v in &values {
                assert_eq!(
                    index.code(lut, v),
                    lut.partition_point(|&x| less(x, v)),
                    "{v}"
                );
            }
        }
    }

    #[test]
    fn bad_tables_are_errors() {
        assert!(lut_lookup(&[], &[], 1.0, &[0.0]).is_err());
        assert!(lut_lookup(&[0.0, 1.0], &[1.0], 1.0, &[0.0]).is_err());
        assert!(lut_lookup(&[1.0, 0.0], &[1.0, 2.0], 1.0, &[0.0]).is_err());
        assert!(lut_lookup(&[f32::NAN, 0.0], &[1.0, 2.0], 1.0, &[0.0]).is_err());
    }
}
