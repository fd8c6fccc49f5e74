//! TemporalTracker on hand-built profiles with known answers, and against a
//! direct (non-streaming) reference on random sequences.

use gnomon_core::{
    find_crossing, Edge, KernelError, Sample, SecondDips, ShadowTimes, SimdPath, TemporalTracker,
    TrackerParams,
};

/// Frames 0-9: 200; 10-13: 180 140 100 60; 14-23: 40; 24-27: 70 110 150 190;
/// 28-37: 200. Threshold 120; steepest fall at j = 11 (first of three
/// 40-steps), crossing between 140 (frame 11) and 100: t = 11.5; steepest rise
/// at j = 25 (first 40-step), crossing between 110 (frame 25) and 150:
/// t = 25.25.
fn ramp_profile() -> Vec<u16> {
    let mut p = vec![200; 10];
    p.extend([180, 140, 100, 60]);
    p.extend([40; 10]);
    p.extend([70, 110, 150, 190]);
    p.extend([200; 10]);
    p
}

/// A tracker on SIMD path `path` (with the decoding table `lut` when given)
/// that has seen every frame of the per-pixel `profiles`.
fn fed<T: Sample>(
    profiles: &[Vec<T>],
    height: usize,
    width: usize,
    params: TrackerParams,
    lut: Option<&[f32]>,
    path: SimdPath,
) -> TemporalTracker<T> {
    let mut tracker = match lut {
        Some(lut) => TemporalTracker::<T>::with_table(height, width, params, lut),
        None => TemporalTracker::<T>::new(height, width, params),
    }
    .unwrap();
    tracker.set_simd_path(path).unwrap();
    for f in 0..profiles[0].len() {
        let frame: Vec<T> = profiles.iter().map(|p| p[f]).collect();
        tracker.update(&frame).unwrap();
    }
    tracker
}

/// Feed per-pixel profiles (all the same length) as frames of `height × width`,
/// on every instruction set this CPU supports: the results must be identical.
fn track<T: Sample>(
    profiles: &[Vec<T>],
    height: usize,
    width: usize,
    params: TrackerParams,
    min_contrast: f32,
    lut: Option<&[f32]>,
) -> ShadowTimes {
    assert_eq!(profiles.len(), height * width);
    let mut results = SimdPath::supported().into_iter().map(|path| {
        let tracker = fed(profiles, height, width, params, lut, path);
        (path, tracker.finish(min_contrast).unwrap())
    });
    let (_, first) = results.next().unwrap();
    for (path, other) in results {
        assert!(
            identical(&first, &other),
            "{} differs from the best path",
            path.name()
        );
    }
    first
}

/// [`track`]'s second candidates ([`TemporalTracker::finish_second`], with
/// `second_dips` on), identical on every path; the best dips' times equal
/// those of a tracker without second candidates.
fn track_second<T: Sample>(
    profiles: &[Vec<T>],
    height: usize,
    width: usize,
    params: TrackerParams,
    lut: Option<&[f32]>,
) -> SecondDips {
    let without = TrackerParams {
        second_dips: false,
        ..params
    };
    let plain = track(profiles, height, width, without, 0.0, lut);
    let params = TrackerParams {
        second_dips: true,
        ..params
    };
    let mut results = SimdPath::supported().into_iter().map(|path| {
        let tracker = fed(profiles, height, width, params, lut, path);
        assert!(
            identical(&tracker.finish(0.0).unwrap(), &plain),
            "{}: the best dips change with second_dips",
            path.name()
        );
        (path, tracker.finish_second().unwrap())
    });
    let (_, first) = results.next().unwrap();
    let eq = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(&p, &q)| same(p, q));
    for (path, o) in results {
        assert!(
            eq(&first.imax, &o.imax)
                && eq(&first.imin, &o.imin)
                && eq(&first.enter, &o.enter)
                && eq(&first.leave, &o.leave)
                && eq(&first.best_enter, &o.best_enter)
                && eq(&first.best_leave, &o.best_leave),
            "{} differs from the best path",
            path.name()
        );
    }
    first
}

/// Equal arrays, NaN equal to NaN.
fn identical(a: &ShadowTimes, b: &ShadowTimes) -> bool {
    let eq = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(&p, &q)| same(p, q));
    eq(&a.imax, &b.imax)
        && eq(&a.imin, &b.imin)
        && eq(&a.threshold, &b.threshold)
        && eq(&a.enter, &b.enter)
        && eq(&a.leave, &b.leave)
        && eq(&a.enter_slope, &b.enter_slope)
        && eq(&a.leave_slope, &b.leave_slope)
        && a.valid == b.valid
}

#[test]
fn the_paths_this_cpu_supports() {
    let paths = SimdPath::supported();
    assert_eq!(paths.last(), Some(&SimdPath::Portable));
    assert!(paths.contains(&SimdPath::active()));
    assert_eq!(paths[0], SimdPath::detect());
    #[cfg(target_arch = "x86_64")]
    assert!(paths.contains(&SimdPath::Sse2));
    for p in paths {
        assert_eq!(SimdPath::from_name(p.name()), Some(p));
    }
}

fn params(window: usize, max_width: usize) -> TrackerParams {
    TrackerParams {
        window,
        max_width,
        ..TrackerParams::default()
    }
}

fn to_u8(p: &[u16]) -> Vec<u8> {
    p.iter().map(|&v| v as u8).collect()
}

