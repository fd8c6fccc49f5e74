//! The shadow line of every frame on one reference plane (`gnomon.geometry.reference_lines.lines_on_plane`,
//! docs/method.md §3): where the shadow-time map crosses each frame ([`isochrone_crossings`]),
//! and each frame's crossings, in plane coordinates, fitted with a robust total-least-squares
//! line ([`frame_lines`]); the fits long enough to be lines set their own direction.
//!
//! Invariants: the crossings are grouped by frame (`bounds[t] .. bounds[t + 1]` are frame `t`'s,
//! in the caller's order); a direction is a unit 2-vector; the directions of the accepted frames
//! keep one sense (each within 90° of the previous accepted one), so their angles can be
//! interpolated. Frames are fitted in parallel; only the choice of sense runs in frame order.

use rayon::prelude::*;

use crate::error::KernelError;

/// What [`frame_lines`] needs: `gnomon.util.fitting.fit_line_robust`'s `k` and `iterations`, and
/// `gnomon.geometry.reference_lines`' `MIN_POINTS`, `MIN_EXTENT_TO_RMS` and `min_extent_fraction`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineParams {
    /// Residuals beyond `k` robust σ (1.4826·MAD) are outliers.
    pub k: f64,
    /// At most this many fits per frame (fewer when the inliers stop changing).
    pub iterations: usize,
    /// A frame needs this many crossings, and its line this many inliers.
    pub min_points: usize,
    /// A fit is a line when its inliers' extent is at least this many times their RMS distance to it.
    pub min_extent_to_rms: f64,
    /// A line sets its direction when its extent is at least this share of the 90th percentile
    /// of the lines' extents.
    pub min_extent_fraction: f64,
}

/// Per frame (`N`): `accepted[t]` the frame's own fit set its line; then `centre[t]` (plane
/// coordinates), `direction[t]` (unit), `rms[t]` (RMS distance of the inliers to the line),
/// `count[t]` (inliers) and `extent[t]` (their length along it: 5th to 95th percentile over
/// 0.9); NaN / 0 elsewhere. `inliers` (`K`, the crossings' order) marks the accepted lines'
/// inliers.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameLines {
    pub accepted: Vec<u8>,
    pub centre: Vec<[f64; 2]>,
    pub direction: Vec<[f64; 2]>,
    pub rms: Vec<f64>,
    pub count: Vec<i64>,
    pub extent: Vec<f64>,
    pub inliers: Vec<u8>,
}

/// numpy's `percentile(values, q)` (method "linear") of sorted finite values, `q` in [0, 100]:
/// the same virtual index `(n − 1)·q/100` and the same two-sided interpolation.
fn percentile_sorted(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    let virtual_index = (n as f64 - 1.0) * (q / 100.0);
    if virtual_index >= n as f64 - 1.0 {
        return sorted[n - 1];
    }
    let below = virtual_index.floor();
    let i = below.max(0.0) as usize;
    let (a, b) = (sorted[i], sorted[i + 1]);
    let gamma = virtual_index - below;
    let diff = b - a;
    if gamma >= 0.5 {
        b - diff * (1.0 - gamma)
    } else {
        a + diff * gamma
    }
}

/// `gnomon.geometry.reference_lines._extent`: the length the values cover (5th to 95th percentile,
/// stretched to the full range); 0 for fewer than 2.
fn extent(mut along: Vec<f64>) -> f64 {
    if along.len() < 2 {
        return 0.0;
    }
    along.sort_unstable_by(f64::total_cmp);
    (percentile_sorted(&along, 95.0) - percentile_sorted(&along, 5.0)) / 0.9
}

