//! Per-pixel work on a scan's surface after fusion, as the numpy definitions
//! in `gnomon.geometry.meshing` and `gnomon.runs.scan` state them (the tests compare
//! both): the world-frame points of a depth map ([`world_points`]), the grid's
//! unit normals ([`grid_normals`]) and the binary STL records of a mesh
//! ([`stl_records`]).
//!
//! Invariants: maps are row-major `H·W` (points `H·W·3`); a pixel is on the
//! surface where `valid` is non-zero; rows are processed in parallel (rayon),
//! each output element depending only on its own inputs and its 4-neighbours.

use rayon::prelude::*;

use crate::error::KernelError;

/// Rows of pixels (or faces) per parallel work item.
const ROWS_PER_TASK: usize = 4;
const FACES_PER_TASK: usize = 16384;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn finite(a: V3) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// [`fuse_supported`]'s depth and σ maps (f32) and per-pixel codes.
pub type FusedMaps = (Vec<f32>, Vec<f32>, Vec<u8>);

/// Inverse-variance fusion of K depth estimates per pixel, then the pixels no
/// neighbour supports dropped (`gnomon.reconstruct.fusion.fuse_depths` with Gaussian weights,
/// then `gnomon.geometry.triangulation.supported_by_neighbours`).
///
/// * `depths`, `sigmas`: `K·H·W` (f32), estimate k of pixel p at `k·H·W + p`;
///   an estimate counts where both are finite and σ > 0;
/// * fused `Z = Σ wₖZₖ`, `σ = √Σ (wₖσₖ)²` with `wₖ = σₖ⁻² / Σ σ⁻²` (f64); two
///   or more estimates spreading more than `max(6·√Σσₖ², jump·|Z|)` are a
///   conflict (no depth);
/// * a fused depth is kept when at least `min_support` of its 8 neighbours are
///   within `jump·|Z|` of it (f32, as the depth map is).
///
/// Returns (depth, σ) f32 with NaN where not kept, and per pixel a code:
/// 0 none, 1 kept, 2 conflict, 3 fused but unsupported. Rows in parallel.
pub fn fuse_supported(
    depths: &[f32],
    sigmas: &[f32],
    estimates: usize,
    width: usize,
    jump: f64,
    min_support: usize,
) -> Result<FusedMaps, KernelError> {
    if estimates == 0 || depths.len() % estimates != 0 {
        return Err(KernelError::parameter(
            "estimates",
            format!("{estimates} does not divide the {} depths", depths.len()),
        ));
    }
    let n = depths.len() / estimates;
    KernelError::check_image(
        n,
        width,
        &[("sigmas (one per depth)", depths.len(), sigmas.len())],
    )?;
    const CONFLICT_SIGMAS: f64 = 6.0;
    let mut fused = vec![f32::NAN; n];
    let mut sigma = vec![f32::NAN; n];
    let mut code = vec![0u8; n];
    fused
        .par_chunks_mut(width)
        .zip(sigma.par_chunks_mut(width))
        .zip(code.par_chunks_mut(width))
        .enumerate()
        .for_each(|(row, ((fused, sigma), code))| {
            for u in 0..width {
                let p = row * width + u;
                let (mut total, mut count) = (0.0f64, 0usize);
                let (mut hi, mut lo) = (f64::NEG_INFINITY, f64::INFINITY);
                let mut var = 0.0f64;
                for k in 0..estimates {
                    let (z, s) = (f64::from(depths[k * n + p]), f64::from(sigmas[k * n + p]));
                    if z.is_finite() && s.is_finite() && s > 0.0 {
                        total += 1.0 / (s * s);
                        count += 1;
                        hi = hi.max(z);
                        lo = lo.min(z);
                        var += s * s;
                    }
                }
                if count == 0 {
                    continue;
                }
                let (mut z_sum, mut s_sum) = (0.0f64, 0.0f64);
                for k in 0..estimates {
                    let (z, s) = (f64::from(depths[k * n + p]), f64::from(sigmas[k * n + p]));
                    if z.is_finite() && s.is_finite() && s > 0.0 {
                        let w = (1.0 / (s * s)) / total;
                        z_sum += w * z;
                        s_sum += (w * s) * (w * s);
                    }
                }
                if count >= 2 && hi - lo > (CONFLICT_SIGMAS * var.sqrt()).max(jump * z_sum.abs()) {
                    code[u] = 2;
                    continue;
                }
                fused[u] = z_sum as f32;
                sigma[u] = s_sum.sqrt() as f32;
            }
        });
    // Neighbour support on the fused map (f32 comparisons, as numpy on the float32 map).
    let height = n / width;
    let jump32 = jump as f32;
    let support: Vec<u8> = (0..height)
        .into_par_iter()
        .flat_map_iter(|v| {
            let fused = &fused;
            (0..width).map(move |u| {
                let z = fused[v * width + u];
                let mut count = 0usize;
                for (dv, du) in [
                    (-1, -1),
                    (-1, 0),
                    (-1, 1),
                    (0, -1),
                    (0, 1),
                    (1, -1),
                    (1, 0),
                    (1, 1),
                ] {
                    let (vv, uu) = (v as i64 + dv, u as i64 + du);
                    if vv < 0 || uu < 0 || vv >= height as i64 || uu >= width as i64 {
                        continue;
                    }
                    let o = fused[vv as usize * width + uu as usize];
                    if (z - o).abs() <= jump32 * z.abs() {
                        count += 1;
                    }
                }
                u8::from(z.is_finite() && count >= min_support)
            })
        })
        .collect();
    for p in 0..n {
        if fused[p].is_finite() {
            if support[p] != 0 {
                code[p] = 1;
            } else {
                code[p] = 3;
                fused[p] = f32::NAN;
                sigma[p] = f32::NAN;
            }
        }
    }
    Ok((fused, sigma, code))
}

