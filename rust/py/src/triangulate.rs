//! Triangulation: camera rays ∩ the shadow planes at each pixel's time, the depth's σ, and
//! the angles between rays and planes (see `gnomon-core`'s `triangulate`).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, camera_rays, grid, grid3, image, mask, on_slices, Borrowed};

/// `(points (H, W, 3) float32, valid (H, W) bool)`.
type PointsAndMask<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<bool>>);

/// Borrow `obj` as the (N, 4) float64 shadow planes, one row per frame.
fn shadow_planes<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Borrowed<'py, f64, 2>> {
    borrow::<f64, 2>(obj, "planes", [Any("N"), Exactly(4)])
}

/// Camera rays ∩ shadow planes interpolated at each pixel's shadow time.
#[pyfunction]
#[pyo3(signature = (rays, times, planes, min_cos = 1e-3))]
pub(crate) fn triangulate<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>, min_cos: f64,
) -> PyResult<PointsAndMask<'py>> {
    let (times, h, w) = grid::<f32>(times, "times")?;
    let (rays, planes) = (camera_rays(rays, h, w)?, shadow_planes(planes)?);
    let (points, valid) = on_slices!(py, [rays, times, planes] => {
        gnomon_core::triangulate(rays, times, planes, min_cos)
    })?;
    Ok((grid3(py, points, h, w)?, mask(py, valid, h, w)?))
}

/// (H, W) float32 camera Z of [`triangulate`]'s points, NaN where it gives none (see
/// `gnomon_core::triangulate_depth`).
#[pyfunction]
#[pyo3(signature = (rays, times, planes, min_cos = 1e-3))]
pub(crate) fn triangulate_depth<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>, min_cos: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (times, h, w) = grid::<f32>(times, "times")?;
    let (rays, planes) = (camera_rays(rays, h, w)?, shadow_planes(planes)?);
    let depth = on_slices!(py, [rays, times, planes] => {
        gnomon_core::triangulate_depth(rays, times, planes, min_cos)
    })?;
    image(py, depth, h, w)
}

/// σZ, ∂Z/∂t and the line's time σ of every pixel, each (H, W) float32 (see
/// `gnomon_core::depth_sigma`).
#[pyfunction]
#[pyo3(signature = (rays, times, planes, depth, sigma_t_pixel, line_sigma, line_fill, step, min_cos = 1e-3))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn depth_sigma<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>, depth: &Bound<'py, PyAny>, sigma_t_pixel: &Bound<'py, PyAny>,
    line_sigma: &Bound<'py, PyAny>, line_fill: f64, step: f64, min_cos: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let (times, h, w) = grid::<f32>(times, "times")?;
    let (rays, planes) = (camera_rays(rays, h, w)?, shadow_planes(planes)?);
    let depth = borrow::<f32, 2>(depth, "depth", [Exactly(h), Exactly(w)])?;
    let sigma_t_pixel = borrow::<f32, 2>(sigma_t_pixel, "sigma_t_pixel", [Exactly(h), Exactly(w)])?;
    let line_sigma = borrow::<f64, 1>(line_sigma, "line_sigma", [Any("N")])?;
    let out = on_slices!(py, [rays, times, planes, depth, sigma_t_pixel, line_sigma] => {
        let (line, t) = (line_sigma, sigma_t_pixel);
        gnomon_core::depth_sigma(rays, times, planes, depth, t, line, line_fill, step, min_cos)
    })?;
    let sigmas = [out.sigma_z, out.dz_dt, out.sigma_t_line];
    PyTuple::new(py, sigmas.into_iter().map(|s| image(py, s, h, w)).collect::<PyResult<Vec<_>>>()?)
}

/// The σZ a completed plane's own error adds at each pixel, (H, W) float32 (see
/// `gnomon_core::completion_sigma`).
#[pyfunction]
#[pyo3(signature = (rays, times, depth, planes, line_point, line_direction, sigma_rad, min_cos = 1e-3))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn completion_sigma<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>, planes: &Bound<'py, PyAny>, line_point: &Bound<'py, PyAny>,
    line_direction: &Bound<'py, PyAny>, sigma_rad: f64, min_cos: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (times, h, w) = grid::<f64>(times, "times")?;
    let rays = camera_rays(rays, h, w)?;
    let depth = borrow::<f64, 2>(depth, "depth", [Exactly(h), Exactly(w)])?;
    let planes = shadow_planes(planes)?;
    let lines = [Exactly(planes.shape()[0]), Exactly(3)];
    let line_point = borrow::<f64, 2>(line_point, "line_point", lines)?;
    let line_direction = borrow::<f64, 2>(line_direction, "line_direction", lines)?;
    let sigma = on_slices!(py, [rays, times, depth, planes, line_point, line_direction] => {
        let completion = gnomon_core::Completion { line_point, line_direction, sigma_rad };
        gnomon_core::completion_sigma(rays, times, depth, planes, completion, min_cos)
    })?;
    image(py, sigma, h, w)
}

/// Angles (degrees) between the selected pixels' rays and their shadow planes (see
/// `gnomon_core::ray_plane_angles`), row-major.
#[pyfunction]
#[pyo3(signature = (rays, times, planes, selected))]
pub(crate) fn ray_plane_angles<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>, selected: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (times, h, w) = grid::<f64>(times, "times")?;
    let (rays, planes) = (camera_rays(rays, h, w)?, shadow_planes(planes)?);
    let selected = borrow::<u8, 2>(selected, "selected", [Exactly(h), Exactly(w)])?;
    let angles = on_slices!(py, [rays, times, planes, selected] => {
        gnomon_core::ray_plane_angles(rays, times, planes, selected)
    })?;
    Ok(angles.into_pyarray(py))
}