/// The median of finite values (the mean of the two middle ones for an even count).
fn median(mut values: Vec<f64>) -> f64 {
    let n = values.len();
    values.sort_unstable_by(f64::total_cmp);
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// `gnomon.util.fitting.fit_line_robust` on one frame's points: (centroid, unit direction of most
/// spread, inlier mask). The direction is the major axis of the inliers' scatter matrix (the
/// first right singular vector of the centred points, up to sign and round-off).
fn fit_line_robust(
    points: &[[f64; 2]],
    k: f64,
    iterations: usize,
) -> ([f64; 2], [f64; 2], Vec<bool>) {
    let n = points.len();
    let mut mask = vec![true; n];
    let mean = |mask: &[bool]| {
        let (mut sx, mut sy, mut m) = (0.0, 0.0, 0usize);
        for (p, _) in points.iter().zip(mask).filter(|(_, &on)| on) {
            sx += p[0];
            sy += p[1];
            m += 1;
        }
        [sx / m as f64, sy / m as f64]
    };
    let mut centre = mean(&mask);
    let mut direction = [1.0, 0.0];
    for _ in 0..iterations {
        centre = mean(&mask);
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for (p, _) in points.iter().zip(&mask).filter(|(_, &on)| on) {
            let (x, y) = (p[0] - centre[0], p[1] - centre[1]);
            sxx += x * x;
            syy += y * y;
            sxy += x * y;
        }
        let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        direction = [theta.cos(), theta.sin()];
        let normal = [-direction[1], direction[0]];
        let r: Vec<f64> = points
            .iter()
            .map(|p| dot([p[0] - centre[0], p[1] - centre[1]], normal).abs())
            .collect();
        let inside: Vec<f64> = r
            .iter()
            .zip(&mask)
            .filter(|(_, &on)| on)
            .map(|(&v, _)| v)
            .collect();
        let floor = 1e-9 * (1.0 + centre[0].abs().max(centre[1].abs()));
        let scale = (1.4826 * median(inside)).max(floor);
        let new: Vec<bool> = r.iter().map(|&v| v <= k * scale).collect();
        if new.iter().filter(|&&on| on).count() < 2 || new == mask {
            break;
        }
        mask = new;
    }
    (centre, direction, mask)
}

/// One frame's fit that is a line: centre, direction, inliers, extent.
struct Fit {
    centre: [f64; 2],
    direction: [f64; 2],
    inliers: Vec<bool>,
    extent: f64,
}

fn fit_frame(points: &[[f64; 2]], p: &LineParams) -> Option<Fit> {
    if points.len() < p.min_points {
        return None;
    }
    let (centre, direction, inliers) = fit_line_robust(points, p.k, p.iterations);
    let chosen: Vec<[f64; 2]> = points
        .iter()
        .zip(&inliers)
        .filter(|(_, &on)| on)
        .map(|(q, _)| *q)
        .collect();
    if chosen.len() < p.min_points {
        return None;
    }
    let ext = extent(chosen.iter().map(|&q| dot(q, direction)).collect());
    let normal = [-direction[1], direction[0]];
    let sum_sq: f64 = chosen
        .iter()
        .map(|q| dot([q[0] - centre[0], q[1] - centre[1]], normal).powi(2))
        .sum();
    let spread = (sum_sq / chosen.len() as f64).sqrt();
    if ext < p.min_extent_to_rms * spread {
        return None;
    }
    Some(Fit {
        centre,
        direction,
        inliers,
        extent: ext,
    })
}

/// Every frame's own shadow line (see the module and [`FrameLines`]).
///
/// * `xy`: `K·2` crossings in plane coordinates, grouped by frame;
/// * `bounds`: `N + 1` non-decreasing offsets into the `K` crossings, frame `t`'s being
///   `bounds[t] .. bounds[t + 1]`.
///
/// A frame with at least `min_points` crossings is fitted; the fit counts when it keeps
/// `min_points` inliers and is a line (extent ≥ `min_extent_to_rms` × RMS). Of those, the ones
/// whose extent reaches `min_extent_fraction` of the 90th percentile of the extents are
/// accepted, in frame order, each direction turned to within 90° of the previous accepted one.
pub fn frame_lines(xy: &[f64], bounds: &[i64], p: &LineParams) -> Result<FrameLines, KernelError> {
    if xy.len() % 2 != 0 {
        return Err(KernelError::parameter(
            "xy",
            format!("needs pairs of plane coordinates, got {} values", xy.len()),
        ));
    }
    let k = xy.len() / 2;
    if bounds.is_empty()
        || bounds[0] < 0
        || bounds.windows(2).any(|w| w[1] < w[0])
        || bounds[bounds.len() - 1] as usize > k
    {
        return Err(KernelError::parameter(
            "bounds",
            format!("must be non-decreasing offsets within 0..={k}"),
        ));
    }
    if xy.iter().any(|v| !v.is_finite()) {
        return Err(KernelError::parameter("xy", "must be finite"));
    }
    let finite_at_least = |v: f64, low: f64| v.is_finite() && v >= low;
    let valid = finite_at_least(p.k, 0.0)
        && p.k > 0.0
        && finite_at_least(p.min_extent_to_rms, 0.0)
        && finite_at_least(p.min_extent_fraction, 0.0)
        && p.min_points >= 2;
    if !valid {
        return Err(KernelError::parameter(
            "params",
            format!("k > 0, extents ≥ 0 and finite, min_points ≥ 2 wanted, got {p:?}"),
        ));
    }
    let points: Vec<[f64; 2]> = xy.chunks_exact(2).map(|q| [q[0], q[1]]).collect();
    let n_frames = bounds.len() - 1;
    let fits: Vec<Option<Fit>> = (0..n_frames)
        .into_par_iter()
        .map(|t| fit_frame(&points[bounds[t] as usize..bounds[t + 1] as usize], p))
        .collect();
    let mut out = FrameLines {
        accepted: vec![0; n_frames],
        centre: vec![[f64::NAN; 2]; n_frames],
        direction: vec![[f64::NAN; 2]; n_frames],
        rms: vec![f64::NAN; n_frames],
        count: vec![0; n_frames],
        extent: vec![0.0; n_frames],
        inliers: vec![0; k],
    };
    let mut extents: Vec<f64> = fits.iter().flatten().map(|f| f.extent).collect();
    if extents.is_empty() {
        return Ok(out);
    }
    extents.sort_unstable_by(f64::total_cmp);
    let longest = percentile_sorted(&extents, 90.0);
    let mut previous: Option<f64> = None;
    for (t, fit) in fits.iter().enumerate() {
        let Some(fit) = fit else { continue };
        if fit.extent < p.min_extent_fraction * longest {
            continue;
        }
        let mut d = fit.direction;
        if let Some(angle) = previous {
            if (d[1].atan2(d[0]) - angle).cos() < 0.0 {
                d = [-d[0], -d[1]];
            }
        }
        previous = Some(d[1].atan2(d[0]));
        let start = bounds[t] as usize;
        let chosen: Vec<[f64; 2]> = points[start..bounds[t + 1] as usize]
            .iter()
            .zip(&fit.inliers)
            .filter(|(_, &on)| on)
            .map(|(q, _)| *q)
            .collect();
        let normal = [-d[1], d[0]];
        let c = fit.centre;
        let sum_sq: f64 = chosen
            .iter()
            .map(|q| dot([q[0] - c[0], q[1] - c[1]], normal).powi(2))
            .sum();
        out.accepted[t] = 1;
        out.centre[t] = c;
        out.direction[t] = d;
        out.rms[t] = (sum_sq / chosen.len() as f64).sqrt();
        out.count[t] = chosen.len() as i64;
        out.extent[t] = extent(chosen.iter().map(|&q| dot(q, d)).collect());
        for (flag, &on) in out.inliers[start..].iter_mut().zip(&fit.inliers) {
            *flag = u8::from(on);
        }
    }
    Ok(out)
}

/// Sub-pixel points where a shadow-time map crosses each integer frame
/// (`gnomon.geometry.reference_lines.isochrone_crossings`, whose numpy definition this is, value for value).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Crossings {
    /// The frame crossed.
    pub frame: Vec<i64>,
    /// Column (`u`) and row (`v`) of the crossing, pixels; one of them an integer.
    pub u: Vec<f64>,
    pub v: Vec<f64>,
}

