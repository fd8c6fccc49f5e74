//! Per-pixel triangulation: each pixel's camera ray meets the shadow plane of
//! its shadow time (docs/method.md §4), the plane interpolated between frames.

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::KernelError;
use crate::geometry::{Plane, Ray};

/// Pixels per parallel work item (about a 1080p row pair).
const PIXELS_PER_TASK: usize = 4096;

/// The shadow plane at fractional frame time `t` from per-frame planes.
///
/// `t` exactly integer → that frame's plane; otherwise
/// [`Plane::lerp`]`(planes[i], planes[i+1], t − i)` with `i = ⌊t⌋`. `None`
/// when `t` is NaN, outside `[0, N−1]`, or a plane it needs is missing.
pub fn plane_at(planes: &[Option<Plane>], t: f64) -> Option<Plane> {
    if !(t >= 0.0 && t <= planes.len() as f64 - 1.0) {
        return None;
    }
    let i = t.floor() as usize;
    let s = t - i as f64;
    if s == 0.0 {
        return planes[i];
    }
    let (a, b) = (planes[i]?, planes.get(i + 1).copied().flatten()?);
    Some(Plane::lerp(&a, &b, s))
}

/// Where the ray `ray` (3 values, any length) meets the plane at time `t`
/// ([`plane_at`], [`Plane::intersect`] with `min_cos`); `None` as [`triangulate`] says.
fn hit(
    planes: &[Option<Plane>],
    t: f32,
    ray: &[f64],
    min_cos: f64,
) -> Option<nalgebra::Point3<f64>> {
    plane_at(planes, f64::from(t)).and_then(|plane| {
        let ray = Ray::new(Vector3::new(ray[0], ray[1], ray[2]))?;
        plane.intersect(&ray, min_cos)
    })
}

/// The planes of `N·4` rows `[nx, ny, nz, d]` (`None` for a row with a NaN), checked.
fn plane_rows(planes: &[f64]) -> Result<Vec<Option<Plane>>, KernelError> {
    if planes.len() % 4 != 0 {
        return Err(KernelError::parameter(
            "planes",
            format!(
                "needs rows of 4 values [nx, ny, nz, d], got {} values",
                planes.len()
            ),
        ));
    }
    Ok(planes
        .chunks_exact(4)
        .map(|row| Plane::from_row([row[0], row[1], row[2], row[3]]))
        .collect())
}

/// Intersect every pixel's ray with the shadow plane at its shadow time.
///
/// * `rays`: `H·W·3` unit camera-frame ray directions, row-major (pixel-major
///   xyz);
/// * `times`: `H·W` shadow times in frames (NaN = none);
/// * `planes`: `N·4` rows `[nx, ny, nz, d]` of the plane `n·X = d` at frames
///   `0 … N−1` in the camera frame (any NaN in a row = no plane that frame);
/// * `min_cos`: rays closer than this to parallel to the plane (`|n·r|`) are
///   rejected.
///
/// Returns the camera-frame points (`H·W·3`, NaN where invalid) and a validity
/// mask (`H·W`, 1 = point). A pixel is invalid if its time is NaN or outside
/// `[0, N−1]`, a plane it needs is missing, its ray is degenerate, the ray is
/// too oblique, or the point is not in front of the camera.
pub fn triangulate(
    rays: &[f64],
    times: &[f32],
    planes: &[f64],
    min_cos: f64,
) -> Result<(Vec<f32>, Vec<u8>), KernelError> {
    let planes = checked_inputs(rays, times, planes, min_cos)?;

    let mut points = vec![f32::NAN; rays.len()];
    let mut valid = vec![0u8; times.len()];
    points
        .par_chunks_mut(3 * PIXELS_PER_TASK)
        .zip(valid.par_chunks_mut(PIXELS_PER_TASK))
        .zip(times.par_chunks(PIXELS_PER_TASK))
        .zip(rays.par_chunks(3 * PIXELS_PER_TASK))
        .for_each(|(((points, valid), times), rays)| {
            for (((point, ok), &t), ray) in points
                .chunks_exact_mut(3)
                .zip(valid.iter_mut())
                .zip(times)
                .zip(rays.chunks_exact(3))
            {
                if let Some(p) = hit(&planes, t, ray, min_cos) {
                    point[0] = p.x as f32;
                    point[1] = p.y as f32;
                    point[2] = p.z as f32;
                    *ok = 1;
                }
            }
        });
    Ok((points, valid))
}