#[test]
fn ramp_has_the_known_crossings() {
    let p = to_u8(&ramp_profile());
    for max_width in [8, 16, 32] {
        let t = track(
            std::slice::from_ref(&p),
            1,
            1,
            params(4, max_width),
            70.0,
            None,
        );
        assert_eq!((t.imax[0], t.imin[0], t.contrast[0]), (200.0, 40.0, 160.0));
        assert_eq!(t.threshold[0], 120.0);
        assert_eq!((t.valid[0], t.ambiguous[0], t.clipped[0]), (1, 0, 0));
        assert_eq!(t.rival[0], 0.0);
        assert_eq!(t.enter[0], 11.5, "max_width {max_width}");
        assert_eq!(t.leave[0], 25.25, "max_width {max_width}");
        assert_eq!(t.enter_slope[0], 40.0);
        assert_eq!(t.leave_slope[0], 40.0);
    }
}

#[test]
fn u16_ramp_matches_u8() {
    let p16: Vec<u16> = ramp_profile().iter().map(|&v| v * 256).collect();
    let t = track(&[p16], 1, 1, params(4, 16), 70.0 * 256.0, None);
    assert_eq!(t.threshold[0], 120.0 * 256.0);
    assert_eq!(t.enter[0], 11.5);
    assert_eq!(t.leave[0], 25.25);
    assert_eq!(t.enter_slope[0], 40.0 * 256.0);
}

#[test]
fn windows_are_clamped_at_the_sequence_ends() {
    // Falls at frame 1 (window frames -3..4 clamped to 0), rises at the last frame.
    let mut p: Vec<u8> = vec![200, 60];
    p.extend([40; 6]);
    p.push(200);
    let n = p.len() as f32;
    for max_width in [4, 8, 16] {
        let t = track(
            std::slice::from_ref(&p),
            1,
            1,
            params(4, max_width),
            10.0,
            None,
        );
        assert_eq!(t.enter[0], 80.0f32 / 140.0, "max_width {max_width}");
        assert_eq!(t.leave[0], n - 2.0 + 0.5, "max_width {max_width}");
    }
}

#[test]
fn lut_puts_the_threshold_at_mid_irradiance() {
    let lut: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    let p = to_u8(&ramp_profile());
    let t = track(
        std::slice::from_ref(&p),
        1,
        1,
        params(4, 16),
        70.0,
        Some(&lut),
    );
    let thr = (lut[200] + lut[40]) * 0.5;
    assert_eq!(t.threshold[0], thr);
    // In DN the mid-irradiance is ≈ 147, above the DN mid-level 120: the fall
    // crosses it between 180 (frame 10) and 140 (frame 11), a frame earlier.
    assert!(lut[140] < thr && thr <= lut[180]);
    let expect = 10.0 + (lut[180] - thr) / (lut[180] - lut[140]);
    assert!(
        (t.enter[0] - expect).abs() < 1e-6,
        "{} vs {expect}",
        t.enter[0]
    );
    assert!((t.enter_slope[0] - (lut[180] - lut[140])).abs() < 1e-7);
    // The rise crosses between 110 (frame 25) and 150, as in DN.
    assert!(lut[110] < thr && thr <= lut[150]);
    let expect = 25.0 + (lut[110] - thr) / (lut[110] - lut[150]);
    assert!(
        (t.leave[0] - expect).abs() < 1e-6,
        "{} vs {expect}",
        t.leave[0]
    );
}

#[test]
fn low_contrast_and_flat_pixels_are_invalid() {
    let ramp = to_u8(&ramp_profile());
    let flat = vec![90u8; ramp.len()];
    let t = track(&[ramp, flat], 1, 2, params(4, 16), 170.0, None);
    assert_eq!(t.valid, vec![0, 0]);
    assert!(t.enter.iter().chain(&t.leave).all(|v| v.is_nan()));
    assert!(t
        .enter_slope
        .iter()
        .chain(&t.leave_slope)
        .all(|v| v.is_nan()));
    assert_eq!(t.contrast, vec![160.0, 0.0]);
    // A flat pixel has no dip at all: invalid whatever the minimum contrast.
    let t = track(&[vec![90u8; 40]], 1, 1, params(4, 16), 0.0, None);
    assert_eq!((t.valid[0], t.contrast[0]), (0, 0.0));
    assert!(t.enter[0].is_nan() && t.leave[0].is_nan());
}

