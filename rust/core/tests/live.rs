//! The live watch: pixels are reported once their dip has ended, with the
//! block tracker's times for a clean dip, and never before.

use gnomon_core::{FinishedPixel, KernelError, TemporalTracker, TrackerParams, WatchParams};

/// Frames 0-9: 200; 10-13: 180 140 100 60; 14-23: 40; 24-27: 70 110 150 190;
/// 28-37: 200 (as in tests/tracker.rs). Mid-level 120: enter t = 11.5,
/// leave t = 25.25; frames 26, 27, 28 are the first three at or above 120.
fn ramp(shift: usize) -> Vec<u8> {
    let mut p = vec![200u8; 10 + shift];
    p.extend([180, 140, 100, 60]);
    p.extend([40; 10]);
    p.extend([70, 110, 150, 190]);
    p.extend(vec![200u8; 10usize.saturating_sub(shift).max(2) + 20]);
    p
}

fn params() -> TrackerParams {
    TrackerParams {
        window: 4,
        max_width: 32,
        ambiguity: 0.6,
        second_dips: false,
    }
}

fn watch(recover: usize) -> WatchParams {
    WatchParams {
        min_contrast: 20.0,
        recover,
    }
}

/// Feed `profiles` (one per pixel, equal lengths) frame by frame; the pixels
/// finished after each frame.
fn run(
    profiles: &[Vec<u8>],
    width: usize,
    recover: usize,
) -> (TemporalTracker<u8>, Vec<Vec<FinishedPixel>>) {
    let height = profiles.len() / width;
    let mut tracker = TemporalTracker::<u8>::new(height, width, params()).unwrap();
    tracker.watch(watch(recover)).unwrap();
    let mut per_frame = Vec::new();
    for f in 0..profiles[0].len() {
        let frame: Vec<u8> = profiles.iter().map(|p| p[f]).collect();
        tracker.update(&frame).unwrap();
        per_frame.push(tracker.take_finished().unwrap());
    }
    (tracker, per_frame)
}

#[test]
fn a_ramp_dip_finishes_after_the_recovery_with_the_tracker_s_times() {
    let (tracker, per_frame) = run(&[ramp(0)], 1, 3);
    for (f, done) in per_frame.iter().enumerate() {
        assert_eq!(done.len(), usize::from(f == 28), "frame {f}: {done:?}");
    }
    let p = per_frame[28][0];
    assert_eq!((p.index, p.frame), (0, 28));
    assert_eq!((p.imax, p.imin), (200.0, 40.0));
    assert_eq!(p.threshold, 120.0);
    assert!((p.enter - 11.5).abs() < 1e-6, "{}", p.enter);
    assert!((p.leave - 25.25).abs() < 1e-6, "{}", p.leave);
    assert!((p.enter_slope - 40.0).abs() < 1e-6 && (p.leave_slope - 40.0).abs() < 1e-6);
    // The block tracker's final word on the same frames agrees.
    let fin = tracker.finish(20.0).unwrap();
    assert_eq!((fin.enter[0], fin.leave[0]), (p.enter, p.leave));
    assert_eq!(tracker.watch_counts(), Some((0, 0, 1)));
}

#[test]
fn recovery_frames_set_the_delay() {
    for recover in [1, 2, 5] {
        let (_, per_frame) = run(&[ramp(0)], 1, recover);
        let at: Vec<usize> = (0..per_frame.len())
            .filter(|&f| !per_frame[f].is_empty())
            .collect();
        assert_eq!(at, vec![26 + recover - 1], "recover {recover}");
    }
}

#[test]
fn pixels_finish_in_the_frame_their_own_dip_ends() {
    // Four pixels (2 × 2), dips shifted by 0, 3, 6, 9 frames; a flat pixel never finishes.
    let mut profiles: Vec<Vec<u8>> = [0, 3, 6].iter().map(|&s| ramp(s)).collect();
    let len = profiles[0]
        .len()
        .min(profiles[1].len())
        .min(profiles[2].len());
    profiles.iter_mut().for_each(|p| p.truncate(len));
    profiles.push(vec![200; len]);
    let (tracker, per_frame) = run(&profiles, 2, 3);
    let fin = tracker.finish(20.0).unwrap();
    for (i, shift) in [0usize, 3, 6].iter().enumerate() {
        let when: Vec<usize> = (0..len)
            .filter(|&f| per_frame[f].iter().any(|p| p.index as usize == i))
            .collect();
        assert_eq!(when, vec![28 + shift], "pixel {i}");
        let p = per_frame[28 + shift]
            .iter()
            .find(|p| p.index as usize == i)
            .unwrap();
        assert!((p.enter - (11.5 + *shift as f32)).abs() < 1e-5);
        assert!((p.leave - (25.25 + *shift as f32)).abs() < 1e-5);
        assert_eq!((fin.enter[i], fin.leave[i]), (p.enter, p.leave));
    }
    assert!(per_frame.iter().flatten().all(|p| p.index != 3));
    assert_eq!(tracker.watch_counts(), Some((1, 0, 3)));
}