/// Per pixel and channel, the median of the samples a pixel is lit in (`gnomon.capture.texture.LitColour.finish`).
///
/// * `stack`: `K·P·3` colour samples (K frames of P pixels, RGB), u8;
/// * `lit`: `K·P`, non-zero = the pixel is lit in that frame (a pixel lit in
///   none takes all K).
///
/// The median of n lit samples is `(s[(n−1)/2] + s[n/2] + 1) / 2` of the sorted
/// samples (integer, rounding half up). Chunks of pixels in parallel.
pub fn lit_median(stack: &[u8], lit: &[u8], frames: usize) -> Result<Vec<u8>, KernelError> {
    lit_median_channels(stack, lit, frames, 3)
}

/// [`lit_median`] of samples with `channels` values each (`stack`: `K·P·channels`; 1 for
/// grey frames, whose median is then taken once per pixel instead of once per repeated
/// channel), the output `P·channels`.
pub fn lit_median_channels(
    stack: &[u8],
    lit: &[u8],
    frames: usize,
    channels: usize,
) -> Result<Vec<u8>, KernelError> {
    if frames == 0 || lit.len() % frames != 0 {
        return Err(KernelError::parameter(
            "frames",
            format!("{frames} does not divide the {} lit flags", lit.len()),
        ));
    }
    if channels == 0 {
        return Err(KernelError::parameter("channels", "at least one"));
    }
    let pixels = lit.len() / frames;
    if stack.len() != channels * lit.len() {
        return Err(KernelError::LengthMismatch {
            what: "stack (one sample per channel and lit flag)",
            expected: channels * lit.len(),
            got: stack.len(),
        });
    }
    Ok(lit_medians(stack, frames, pixels, channels, |p, flags| {
        for (k, f) in flags.iter_mut().enumerate() {
            *f = lit[k * pixels + p] != 0;
        }
    }))
}