/// Camera Z of [`triangulate`]'s points (`H·W`, f32, NaN where it gives no point): the same
/// intersections, value for value, without writing the points' x and y or a mask.
pub fn triangulate_depth(
    rays: &[f64],
    times: &[f32],
    planes: &[f64],
    min_cos: f64,
) -> Result<Vec<f32>, KernelError> {
    let planes = checked_inputs(rays, times, planes, min_cos)?;
    let mut depth = vec![f32::NAN; times.len()];
    depth
        .par_chunks_mut(PIXELS_PER_TASK)
        .zip(times.par_chunks(PIXELS_PER_TASK))
        .zip(rays.par_chunks(3 * PIXELS_PER_TASK))
        .for_each(|((depth, times), rays)| {
            for ((z, &t), ray) in depth.iter_mut().zip(times).zip(rays.chunks_exact(3)) {
                if let Some(p) = hit(&planes, t, ray, min_cos) {
                    *z = p.z as f32;
                }
            }
        });
    Ok(depth)
}

/// The inputs of [`triangulate`] and [`triangulate_depth`] checked: 3 ray components per time,
/// the planes' rows, `min_cos`; the planes as rows.
fn checked_inputs(
    rays: &[f64],
    times: &[f32],
    planes: &[f64],
    min_cos: f64,
) -> Result<Vec<Option<Plane>>, KernelError> {
    if rays.len() != 3 * times.len() {
        return Err(KernelError::LengthMismatch {
            what: "rays (3 per shadow time)",
            expected: 3 * times.len(),
            got: rays.len(),
        });
    }
    let planes = plane_rows(planes)?;
    check_min_cos(min_cos)?;
    Ok(planes)
}

fn check_min_cos(min_cos: f64) -> Result<(), KernelError> {
    if !(0.0..=1.0).contains(&min_cos) {
        return Err(KernelError::parameter(
            "min_cos",
            format!("must be in [0, 1], got {min_cos}"),
        ));
    }
    Ok(())
}

/// First-order depth σ of every pixel (`gnomon.geometry.uncertainty.depth_sigma`, whose numpy
/// definition this is, value for value): `σZ = |∂Z/∂t| · sqrt(σt_pixel² + σt_line²)`.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthSigma {
    /// σZ (world units), NaN where `depth` is not finite.
    pub sigma_z: Vec<f32>,
    /// ∂Z/∂t (world units per frame): central difference of the depths at `t ± step`, else
    /// the forward one, else the backward one (NaN when none exists).
    pub dz_dt: Vec<f32>,
    /// The line's time σ (frames) at each pixel's time.
    pub sigma_t_line: Vec<f32>,
}

/// Where neither `t + step` nor `t − step` gives a depth, [`depth_sigma`] takes the
/// derivative again with `step / FINE_STEP_DIVISOR`: a depth whose ray lies in the
/// shadow planes a quarter frame away has a large ∂Z/∂t, not the typical one its
/// missing σ would get.
pub const FINE_STEP_DIVISOR: f64 = 64.0;