#[test]
fn errors_name_the_problem() {
    assert!(TemporalTracker::<u8>::new(0, 4, params(4, 16)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(0, 16)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(4, 1)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(4, 1000)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(9, 8)).is_err());
    for ambiguity in [0.0, -0.5, 1.5, f32::NAN] {
        let p = TrackerParams {
            ambiguity,
            ..TrackerParams::default()
        };
        assert!(TemporalTracker::<u8>::new(4, 4, p).is_err(), "{ambiguity}");
    }
    let mut t = TemporalTracker::<u8>::new(2, 3, params(4, 16)).unwrap();
    assert_eq!(t.finish(0.0), Err(KernelError::NoFrames));
    let err = t.update(&[0; 5]).unwrap_err();
    assert_eq!(
        err,
        KernelError::LengthMismatch {
            what: "frame",
            expected: 6,
            got: 5
        }
    );
    assert!(err.to_string().contains("expected 6"));
    t.update(&[0; 6]).unwrap();
    assert!(t.finish(f32::NAN).is_err());
    // a plain tracker takes no gain, a normalised one needs it
    let mut plain = TemporalTracker::<u16>::new(2, 3, params(4, 16)).unwrap();
    assert!(matches!(
        plain.update_with_gain(&[0u16; 6], 1.0),
        Err(KernelError::InvalidParameter { name: "gain", .. })
    ));
    let table: Vec<f32> = (0..256).map(|v| v as f32 / 255.0).collect();
    let mut n = TemporalTracker::normalised(2, 3, params(4, 16), &table).unwrap();
    assert!(n.update(&[0u16; 6]).is_err());
    assert!(n.update_with_gain(&[0u16; 6], 1.0).is_err()); // a u16 frame for a u8 table
    assert!(n.update_with_gain(&[0u8; 6], 0.0).is_err());
    assert!(n.update_with_gain(&[0u8; 6], f64::NAN).is_err());
    n.update_with_gain(&[0u8; 6], 0.5).unwrap();
    assert_eq!(n.frames_seen(), 1);
    let short = [0.0; 255];
    let mut decreasing: Vec<f32> = (0..256).map(|v| v as f32).collect();
    decreasing[100] = 0.0;
    let mut nan: Vec<f32> = (0..256).map(|v| v as f32).collect();
    nan[3] = f32::NAN;
    for bad in [&short[..], &decreasing, &nan] {
        assert!(matches!(
            TemporalTracker::<u8>::with_table(2, 3, params(4, 16), bad),
            Err(KernelError::InvalidLut { .. })
        ));
        assert!(matches!(
            TemporalTracker::normalised(2, 3, params(4, 16), bad),
            Err(KernelError::InvalidLut { .. })
        ));
    }
}

#[test]
fn crossing_nearest_the_centre_wins() {
    // Two falls through 5: pairs (1,2) and (4,5); centre pair (2,3).
    let v = [9.0, 9.0, 1.0, 1.0, 9.0, 1.0];
    let c = find_crossing(&v, 5.0, Edge::Enter).unwrap();
    assert_eq!((c.index, c.fraction, c.slope), (1, 0.5, 8.0));
    // Equidistant: the earlier pair wins.
    let v = [9.0, 1.0, 9.0, 9.0, 9.0, 1.0];
    assert_eq!(find_crossing(&v, 5.0, Edge::Enter).unwrap().index, 0);
    assert!(find_crossing(&v, 0.5, Edge::Enter).is_none());
    // Exactly at the threshold: a fall starts at v_k = thr, a rise ends at it.
    let v = [5.0, 5.0, 1.0, 1.0];
    assert_eq!(find_crossing(&v, 5.0, Edge::Enter).unwrap().fraction, 0.0);
    let v = [1.0, 1.0, 5.0, 5.0];
    assert_eq!(find_crossing(&v, 5.0, Edge::Leave).unwrap().fraction, 1.0);
}

// ---- Random sequences against a direct reference -------------------------

struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// A profile with one or two shadows passing at random times, noise, and
/// coarse quantisation so that ties are common.
fn random_profile(rng: &mut XorShift, len: usize, hi: u64) -> Vec<u16> {
    let dips = 1 + rng.below(2) as usize;
    let spans: Vec<(usize, usize, u64)> = (0..dips)
        .map(|_| {
            let enter = rng.below(len as u64) as usize;
            let leave = enter + rng.below(len as u64 / 3 + 1) as usize;
            (enter, leave, hi / 5 + rng.below(hi / 3))
        })
        .collect();
    (0..len)
        .map(|f| {
            let base = spans
                .iter()
                .filter(|&&(e, l, _)| e <= f && f < l)
                .map(|&(_, _, level)| level)
                .min()
                .unwrap_or(hi * 3 / 4);
            let noise = rng.below(hi / 8 + 1);
            (((base + noise) / 4) * 4).min(hi) as u16
        })
        .collect()
}

/// The second candidate of one pixel, and the best dip's times whatever its validity.
#[derive(Debug, Clone, Copy)]
struct Second {
    imax: f32,
    imin: f32,
    enter: f32,
    leave: f32,
    best_enter: f32,
    best_leave: f32,
}

/// [`reference`]'s fold, keeping where the second event is: a far frame
/// deeper than the best makes the best the second; a far frame deeper than
/// the second (not the best) becomes it.
fn reference_second(profile: &[u16], p: TrackerParams, lut: &[f32]) -> Second {
    let (n, w, half) = (profile.len(), p.max_width, p.window);
    let depth = frame_depths(profile, w);
    let (mut d1, mut d2) = (0u16, 0u16);
    let (mut k1, mut k2) = (None::<usize>, None::<usize>);
    for (k, &(d, _)) in depth.iter().enumerate() {
        let same_event = k1.is_some_and(|k1| k - k1 <= w);
        if same_event {
            if d > d1 {
                (d1, k1) = (d, Some(k));
            }
        } else if d > d1 {
            (d2, k2) = (d2.max(d1), k1);
            (d1, k1) = (d, Some(k));
        } else if d > d2 {
            (d2, k2) = (d, Some(k));
        }
    }
    // The times of the dip whose darkest sample is at frame k.
    let times = |k: usize| -> (f32, f32) {
        let (hi, lo) = (depth[k].1, profile[k]);
        let thr = (lut[hi as usize] + lut[lo as usize]) * 0.5;
        let bright = |c: usize| 2 * u32::from(profile[c]) >= u32::from(hi) + u32::from(lo);
        let b = k / w;
        let enter_at = (b.saturating_sub(1) * w..k)
            .rev()
            .find(|&c| bright(c))
            .unwrap()
            + 1;
        let leave_at = (k + 1..n).find(|&c| bright(c)).unwrap();
        let solve = |j: usize, edge: Edge| -> f32 {
            let window: Vec<f32> = (0..2 * half)
                .map(|i| {
                    let f = (j as i64 - half as i64 + i as i64).clamp(0, n as i64 - 1);
                    lut[profile[f as usize] as usize]
                })
                .collect();
            find_crossing(&window, thr, edge).map_or(f32::NAN, |c| {
                let frame = j as i64 - half as i64 + c.index as i64;
                (frame as f64 + f64::from(c.fraction)) as f32
            })
        };
        (solve(enter_at, Edge::Enter), solve(leave_at, Edge::Leave))
    };
    let (best_enter, best_leave) = k1.map_or((f32::NAN, f32::NAN), times);
    match k2.filter(|_| d2 > 0) {
        Some(k) => {
            let (enter, leave) = times(k);
            Second {
                imax: f32::from(depth[k].1),
                imin: f32::from(profile[k]),
                enter,
                leave,
                best_enter,
                best_leave,
            }
        }
        None => Second {
            imax: 0.0,
            imin: 0.0,
            enter: f32::NAN,
            leave: f32::NAN,
            best_enter,
            best_leave,
        },
    }
}