/// Each pixel's and channel's median of its lit samples (`stack`: `K·P·channels`), the lit
/// frames of pixel `p` written by `lit_at(p, flags)` (K flags): the rule of [`lit_median`].
fn lit_medians<F>(stack: &[u8], frames: usize, pixels: usize, channels: usize, lit_at: F) -> Vec<u8>
where
    F: Fn(usize, &mut [bool]) + Sync,
{
    let mut out = vec![0u8; channels * pixels];
    const PIXELS_PER_CHUNK: usize = 8192;
    out.par_chunks_mut(channels * PIXELS_PER_CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            let mut values = vec![0u8; frames];
            let mut lit = vec![false; frames];
            for (i, o) in out.chunks_exact_mut(channels).enumerate() {
                let p = chunk * PIXELS_PER_CHUNK + i;
                lit_at(p, &mut lit);
                let any = lit.iter().any(|&l| l);
                for (c, o) in o.iter_mut().enumerate() {
                    let mut n = 0;
                    for (k, &l) in lit.iter().enumerate() {
                        if !any || l {
                            values[n] = stack[channels * (k * pixels + p) + c];
                            n += 1;
                        }
                    }
                    let v = &mut values[..n];
                    v.sort_unstable();
                    let (a, b) = (u16::from(v[(n - 1) / 2]), u16::from(v[n / 2]));
                    *o = (a + b).div_ceil(2) as u8;
                }
            }
        });
    out
}

/// World-frame points `H·W·3` (f32) of a camera depth map, NaN off the surface.
///
/// * `rays`: `H·W·3` camera-frame ray directions of the pixels (any length, `r_z ≠ 0`);
/// * `depth`: `H·W` camera Z (world units); `valid`: `H·W`, non-zero = a surface pixel;
/// * `rotation`, `translation`: the pose, world → camera (`X_cam = R·X_world + t`).
///
/// As `gnomon.geometry.surface.build_surface` defines it: the camera-frame point
/// `p = r·(Z/r_z)` rounded to f32 (`points_from_depth`), then
/// `X_world = Rᵀ·(p − t)` in f64 (`Pose.camera_to_world`), rounded to f32.
/// Rows in parallel; each output depends on its own pixel only.
pub fn world_points(
    rays: &[f64],
    depth: &[f32],
    valid: &[u8],
    width: usize,
    rotation: [[f64; 3]; 3],
    translation: [f64; 3],
) -> Result<Vec<f32>, KernelError> {
    let n = depth.len();
    KernelError::check_image(
        n,
        width,
        &[
            ("rays (3 per pixel)", 3 * n, rays.len()),
            ("valid (one per pixel)", n, valid.len()),
        ],
    )?;
    let mut out = vec![f32::NAN; 3 * n];
    let rows = ROWS_PER_TASK * 4;
    out.par_chunks_mut(3 * width * rows)
        .zip(rays.par_chunks(3 * width * rows))
        .zip(depth.par_chunks(width * rows))
        .zip(valid.par_chunks(width * rows))
        .for_each(|(((out, rays), depth), valid)| {
            for (((o, r), &z), &ok) in out
                .chunks_exact_mut(3)
                .zip(rays.chunks_exact(3))
                .zip(depth)
                .zip(valid)
            {
                if ok == 0 {
                    continue;
                }
                let scale = f64::from(z) / r[2];
                let p = [0, 1, 2].map(|k| f64::from((r[k] * scale) as f32) - translation[k]);
                for (j, o) in o.iter_mut().enumerate() {
                    *o = (p[0] * rotation[0][j] + p[1] * rotation[1][j] + p[2] * rotation[2][j])
                        as f32;
                }
            }
        });
    Ok(out)
}