/// σZ of every pixel by first-order propagation (see [`DepthSigma`]).
///
/// * `rays`, `times`, `planes`, `min_cos` as [`triangulate`]; `depth` (`H·W`) the pixel's
///   depth at its time (NaN = none: σZ NaN there);
/// * `sigma_t_pixel` (`H·W`) the time σ of each pixel (frames);
/// * `line_sigma` (`N ≥ 1`) the time σ each row's line adds, interpolated at `t` between rows
///   `i = clamp(⌊t⌋, 0, N−1)` and `min(i + 1, N−1)` with weight `t − ⌊t⌋` (f64); a non-finite
///   time takes row 0 with weight 0 (as numpy's casts do); where the interpolation is not
///   finite, `line_fill` (the rows' median);
/// * `step` (frames): the depths at `t ± step` give ∂Z/∂t (central, else one-sided), or,
///   where neither exists, those at `t ± step / FINE_STEP_DIVISOR`.
///
/// The arithmetic is the numpy definition's, type for type: the depths and their differences
/// in f32 (`step` and `2·step` rounded to f32), the line's σ in f64, `σt_pixel²` in f32,
/// σZ rounded to f32 at the end. Chunks of pixels in parallel.
#[allow(clippy::too_many_arguments)]
pub fn depth_sigma(
    rays: &[f64],
    times: &[f32],
    planes: &[f64],
    depth: &[f32],
    sigma_t_pixel: &[f32],
    line_sigma: &[f64],
    line_fill: f64,
    step: f64,
    min_cos: f64,
) -> Result<DepthSigma, KernelError> {
    let n = times.len();
    for (what, got, expected) in [
        ("rays (3 per shadow time)", rays.len(), 3 * n),
        ("depth (one per shadow time)", depth.len(), n),
        (
            "sigma_t_pixel (one per shadow time)",
            sigma_t_pixel.len(),
            n,
        ),
    ] {
        if got != expected {
            return Err(KernelError::LengthMismatch {
                what,
                expected,
                got,
            });
        }
    }
    let planes = plane_rows(planes)?;
    check_min_cos(min_cos)?;
    if line_sigma.is_empty() {
        return Err(KernelError::parameter(
            "line_sigma",
            "needs one value per plane row, got none",
        ));
    }
    if !(step.is_finite() && step > 0.0) {
        return Err(KernelError::parameter(
            "step",
            format!("must be finite and > 0, got {step}"),
        ));
    }
    let last = line_sigma.len() as i64 - 1;
    let line = |k: i64| {
        let v = line_sigma[k as usize];
        if v.is_finite() {
            v
        } else {
            f64::NAN
        }
    };
    let (h, h2) = (step as f32, (2.0 * step) as f32);
    let fine_step = step / FINE_STEP_DIVISOR;
    let (fine, fine2) = (fine_step as f32, (2.0 * fine_step) as f32);
    // The depth at time `t` on a ray normalised once per pixel (`hit` on the same ray, value for value).
    let z_at = |t: f32, ray: Option<Ray>| {
        ray.and_then(|ray| plane_at(&planes, f64::from(t))?.intersect(&ray, min_cos))
            .map_or(f32::NAN, |p| p.z as f32)
    };
    let mut out = DepthSigma {
        sigma_z: vec![f32::NAN; n],
        dz_dt: vec![f32::NAN; n],
        sigma_t_line: vec![f32::NAN; n],
    };
    out.sigma_z
        .par_chunks_mut(PIXELS_PER_TASK)
        .zip(out.dz_dt.par_chunks_mut(PIXELS_PER_TASK))
        .zip(out.sigma_t_line.par_chunks_mut(PIXELS_PER_TASK))
        .enumerate()
        .for_each(|(chunk, ((sigma_z, dz_dt), st_line))| {
            let start = chunk * PIXELS_PER_TASK;
            for k in 0..sigma_z.len() {
                let i = start + k;
                let (t, z) = (times[i], depth[i]);
                let r = &rays[3 * i..3 * i + 3];
                // (a time that is not finite meets no plane: its ray is not needed)
                let ray = if t.is_finite() {
                    Ray::new(Vector3::new(r[0], r[1], r[2]))
                } else {
                    None
                };
                let derivative = |h: f32, h2: f32| {
                    let (plus, minus) = (z_at(t + h, ray), z_at(t - h, ray));
                    let central = (plus - minus) / h2;
                    let forward = (plus - z) / h;
                    let backward = (z - minus) / h;
                    if central.is_finite() {
                        central
                    } else if forward.is_finite() {
                        forward
                    } else {
                        backward
                    }
                };
                let mut dz = derivative(h, h2);
                if !dz.is_finite() && z.is_finite() {
                    // Neither t + step nor t − step meets the ray (it lies in the planes there, or
                    // behind the camera): the slope at t itself, from a step within t's own pair
                    // of rows, where the interpolated plane moves linearly.
                    dz = derivative(fine, fine2);
                }
                let floor = t.floor();
                // numpy: nan_to_num, then the int64 cast (x86: out of range → i64::MIN), then clip
                let row = if floor.is_finite() && floor.abs() < 9.0e18 {
                    (floor as i64).clamp(0, last)
                } else {
                    0
                };
                let frac = {
                    let f = t - floor;
                    if f.is_nan() {
                        0.0
                    } else {
                        f
                    }
                };
                let next = (row + 1).clamp(0, last);
                let mut st = f64::from(1.0 - frac) * line(row) + f64::from(frac) * line(next);
                if !st.is_finite() {
                    st = line_fill;
                }
                let sp = sigma_t_pixel[i];
                let total = (f64::from(sp * sp) + st * st).sqrt();
                dz_dt[k] = dz;
                st_line[k] = st as f32;
                sigma_z[k] = if z.is_finite() {
                    (f64::from(dz.abs()) * total) as f32
                } else {
                    f32::NAN
                };
            }
        });
    Ok(out)
}

