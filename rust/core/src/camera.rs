//! The per-pixel rays of OpenCV's pinhole camera with 5 distortion
//! coefficients `(k1, k2, p1, p2, k3)`, as `gnomon.camera.models.OpenCVCamera`
//! defines the model (docs/architecture.md, "Camera models").
//!
//! The distortion maps undistorted normalised coordinates `(x, y)` to
//! distorted ones; a pixel `(u, v)` gives `t = ((u − cx)/fx, (v − cy)/fy)` and
//! its ray is `(x, y, 1)/‖·‖` with `distort(x, y) = t`. [`ray_map`] solves that
//! equation by Newton's method: a row's pixels take [`BATCH_STEPS`] steps
//! together (vectorised), then each pixel not yet within the tolerance
//! iterates on its own from the pinhole point.
//!
//! Invariants: rows are processed in parallel (rayon), each pixel from its own
//! coordinates only; a pixel's ray is returned only when its reprojection
//! residual is under the tolerance on the unfolded branch (`det J > 0`);
//! otherwise its ray is NaN and its flag 0, and the caller solves it another
//! way.

use rayon::prelude::*;

use crate::error::KernelError;

/// Rows of pixels per parallel work item.
const ROWS_PER_TASK: usize = 8;

/// The distortion `d(x, y) − t` and its Jacobian `[[a, b], [b, d]]` at `(x, y)`.
#[inline(always)]
fn residual_and_jacobian(x: f64, y: f64, t: (f64, f64), k: &[f64; 5]) -> (f64, f64, f64, f64, f64) {
    let [k1, k2, p1, p2, k3] = *k;
    let (x2, y2, xy) = (x * x, y * y, x * y);
    let r2 = x2 + y2;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    let ex = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2) - t.0;
    let ey = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy - t.1;
    let dr = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)); // d radial / dx = dr·x
    let a = radial + x2 * dr + 2.0 * p1 * y + 6.0 * p2 * x;
    let b = xy * dr + 2.0 * p1 * x + 2.0 * p2 * y;
    let d = radial + y2 * dr + 6.0 * p1 * y + 2.0 * p2 * x;
    (ex, ey, a, b, d)
}

/// Undistorted normalised `(x, y)` of the distorted normalised point `t`, or
/// `None` when Newton's method does not reach the tolerance.
///
/// Starts from the pinhole point `t`: for a radial lens that start lies on the
/// near side of the root along the radius (barrel: `d` concave in `r`, start
/// inside; pincushion: convex, start outside), so the iterates approach it
/// monotonically and never cross the fold (`det J = 0`) onto the branch
/// beyond. Accepted once `|(fx·ex, fy·ey)| < tol_px` with `det J > 0`; `None`
/// after `max_steps` steps, or at `det J ≤ 0` or a non-finite value.
#[inline]
fn undistort_point(
    t: (f64, f64),
    k: &[f64; 5],
    f: (f64, f64),
    tol_px: f64,
    max_steps: u32,
) -> Option<(f64, f64)> {
    let (mut x, mut y) = t;
    let tol2 = tol_px * tol_px;
    let mut step = 0;
    loop {
        let (ex, ey, a, b, d) = residual_and_jacobian(x, y, t, k);
        let det = a * d - b * b;
        let (rx, ry) = (ex * f.0, ey * f.1);
        let res2 = rx * rx + ry * ry;
        if det.is_nan() || det <= 0.0 || !res2.is_finite() {
            return None;
        }
        if res2 < tol2 {
            return Some((x, y));
        }
        if step == max_steps {
            return None;
        }
        let inv_det = 1.0 / det;
        x -= (d * ex - b * ey) * inv_det;
        y -= (a * ey - b * ex) * inv_det;
        step += 1;
    }
}

/// Newton steps taken on a whole row at once, with no test per pixel (the
/// loop over the row then vectorises); an ordinary lens needs 2-3 from the
/// pinhole start.
const BATCH_STEPS: u32 = 3;