/// Unit surface normals `H·W·3` (f32) from the pixel grid, oriented towards the camera.
///
/// * `points`: `H·W·3` coordinates in any frame (world units);
/// * `depth`: `H·W` camera Z for the discontinuity test;
/// * `valid`: `H·W`, non-zero = a surface pixel; `width` = W;
/// * `camera_centre`: the camera's centre in the frame of `points`.
///
/// A neighbour (left/right along the row, up/down along the column) qualifies
/// when it is valid and `|Z_n − Z| ≤ max_relative_jump·|Z|`. The tangent
/// along each axis is the central difference where both neighbours qualify,
/// one-sided where one does, none otherwise; the normal is the unit
/// `t_row × t_column` flipped to face the camera, or the unit vector towards
/// the camera where it is undefined (no tangent, zero or non-finite). NaN
/// where `valid` is zero. All in f64, as `gnomon.geometry.meshing.grid_normals`.
pub fn grid_normals(
    points: &[f32],
    depth: &[f32],
    valid: &[u8],
    width: usize,
    camera_centre: [f64; 3],
    max_relative_jump: f64,
) -> Result<Vec<f32>, KernelError> {
    let n = valid.len();
    KernelError::check_image(
        n,
        width,
        &[
            ("depth (one per pixel)", n, depth.len()),
            ("points (3 per pixel)", 3 * n, points.len()),
        ],
    )?;
    let height = n / width;
    let p = |i: usize| -> V3 {
        if valid[i] != 0 {
            [
                f64::from(points[3 * i]),
                f64::from(points[3 * i + 1]),
                f64::from(points[3 * i + 2]),
            ]
        } else {
            [f64::NAN; 3]
        }
    };
    let z = |i: usize| -> f64 {
        if valid[i] != 0 {
            f64::from(depth[i])
        } else {
            f64::NAN
        }
    };
    // Tangent at pixel i from its neighbours lo/hi (None outside the image).
    let tangent = |i: usize, lo: Option<usize>, hi: Option<usize>| -> V3 {
        let zi = z(i);
        let limit = max_relative_jump * zi.abs();
        let ok = |j: Option<usize>| j.is_some_and(|j| (z(j) - zi).abs() <= limit);
        match (ok(lo), ok(hi), lo, hi) {
            (true, true, Some(l), Some(h)) => sub(p(h), p(l)),
            (false, true, _, Some(h)) => sub(p(h), p(i)),
            (true, false, Some(l), _) => sub(p(i), p(l)),
            _ => [f64::NAN; 3],
        }
    };
    let mut out = vec![f32::NAN; 3 * n];
    out.par_chunks_mut(3 * width * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(task, block)| {
            let row0 = task * ROWS_PER_TASK;
            for (r, row) in block.chunks_exact_mut(3 * width).enumerate() {
                let v = row0 + r;
                for u in 0..width {
                    let i = v * width + u;
                    if valid[i] == 0 {
                        continue;
                    }
                    let along_u = tangent(
                        i,
                        u.checked_sub(1).map(|_| i - 1),
                        (u + 1 < width).then_some(i + 1),
                    );
                    let along_v = tangent(
                        i,
                        v.checked_sub(1).map(|_| i - width),
                        (v + 1 < height).then_some(i + width),
                    );
                    let pi = p(i);
                    let to_cam = sub(camera_centre, pi);
                    let len = dot(to_cam, to_cam).sqrt();
                    let to_cam = [to_cam[0] / len, to_cam[1] / len, to_cam[2] / len];
                    let c = cross(along_u, along_v);
                    let norm = dot(c, c).sqrt();
                    let mut nrm = [c[0] / norm, c[1] / norm, c[2] / norm];
                    if !finite(nrm) || norm == 0.0 {
                        nrm = to_cam;
                    }
                    if dot(nrm, to_cam) < 0.0 {
                        nrm = [-nrm[0], -nrm[1], -nrm[2]];
                    }
                    let o = &mut row[3 * u..3 * u + 3];
                    o[0] = nrm[0] as f32;
                    o[1] = nrm[1] as f32;
                    o[2] = nrm[2] as f32;
                }
            }
        });
    Ok(out)
}

/// Size of one binary STL record: normal, three corners (12 f32), attribute (u16).
pub const STL_RECORD_BYTES: usize = 50;