/// Median of the finite non-zero steps between neighbours (`times[i + stride] − times[i]` over
/// the pairs `pairs` yields), in f32 as numpy takes it (the mean of the two middle ones for an
/// even count); 0 when there is none.
fn typical_step(steps: impl Iterator<Item = f32>) -> f64 {
    let mut d: Vec<f32> = steps.filter(|v| v.is_finite() && *v != 0.0).collect();
    let n = d.len();
    if n == 0 {
        return 0.0;
    }
    let (_, &mut upper, _) = d.select_nth_unstable_by(n / 2, f32::total_cmp);
    if n % 2 == 1 {
        return f64::from(upper);
    }
    let lower = d[..n / 2].iter().copied().fold(f32::NEG_INFINITY, f32::max);
    f64::from((lower + upper) / 2.0)
}

/// `x.ceil() as i64`, without a call to libm's `ceilf` (the baseline x86-64 target has no rounding
/// instruction; two calls per pair of neighbours were a tenth of [`isochrone_crossings`]): below
/// 2^23 in magnitude the truncation, plus one when it lies below `x`; from 2^23 on (and NaN, ±∞)
/// `x` is its own ceiling, cast as `as` casts it.
#[inline]
fn ceil_to_i64(x: f32) -> i64 {
    if x.abs() < 8_388_608.0 {
        let t = x as i64; // exact: |x| < 2^23
        if (t as f32) < x {
            t + 1
        } else {
            t
        }
    } else {
        x as i64
    }
}

