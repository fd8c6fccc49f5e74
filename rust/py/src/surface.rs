//! The surface on the pixel grid: fused depths, world points, normals, lit colours and a
//! mesh's STL records (see `gnomon-core`'s `surface`).

use numpy::{IntoPyArray, PyArray1, PyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, camera_rays, grid, grid3, image, on_slices, shape_error};
use crate::errors::KernelArrayError;

/// Fused depth and σ of K estimates per pixel, neighbour-supported only, and each pixel's code
/// (0 none, 1 kept, 2 conflict, 3 unsupported), each (H, W) (see `gnomon_core::fuse_supported`).
#[pyfunction]
#[pyo3(signature = (depths, sigmas, max_relative_jump, min_support = 2))]
pub(crate) fn fuse_supported<'py>(
    py: Python<'py>, depths: &Bound<'py, PyAny>, sigmas: &Bound<'py, PyAny>,
    max_relative_jump: f64, min_support: usize,
) -> PyResult<Bound<'py, PyTuple>> {
    let depths = borrow::<f32, 3>(depths, "depths", [Any("K"), Any("H"), Any("W")])?;
    let (k, h, w) = (depths.shape()[0], depths.shape()[1], depths.shape()[2]);
    let sigmas = borrow::<f32, 3>(sigmas, "sigmas", [Exactly(k), Exactly(h), Exactly(w)])?;
    let (depth, sigma, code) = on_slices!(py, [depths, sigmas] => {
        gnomon_core::fuse_supported(depths, sigmas, k, w.max(1), max_relative_jump, min_support)
    })?;
    let (depth, sigma, code) =
        (image(py, depth, h, w)?, image(py, sigma, h, w)?, image(py, code, h, w)?);
    PyTuple::new(py, [depth.into_any(), sigma.into_any(), code.into_any()])
}

/// Per pixel and channel, the median of the frames it is lit in: (H, W, C) uint8 of a stack
/// (K, H, W, C), C 3 (RGB) or 1 (grey) (see `gnomon_core::lit_median_channels`).
#[pyfunction]
#[pyo3(signature = (stack, lit))]
pub(crate) fn lit_median<'py>(
    py: Python<'py>, stack: &Bound<'py, PyAny>, lit: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let lit = borrow::<u8, 3>(lit, "lit", [Any("K"), Any("H"), Any("W")])?;
    let (k, h, w) = (lit.shape()[0], lit.shape()[1], lit.shape()[2]);
    let stack = borrow::<u8, 4>(stack, "stack", [Exactly(k), Exactly(h), Exactly(w), Any("C")])?;
    let channels = colour_channels(stack.shape()[3])?;
    let out =
        on_slices!(py, [stack, lit] => gnomon_core::lit_median_channels(stack, lit, k, channels))?;
    pixel_channels(py, out, h, w, channels)
}

/// [`lit_median`] with the lit frames found per pixel from its shadow interval: `times` (K,)
/// the kept frames' capture frames, `start` and `end` (H, W) float64 (see
/// `gnomon_core::lit_median_between`); (H, W, C) uint8.
#[pyfunction]
#[pyo3(signature = (stack, times, start, end, margin))]
pub(crate) fn lit_median_between<'py>(
    py: Python<'py>, stack: &Bound<'py, PyAny>, times: &Bound<'py, PyAny>,
    start: &Bound<'py, PyAny>, end: &Bound<'py, PyAny>, margin: f64,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let (start, h, w) = grid::<f64>(start, "start")?;
    let end = borrow::<f64, 2>(end, "end", [Exactly(h), Exactly(w)])?;
    let times = borrow::<f64, 1>(times, "times", [Any("K")])?;
    let k = times.shape()[0];
    let stack = borrow::<u8, 4>(stack, "stack", [Exactly(k), Exactly(h), Exactly(w), Any("C")])?;
    let channels = colour_channels(stack.shape()[3])?;
    let out = on_slices!(py, [stack, times, start, end] => {
        gnomon_core::lit_median_between(stack, times, start, end, margin, channels)
    })?;
    pixel_channels(py, out, h, w, channels)
}

/// A colour stack's channels: 1 (grey) or 3 (RGB), else an error.
fn colour_channels(channels: usize) -> PyResult<usize> {
    if channels == 1 || channels == 3 {
        Ok(channels)
    } else {
        Err(KernelArrayError::new_err(format!("stack: expected 1 or 3 channels, got {channels}")))
    }
}

/// A row-major (height, width, channels) core result as a numpy array.
fn pixel_channels<'py>(
    py: Python<'py>, data: Vec<u8>, height: usize, width: usize, channels: usize,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let array = numpy::ndarray::Array3::from_shape_vec((height, width, channels), data)
        .map_err(shape_error)?;
    Ok(array.into_pyarray(py))
}

/// World-frame points (H, W, 3) float32 of a depth map, NaN off the surface (see
/// `gnomon_core::world_points`).
#[pyfunction]
#[pyo3(signature = (rays, depth, valid, rotation, translation))]
pub(crate) fn world_points<'py>(
    py: Python<'py>, rays: &Bound<'py, PyAny>, depth: &Bound<'py, PyAny>,
    valid: &Bound<'py, PyAny>, rotation: [[f64; 3]; 3], translation: [f64; 3],
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (depth, h, w) = grid::<f32>(depth, "depth")?;
    let valid = borrow::<u8, 2>(valid, "valid", [Exactly(h), Exactly(w)])?;
    let rays = camera_rays(rays, h, w)?;
    let points = on_slices!(py, [rays, depth, valid] => {
        gnomon_core::world_points(rays, depth, valid, w.max(1), rotation, translation)
    })?;
    grid3(py, points, h, w)
}

/// Unit normals (H, W, 3) float32 of the surface on the pixel grid (see `gnomon_core::grid_normals`).
#[pyfunction]
#[pyo3(signature = (points, depth, valid, camera_centre, max_relative_jump))]
pub(crate) fn grid_normals<'py>(
    py: Python<'py>, points: &Bound<'py, PyAny>, depth: &Bound<'py, PyAny>,
    valid: &Bound<'py, PyAny>, camera_centre: [f64; 3], max_relative_jump: f64,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (valid, h, w) = grid::<u8>(valid, "valid")?;
    let depth = borrow::<f32, 2>(depth, "depth", [Exactly(h), Exactly(w)])?;
    let points = borrow::<f32, 3>(points, "points", [Exactly(h), Exactly(w), Exactly(3)])?;
    let normals = on_slices!(py, [points, depth, valid] => {
        gnomon_core::grid_normals(points, depth, valid, w.max(1), camera_centre, max_relative_jump)
    })?;
    grid3(py, normals, h, w)
}

/// The records of a binary STL file (F·50,) uint8 (see `gnomon_core::stl_records`).
#[pyfunction]
#[pyo3(signature = (vertices, faces))]
pub(crate) fn stl_records<'py>(
    py: Python<'py>, vertices: &Bound<'py, PyAny>, faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<u8>>> {
    let vertices = borrow::<f32, 2>(vertices, "vertices", [Any("V"), Exactly(3)])?;
    let faces = borrow::<i32, 2>(faces, "faces", [Any("F"), Exactly(3)])?;
    let records = on_slices!(py, [vertices, faces] => gnomon_core::stl_records(vertices, faces))?;
    Ok(records.into_pyarray(py))
}
