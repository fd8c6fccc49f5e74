//! Sub-frame threshold crossings in a window of samples: where the intensity
//! falls into a dip ([`Edge::Enter`]) or rises out of it ([`Edge::Leave`]).
//!
//! Both the block tracker ([`crate::tracker`], at [`finish`]) and the live
//! watch ([`crate::live`], as each pixel finishes) decode the `2m` samples kept
//! around a crossing and interpolate it here, so that the two give the same
//! times for the same samples. Pure functions of `f32` slices: no state, no
//! sample type, no dependency on either caller.
//!
//! [`finish`]: crate::TemporalTracker::finish

/// One threshold crossing in a window of samples.
///
/// Invariants (as [`find_crossing`] makes it, for a window of `n ≥ 2` values):
/// `index ≤ n − 2`, so that `index + 1` is in the window; `fraction` and
/// `slope` are finite when the two values are, and `slope > 0` (the values
/// of a crossing pair differ).
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