/// The number of rows of `planes` (`N·4` values `[nx, ny, nz, d]`), at least one.
fn plane_row_count(planes: &[f64]) -> Result<usize, KernelError> {
    if planes.is_empty() || planes.len() % 4 != 0 {
        return Err(KernelError::parameter(
            "planes",
            format!(
                "needs one or more rows of 4 values [nx, ny, nz, d], got {} values",
                planes.len()
            ),
        ));
    }
    Ok(planes.len() / 4)
}

/// The angle (degrees) between each selected pixel's ray and the shadow plane at its time
/// (`gnomon.geometry.surface.ray_plane_angles`): a depth moves by a plane's error over its sine.
///
/// * `rays`: `H·W·3` camera-frame ray directions (any length);
/// * `times`: `H·W` times in rows of `planes`; the plane's normal is interpolated
///   linearly between rows `i = clamp(⌊t⌋, 0, N−1)` and `min(i + 1, N−1)` at `t − i`;
/// * `planes`: `N·4` rows `[nx, ny, nz, d]` (a NaN row gives a NaN angle);
/// * `selected`: `H·W`, non-zero = wanted.
///
/// Returns the angles of the selected pixels in row-major order:
/// `asin(|n·r| / (|n|·|r|))` in degrees (f64, the sine clamped to [0, 1]; NaN
/// where it is undefined). Chunks of pixels in parallel, concatenated in order.
pub fn ray_plane_angles(
    rays: &[f64],
    times: &[f64],
    planes: &[f64],
    selected: &[u8],
) -> Result<Vec<f64>, KernelError> {
    let n = times.len();
    if rays.len() != 3 * n {
        return Err(KernelError::LengthMismatch {
            what: "rays (3 per time)",
            expected: 3 * n,
            got: rays.len(),
        });
    }
    if selected.len() != n {
        return Err(KernelError::LengthMismatch {
            what: "selected (one per time)",
            expected: n,
            got: selected.len(),
        });
    }
    let last = plane_row_count(planes)? - 1;
    let normal = |k: usize| [planes[4 * k], planes[4 * k + 1], planes[4 * k + 2]];
    let angle = |t: f64, r: &[f64]| -> f64 {
        if t.is_nan() {
            return f64::NAN;
        }
        let i = (t.floor().max(0.0) as usize).min(last);
        let j = (i + 1).min(last);
        let f = t - i as f64;
        let (a, b) = (normal(i), normal(j));
        let m = [0, 1, 2].map(|k| (1.0 - f) * a[k] + f * b[k]);
        let dot = m[0] * r[0] + m[1] * r[1] + m[2] * r[2];
        let norm_m = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        let norm_r = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        (dot.abs() / (norm_m * norm_r))
            .clamp(0.0, 1.0)
            .asin()
            .to_degrees()
    };
    let parts: Vec<Vec<f64>> = times
        .par_chunks(PIXELS_PER_TASK)
        .zip(rays.par_chunks(3 * PIXELS_PER_TASK))
        .zip(selected.par_chunks(PIXELS_PER_TASK))
        .map(|((times, rays), selected)| {
            times
                .iter()
                .zip(rays.chunks_exact(3))
                .zip(selected)
                .filter(|(_, &s)| s != 0)
                .map(|((&t, r), _)| angle(t, r))
                .collect()
        })
        .collect();
    Ok(parts.concat())
}