/// Where a shadow-time map crosses each integer frame, sub-pixel (see [`Crossings`]).
///
/// * `times`: `H·W` shadow times (frames, NaN = none), row-major, `width` W;
/// * `n_frames`: frames `0 … n_frames − 1` are looked for.
///
/// The crossings are searched along the axis where the times change fastest (the typical step
/// along the rows unless the one along the columns is larger), in the sweep's own sense only;
/// each pair of neighbours `(a, b)` owns the frames in `[min, max)`, located by linear
/// interpolation (`along = c + (frame − a)/(b − a)`, `b − a` in f32, the rest in f64). With
/// `unique`, a frame crossed twice on one line (row or column) is dropped there. Order: lines,
/// then pairs along them, then frames (numpy's `nonzero` order). Lines in parallel.
pub fn isochrone_crossings(
    times: &[f32],
    width: usize,
    n_frames: i64,
    unique: bool,
) -> Result<Crossings, KernelError> {
    if times.is_empty() {
        return Ok(Crossings::default());
    }
    KernelError::check_image(times.len(), width, &[])?;
    if n_frames < 0 {
        return Err(KernelError::parameter(
            "n_frames",
            format!("must be ≥ 0, got {n_frames}"),
        ));
    }
    let height = times.len() / width;
    let du = typical_step(
        times
            .chunks_exact(width)
            .flat_map(|row| row.windows(2).map(|w| w[1] - w[0])),
    );
    let dv = typical_step(
        times
            .chunks_exact(width)
            .zip(times.chunks_exact(width).skip(1))
            .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| y - x)),
    );
    // the typical steps are medians of finite values: never NaN
    let along_rows = dv.abs() <= du.abs();
    let direction = if along_rows { du } else { dv };
    let (lines, length) = if along_rows {
        (height, width)
    } else {
        (width, height)
    };
    let at = |line: usize, k: usize| {
        if along_rows {
            times[line * width + k]
        } else {
            times[k * width + line]
        }
    };
    let last_frame = n_frames - 1;
    let per_line: Vec<Crossings> = (0..lines)
        .into_par_iter()
        .map(|line| {
            // (frame, pair index, a, b) of this line
            let mut found: Vec<(i64, usize, f32, f32)> = Vec::new();
            for k in 0..length.saturating_sub(1) {
                let (a, b) = (at(line, k), at(line, k + 1));
                let step = f64::from(b - a) * direction.signum();
                if !(a.is_finite() && b.is_finite() && step > 0.0 && direction != 0.0) {
                    continue;
                }
                // numpy: ceil in f32, then the int64 cast
                let first = ceil_to_i64(a.min(b)).max(0);
                let last = (ceil_to_i64(a.max(b)) - 1).min(last_frame);
                for frame in first..=last {
                    found.push((frame, k, a, b));
                }
            }
            if unique {
                let mut frames: Vec<i64> = found.iter().map(|f| f.0).collect();
                frames.sort_unstable();
                let twice: Vec<i64> = frames
                    .windows(2)
                    .filter(|w| w[0] == w[1])
                    .map(|w| w[0])
                    .collect();
                if !twice.is_empty() {
                    found.retain(|f| twice.binary_search(&f.0).is_err());
                }
            }
            let mut out = Crossings::default();
            for (frame, k, a, b) in found {
                let along = k as f64 + (frame as f64 - f64::from(a)) / f64::from(b - a);
                let across = line as f64;
                out.frame.push(frame);
                let (u, v) = if along_rows {
                    (along, across)
                } else {
                    (across, along)
                };
                out.u.push(u);
                out.v.push(v);
            }
            out
        })
        .collect();
    let mut out = Crossings::default();
    for part in per_line {
        out.frame.extend(part.frame);
        out.u.extend(part.u);
        out.v.extend(part.v);
    }
    Ok(out)
}

