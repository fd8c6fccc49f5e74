//! The unit ray of every pixel of OpenCV's 5-coefficient camera (see `gnomon-core`'s `camera`).

use numpy::{PyArray2, PyArray3};
use pyo3::prelude::*;

use crate::arrays::{grid3, mask};
use crate::errors::kernel_error;

/// `(rays (H, W, 3) float64, solved (H, W) bool)`.
type RaysAndMask<'py> = (Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<bool>>);

/// Unit rays (H, W, 3) float64 of every pixel of OpenCV's 5-coefficient camera and their
/// solved mask (see `gnomon_core::ray_map`).
#[pyfunction]
#[pyo3(signature = (width, height, intrinsics, dist, tol_px, max_steps))]
pub(crate) fn ray_map<'py>(
    py: Python<'py>, width: usize, height: usize, intrinsics: [f64; 4], dist: [f64; 5],
    tol_px: f64, max_steps: u32,
) -> PyResult<RaysAndMask<'py>> {
    let (rays, solved) = py
        .detach(|| gnomon_core::ray_map(width, height, intrinsics, dist, tol_px, max_steps))
        .map_err(kernel_error)?;
    Ok((grid3(py, rays, height, width)?, mask(py, solved, height, width)?))
}