/// What the tracker reports for one pixel.
#[derive(Debug, Clone, Copy)]
struct Pixel {
    imax: f32,
    imin: f32,
    rival: f32,
    valid: u8,
    ambiguous: u8,
    enter: f32,
    leave: f32,
    enter_slope: f32,
    leave_slope: f32,
}

/// (depth, lit level) of every frame of a stored profile, straight from the
/// definitions: the lit level is the lower of the brightest sample before the
/// frame (from block `b − 1` on) and after it (to the end of block `b + 1`),
/// blocks of `w` frames.
fn frame_depths(profile: &[u16], w: usize) -> Vec<(u16, u16)> {
    let n = profile.len();
    let max_of = |r: std::ops::Range<usize>| profile[r].iter().copied().max().unwrap_or(0);
    (0..n)
        .map(|k| {
            let b = k / w;
            let left = max_of(b.saturating_sub(1) * w..k);
            let right = max_of((k + 1).min(n)..((b + 2) * w).min(n));
            let lit = left.min(right);
            (lit.saturating_sub(profile[k]), lit)
        })
        .collect()
}

/// The dip of the module documentation on a whole stored profile, straight
/// from the definitions (no streaming, no blocks of work, no SIMD).
fn reference(profile: &[u16], p: TrackerParams, lut: &[f32], min_contrast: f32) -> Pixel {
    let (n, w, half) = (profile.len(), p.max_width, p.window);
    let depth = frame_depths(profile, w);
    let (mut d1, mut d2, mut k1) = (0u16, 0u16, None::<usize>);
    for (k, &(d, _)) in depth.iter().enumerate() {
        let same_event = k1.is_some_and(|k1| k - k1 <= w);
        if same_event {
            if d > d1 {
                (d1, k1) = (d, Some(k));
            }
        } else if d > d1 {
            d2 = d2.max(d1);
            (d1, k1) = (d, Some(k));
        } else {
            d2 = d2.max(d);
        }
    }
    let Some(k1) = k1 else {
        return Pixel {
            imax: 0.0,
            imin: 0.0,
            rival: 0.0,
            valid: 0,
            ambiguous: 0,
            enter: f32::NAN,
            leave: f32::NAN,
            enter_slope: f32::NAN,
            leave_slope: f32::NAN,
        };
    };
    let (hi, lo) = (depth[k1].1, profile[k1]);
    let contrast = f32::from(hi) - f32::from(lo);
    let deep = contrast >= min_contrast;
    let ambiguous = deep && f32::from(d2) >= p.ambiguity * contrast;
    let valid = deep && !ambiguous;
    let thr = (lut[hi as usize] + lut[lo as usize]) * 0.5;
    let bright = |c: usize| 2 * u32::from(profile[c]) >= u32::from(hi) + u32::from(lo);
    let b = k1 / w;
    let enter_at = (b.saturating_sub(1) * w..k1)
        .rev()
        .find(|&c| bright(c))
        .unwrap()
        + 1;
    let leave_at = (k1 + 1..n).find(|&c| bright(c)).unwrap();
    let solve = |j: usize, edge: Edge| -> (f32, f32) {
        let window: Vec<f32> = (0..2 * half)
            .map(|i| {
                let f = (j as i64 - half as i64 + i as i64).clamp(0, n as i64 - 1);
                lut[profile[f as usize] as usize]
            })
            .collect();
        match find_crossing(&window, thr, edge) {
            Some(c) => {
                let frame = j as i64 - half as i64 + c.index as i64;
                ((frame as f64 + f64::from(c.fraction)) as f32, c.slope)
            }
            None => (f32::NAN, f32::NAN),
        }
    };
    let ((enter, enter_slope), (leave, leave_slope)) = if valid {
        (solve(enter_at, Edge::Enter), solve(leave_at, Edge::Leave))
    } else {
        ((f32::NAN, f32::NAN), (f32::NAN, f32::NAN))
    };
    Pixel {
        imax: f32::from(hi),
        imin: f32::from(lo),
        rival: f32::from(d2),
        valid: u8::from(valid),
        ambiguous: u8::from(ambiguous),
        enter,
        leave,
        enter_slope,
        leave_slope,
    }
}

fn same(a: f32, b: f32) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

fn pixel(t: &ShadowTimes, i: usize) -> Pixel {
    Pixel {
        imax: t.imax[i],
        imin: t.imin[i],
        rival: t.rival[i],
        valid: t.valid[i],
        ambiguous: t.ambiguous[i],
        enter: t.enter[i],
        leave: t.leave[i],
        enter_slope: t.enter_slope[i],
        leave_slope: t.leave_slope[i],
    }
}