#[test]
fn a_shallow_dip_or_a_dip_that_does_not_recover_is_not_finished() {
    let shallow: Vec<u8> = ramp(0).iter().map(|&v| 200 - (200 - v) / 10).collect(); // 16 DN deep
    let mut dusk = vec![200u8; 10];
    dusk.extend(vec![40u8; 40]); // falls and never comes back
    dusk.truncate(shallow.len());
    dusk.resize(shallow.len(), 40);
    let (tracker, per_frame) = run(&[shallow, dusk], 2, 3);
    assert!(per_frame.iter().all(Vec::is_empty));
    assert_eq!(tracker.watch_counts(), Some((1, 1, 0)));
}

#[test]
fn noise_above_the_mid_level_must_last_to_end_the_dip() {
    // One sample back above the mid-level inside the dip, then dark again: not the end.
    let mut p = ramp(0);
    p[18] = 150;
    let (_, per_frame) = run(&[p], 1, 2);
    let at: Vec<usize> = (0..per_frame.len())
        .filter(|&f| !per_frame[f].is_empty())
        .collect();
    assert_eq!(at, vec![27]);
}

#[test]
fn a_dip_wider_than_the_ring_has_no_enter_time() {
    // W = 4, m = 2: the ring holds 3·4 + 2·2 = 16 frames; the dip lasts 30.
    let small = TrackerParams {
        window: 2,
        max_width: 4,
        ambiguity: 0.6,
        second_dips: false,
    };
    let mut p = vec![200u8; 5];
    p.extend(vec![40u8; 30]);
    p.extend(vec![200u8; 5]);
    let mut tracker = TemporalTracker::<u8>::new(1, 1, small).unwrap();
    tracker.watch(watch(2)).unwrap();
    let mut done = Vec::new();
    for &v in &p {
        tracker.update(&[v]).unwrap();
        done.extend(tracker.take_finished().unwrap());
    }
    assert_eq!(done.len(), 1);
    assert!(done[0].enter.is_nan());
    assert!((done[0].leave - 34.5).abs() < 1e-6, "{}", done[0].leave);
}

#[test]
fn the_watch_checks_its_settings() {
    let mut t = TemporalTracker::<u8>::new(2, 2, params()).unwrap();
    assert!(matches!(
        t.take_finished(),
        Err(KernelError::InvalidParameter { name: "watch", .. })
    ));
    assert_eq!(t.watch_counts(), None);
    for (min_contrast, recover, name) in [
        (0.0, 3, "min_contrast"),
        (f32::NAN, 3, "min_contrast"),
        (10.0, 0, "recover"),
        (10.0, 256, "recover"),
    ] {
        let err = t
            .watch(WatchParams {
                min_contrast,
                recover,
            })
            .unwrap_err();
        assert!(
            matches!(err, KernelError::InvalidParameter { name: n, .. } if n == name),
            "{err}"
        );
    }
}

#[test]
fn the_lut_sets_the_linear_threshold() {
    // Square law: L(200) = 40000, L(40) = 1600, threshold 20800 ≈ DN 144.2.
    let lut: Vec<f32> = (0..256).map(|v| (v * v) as f32).collect();
    let mut t = TemporalTracker::<u8>::with_table(1, 1, params(), &lut).unwrap();
    t.watch(watch(3)).unwrap();
    let mut done = Vec::new();
    for &v in &ramp(0) {
        t.update(&[v]).unwrap();
        done.extend(t.take_finished().unwrap());
    }
    let fin = t.finish(20.0).unwrap();
    assert_eq!(done.len(), 1);
    assert_eq!(done[0].threshold, 20800.0);
    assert_eq!((fin.enter[0], fin.leave[0]), (done[0].enter, done[0].leave));
}

#[test]
fn every_instruction_set_finishes_the_same_pixels_at_the_same_frames() {
    // 3 rows × 75 pixels (vectors and a tail): ramps shifted by the pixel, some noise.
    let (height, width) = (3, 75);
    let mut state = 12345u64;
    let mut noise = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % 7) as i32 - 3
    };
    let len = 140;
    let profiles: Vec<Vec<u8>> = (0..height * width)
        .map(|i| {
            let mut p = ramp(i % 97);
            p.resize(len, 200);
            p.iter()
                .map(|&v| (i32::from(v) + noise()).clamp(0, 255) as u8)
                .collect()
        })
        .collect();
    let runs: Vec<Vec<FinishedPixel>> = gnomon_core::SimdPath::supported()
        .into_iter()
        .map(|path| {
            let mut t = TemporalTracker::<u8>::new(height, width, params()).unwrap();
            t.set_simd_path(path).unwrap();
            t.watch(watch(3)).unwrap();
            let mut all = Vec::new();
            for f in 0..len {
                let frame: Vec<u8> = profiles.iter().map(|p| p[f]).collect();
                t.update(&frame).unwrap();
                all.extend(t.take_finished().unwrap());
            }
            all
        })
        .collect();
    assert!(runs[0].len() > height * width / 2, "{}", runs[0].len());
    for other in &runs[1..] {
        assert_eq!(other.len(), runs[0].len());
        for (a, b) in runs[0].iter().zip(other) {
            assert_eq!(
                (a.index, a.frame, a.imax, a.imin),
                (b.index, b.frame, b.imax, b.imin)
            );
            assert!(
                a.enter.to_bits() == b.enter.to_bits() && a.leave.to_bits() == b.leave.to_bits()
            );
        }
    }
}