/// How the planes of a two-plane scan's one-line frames were completed, for [`completion_sigma`].
#[derive(Debug, Clone, Copy)]
pub struct Completion<'a> {
    /// `N·3`: a point of the line each row was completed from (NaN x: a measured row).
    pub line_point: &'a [f64],
    /// `N·3`: that line's unit direction.
    pub line_direction: &'a [f64],
    /// The completion's 1σ error, an angle (radians) about the line.
    pub sigma_rad: f64,
}

/// The σZ (world units, camera Z, `H·W` f32) a completed plane's own error adds at each pixel
/// (`gnomon.geometry.uncertainty.completion_depth_sigma`, whose numpy definition this is, value for value).
///
/// A row completed from one line and the light is exact along its line and off by a turn
/// about it: by `sigma_rad`, a point at distance `d` from the line moves `sigma_rad·d` along
/// the plane's normal, `sigma_rad·d·|r_z|/max(|n̂·r|, min_cos)` of camera Z along its ray `r`.
/// A pixel's plane is interpolated between rows `k0 = clamp(⌊t⌋, 0, N−1)` and
/// `min(k0 + 1, N−1)` with weights `1 − f` and `f` (`f = t − k0`, f64); both rows' errors
/// come from one light, so their terms add linearly with those weights; a measured row (its
/// line point's x NaN) and a zero weight add nothing.
///
/// * `rays`: `H·W·3` camera rays (as the ray map); `times`: `H·W` plane rows;
///   `depth`: `H·W` camera Z (NaN = no point);
/// * `planes`: `N·4` rows `[nx, ny, nz, d]`; `completion`: the completing lines of its rows
///   and their error ([`Completion`]);
/// * `min_cos`: the floor of `|n̂·r|`, as [`triangulate`]'s.
///
/// 0 where the depth or time is not finite, no row is completed, or `sigma_rad ≤ 0`. The
/// arithmetic is the numpy definition's, in f64 in its order, rounded to f32 at the end.
/// Chunks of pixels in parallel.
pub fn completion_sigma(
    rays: &[f64],
    times: &[f64],
    depth: &[f64],
    planes: &[f64],
    completion: Completion<'_>,
    min_cos: f64,
) -> Result<Vec<f32>, KernelError> {
    let Completion {
        line_point,
        line_direction,
        sigma_rad,
    } = completion;
    check_min_cos(min_cos)?;
    let n = times.len();
    let rows = plane_row_count(planes)?;
    for (what, got, expected) in [
        ("rays (3 per time)", rays.len(), 3 * n),
        ("depth (one per time)", depth.len(), n),
        ("line_point (3 per plane row)", line_point.len(), 3 * rows),
        (
            "line_direction (3 per plane row)",
            line_direction.len(),
            3 * rows,
        ),
    ] {
        if got != expected {
            return Err(KernelError::LengthMismatch {
                what,
                expected,
                got,
            });
        }
    }
    let mut sigma = vec![0.0f32; n];
    let completed: Vec<bool> = (0..rows).map(|k| line_point[3 * k].is_finite()).collect();
    if !completed.iter().any(|&c| c) || sigma_rad.is_nan() || sigma_rad <= 0.0 {
        return Ok(sigma);
    }
    let last = rows - 1;
    // The term of row `k` with weight `w` for the camera point `x` on the unit-free ray `r`.
    let term = |k: usize, w: f64, x: [f64; 3], r: &[f64]| -> f64 {
        let p = &line_point[3 * k..3 * k + 3];
        let d = &line_direction[3 * k..3 * k + 3];
        let a = [x[0] - p[0], x[1] - p[1], x[2] - p[2]];
        let c = [
            a[1] * d[2] - a[2] * d[1],
            a[2] * d[0] - a[0] * d[2],
            a[0] * d[1] - a[1] * d[0],
        ];
        let dist = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let m = &planes[4 * k..4 * k + 3];
        let norm = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        let dot = (m[0] / norm) * r[0] + (m[1] / norm) * r[1] + (m[2] / norm) * r[2];
        // numpy's maximum propagates a NaN where f64::max would drop it
        let cos = if dot.is_nan() {
            f64::NAN
        } else {
            dot.abs().max(min_cos)
        };
        w * sigma_rad * dist * r[2].abs() / cos
    };
    sigma
        .par_chunks_mut(PIXELS_PER_TASK)
        .enumerate()
        .for_each(|(chunk, out)| {
            let start = chunk * PIXELS_PER_TASK;
            for (j, s) in out.iter_mut().enumerate() {
                let i = start + j;
                let (t, z) = (times[i], depth[i]);
                if !(t.is_finite() && z.is_finite()) {
                    continue;
                }
                let r = &rays[3 * i..3 * i + 3];
                let scale = z / r[2];
                let x = [r[0] * scale, r[1] * scale, r[2] * scale];
                // numpy: the int64 cast of floor(t) (x86: out of range → i64::MIN), then clip to 0 … N − 1
                let floor = t.floor();
                let k0 = if floor.abs() < 9.0e18 {
                    (floor as i64).clamp(0, last as i64) as usize
                } else {
                    0
                };
                let frac = t - k0 as f64;
                let mut total = 0.0f64;
                for (k, w) in [(k0, 1.0 - frac), ((k0 + 1).min(last), frac)] {
                    if completed[k] && w > 0.0 {
                        total += term(k, w, x, r);
                    }
                }
                *s = total as f32;
            }
        });
    Ok(sigma)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAN_ROW: [f64; 4] = [f64::NAN; 4];

    #[test]
    fn exact_frame_uses_its_plane() {
        // Plane z = 2 at frame 0, x = 1 at frame 1.
        let planes = [0.0, 0.0, 1.0, 2.0, 1.0, 0.0, 0.0, 1.0];
        let r = Vector3::new(0.5, 0.0, 1.0).normalize();
        let rays = [r.x, r.y, r.z, r.x, r.y, r.z];
        let (points, valid) = triangulate(&rays, &[0.0, 1.0], &planes, 1e-3).unwrap();
        assert_eq!(valid, vec![1, 1]);
        let expect = [1.0, 0.0, 2.0, 1.0, 0.0, 2.0];
        for (p, e) in points.iter().zip(expect) {
            assert!((p - e).abs() < 1e-6, "{points:?}");
        }
    }

    #[test]
    fn fractional_time_interpolates_planes() {
        // z = 2 at frame 3, z = 4 at frame 4 (given with the opposite sign).
        let mut planes = vec![f64::NAN; 3 * 4];
        planes.extend([0.0, 0.0, 1.0, 2.0, 0.0, 0.0, -1.0, -4.0]);
        let rays = [0.0, 0.0, 1.0];
        let (points, valid) = triangulate(&rays, &[3.25], &planes, 1e-3).unwrap();
        assert_eq!(valid, vec![1]);
        assert!((points[2] - 2.5).abs() < 1e-6);
    }

    #[test]
    fn invalid_cases() {
        let mut planes = vec![0.0, 0.0, 1.0, 2.0];
        planes.extend(NAN_ROW);
        planes.extend([0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 1.0, -2.0]);
        let z = [0.0, 0.0, 1.0];
        let rays: Vec<f64> = z.iter().copied().cycle().take(3 * 7).collect();
        //          NaN       <0    >N-1  NaN plane  next NaN  behind  ok
        let times = [f32::NAN, -0.5, 3.5, 1.0, 0.5, 3.0, 2.0];
        let (points, valid) = triangulate(&rays, &times, &planes, 1e-3).unwrap();
        assert_eq!(valid, vec![0, 0, 0, 0, 0, 0, 1]);
        assert!(points[..18].iter().all(|v| v.is_nan()));
        assert_eq!(&points[18..], &[0.0, 0.0, 2.0]);
    }

    #[test]
    fn ray_plane_angles_of_interpolated_planes() {
        // Row 0: z = 0 (normal along z), rows 1, 2: x = 0 (normal along x), row 3 missing; a ray along z.
        let mut planes = vec![0.0, 0.0, 1.0, 0.0];
        planes.extend([1.0, 0.0, 0.0, 0.0].repeat(2));
        planes.extend([f64::NAN; 4]);
        let rays = [0.0, 0.0, 2.0].repeat(5);
        let times = [0.0, 0.5, 1.0, 2.5, 0.25];
        let got = ray_plane_angles(&rays, &times, &planes, &[1, 1, 1, 1, 0]).unwrap();
        assert_eq!(got.len(), 4);
        assert!((got[0] - 90.0).abs() < 1e-12); // the ray crosses z = 0 square on
        assert!((got[1] - 45.0).abs() < 1e-12); // halfway: normal (1, 0, 1)/√2
        assert!(got[2].abs() < 1e-12); // the ray lies in x = 0
        assert!(got[3].is_nan()); // row 3 is missing
        assert!(ray_plane_angles(&rays[..14], &times, &planes, &[1; 5]).is_err());
        assert!(ray_plane_angles(&rays, &times, &planes[..5], &[1; 5]).is_err());
    }

    #[test]
    fn depth_sigma_of_a_moving_plane() {
        // z = 2 + t/2 at frames 0..4 (row k: z = 2 + k/2): a ray along z has ∂Z/∂t = 0.5.
        let planes: Vec<f64> = (0..5)
            .flat_map(|k| [0.0, 0.0, 1.0, 2.0 + 0.5 * k as f64])
            .collect();
        let rays = [0.0, 0.0, 1.0].repeat(5);
        //          central, forward (t − h < 0), backward (t + h > 4), no time, NaN line row
        let times = [1.5f32, 0.1, 3.9, f32::NAN, 2.5];
        let (points, _) = triangulate(&rays, &times, &planes, 1e-3).unwrap();
        let depth: Vec<f32> = points.chunks_exact(3).map(|p| p[2]).collect();
        let line = [0.1, 0.2, 0.3, f64::NAN, 0.5];
        let sp = [0.4f32; 5];
        let got =
            depth_sigma(&rays, &times, &planes, &depth, &sp, &line, 0.25, 0.25, 1e-3).unwrap();
        for i in [0, 1, 2, 4] {
            assert!((got.dz_dt[i] - 0.5).abs() < 1e-6, "{:?}", got.dz_dt);
        }
        assert!(got.dz_dt[3].is_nan() && got.sigma_z[3].is_nan());
        // line σ: 0.2·0.5 + 0.3·0.5 at t = 1.5; the NaN row 3 at t = 2.5 gives the fill 0.25
        let st = [0.25, 0.9 * 0.1 + 0.1 * 0.2, 0.25, 0.1, 0.25];
        for i in [0, 1, 2, 4] {
            assert!((f64::from(got.sigma_t_line[i]) - st[i]).abs() < 1e-6);
            let want = 0.5 * (0.16 + st[i] * st[i]).sqrt();
            assert!(
                (f64::from(got.sigma_z[i]) - want).abs() < 1e-6,
                "{i}: {:?}",
                got.sigma_z
            );
        }
        // t = 3.9: the next row clamps to the last one; a NaN time takes row 0
        assert!((f64::from(got.sigma_t_line[3]) - 0.1).abs() < 1e-7);
        assert!(depth_sigma(&rays, &times, &planes, &depth, &sp, &[], 0.0, 0.25, 1e-3).is_err());
        assert!(depth_sigma(
            &rays,
            &times,
            &planes,
            &depth[..4],
            &sp,
            &line,
            0.0,
            0.25,
            1e-3
        )
        .is_err());
        assert!(depth_sigma(&rays, &times, &planes, &depth, &sp, &line, 0.0, 0.0, 1e-3).is_err());
    }

    #[test]
    fn depth_sigma_where_the_ray_leaves_the_planes_a_quarter_frame_away() {
        // Between rows 0 and 1 (t in 0..1) the plane is n·X = d with n = (1, 0, 0.016·(0.75 − t)),
        // d = t − 0.375: a ray along z meets it at Z = d / n_z, in front of the camera at t = 0.5
        // (Z = 31.25), behind it at t = 0.25, and lies in it at t = 0.75. So neither t ± 0.25 gives a
        // depth, and ∂Z/∂t = 0.375 / (0.016·(0.75 − t)²) = 375 at t = 0.5 comes from the fine step.
        let planes = [1.0, 0.0, 0.012, -0.375, 1.0, 0.0, -0.004, 0.625];
        let rays = [0.0, 0.0, 1.0];
        let (points, _) = triangulate(&rays, &[0.5], &planes, 1e-3).unwrap();
        assert!((points[2] - 31.25).abs() < 0.01, "{points:?}"); // f32 times, f64 planes
        let got = depth_sigma(
            &rays,
            &[0.5],
            &planes,
            &[points[2]],
            &[0.1],
            &[0.0, 0.0],
            0.0,
            0.25,
            1e-3,
        )
        .unwrap();
        assert!((got.dz_dt[0] - 375.0).abs() < 1.0, "{:?}", got.dz_dt);
        assert!((got.sigma_z[0] - 37.5).abs() < 0.1, "{:?}", got.sigma_z);
    }

    #[test]
    fn completion_sigma_turns_about_the_line() {
        // Row 0: the plane z = 2 completed from the line along x through (0, 0, 2); row 1 measured.
        let planes = [0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 1.0, 2.0];
        let line_point = [0.0, 0.0, 2.0, f64::NAN, f64::NAN, f64::NAN];
        let line_direction = [1.0, 0.0, 0.0, f64::NAN, f64::NAN, f64::NAN];
        // The ray (0, 0.6, 0.8) meets z = 2 at (0, 1.5, 2): 1.5 from the line, |n·r| = 0.8.
        let r = [0.0, 0.6, 0.8];
        let rays: Vec<f64> = r.iter().cycle().take(12).copied().collect();
        let s = 0.01;
        let completion = Completion {
            line_point: &line_point,
            line_direction: &line_direction,
            sigma_rad: s,
        };
        let sigma = completion_sigma(
            &rays,
            &[0.0, 0.25, 1.0, f64::NAN],
            &[2.0, 2.0, 2.0, 2.0],
            &planes,
            completion,
            1e-3,
        )
        .unwrap();
        // a turn by s moves the point s·1.5 along the normal (z): Z by s·1.5·0.8/0.8
        let expect = [1.5 * s, 0.75 * 1.5 * s, 0.0, 0.0];
        for (got, want) in sigma.iter().zip(expect) {
            assert!((f64::from(*got) - want).abs() < 1e-7, "{sigma:?}");
        }
        let none =
            completion_sigma(&rays[..3], &[0.0], &[f64::NAN], &planes, completion, 1e-3).unwrap();
        assert_eq!(none, vec![0.0]);
        let short = Completion {
            line_point: &line_point[..3],
            ..completion
        };
        assert!(completion_sigma(&rays[..3], &[0.0], &[2.0], &planes, short, 1e-3).is_err());
    }

    #[test]
    fn bad_lengths_are_errors() {
        assert!(triangulate(&[0.0; 5], &[0.0; 2], &[0.0; 4], 1e-3).is_err());
        assert!(triangulate(&[0.0; 6], &[0.0; 2], &[0.0; 5], 1e-3).is_err());
        assert!(triangulate(&[0.0; 6], &[0.0; 2], &[0.0; 4], 2.0).is_err());
    }
}