fn same_pixel(a: &Pixel, b: &Pixel) -> bool {
    same(a.imax, b.imax)
        && same(a.imin, b.imin)
        && same(a.rival, b.rival)
        && a.valid == b.valid
        && a.ambiguous == b.ambiguous
        && same(a.enter, b.enter)
        && same(a.leave, b.leave)
        && same(a.enter_slope, b.enter_slope)
        && same(a.leave_slope, b.leave_slope)
}

fn check_against_reference<T: Sample>(
    profiles16: &[Vec<u16>],
    convert: impl Fn(u16) -> T,
    p: TrackerParams,
    lut: &[f32],
    lut_arg: Option<&[f32]>,
) {
    let (height, width) = (3, profiles16.len() / 3);
    let profiles: Vec<Vec<T>> = profiles16
        .iter()
        .map(|p| p.iter().map(|&v| convert(v)).collect())
        .collect();
    let min_contrast = 8.0;
    let t = track(&profiles, height, width, p, min_contrast, lut_arg);
    for (i, profile) in profiles16.iter().enumerate() {
        let want = reference(profile, p, lut, min_contrast);
        let got = pixel(&t, i);
        assert!(
            same_pixel(&got, &want),
            "pixel {i}, {p:?}:\n got {got:?}\nwant {want:?}\n{profile:?}"
        );
        if got.valid == 1 && got.enter.is_finite() && got.leave.is_finite() {
            assert!(got.enter < got.leave, "pixel {i}: enter after leave");
        }
    }
    let second = track_second(&profiles, height, width, p, lut_arg);
    for (i, profile) in profiles16.iter().enumerate() {
        let want = reference_second(profile, p, lut);
        let got = Second {
            imax: second.imax[i],
            imin: second.imin[i],
            enter: second.enter[i],
            leave: second.leave[i],
            best_enter: second.best_enter[i],
            best_leave: second.best_leave[i],
        };
        let ok = same(got.imax, want.imax)
            && same(got.imin, want.imin)
            && same(got.enter, want.enter)
            && same(got.leave, want.leave)
            && same(got.best_enter, want.best_enter)
            && same(got.best_leave, want.best_leave);
        assert!(
            ok,
            "second, pixel {i}, {p:?}:\n got {got:?}\nwant {want:?}\n{profile:?}"
        );
        assert_eq!(
            second.contrast[i], t.rival[i],
            "pixel {i}: the second is the rival"
        );
    }
}

#[test]
fn random_sequences_match_the_reference() {
    let mut rng = XorShift(0x2545_f491_4f6c_dd1d);
    let identity8: Vec<f32> = (0..256).map(|v| v as f32).collect();
    let gamma8: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    for len in [1, 2, 3, 5, 17, 40, 75, 130] {
        let profiles: Vec<Vec<u16>> = (0..3 * 70)
            .map(|_| random_profile(&mut rng, len, 255))
            .collect();
        for half in [1, 2, 4] {
            for max_width in [4, 5, 8, 16, 33] {
                for ambiguity in [0.6, 1.0] {
                    let p = TrackerParams {
                        window: half,
                        max_width,
                        ambiguity,
                        second_dips: false,
                    };
                    check_against_reference(&profiles, |v| v as u8, p, &identity8, None);
                }
            }
        }
        let p = params(4, 16);
        check_against_reference(&profiles, |v| v as u8, p, &gamma8, Some(&gamma8));
    }
}

#[test]
fn random_u16_sequences_match_the_reference() {
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let identity16: Vec<f32> = (0..65536).map(|v| v as f32).collect();
    for len in [4, 31, 64, 100] {
        let profiles: Vec<Vec<u16>> = (0..3 * 80)
            .map(|_| random_profile(&mut rng, len, 4095))
            .collect();
        for max_width in [4, 7, 16] {
            check_against_reference(&profiles, |v| v, params(4, max_width), &identity16, None);
        }
    }
}

// ---- Several darkening events: one dip per pixel ------------------------

/// Lit 200 DN for `len` frames; `dips` are `(first dark frame, frames, level)`
/// with instantaneous edges.
fn with_dips(len: usize, dips: &[(usize, usize, u8)]) -> Vec<u8> {
    let mut p = vec![200u8; len];
    for &(start, width, level) in dips {
        p[start..start + width].fill(level);
    }
    p
}

#[test]
fn a_wide_cloud_dip_does_not_take_the_shadow_s_place() {
    // A slow cloud (raised cosine over 100 frames, 60 DN deep) and, later,
    // the sharp shadow (frames 150..157 at 40 DN): the steepest fall and rise
    // of the whole capture are the shadow's, but a cloud with sharper flanks
    // than the shadow's edges must not win either.
    let mut p = with_dips(200, &[(150, 8, 40)]);
    for (t, v) in p.iter_mut().enumerate().take(120).skip(20) {
        let phase = 2.0 * std::f64::consts::PI * (t as f64 - 70.0) / 100.0;
        *v = (200.0 - 30.0 * (1.0 + phase.cos())).round() as u8;
    }
    let t = track(&[p], 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.imax[0], t.imin[0], t.valid[0]), (200.0, 40.0, 1));
    assert_eq!(t.enter[0], 149.5);
    assert_eq!(t.leave[0], 157.5);
    // The cloud is shallow within any 2W frames: a far weaker rival.
    assert!(
        t.rival[0] > 0.0 && t.rival[0] < 0.3 * t.contrast[0],
        "{}",
        t.rival[0]
    );
    // A cloud with sharper flanks (frames 60..63 at 120 DN: 80 DN steps)
    // than the shadow's edges (40 DN steps): the steepest fall and rise of the
    // capture are the cloud's, the deepest dip is the shadow's.
    let mut p = with_dips(200, &[(60, 4, 120), (153, 6, 40)]);
    p[150..153].copy_from_slice(&[160, 120, 80]);
    p[159..162].copy_from_slice(&[80, 120, 160]);
    let t = track(&[p], 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.valid[0], t.ambiguous[0], t.rival[0]), (1, 0, 80.0));
    assert_eq!((t.enter[0], t.leave[0]), (151.0, 160.0));
    assert_eq!((t.enter_slope[0], t.leave_slope[0]), (40.0, 40.0));
}

