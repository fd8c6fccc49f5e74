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
    if rays.len() != 3 * times.len() {
        return Err(KernelError::LengthMismatch {
            what: "rays (3 per shadow time)",
            expected: 3 * times.len(),
            got: rays.len(),
        });
    }
    if planes.len() % 4 != 0 {
        return Err(KernelError::parameter(
            "planes",
            format!(
                "needs rows of 4 values [nx, ny, nz, d], got {} values",
                planes.len()
            ),
        ));
    }
    if !(0.0..=1.0).contains(&min_cos) {
        return Err(KernelError::parameter(
            "min_cos",
            format!("must be in [0, 1], got {min_cos}"),
        ));
    }
    let planes: Vec<Option<Plane>> = planes
        .chunks_exact(4)
        .map(|row| Plane::from_row([row[0], row[1], row[2], row[3]]))
        .collect();

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
                let hit = plane_at(&planes, f64::from(t)).and_then(|plane| {
                    let ray = Ray::new(Vector3::new(ray[0], ray[1], ray[2]))?;
                    plane.intersect(&ray, min_cos)
                });
                if let Some(p) = hit {
                    point[0] = p.x as f32;
                    point[1] = p.y as f32;
                    point[2] = p.z as f32;
                    *ok = 1;
                }
            }
        });
    Ok((points, valid))
}

/// The angle (degrees) between each selected pixel's ray and the shadow plane at its time
/// (`gnomon.pipeline.ray_plane_angles`): a depth moves by a plane's error over its sine.
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
    if planes.is_empty() || planes.len() % 4 != 0 {
        return Err(KernelError::parameter(
            "planes",
            format!(
                "needs one or more rows of 4 values [nx, ny, nz, d], got {} values",
                planes.len()
            ),
        ));
    }
    let last = planes.len() / 4 - 1;
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
    fn bad_lengths_are_errors() {
        assert!(triangulate(&[0.0; 5], &[0.0; 2], &[0.0; 4], 1e-3).is_err());
        assert!(triangulate(&[0.0; 6], &[0.0; 2], &[0.0; 5], 1e-3).is_err());
        assert!(triangulate(&[0.0; 6], &[0.0; 2], &[0.0; 4], 2.0).is_err());
    }
}