/// When a plane's shadow lines pass each of its points: the bracketing pair of lines by bisection,
/// the time interpolated between their frames by the point's signed distances to them.
///
/// * `xy`: `K·2` points in the plane's coordinates, `(x, y)` per point;
/// * `lines`: `N·3` lines `(n_x, n_y, offset)` in the order they sweep the plane (`N ≥ 2`, a line's
///   signed distance `x·n_x + y·n_y − offset` is positive ahead of it, where it has not yet passed);
/// * `frames`: the `N` frames of the lines (increasing);
/// * `steps`: bisection steps (`⌈log2 N⌉ + 1` halve `[0, N − 1]` to one pair).
///
/// A point ahead of the first line and passed by the last is bracketed by bisection (`mid = (lo +
/// hi) / 2`, `lo = mid` while it is ahead of line `mid`, else `hi = mid`) and gets
/// `frames[lo] + (frames[hi] − frames[lo])·s_lo / (s_lo − s_hi)`; any other point, or one whose
/// bisection did not end on neighbours, or whose time is not finite, NaN. Each distance is
/// `(x·n_x + y·n_y) − offset` in f64, without fused multiply-adds: element for element numpy's
/// `gnomon.geometry.plane_times._times_at_points_numpy`. Points in parallel.
pub fn line_times(
    xy: &[f64],
    lines: &[f64],
    frames: &[i64],
    steps: usize,
) -> Result<Vec<f64>, KernelError> {
    let n = frames.len();
    if n < 2 {
        return Err(KernelError::parameter(
            "frames",
            format!("{n} lines: at least 2 are needed"),
        ));
    }
    if lines.len() != 3 * n {
        return Err(KernelError::LengthMismatch {
            what: "lines",
            expected: 3 * n,
            got: lines.len(),
        });
    }
    if xy.len() % 2 != 0 {
        return Err(KernelError::parameter(
            "xy",
            format!("{} values are not (x, y) pairs", xy.len()),
        ));
    }
    let last = n - 1;
    let signed =
        |x: f64, y: f64, k: usize| x * lines[3 * k] + y * lines[3 * k + 1] - lines[3 * k + 2];
    let time = |x: f64, y: f64| -> f64 {
        if !(signed(x, y, 0) > 0.0 && signed(x, y, last) <= 0.0) {
            return f64::NAN;
        }
        let (mut lo, mut hi) = (0usize, last);
        for _ in 0..steps {
            let mid = (lo + hi) / 2;
            if signed(x, y, mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (s_lo, s_hi) = (signed(x, y, lo), signed(x, y, hi));
        let frac = s_lo / (s_lo - s_hi);
        let t = frames[lo] as f64 + (frames[hi] - frames[lo]) as f64 * frac;
        if hi == lo + 1 && t.is_finite() {
            t
        } else {
            f64::NAN
        }
    };
    const CHUNK: usize = 8192; // points per task
    let mut out = vec![f64::NAN; xy.len() / 2];
    out.par_chunks_mut(CHUNK)
        .zip(xy.par_chunks(2 * CHUNK))
        .for_each(|(out, xy)| {
            for (t, p) in out.iter_mut().zip(xy.chunks_exact(2)) {
                *t = time(p[0], p[1]);
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PARAMS: LineParams = LineParams {
        k: 3.0,
        iterations: 5,
        min_points: 10,
        min_extent_to_rms: 20.0,
        min_extent_fraction: 0.5,
    };

    /// Points along the line through `c` at angle `a` (radians), `n` of them 1 apart, offset
    /// across it by ±`noise` in the pattern + − − + (no mean, no tilt over whole groups of 4).
    fn line_points(c: [f64; 2], a: f64, n: usize, noise: f64) -> Vec<f64> {
        let (d, m) = ([a.cos(), a.sin()], [-a.sin(), a.cos()]);
        (0..n)
            .flat_map(|i| {
                let s = i as f64 - (n as f64 - 1.0) / 2.0;
                let e = if i % 4 == 0 || i % 4 == 3 {
                    noise
                } else {
                    -noise
                };
                [c[0] + s * d[0] + e * m[0], c[1] + s * d[1] + e * m[1]]
            })
            .collect()
    }

    #[test]
    fn percentiles_are_numpys() {
        // np.percentile([1, 2, 4, 8, 16], [5, 90, 95, 100]) = 1.2, 12.8, 14.4, 16
        let v = [1.0, 2.0, 4.0, 8.0, 16.0];
        for (q, want) in [
            (5.0, 1.2),
            (90.0, 12.8),
            (95.0, 14.4),
            (100.0, 16.0),
            (0.0, 1.0),
        ] {
            assert!((percentile_sorted(&v, q) - want).abs() < 1e-12, "{q}");
        }
        assert_eq!(percentile_sorted(&[3.0], 50.0), 3.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
    }

    #[test]
    fn lines_are_fitted_with_one_sense_and_outliers_dropped() {
        // frame 0: 40 points at 30° (π/6); frame 1: 40 points at 210° (the same line, reversed) plus an
        // outlier; frame 2: too few points; frame 3: a short line (extent 11 < 0.5 · 39)
        let mut xy = line_points([5.0, 2.0], std::f64::consts::FRAC_PI_6, 40, 0.01);
        let mut b = line_points(
            [6.0, 2.0],
            std::f64::consts::FRAC_PI_6 + std::f64::consts::PI,
            40,
            0.01,
        );
        b.extend([30.0, -40.0]);
        xy.extend(b);
        xy.extend(line_points([0.0, 0.0], 0.0, 5, 0.0));
        xy.extend(line_points([0.0, 0.0], 0.5, 12, 0.01));
        let bounds = [0, 40, 81, 86, 98];
        let got = frame_lines(&xy, &bounds, &PARAMS).unwrap();
        assert_eq!(got.accepted, vec![1, 1, 0, 0]);
        for t in 0..2 {
            let d = got.direction[t];
            assert!(
                (d[0] - std::f64::consts::FRAC_PI_6.cos()).abs() < 1e-9
                    && (d[1] - std::f64::consts::FRAC_PI_6.sin()).abs() < 1e-9
            );
            assert!((got.rms[t] - 0.01).abs() < 1e-9);
            assert_eq!(got.count[t], 40);
            assert!((got.extent[t] - 39.0).abs() < 1e-9, "{}", got.extent[t]);
        }
        assert!((got.centre[1][0] - 6.0).abs() < 1e-9 && (got.centre[1][1] - 2.0).abs() < 1e-9);
        assert_eq!(got.inliers[80], 0); // the outlier
        assert!(got.inliers[..80].iter().all(|&f| f == 1));
        assert!(got.inliers[81..].iter().all(|&f| f == 0));
        assert!(got.rms[2].is_nan() && got.count[3] == 0);
    }

    #[test]
    fn the_sense_follows_the_previous_line_across_the_vertical() {
        // 80° then 95°: the fit of the second gives −85° (axes are found within ±90°), turned to 95°
        let (a, b) = (80f64.to_radians(), 95f64.to_radians());
        let mut xy = line_points([0.0, 0.0], a, 40, 0.01);
        xy.extend(line_points([1.0, 0.0], b, 40, 0.01));
        let got = frame_lines(&xy, &[0, 40, 80], &PARAMS).unwrap();
        assert_eq!(got.accepted, vec![1, 1]);
        let d = got.direction[1];
        assert!((d[1].atan2(d[0]) - b).abs() < 1e-9, "{d:?}");
    }

    #[test]
    fn crossings_of_ramps_along_rows_and_columns() {
        // 3 rows × 6 columns, t = 0.8·u + 0.05·v + 0.1 (along the rows): frame f is crossed at
        // u = (f − 0.1 − 0.05·v)/0.8
        let times: Vec<f32> = (0..18)
            .map(|i| 0.8 * (i % 6) as f32 + 0.05 * (i / 6) as f32 + 0.1)
            .collect();
        let got = isochrone_crossings(&times, 6, 10, true).unwrap();
        assert_eq!(got.frame, [1, 2, 3, 4].repeat(3));
        for ((&f, &u), &v) in got.frame.iter().zip(&got.u).zip(&got.v) {
            assert!((u - (f as f64 - 0.1 - 0.05 * v) / 0.8).abs() < 1e-6, "{u}");
            assert!(v == 0.0 || v == 1.0 || v == 2.0);
        }
        // the transpose sweeps along the columns, downwards: the same crossings with u and v swapped
        let transposed: Vec<f32> = (0..18).map(|i| times[(i % 3) * 6 + i / 3]).collect();
        let down = isochrone_crossings(&transposed, 3, 10, true).unwrap();
        assert_eq!(down.frame, got.frame);
        assert_eq!(
            (down.u.clone(), down.v.clone()),
            (got.v.clone(), got.u.clone())
        );
        // a frame crossed twice on a row (a wrong time) is dropped there unless all are kept
        let mut spiky = times.clone();
        spiky[3] = 0.5; // row 0: 0.1 0.9 1.7 0.5 3.3 4.1 crosses frame 1 twice (0.9 → 1.7 and 0.5 → 3.3)
        let unique = isochrone_crossings(&spiky, 6, 10, true).unwrap();
        let all = isochrone_crossings(&spiky, 6, 10, false).unwrap();
        let row0 = |c: &Crossings| -> Vec<i64> {
            c.frame
                .iter()
                .zip(&c.v)
                .filter(|(_, &v)| v == 0.0)
                .map(|(&f, _)| f)
                .collect()
        };
        assert_eq!(row0(&unique), [2, 3, 4]);
        assert_eq!(row0(&all), [1, 1, 2, 3, 4]);
        assert!(isochrone_crossings(&times, 7, 10, true).is_err());
        assert_eq!(
            isochrone_crossings(&[], 1, 10, true).unwrap(),
            Crossings::default()
        );
    }

    #[test]
    fn ceilings_are_libms() {
        let mut state = 99u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 32) as u32
        };
        let special = [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.0000001,
            0.99999994,
            -0.99999994,
            2.5,
            -2.5,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_608.0,
            8_388_609.0,
            1e20,
            -1e20,
            9.3e18,
            -9.3e18,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        for &x in &special {
            assert_eq!(ceil_to_i64(x), x.ceil() as i64, "{x}");
        }
        for _ in 0..200_000 {
            let x = f32::from_bits(next());
            assert_eq!(ceil_to_i64(x), x.ceil() as i64, "{x}");
            let y = (next() % 2_000_000) as f32 / 7.0 - 140_000.0; // frame-like values
            assert_eq!(ceil_to_i64(y), y.ceil() as i64, "{y}");
        }
    }

    #[test]
    fn a_scatter_is_not_a_line_and_bad_input_is_an_error() {
        // 30 points on a 3 × 10 grid: extent ≈ 9, RMS ≈ 0.8 (< 20 × RMS)
        let xy: Vec<f64> = (0..30)
            .flat_map(|i| [(i % 10) as f64, (i / 10) as f64])
            .collect();
        let got = frame_lines(&xy, &[0, 30], &PARAMS).unwrap();
        assert_eq!(got.accepted, vec![0]);
        assert!(frame_lines(&xy, &[0, 31], &PARAMS).is_err());
        assert!(frame_lines(&xy, &[10, 5], &PARAMS).is_err());
        assert!(frame_lines(&xy[..5], &[0, 2], &PARAMS).is_err());
        assert!(frame_lines(&[f64::NAN, 0.0], &[0, 1], &PARAMS).is_err());
        let bad = LineParams { k: 0.0, ..PARAMS };
        assert!(frame_lines(&xy, &[0, 30], &bad).is_err());
    }

    #[test]
    fn line_times_interpolate_between_the_bracketing_lines() {
        // vertical lines x = 2, 4, 6, 8 at frames 10, 11, 13, 14, sweeping towards +x: ahead of a line (not
        // yet reached) is x > x₀, so n = (1, 0), offset x₀
        let xs = [2.0, 4.0, 6.0, 8.0];
        let lines: Vec<f64> = xs.iter().flat_map(|&x0: &f64| [1.0, 0.0, x0]).collect();
        let frames = [10, 11, 13, 14];
        let xy = [3.0, 0.0, 5.0, 7.0, 8.0, 1.0, 1.0, 0.0, 9.0, 0.0];
        let got = line_times(&xy, &lines, &frames, 3).unwrap();
        assert_eq!(got[0], 10.5);
        assert_eq!(got[1], 12.0);
        assert_eq!(got[2], 14.0);
        assert!(got[3].is_nan() && got[4].is_nan()); // before the first line, past the last
        assert!(line_times(&xy, &lines[..9], &frames, 3).is_err());
        assert!(line_times(&xy[..3], &lines, &frames, 3).is_err());
        assert!(line_times(&xy, &lines[..3], &frames[..1], 3).is_err());
    }
}