#[test]
fn a_second_comparable_dip_makes_the_pixel_ambiguous() {
    let two = with_dips(160, &[(30, 6, 40), (110, 6, 55)]);
    let t = track(&[two], 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.valid[0], t.ambiguous[0]), (0, 1));
    assert_eq!((t.contrast[0], t.rival[0]), (160.0, 145.0));
    assert!(t.enter[0].is_nan() && t.leave[0].is_nan());
    // The same second dip, shallower than `ambiguity` × the first: not ambiguous.
    let weak = with_dips(160, &[(30, 6, 40), (110, 6, 120)]);
    let t = track(&[weak], 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.valid[0], t.ambiguous[0], t.rival[0]), (1, 0, 80.0));
    assert_eq!((t.enter[0], t.leave[0]), (29.5, 35.5));
    // The deeper dip second in time wins just the same.
    let later = with_dips(160, &[(30, 6, 120), (110, 6, 40)]);
    let t = track(&[later], 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.enter[0], t.leave[0], t.rival[0]), (109.5, 115.5, 80.0));
}

#[test]
fn the_second_candidate_keeps_the_other_dip_s_times() {
    // Two comparable dips: ambiguous, but both candidates' times are there.
    let two = with_dips(160, &[(30, 6, 40), (110, 6, 55)]);
    let p = params(4, 16);
    let s = track_second(std::slice::from_ref(&two), 1, 1, p, None);
    assert_eq!((s.best_enter[0], s.best_leave[0]), (29.5, 35.5));
    assert_eq!((s.enter[0], s.leave[0]), (109.5, 115.5));
    assert_eq!((s.imax[0], s.imin[0], s.contrast[0]), (200.0, 55.0, 145.0));
    // The deeper dip later in time: the earlier becomes the second.
    let later = with_dips(160, &[(30, 6, 120), (110, 6, 40)]);
    let s = track_second(&[later], 1, 1, p, None);
    assert_eq!((s.best_enter[0], s.best_leave[0]), (109.5, 115.5));
    assert_eq!((s.enter[0], s.leave[0], s.contrast[0]), (29.5, 35.5, 80.0));
    // One dip only: no second.
    let one = with_dips(160, &[(30, 6, 40)]);
    let s = track_second(&[one], 1, 1, p, None);
    assert!(s.enter[0].is_nan() && s.leave[0].is_nan() && s.contrast[0] == 0.0);
    // The stream goes on unchanged after a look at the candidates.
    let p = TrackerParams {
        second_dips: true,
        ..p
    };
    let mut tracker = TemporalTracker::<u8>::new(1, 1, p).unwrap();
    for (f, &v) in two.iter().enumerate() {
        tracker.update(&[v]).unwrap();
        if f == 80 {
            let early = tracker.finish_second().unwrap();
            assert!(early.enter[0].is_nan(), "no second dip yet at frame 80");
        }
    }
    assert_eq!(tracker.finish_second().unwrap().enter[0], 109.5);
}

#[test]
fn a_rise_before_the_fall_is_not_the_leave() {
    // Dark until frame 10 (dawn: the capture starts with a rise steeper than
    // anything after), the shadow at frames 60..67, dusk from frame 110 on
    // (a fall that never comes back).
    let mut p = with_dips(140, &[(0, 10, 40), (60, 8, 40)]);
    p[110..].fill(30);
    for max_width in [8, 16, 32] {
        let t = track(
            std::slice::from_ref(&p),
            1,
            1,
            params(4, max_width),
            20.0,
            None,
        );
        assert_eq!(
            (t.valid[0], t.ambiguous[0]),
            (1, 0),
            "max_width {max_width}"
        );
        assert_eq!(
            (t.enter[0], t.leave[0]),
            (59.5, 67.5),
            "max_width {max_width}"
        );
        assert_eq!(t.rival[0], 0.0, "max_width {max_width}");
    }
}

#[test]
fn clipped_levels_flag_the_pixel() {
    let mut p = with_dips(60, &[(20, 8, 40)]);
    let t = track(std::slice::from_ref(&p), 1, 1, params(4, 16), 20.0, None);
    assert_eq!(t.clipped[0], 0);
    p.iter_mut().filter(|v| **v == 200).for_each(|v| *v = 255);
    let t = track(std::slice::from_ref(&p), 1, 1, params(4, 16), 20.0, None);
    assert_eq!((t.clipped[0], t.valid[0]), (1, 1));
    let p = with_dips(60, &[(20, 8, 0)]);
    let t = track(&[p], 1, 1, params(4, 16), 20.0, None);
    assert_eq!(t.clipped[0], 1);
}