/// One image row's Newton iterates, advanced together.
struct Row {
    tx: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    /// `det J > 0` at every iterate so far (the unfolded branch).
    unfolded: Vec<bool>,
}

impl Row {
    fn new(width: usize) -> Self {
        Row {
            tx: vec![0.0; width],
            x: vec![0.0; width],
            y: vec![0.0; width],
            unfolded: vec![true; width],
        }
    }

    /// `steps` Newton steps from the pinhole point for every pixel of the row at
    /// normalised `ty` (`f = (fx, cx)` for the columns). A pixel whose iterate
    /// met `det J ≤ 0` (or NaN) is flagged in `unfolded` and its later iterates are
    /// not used.
    fn solve(&mut self, ty: f64, f: (f64, f64), k: &[f64; 5], steps: u32) {
        for (u, (((tx, x), y), unfolded)) in self
            .tx
            .iter_mut()
            .zip(self.x.iter_mut())
            .zip(self.y.iter_mut())
            .zip(self.unfolded.iter_mut())
            .enumerate()
        {
            *tx = (u as f64 - f.1) / f.0;
            (*x, *y, *unfolded) = (*tx, ty, true);
        }
        for _ in 0..steps {
            for (((tx, x), y), unfolded) in self
                .tx
                .iter()
                .zip(self.x.iter_mut())
                .zip(self.y.iter_mut())
                .zip(self.unfolded.iter_mut())
            {
                let (ex, ey, a, b, d) = residual_and_jacobian(*x, *y, (*tx, ty), k);
                let det = a * d - b * b;
                *unfolded &= det > 0.0;
                let inv_det = 1.0 / det;
                *x -= (d * ex - b * ey) * inv_det;
                *y -= (a * ey - b * ex) * inv_det;
            }
        }
    }
}