/// The records of a binary STL file (after its 80-byte header and count), little-endian.
///
/// `vertices` `V·3` f32, `faces` `F·3` indices into them (checked). Each record is
/// the face's unit normal (right-hand rule over its corners, computed in f32 as
/// `gnomon.geometry.meshing.face_normals`: zero for a degenerate face), its three corners and a
/// zero attribute.
pub fn stl_records(vertices: &[f32], faces: &[i32]) -> Result<Vec<u8>, KernelError> {
    if vertices.len() % 3 != 0 {
        return Err(KernelError::parameter(
            "vertices",
            "expected rows of 3 coordinates",
        ));
    }
    let nv = vertices.len() / 3;
    if faces.len() % 3 != 0 || faces.iter().any(|&f| f < 0 || f as usize >= nv) {
        return Err(KernelError::parameter(
            "faces",
            "expected rows of 3 vertex indices in range",
        ));
    }
    let nf = faces.len() / 3;
    let mut out = vec![0u8; nf * STL_RECORD_BYTES];
    let corner = |k: i32| -> [f32; 3] {
        let k = k as usize;
        [vertices[3 * k], vertices[3 * k + 1], vertices[3 * k + 2]]
    };
    out.par_chunks_mut(STL_RECORD_BYTES * FACES_PER_TASK)
        .zip(faces.par_chunks(3 * FACES_PER_TASK))
        .for_each(|(records, faces)| {
            for (rec, f) in records
                .chunks_exact_mut(STL_RECORD_BYTES)
                .zip(faces.chunks_exact(3))
            {
                let (a, b, c) = (corner(f[0]), corner(f[1]), corner(f[2]));
                let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let mut n = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if norm == 0.0 {
                    n = [0.0; 3];
                } else {
                    n = [n[0] / norm, n[1] / norm, n[2] / norm];
                }
                for (k, x) in n.iter().chain(&a).chain(&b).chain(&c).enumerate() {
                    rec[4 * k..4 * k + 4].copy_from_slice(&x.to_le_bytes());
                }
                // bytes 48..50: the attribute, 0
            }
        });
    Ok(out)
}