#[test]
fn finish_is_a_preview_that_does_not_disturb_the_stream() {
    let mut rng = XorShift(7);
    let profiles: Vec<Vec<u8>> = (0..3 * 40)
        .map(|_| to_u8(&random_profile(&mut rng, 60, 255)))
        .collect();
    let frame = |f: usize| -> Vec<u8> { profiles.iter().map(|p| p[f]).collect() };
    let mut streaming = TemporalTracker::<u8>::new(3, 40, params(4, 7)).unwrap();
    for f in 0..60 {
        streaming.update(&frame(f)).unwrap();
        assert_eq!(streaming.frames_seen(), f + 1);
        if f % 9 == 4 {
            let preview = streaming.finish(10.0).unwrap();
            let mut fresh = TemporalTracker::<u8>::new(3, 40, params(4, 7)).unwrap();
            for g in 0..=f {
                fresh.update(&frame(g)).unwrap();
            }
            let expect = fresh.finish(10.0).unwrap();
            for (a, b) in preview
                .enter
                .iter()
                .zip(&expect.enter)
                .chain(preview.leave.iter().zip(&expect.leave))
            {
                assert!(same(*a, *b), "frame {f}: {a} vs {b}");
            }
        }
    }
    let prefix: Vec<Vec<u8>> = profiles.clone();
    let full = track(&prefix, 3, 40, params(4, 7), 10.0, None);
    let end = streaming.finish(10.0).unwrap();
    for (a, b) in end
        .enter
        .iter()
        .zip(&full.enter)
        .chain(end.leave.iter().zip(&full.leave))
    {
        assert!(same(*a, *b));
    }
}

#[test]
fn finish_second_is_refused_without_second_dips() {
    let two = with_dips(160, &[(30, 6, 40), (110, 6, 55)]);
    let mut tracker = TemporalTracker::<u8>::new(1, 1, params(4, 16)).unwrap();
    for &v in &two {
        tracker.update(&[v]).unwrap();
    }
    match tracker.finish_second() {
        Err(KernelError::InvalidParameter { name, .. }) => assert_eq!(name, "second_dips"),
        other => panic!("expected the second_dips refusal, got {other:?}"),
    }
    // The rival depth (the second dip's contrast, 200 − 55) is still tracked.
    let t = tracker.finish(0.0).unwrap();
    assert_eq!(t.rival[0], 145.0);
}

#[test]
fn per_pixel_levels_divide_each_pixel_by_its_own_factor() {
    // Pixel 0 dips in frames 20-22 in a light that halves during them; pixel 1 the same but its
    // frames 18-24 are also darkened by its own factor 0.6 (a cloud that dims it more). With
    // per-pixel levels (1 for pixel 0, 0.6 for pixel 1 in those frames) both dips come back to
    // the times of the same dip seen in a steady light.
    let table: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    let dn = |x: f32| ((x.powf(1.0 / 2.2) * 255.0).round()) as u8;
    let mut steady = TemporalTracker::normalised(1, 2, params(4, 16), &table).unwrap();
    let mut cloudy = TemporalTracker::normalised(1, 2, params(4, 16), &table).unwrap();
    for k in 0..48usize {
        let shadow = if (20..=22).contains(&k) { 0.3 } else { 1.0 };
        let lit = 0.5 * shadow;
        steady.update_with_gain(&[dn(lit), dn(lit)], 1.0).unwrap();
        if (18..=24).contains(&k) {
            let frame = [dn(lit), dn(lit * 0.6)];
            cloudy.update_with_levels(&frame, 1.0, &[1.0, 0.6]).unwrap();
        } else {
            cloudy.update_with_gain(&[dn(lit), dn(lit)], 1.0).unwrap();
        }
    }
    let a = steady.finish(1.0).unwrap();
    let b = cloudy.finish(1.0).unwrap();
    for p in 0..2 {
        assert!(a.enter[p].is_finite() && a.leave[p].is_finite());
        // (pixel 1's samples are rounded to DN at 0.6 of the level: a fraction of a frame's noise)
        assert!(
            (a.enter[p] - b.enter[p]).abs() < 0.05,
            "{p}: {} {}",
            a.enter[p],
            b.enter[p]
        );
        assert!(
            (a.leave[p] - b.leave[p]).abs() < 0.05,
            "{p}: {} {}",
            a.leave[p],
            b.leave[p]
        );
    }
    // errors: the levels' length, a level that is not > 0, a plain tracker, a frame of another type
    assert!(matches!(
        cloudy.update_with_levels(&[0u8; 2], 1.0, &[1.0]),
        Err(KernelError::LengthMismatch { what: "levels", .. })
    ));
    assert!(cloudy
        .update_with_levels(&[0u8; 2], 1.0, &[1.0, 0.0])
        .is_err());
    assert!(cloudy
        .update_with_levels(&[0u8; 2], 1.0, &[1.0, f32::NAN])
        .is_err());
    assert!(cloudy
        .update_with_levels(&[0u16; 2], 1.0, &[1.0, 1.0])
        .is_err());
    assert!(cloudy
        .update_with_levels(&[0u8; 2], 0.0, &[1.0, 1.0])
        .is_err());
    let mut plain = TemporalTracker::<u16>::new(1, 2, params(4, 16)).unwrap();
    assert!(plain
        .update_with_levels(&[0u16; 2], 1.0, &[1.0, 1.0])
        .is_err());
}

// ---- Normalised frames against the straightforward encoding -------------

