//! Planes and camera rays in the camera frame (OpenCV: x right, y down,
//! z forward; the camera centre at the origin).

use nalgebra::{Point3, Unit, Vector3};

/// Norms below this are treated as zero when normalising.
const MIN_NORM: f64 = 1e-12;

/// An oriented plane `n · X = d` with a unit normal `n`.
///
/// `(n, d)` and `(−n, −d)` are the same set of points; [`Plane::lerp`] aligns
/// the signs before interpolating.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    normal: Unit<Vector3<f64>>,
    offset: f64,
}

impl Plane {
    /// The plane `normal · X = offset`, both scaled so the normal is unit.
    /// `None` if the normal is (nearly) zero or anything is not finite.
    pub fn new(normal: Vector3<f64>, offset: f64) -> Option<Plane> {
        if !offset.is_finite() || !normal.iter().all(|c| c.is_finite()) {
            return None;
        }
        let (normal, norm) = Unit::try_new_and_get(normal, MIN_NORM)?;
        Some(Plane {
            normal,
            offset: offset / norm,
        })
    }

    /// The plane of a row `[nx, ny, nz, d]`; `None` for NaN rows (no plane).
    pub fn from_row(row: [f64; 4]) -> Option<Plane> {
        Plane::new(Vector3::new(row[0], row[1], row[2]), row[3])
    }

    pub fn normal(&self) -> &Unit<Vector3<f64>> {
        &self.normal
    }

    /// `d` in `n · X = d`: the signed distance of the plane from the origin.
    pub fn offset(&self) -> f64 {
        self.offset
    }

    /// The same plane with the opposite orientation.
    pub fn flipped(&self) -> Plane {
        Plane {
            normal: -self.normal,
            offset: -self.offset,
        }
    }

    /// Signed distance `n · p − d` of a point from the plane.
    pub fn signed_distance(&self, point: &Point3<f64>) -> f64 {
        self.normal.dot(&point.coords) - self.offset
    }

    /// Sign-aligned linear interpolation from `a` (`s = 0`) to `b` (`s = 1`).
    ///
    /// `b` is flipped if `n_a · n_b < 0`; then `(n, d)` are interpolated
    /// linearly and renormalised. `s` is clamped to `[0, 1]`, where the
    /// interpolated normal has norm `≥ 1/√2`, so the result always exists.
    pub fn lerp(a: &Plane, b: &Plane, s: f64) -> Plane {
        let s = if s.is_nan() { 0.0 } else { s.clamp(0.0, 1.0) };
        let b = if a.normal.dot(&b.normal) < 0.0 {
            b.flipped()
        } else {
            *b
        };
        let normal = a.normal.into_inner() * (1.0 - s) + b.normal.into_inner() * s;
        let offset = a.offset * (1.0 - s) + b.offset * s;
        let norm = normal.norm();
        Plane {
            normal: Unit::new_unchecked(normal / norm),
            offset: offset / norm,
        }
    }

    /// Where `ray` meets the plane: `P = (d / n·r) r`.
    ///
    /// `None` when the ray is within `asin(min_cos)` of parallel to the plane
    /// (`|n · r| < min_cos`) or the point is not in front of the camera
    /// (depth `z ≤ 0`).
    pub fn intersect(&self, ray: &Ray, min_cos: f64) -> Option<Point3<f64>> {
        let cos = self.normal.dot(&ray.direction);
        if cos.abs() < min_cos || cos == 0.0 {
            return None;
        }
        let point = ray.at(self.offset / cos);
        (point.z > 0.0).then_some(point)
    }
}

/// A ray from the camera centre with a unit direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    direction: Unit<Vector3<f64>>,
}

impl Ray {
    /// The ray along `direction` (normalised); `None` if it is (nearly) zero
    /// or not finite.
    pub fn new(direction: Vector3<f64>) -> Option<Ray> {
        if !direction.iter().all(|c| c.is_finite()) {
            return None;
        }
        Unit::try_new(direction, MIN_NORM).map(|direction| Ray { direction })
    }

