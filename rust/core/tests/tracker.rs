//! TemporalTracker on hand-built profiles with known answers, and against a
//! direct (non-streaming) reference on random sequences.

use gnomon_core::{
    find_crossing, Edge, KernelError, Sample, ShadowTimes, SimdPath, TemporalTracker, TrackerParams,
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
        let mut tracker = TemporalTracker::<T>::new(height, width, params).unwrap();
        tracker.set_simd_path(path).unwrap();
        for f in 0..profiles[0].len() {
            let frame: Vec<T> = profiles.iter().map(|p| p[f]).collect();
            tracker.update(&frame).unwrap();
        }
        (path, tracker.finish(min_contrast, lut).unwrap())
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

fn params(window: usize, block: usize) -> TrackerParams {
    TrackerParams { window, block }
}

fn to_u8(p: &[u16]) -> Vec<u8> {
    p.iter().map(|&v| v as u8).collect()
}

#[test]
fn ramp_has_the_known_crossings() {
    let p = to_u8(&ramp_profile());
    for block in [1, 7, 16] {
        let t = track(std::slice::from_ref(&p), 1, 1, params(4, block), 70.0, None);
        assert_eq!((t.imax[0], t.imin[0], t.contrast[0]), (200.0, 40.0, 160.0));
        assert_eq!(t.threshold[0], 120.0);
        assert_eq!(t.valid[0], 1);
        assert_eq!(t.enter[0], 11.5, "block {block}");
        assert_eq!(t.leave[0], 25.25, "block {block}");
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
    // Falls at j = 1 (window frames -3..4 clamped to 0), rises at the last frame.
    let mut p: Vec<u8> = vec![200, 60];
    p.extend([40; 6]);
    p.push(200);
    let n = p.len() as f32;
    for block in [1, 2, 16] {
        let t = track(std::slice::from_ref(&p), 1, 1, params(4, block), 10.0, None);
        assert_eq!(t.enter[0], 80.0f32 / 140.0, "block {block}");
        assert_eq!(t.leave[0], n - 2.0 + 0.5, "block {block}");
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
    let t = track(&[vec![90u8; 40]], 1, 1, params(4, 16), 0.0, None);
    assert_eq!(t.valid, vec![1]);
    assert!(t.enter[0].is_nan() && t.leave[0].is_nan());
}

#[test]
fn errors_name_the_problem() {
    assert!(TemporalTracker::<u8>::new(0, 4, params(4, 16)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(0, 16)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(4, 0)).is_err());
    assert!(TemporalTracker::<u8>::new(4, 4, params(4, 1000)).is_err());
    let mut t = TemporalTracker::<u8>::new(2, 3, params(4, 16)).unwrap();
    assert_eq!(t.finish(0.0, None), Err(KernelError::NoFrames));
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
    assert!(t.finish(f32::NAN, None).is_err());
    assert!(matches!(
        t.finish(0.0, Some(&[0.0; 255])),
        Err(KernelError::InvalidLut { .. })
    ));
    let mut decreasing: Vec<f32> = (0..256).map(|v| v as f32).collect();
    decreasing[100] = 0.0;
    assert!(matches!(
        t.finish(0.0, Some(&decreasing)),
        Err(KernelError::InvalidLut { .. })
    ));
    let mut nan: Vec<f32> = (0..256).map(|v| v as f32).collect();
    nan[3] = f32::NAN;
    assert!(matches!(
        t.finish(0.0, Some(&nan)),
        Err(KernelError::InvalidLut { .. })
    ));
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

/// A profile with a shadow passing at a random time, noise, and coarse
/// quantisation so that ties between steps are common.
fn random_profile(rng: &mut XorShift, len: usize, hi: u64) -> Vec<u16> {
    let enter = rng.below(len as u64) as usize;
    let leave = enter + rng.below(len as u64 / 2 + 1) as usize;
    (0..len)
        .map(|f| {
            let lit = f < enter || f >= leave;
            let base = if lit { hi * 3 / 4 } else { hi / 5 };
            let noise = rng.below(hi / 8 + 1);
            (((base + noise) / 4) * 4).min(hi) as u16
        })
        .collect()
}

/// The algorithm on a whole stored profile, for one pixel.
fn reference(profile: &[u16], half: usize, lut: &[f32]) -> (f32, f32, f32, f32) {
    let n = profile.len();
    let (hi, lo) = (
        *profile.iter().max().unwrap(),
        *profile.iter().min().unwrap(),
    );
    let thr = (lut[hi as usize] + lut[lo as usize]) * 0.5;
    let steepest = |sign: i32| -> Option<usize> {
        let mut best = (0i32, None);
        for j in 1..n {
            let step = sign * (profile[j - 1] as i32 - profile[j] as i32);
            if step > best.0 {
                best = (step, Some(j));
            }
        }
        best.1
    };
    let solve = |j: Option<usize>, edge: Edge| -> (f32, f32) {
        let Some(j) = j else {
            return (f32::NAN, f32::NAN);
        };
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
    let (enter, enter_slope) = solve(steepest(1), Edge::Enter);
    let (leave, leave_slope) = solve(steepest(-1), Edge::Leave);
    (enter, leave, enter_slope, leave_slope)
}

fn same(a: f32, b: f32) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

fn check_against_reference<T: Sample>(
    profiles16: &[Vec<u16>],
    convert: impl Fn(u16) -> T,
    half: usize,
    block: usize,
    lut: &[f32],
    lut_arg: Option<&[f32]>,
) {
    let (height, width) = (3, profiles16.len() / 3);
    let profiles: Vec<Vec<T>> = profiles16
        .iter()
        .map(|p| p.iter().map(|&v| convert(v)).collect())
        .collect();
    let t = track(&profiles, height, width, params(half, block), 0.0, lut_arg);
    for (i, p) in profiles16.iter().enumerate() {
        let (enter, leave, es, ls) = reference(p, half, lut);
        let got = (t.enter[i], t.leave[i], t.enter_slope[i], t.leave_slope[i]);
        assert!(
            same(got.0, enter) && same(got.1, leave) && same(got.2, es) && same(got.3, ls),
            "pixel {i}, window {half}, block {block}: got {got:?}, expected {:?}\n{p:?}",
            (enter, leave, es, ls)
        );
    }
}

#[test]
fn random_sequences_match_the_reference_for_any_block() {
    let mut rng = XorShift(0x2545_f491_4f6c_dd1d);
    let identity8: Vec<f32> = (0..256).map(|v| v as f32).collect();
    let gamma8: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    for len in [1, 2, 3, 5, 17, 40, 75] {
        let profiles: Vec<Vec<u16>> = (0..3 * 70)
            .map(|_| random_profile(&mut rng, len, 255))
            .collect();
        for half in [1, 2, 4, 7] {
            for block in [1, 2, 7, 16, 33] {
                check_against_reference(&profiles, |v| v as u8, half, block, &identity8, None);
            }
        }
        check_against_reference(&profiles, |v| v as u8, 4, 16, &gamma8, Some(&gamma8));
    }
}

#[test]
fn random_u16_sequences_match_the_reference() {
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let identity16: Vec<f32> = (0..65536).map(|v| v as f32).collect();
    for len in [4, 31, 64] {
        let profiles: Vec<Vec<u16>> = (0..3 * 80)
            .map(|_| random_profile(&mut rng, len, 4095))
            .collect();
        for block in [1, 7, 16] {
            check_against_reference(&profiles, |v| v, 4, block, &identity16, None);
        }
    }
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
            let preview = streaming.finish(10.0, None).unwrap();
            let mut fresh = TemporalTracker::<u8>::new(3, 40, params(4, 16)).unwrap();
            for g in 0..=f {
                fresh.update(&frame(g)).unwrap();
            }
            let expect = fresh.finish(10.0, None).unwrap();
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
    let full = track(&prefix, 3, 40, params(4, 1), 10.0, None);
    let end = streaming.finish(10.0, None).unwrap();
    for (a, b) in end
        .enter
        .iter()
        .zip(&full.enter)
        .chain(end.leave.iter().zip(&full.leave))
    {
        assert!(same(*a, *b));
    }
}