/// A frame's normalised codes computed sample by sample, as
/// [`gnomon_core::intensity`] defines them: `min(⌊L(DN) · (S / gain)⌋, 65535)`,
/// or with per-pixel `levels` `min(⌊L(DN) · (S / gain) / level⌋, 65534)` and
/// the input's largest DN stored as 65535.
fn straight_codes(frame: &[u8], table: &[f32], gain: f64, levels: Option<&[f32]>) -> Vec<u16> {
    let factor = (f64::from(gnomon_core::NORMALISED_SCALE) / gain) as f32;
    frame
        .iter()
        .enumerate()
        .map(|(i, &v)| match levels {
            None => (table[usize::from(v)] * factor).clamp(0.0, 65535.0) as u16,
            Some(_) if v == 255 => u16::MAX,
            Some(l) => (table[usize::from(v)] * factor / l[i]).clamp(0.0, 65534.0) as u16,
        })
        .collect()
}

#[test]
fn normalised_frames_equal_a_tracker_fed_their_codes() {
    // Noisy u8 frames of pixels with one to three dips each (some clipped at 0 or 255), in a light
    // whose gain drifts between 0.7 and 1.3, a few frames with per-pixel levels (a cloud), second
    // dips kept. A normalised tracker (codes from each frame's table, stored in parallel pieces,
    // every SIMD path) must find exactly the dips, times and second candidates of a DN tracker
    // fed the same codes computed sample by sample, whose table is the codes' decoding c / S.
    let table: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    let decode: Vec<f32> = (0..65536)
        .map(|c| (f64::from(c) / f64::from(gnomon_core::NORMALISED_SCALE)) as f32)
        .collect();
    let mut rng = XorShift(0x5eed_1234_abcd_9876);
    let (height, width, len) = (5, 53, 150);
    let pixels = height * width;
    let dips: Vec<Vec<(usize, usize, f32)>> = (0..pixels)
        .map(|_| {
            (0..1 + rng.below(3))
                .map(|_| {
                    let enter = rng.below(len as u64) as usize;
                    let depth = 0.05 + (rng.below(90) as f32) / 100.0;
                    (enter, enter + 1 + rng.below(20) as usize, depth)
                })
                .collect()
        })
        .collect();
    let gains: Vec<f64> = (0..len)
        .map(|f| 1.0 + 0.3 * (f as f64 / 11.0).sin())
        .collect();
    let cloudy = |f: usize| (60..66).contains(&f) || f == 120;
    let frames: Vec<(Vec<u8>, Option<Vec<f32>>)> = (0..len)
        .map(|f| {
            let frame = (0..pixels)
                .map(|p| {
                    let lit = 0.2 + 0.7 * (p % 7) as f32 / 6.0;
                    let shade = dips[p]
                        .iter()
                        .filter(|&&(e, l, _)| e <= f && f < l)
                        .fold(1.0f32, |s, &(_, _, d)| s.min(1.0 - d));
                    let x = lit * shade * gains[f] as f32;
                    let noise = rng.below(7) as f32 - 3.0;
                    (x.powf(1.0 / 2.2) * 255.0 + noise).clamp(0.0, 255.0) as u8
                })
                .collect();
            let levels = cloudy(f).then(|| {
                (0..pixels)
                    .map(|_| 0.6 + rng.below(60) as f32 / 100.0)
                    .collect()
            });
            (frame, levels)
        })
        .collect();
    for max_width in [8, 16, 32] {
        let params = TrackerParams {
            window: 4,
            max_width,
            ambiguity: 0.6,
            second_dips: true,
        };
        let mut straight =
            TemporalTracker::<u16>::with_table(height, width, params, &decode).unwrap();
        for (f, (frame, levels)) in frames.iter().enumerate() {
            let codes = straight_codes(frame, &table, gains[f], levels.as_deref());
            straight.update(&codes).unwrap();
        }
        let want = straight.finish(0.0).unwrap();
        let want2 = straight.finish_second().unwrap();
        let eq = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(&p, &q)| same(p, q));
        // (valid and ambiguous pixels, second candidates with times: every case is exercised)
        assert!(want.valid.iter().filter(|&&v| v == 1).count() > pixels / 4);
        assert!(want.ambiguous.iter().filter(|&&v| v == 1).count() > pixels / 4);
        assert!(want2.enter.iter().filter(|v| v.is_finite()).count() > pixels / 10);
        for path in SimdPath::supported() {
            let mut t = TemporalTracker::<u16>::normalised(height, width, params, &table).unwrap();
            t.set_simd_path(path).unwrap();
            for (f, (frame, levels)) in frames.iter().enumerate() {
                match levels {
                    Some(l) => t.update_with_levels(frame, gains[f], l).unwrap(),
                    None => t.update_with_gain(frame, gains[f]).unwrap(),
                }
            }
            let got = t.finish(0.0).unwrap();
            let got2 = t.finish_second().unwrap();
            let at = format!("{}, max_width {max_width}", path.name());
            assert!(eq(&got.enter, &want.enter), "{at}: enter");
            assert!(eq(&got.leave, &want.leave), "{at}: leave");
            assert_eq!(got.valid, want.valid, "{at}: valid");
            assert_eq!(got.ambiguous, want.ambiguous, "{at}: ambiguous");
            assert!(eq(&got2.enter, &want2.enter), "{at}: second enter");
            assert!(eq(&got2.leave, &want2.leave), "{at}: second leave");
            assert!(eq(&got2.best_enter, &want2.best_enter), "{at}: best enter");
            assert!(eq(&got2.best_leave, &want2.best_leave), "{at}: best leave");
        }
    }
}