/// Unit camera-frame rays of every pixel centre of a `width × height` image
/// (pixel `(u, v)` at integer coordinates), and a flag per pixel.
///
/// * `intrinsics`: `[fx, fy, cx, cy]` in pixels (`fx, fy` finite and > 0);
/// * `dist`: `[k1, k2, p1, p2, k3]` (finite);
/// * `tol_px`: a pixel is solved when its ray reprojects within this many
///   pixels of it (> 0);
/// * `max_steps`: Newton steps before giving up on a pixel.
///
/// Returns the rays (`H·W·3`, row-major, NaN where not solved) and the flags
/// (`H·W`, 1 = solved).
pub fn ray_map(
    width: usize,
    height: usize,
    intrinsics: [f64; 4],
    dist: [f64; 5],
    tol_px: f64,
    max_steps: u32,
) -> Result<(Vec<f64>, Vec<u8>), KernelError> {
    let [fx, fy, cx, cy] = intrinsics;
    if !(fx.is_finite() && fx > 0.0 && fy.is_finite() && fy > 0.0) {
        return Err(KernelError::parameter(
            "intrinsics",
            format!("fx, fy must be finite and > 0, got {fx}, {fy}"),
        ));
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(KernelError::parameter(
            "intrinsics",
            format!("cx, cy must be finite, got {cx}, {cy}"),
        ));
    }
    if !dist.iter().all(|c| c.is_finite()) {
        return Err(KernelError::parameter(
            "dist",
            format!("must be finite, got {dist:?}"),
        ));
    }
    if !(tol_px.is_finite() && tol_px > 0.0) {
        return Err(KernelError::parameter(
            "tol_px",
            format!("must be finite and > 0, got {tol_px}"),
        ));
    }
    let n = width.checked_mul(height).ok_or_else(|| {
        KernelError::parameter("width", format!("{width} × {height} pixels overflow"))
    })?;
    let mut rays = vec![f64::NAN; 3 * n];
    let mut solved = vec![0u8; n];
    if n == 0 {
        return Ok((rays, solved));
    }
    rays.par_chunks_mut(3 * width * ROWS_PER_TASK)
        .zip(solved.par_chunks_mut(width * ROWS_PER_TASK))
        .enumerate()
        .for_each(|(task, (rays, solved))| {
            let mut row = Row::new(width);
            for (r, (rays, solved)) in rays
                .chunks_exact_mut(3 * width)
                .zip(solved.chunks_exact_mut(width))
                .enumerate()
            {
                let ty = ((task * ROWS_PER_TASK + r) as f64 - cy) / fy;
                row.solve(ty, (fx, cx), &dist, max_steps.min(BATCH_STEPS));
                for (u, (ray, ok)) in rays.chunks_exact_mut(3).zip(solved.iter_mut()).enumerate() {
                    let t = (row.tx[u], ty);
                    let (x, y) = (row.x[u], row.y[u]);
                    let done = row.unfolded[u] && {
                        let (ex, ey, a, b, d) = residual_and_jacobian(x, y, t, &dist);
                        let (rx, ry) = (ex * fx, ey * fy);
                        a * d - b * b > 0.0 && rx * rx + ry * ry < tol_px * tol_px
                    };
                    let xy = if done {
                        Some((x, y))
                    } else {
                        undistort_point(t, &dist, (fx, fy), tol_px, max_steps)
                    };
                    if let Some((x, y)) = xy {
                        let inv = 1.0 / (x * x + y * y + 1.0).sqrt();
                        ray[0] = x * inv;
                        ray[1] = y * inv;
                        ray[2] = inv;
                        *ok = 1;
                    }
                }
            }
        });
    Ok((rays, solved))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distort(x: f64, y: f64, k: &[f64; 5]) -> (f64, f64) {
        let (ex, ey, ..) = residual_and_jacobian(x, y, (0.0, 0.0), k);
        (ex, ey)
    }

    #[test]
    fn rays_reproject_to_their_pixels() {
        let k = [-0.3, 0.08, 0.001, -0.002, 0.0];
        let (w, h, f) = (64usize, 48usize, [60.0, 58.0, 31.2, 23.9]);
        let (rays, solved) = ray_map(w, h, f, k, 1e-10, 8).unwrap();
        assert!(solved.iter().all(|&s| s == 1));
        for v in 0..h {
            for u in 0..w {
                let r = &rays[3 * (v * w + u)..3 * (v * w + u) + 3];
                assert!(((r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt() - 1.0).abs() < 1e-15);
                let (xd, yd) = distort(r[0] / r[2], r[1] / r[2], &k);
                let (pu, pv) = (f[0] * xd + f[2], f[1] * yd + f[3]);
                assert!(
                    (pu - u as f64).hypot(pv - v as f64) < 1e-9,
                    "pixel ({u}, {v})"
                );
            }
        }
    }

    #[test]
    fn beyond_the_fold_is_not_solved() {
        // k1 = -0.4: distorted radius at most 0.609 (at r² = 1/1.2); a pixel at
        // distorted radius 0.7 has no undistorted point.
        let k = [-0.4, 0.0, 0.0, 0.0, 0.0];
        let (rays, solved) = ray_map(3, 1, [100.0, 100.0, -70.0, 0.0], k, 1e-10, 50).unwrap();
        assert_eq!(solved, vec![0, 0, 0]);
        assert!(rays.iter().all(|r| r.is_nan()));
        let (_, solved) = ray_map(3, 1, [100.0, 100.0, 0.0, 0.0], k, 1e-10, 50).unwrap();
        assert_eq!(solved, vec![1, 1, 1]);
    }

    #[test]
    fn bad_parameters_are_refused() {
        assert!(ray_map(2, 2, [0.0, 1.0, 0.0, 0.0], [0.0; 5], 1e-10, 5).is_err());
        assert!(ray_map(
            2,
            2,
            [1.0, 1.0, 0.0, 0.0],
            [f64::NAN, 0.0, 0.0, 0.0, 0.0],
            1e-10,
            5
        )
        .is_err());
        assert!(ray_map(2, 2, [1.0, 1.0, 0.0, 0.0], [0.0; 5], 0.0, 5).is_err());
    }
}
