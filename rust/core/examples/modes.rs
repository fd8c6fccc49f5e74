//! Tracker cost per frame in each of the scan's configurations:
//! `cargo run -p gnomon-core --release --example modes [MODES] [FRAMES_FILE HEIGHT WIDTH]`.
//!
//! MODES: comma-separated among `plain`, `plain+second`, `norm`,
//! `norm+second`, `levels+second` (default: all). Without a file, 166
//! synthetic 1024×768 u8 frames (a soft shadow edge sweeping across, noise,
//! a light drifting by a few percent); with one, raw row-major u8 frames
//! (`FRAMES_FILE.gains`, f64 per frame, gives their gains when present).
//! Prints the wall time and the process CPU time per frame (all threads).

use std::time::Instant;

use gnomon_core::{TemporalTracker, TrackerParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let modes = args
        .first()
        .map_or("plain,plain+second,norm,norm+second,levels+second", |s| s);
    let (frames, gains, h, w) = match args.get(1) {
        Some(path) => {
            let h: usize = args.get(2).ok_or("height")?.parse()?;
            let w: usize = args.get(3).ok_or("width")?.parse()?;
            let data = std::fs::read(path)?;
            let frames: Vec<Vec<u8>> = data.chunks_exact(h * w).map(<[u8]>::to_vec).collect();
            let gains = match std::fs::read(format!("{path}.gains")) {
                Ok(g) => g
                    .chunks_exact(8)
                    .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                    .collect(),
                Err(_) => vec![1.0; frames.len()],
            };
            (frames, gains, h, w)
        }
        None => synthetic(166, 768, 1024),
    };
    // sRGB-like decoding table (gamma 2.2)
    let lut: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
    let levels: Vec<f32> = (0..h * w)
        .map(|i| 1.0 + 0.02 * (((i * 2654435761) % 1000) as f32 / 500.0 - 1.0))
        .collect();
    for mode in modes.split(',') {
        let second = mode.ends_with("+second");
        let params = TrackerParams {
            second_dips: second,
            ..TrackerParams::default()
        };
        // (best of `GNOMON_REPEAT` runs, default 3: the machine may be shared)
        let repeat: usize = std::env::var("GNOMON_REPEAT")
            .ok()
            .and_then(|r| r.parse().ok())
            .unwrap_or(3);
        let mut best = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for _ in 0..repeat {
            let (cpu0, user0) = (cpu_seconds(), user_seconds());
            let start = Instant::now();
            match mode {
                "plain" | "plain+second" => {
                    let mut t = TemporalTracker::<u8>::with_table(h, w, params, &lut)?;
                    for f in &frames {
                        t.update(f)?;
                    }
                }
                "norm" | "norm+second" | "levels+second" => {
                    let mut t = TemporalTracker::<u16>::normalised(h, w, params, &lut)?;
                    for (f, &g) in frames.iter().zip(&gains) {
                        if mode == "levels+second" {
                            t.update_with_levels(f, g, &levels)?;
                        } else {
                            t.update_with_gain(f, g)?;
                        }
                    }
                }
                other => return Err(format!("unknown mode {other}").into()),
            }
            let n = frames.len() as f64;
            let run = (
                start.elapsed().as_secs_f64() * 1e3 / n,
                (cpu_seconds() - cpu0) * 1e3 / n,
                (user_seconds() - user0) * 1e3 / n,
            );
            if run.1 < best.1 {
                best = run;
            }
        }
        println!(
            "{mode:14} {:.3} ms/frame wall, {:.3} ms/frame CPU ({:.3} user)",
            best.0, best.1, best.2
        );
    }
    Ok(())
}

type Frames = (Vec<Vec<u8>>, Vec<f64>, usize, usize);

/// `n` frames: a soft edge sweeping left to right over the sequence, noise, a drifting light.
fn synthetic(n: usize, h: usize, w: usize) -> Frames {
    let mut seed = 0x9e37_79b9u32;
    let frames = (0..n)
        .map(|f| {
            let edge = (f as f32 + 0.5) * w as f32 / n as f32;
            let light = 1.0 + 0.03 * (f as f32 / 9.0).sin();
            (0..h * w)
                .map(|i| {
                    let x = (i % w) as f32;
                    let s = 1.0 / (1.0 + (-(x - edge) / 6.0).exp());
                    let shadow = if (x - edge).abs() < 12.0 { 0.3 } else { 1.0 };
                    seed ^= seed << 13;
                    seed ^= seed >> 17;
                    seed ^= seed << 5;
                    let noise = (seed >> 29) as f32 - 3.5;
                    ((60.0 + 120.0 * (1.0 - s * 0.2)) * shadow * light + noise).clamp(0.0, 255.0)
                        as u8
                })
                .collect()
        })
        .collect();
    let gains = (0..n)
        .map(|f| 1.0 + 0.03 * (f as f64 / 9.0).sin())
        .collect();
    (frames, gains, h, w)
}

/// User + system CPU time of the whole process (all threads), seconds
/// (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    stat_ticks(11) + stat_ticks(12)
}

/// User CPU time of the whole process, seconds.
fn user_seconds() -> f64 {
    stat_ticks(11)
}

/// Field `i` after the name of `/proc/self/stat` (clock ticks), in seconds.
fn stat_ticks(i: usize) -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after_name = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<&str> = after_name.split_whitespace().collect();
    fields
        .get(i)
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or(0.0)
        / 100.0
}