/// [`lit_median_channels`] with each pixel's lit frames found from its shadow interval
/// (`gnomon.capture.texture.LitColour.finish`): kept frame `k` (at capture frame `times[k]`)
/// is shadowed at a pixel when `min(s, e) − margin ≤ times[k] ≤ max(s, e) + margin`, `s` and
/// `e` the pixel's `start` and `end` (P each, f64) with a NaN one taken as the other; with
/// both NaN no frame is shadowed. The same f64 comparisons as the numpy definition's.
pub fn lit_median_between(
    stack: &[u8],
    times: &[f64],
    start: &[f64],
    end: &[f64],
    margin: f64,
    channels: usize,
) -> Result<Vec<u8>, KernelError> {
    let (frames, pixels) = (times.len(), start.len());
    if end.len() != pixels {
        return Err(KernelError::LengthMismatch {
            what: "end (one per pixel)",
            expected: pixels,
            got: end.len(),
        });
    }
    if frames == 0 || channels == 0 || stack.len() != frames * pixels * channels {
        return Err(KernelError::LengthMismatch {
            what: "stack (one sample per frame, pixel and channel)",
            expected: frames * pixels * channels,
            got: stack.len(),
        });
    }
    Ok(lit_medians(stack, frames, pixels, channels, |p, flags| {
        let (s0, e0) = (start[p], end[p]);
        let (s, e) = (
            if s0.is_nan() { e0 } else { s0 },
            if e0.is_nan() { s0 } else { e0 },
        );
        // np.minimum / np.maximum: NaN when either is (then no comparison holds)
        let (lo, hi) = if s.is_nan() || e.is_nan() {
            (f64::NAN, f64::NAN)
        } else {
            (s.min(e) - margin, s.max(e) + margin)
        };
        for (f, &t) in flags.iter_mut().zip(times) {
            *f = !(t >= lo && t <= hi);
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lit_median_of_the_lit_samples() {
        // 4 frames of 2 pixels: pixel 0 lit in frames 0, 2, 3; pixel 1 in none (all four count).
        let lit = [1, 0, 0, 0, 1, 0, 1, 0];
        let mut stack = Vec::new();
        for k in 0..4u8 {
            stack.extend([10 * k, 200, 7, 50 - k, 100 + k, 3 * k]);
        }
        let got = lit_median(&stack, &lit, 4).unwrap();
        // pixel 0: R of 0, 20, 30 → 20; G 200; B 7. Pixel 1: R 50..47 → (48 + 49 + 1)/2 = 49.
        assert_eq!(got, vec![20, 200, 7, 49, 102, 5]);
        assert!(lit_median(&stack[..23], &lit, 4).is_err());
        assert!(lit_median(&stack, &lit, 3).is_err());
        // one channel: each pixel's median of its grey samples, the same as of three equal channels
        let grey: Vec<u8> = stack.iter().step_by(3).copied().collect();
        let once = lit_median_channels(&grey, &lit, 4, 1).unwrap();
        assert_eq!(once, vec![20, 49]);
        let tripled: Vec<u8> = grey.iter().flat_map(|&g| [g, g, g]).collect();
        assert_eq!(
            lit_median(&tripled, &lit, 4).unwrap(),
            vec![20, 20, 20, 49, 49, 49]
        );
        assert!(lit_median_channels(&grey, &lit, 4, 0).is_err());
        assert!(lit_median_channels(&grey[..7], &lit, 4, 1).is_err());
    }

    #[test]
    fn lit_median_between_finds_the_lit_frames_from_the_interval() {
        // 4 frames at 0, 10, 20, 30 of 4 pixels, one channel
        let times = [0.0, 10.0, 20.0, 30.0];
        let stack: Vec<u8> = (0..4u8)
            .flat_map(|k| [10 * k, 100 + k, 7 * k, 40 - k])
            .collect();
        let nan = f64::NAN;
        // pixel 0: shadowed 9..21 (frames 1, 2): lit 0, 30 -> (0 + 30 + 1) / 2 = 15;
        // pixel 1: end unknown, start 0 (frame 0 shadowed): 101, 102, 103 -> 102;
        // pixel 2: no times: every frame lit -> 0, 7, 14, 21 -> (7 + 14 + 1) / 2 = 11;
        // pixel 3: shadowed in every frame (-5..35): all four -> 40..37 -> (38 + 39 + 1) / 2 = 39
        let start = [10.0, 0.0, nan, -5.0];
        let end = [20.0, nan, nan, 35.0];
        let got = lit_median_between(&stack, &times, &start, &end, 1.0, 1).unwrap();
        assert_eq!(got, vec![15, 102, 11, 39]);
        // the lit flags written out, through lit_median_channels
        let lit = [1, 0, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 1, 1, 1, 0];
        assert_eq!(lit_median_channels(&stack, &lit, 4, 1).unwrap(), got);
        assert!(lit_median_between(&stack, &times, &start, &end[..3], 1.0, 1).is_err());
        assert!(lit_median_between(&stack[..15], &times, &start, &end, 1.0, 1).is_err());
    }

    #[test]
    fn world_points_on_the_rays_at_their_depth() {
        // A camera at world (1, 2, 3) turned 90° about z: X_cam = R·X_world + t with t = −R·c.
        let rotation = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let c = [1.0, 2.0, 3.0];
        let t: [f64; 3] =
            std::array::from_fn(|i| -(0..3).map(|k| rotation[i][k] * c[k]).sum::<f64>());
        assert_eq!(t, [2.0, -1.0, -3.0]);
        let rays = [0.0, 0.0, 1.0, 0.6, 0.0, 0.8, 0.0, 0.6, 0.8, 1.0, 1.0, 1.0];
        let depth = [4.0f32, 8.0, 8.0, f32::NAN];
        let got = world_points(&rays, &depth, &[1, 1, 0, 1], 2, rotation, t).unwrap();
        // camera points (0, 0, 4) and (6, 0, 8): world = Rᵀ·p + c
        let want = [[1.0, 2.0, 7.0], [1.0, -4.0, 11.0]];
        for (i, w) in want.iter().enumerate() {
            for k in 0..3 {
                assert!((f64::from(got[3 * i + k]) - w[k]).abs() < 1e-6, "{i} {k}");
            }
        }
        assert!(got[6..].iter().all(|x| x.is_nan())); // not valid, and no depth
        assert!(world_points(&rays[..9], &depth, &[1; 4], 2, rotation, t).is_err());
        assert!(world_points(&rays, &depth, &[1; 4], 3, rotation, t).is_err());
    }

    fn plane_grid(h: usize, w: usize) -> (Vec<f32>, Vec<f32>) {
        // The plane z = 10 + 0.1 x seen from the origin: points (u, v, z).
        let mut pts = Vec::new();
        let mut depth = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let z = 10.0 + 0.1 * u as f32;
                pts.extend([u as f32, v as f32, z]);
                depth.push(z);
            }
        }
        (pts, depth)
    }

    #[test]
    fn plane_normal_faces_the_camera() {
        let (pts, depth) = plane_grid(4, 5);
        let valid = vec![1u8; 20];
        let n = grid_normals(&pts, &depth, &valid, 5, [0.0, 0.0, 0.0], 0.5).unwrap();
        // tangents (1, 0, 0.1) and (0, 1, 0): normal ∝ (−0.1, 0, 1), flipped towards the camera (−z).
        let len = (0.01f64 + 1.0).sqrt();
        for px in n.chunks_exact(3) {
            assert!((f64::from(px[0]) - 0.1 / len).abs() < 1e-6, "{px:?}");
            assert!(px[1].abs() < 1e-6);
            assert!((f64::from(px[2]) + 1.0 / len).abs() < 1e-6);
        }
    }

    #[test]
    fn invalid_and_isolated_pixels() {
        let (pts, mut depth) = plane_grid(3, 3);
        let mut valid = vec![1u8; 9];
        valid[0] = 0;
        // the centre jumps far away: no neighbour qualifies, it faces the camera
        depth[4] = 100.0;
        let n = grid_normals(&pts, &depth, &valid, 3, [0.0, 0.0, 0.0], 0.05).unwrap();
        assert!(n[..3].iter().all(|x| x.is_nan()));
        let p = [1.0f64, 1.0, 10.1];
        let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        for k in 0..3 {
            assert!(
                (f64::from(n[12 + k]) + p[k] / len).abs() < 1e-6,
                "{:?}",
                &n[12..15]
            );
        }
        assert!(grid_normals(&pts, &depth[..8], &valid, 3, [0.0; 3], 0.05).is_err());
        assert!(grid_normals(&pts, &depth, &valid, 2, [0.0; 3], 0.05).is_err());
    }

    #[test]
    fn stl_record_layout() {
        let v = [0.0f32, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0];
        let rec = stl_records(&v, &[0, 1, 2, 0, 0, 1]).unwrap();
        assert_eq!(rec.len(), 2 * STL_RECORD_BYTES);
        let f = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
        assert_eq!([f(0), f(4), f(8)], [0.0, 0.0, 1.0]);
        assert_eq!([f(12), f(24), f(28), f(40)], [0.0, 2.0, 0.0, 3.0]);
        assert_eq!(&rec[48..50], &[0, 0]);
        // a degenerate face has a zero normal
        assert_eq!([f(50), f(54), f(58)], [0.0, 0.0, 0.0]);
        assert!(stl_records(&v, &[0, 1, 3]).is_err());
        assert!(stl_records(&v, &[0, 1]).is_err());
    }
}
