//! Tracker throughput on synthetic u8 frames (1080p by default):
//! `cargo run -p gnomon-core --release --example throughput [frames] [max_width] [window] [height] [width]`.
//!
//! Prints wall-clock frames/s and the process CPU time per frame (all
//! threads), which is less sensitive to other load on the machine.

use std::time::Instant;

use gnomon_core::{TemporalTracker, TrackerParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut next = |default: usize| -> Result<usize, std::num::ParseIntError> {
        args.next().map_or(Ok(default), |s| s.parse())
    };
    let (frames, max_width, window) = (next(1000)?, next(32)?, next(4)?);
    let (h, w) = (next(1080)?, next(1920)?);
    // 32 distinct frames: a soft shadow edge sweeping left to right, plus a
    // cheap deterministic noise.
    let distinct: Vec<Vec<u8>> = (0..32)
        .map(|f| {
            let edge = (f as f32 + 0.5) * w as f32 / 32.0;
            let mut seed = 0x9e37_79b9u32.wrapping_mul(f as u32 + 1);
            (0..h * w)
                .map(|i| {
                    let x = (i % w) as f32;
                    let s = 1.0 / (1.0 + (-(x - edge) / 6.0).exp());
                    seed ^= seed << 13;
                    seed ^= seed >> 17;
                    seed ^= seed << 5;
                    let noise = (seed >> 29) as f32 - 3.5;
                    (40.0 + 160.0 * (1.0 - s) + noise).clamp(0.0, 255.0) as u8
                })
                .collect()
        })
        .collect();
    let mut tracker = TemporalTracker::<u8>::new(
        h,
        w,
        TrackerParams {
            window,
            max_width,
            ..TrackerParams::default()
        },
    )?;
    let cpu0 = cpu_seconds();
    let start = Instant::now();
    for i in 0..frames {
        tracker.update(&distinct[i % distinct.len()])?;
    }
    let elapsed = start.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    let t = Instant::now();
    let times = tracker.finish(20.0)?;
    let finish = t.elapsed().as_secs_f64();
    let valid = times.valid.iter().filter(|&&v| v == 1).count();
    println!(
        "{frames} frames in {elapsed:.3} s: {:.0} frames/s, {:.3} CPU ms/frame; finish {:.1} ms; {valid} valid",
        frames as f64 / elapsed,
        cpu * 1e3 / frames as f64,
        finish * 1e3
    );
    Ok(())
}

/// User + system CPU time of the whole process (all threads), seconds
/// (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after_name = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}