    pub fn direction(&self) -> &Unit<Vector3<f64>> {
        &self.direction
    }

    /// The point at distance `lambda` along the ray.
    pub fn at(&self, lambda: f64) -> Point3<f64> {
        Point3::from(self.direction.into_inner() * lambda)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn approx(a: &Point3<f64>, b: &Point3<f64>) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn plane_is_normalised() {
        let p = Plane::new(Vector3::new(0.0, 0.0, 2.0), 10.0).unwrap();
        assert_eq!(p.normal().into_inner(), Vector3::z());
        assert_eq!(p.offset(), 5.0);
        assert!(Plane::new(Vector3::zeros(), 1.0).is_none());
        assert!(Plane::from_row([f64::NAN, 0.0, 1.0, 1.0]).is_none());
        assert!(Plane::from_row([0.0, 0.0, 1.0, f64::NAN]).is_none());
    }

    #[test]
    fn ray_meets_plane() {
        let plane = Plane::new(Vector3::new(0.0, 0.0, 1.0), 5.0).unwrap();
        let ray = Ray::new(Vector3::new(1.0, 0.0, 1.0)).unwrap();
        let p = plane.intersect(&ray, 1e-3).unwrap();
        assert!(approx(&p, &Point3::new(5.0, 0.0, 5.0)));
        assert!(plane.signed_distance(&p).abs() < 1e-12);
        // Same plane, opposite orientation: same point.
        let q = plane.flipped().intersect(&ray, 1e-3).unwrap();
        assert!(approx(&p, &q));
    }

    #[test]
    fn grazing_and_behind_are_rejected() {
        let plane = Plane::new(Vector3::new(0.0, 0.0, 1.0), 5.0).unwrap();
        let grazing = Ray::new(Vector3::new(1.0, 0.0, 1e-4)).unwrap();
        assert!(plane.intersect(&grazing, 1e-3).is_none());
        assert!(plane.intersect(&grazing, 1e-5).is_some());
        let behind = Plane::new(Vector3::new(0.0, 0.0, 1.0), -5.0).unwrap();
        let ray = Ray::new(Vector3::z()).unwrap();
        assert!(behind.intersect(&ray, 1e-3).is_none());
        let through_centre = Plane::new(Vector3::new(1.0, 0.0, 0.0), 0.0).unwrap();
        assert!(through_centre.intersect(&ray, 0.0).is_none());
        assert!(Ray::new(Vector3::zeros()).is_none());
    }

    #[test]
    fn lerp_aligns_signs_and_renormalises() {
        let a = Plane::new(Vector3::new(1.0, 0.0, 0.0), 1.0).unwrap();
        let b = Plane::new(Vector3::new(0.6, 0.8, 0.0), 3.0).unwrap();
        let mid = Plane::lerp(&a, &b, 0.5);
        // (n, d) = ((0.8, 0.4, 0), 2) before renormalising by |n| = sqrt(0.8).
        let norm = 0.8f64.sqrt();
        let n = Vector3::new(0.8, 0.4, 0.0) / norm;
        assert!((mid.normal().into_inner() - n).norm() < 1e-12);
        assert!((mid.offset() - 2.0 / norm).abs() < 1e-12);
        // b given with the opposite orientation: same plane, a's orientation.
        let mid_flipped = Plane::lerp(&a, &b.flipped(), 0.5);
        assert!((mid_flipped.normal().into_inner() - n).norm() < 1e-12);
        assert!((mid_flipped.offset() - mid.offset()).abs() < 1e-12);
        // End points.
        assert_eq!(Plane::lerp(&a, &b, 0.0), a);
        let end = Plane::lerp(&a, &b.flipped(), 1.0);
        assert!((end.normal().into_inner() - b.normal().into_inner()).norm() < 1e-12);
        assert!((end.offset() - 3.0).abs() < 1e-12);
    }
}
