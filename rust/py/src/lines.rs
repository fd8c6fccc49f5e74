//! The shadow-time map's isochrones and each frame's shadow line on a reference plane (see
//! `gnomon-core`'s `lines`).

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, flags, grid, on_slices, rows};

/// Where a shadow-time map (H, W) float32 crosses each integer frame (see
/// `gnomon_core::isochrone_crossings`): `(frame (K,) int64, u (K,), v (K,))`.
#[pyfunction]
#[pyo3(signature = (times, n_frames, unique = true))]
pub(crate) fn isochrone_crossings<'py>(
    py: Python<'py>, times: &Bound<'py, PyAny>, n_frames: i64, unique: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let (times, _, w) = grid::<f32>(times, "times")?;
    let out = on_slices!(py, [times] => {
        gnomon_core::isochrone_crossings(times, w.max(1), n_frames, unique)
    })?;
    let (frame, u, v) =
        (out.frame.into_pyarray(py), out.u.into_pyarray(py), out.v.into_pyarray(py));
    PyTuple::new(py, [frame.into_any(), u.into_any(), v.into_any()])
}

/// Every frame's own shadow line on a reference plane (see `gnomon_core::frame_lines`):
/// `(accepted (N,) bool, centre (N, 2), direction (N, 2), rms (N,), count (N,) int64,
/// extent (N,), inliers (K,) bool)`.
#[pyfunction]
#[pyo3(signature = (xy, bounds, k, iterations, min_points, min_extent_to_rms, min_extent_fraction))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn frame_lines<'py>(
    py: Python<'py>, xy: &Bound<'py, PyAny>, bounds: &Bound<'py, PyAny>, k: f64, iterations: usize,
    min_points: usize, min_extent_to_rms: f64, min_extent_fraction: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let xy = borrow::<f64, 2>(xy, "xy", [Any("K"), Exactly(2)])?;
    let bounds = borrow::<i64, 1>(bounds, "bounds", [Any("N + 1")])?;
    let params = gnomon_core::LineParams {
        k,
        iterations,
        min_points,
        min_extent_to_rms,
        min_extent_fraction,
    };
    let out = on_slices!(py, [xy, bounds] => gnomon_core::frame_lines(xy, bounds, &params))?;
    PyTuple::new(
        py,
        [
            flags(&out.accepted).into_pyarray(py).into_any(),
            rows(py, out.centre)?.into_any(),
            rows(py, out.direction)?.into_any(),
            out.rms.into_pyarray(py).into_any(),
            out.count.into_pyarray(py).into_any(),
            out.extent.into_pyarray(py).into_any(),
            flags(&out.inliers).into_pyarray(py).into_any(),
        ],
    )
}

/// When a plane's shadow lines pass each of its points (see `gnomon_core::line_times`): times (K,)
/// in frames, NaN where the lines do not bracket the point.
#[pyfunction]
#[pyo3(signature = (xy, lines, frames, steps))]
pub(crate) fn line_times<'py>(
    py: Python<'py>, xy: &Bound<'py, PyAny>, lines: &Bound<'py, PyAny>, frames: &Bound<'py, PyAny>,
    steps: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let xy = borrow::<f64, 2>(xy, "xy", [Any("K"), Exactly(2)])?;
    let lines = borrow::<f64, 2>(lines, "lines", [Any("N"), Exactly(3)])?;
    let frames = borrow::<i64, 1>(frames, "frames", [Any("N")])?;
    let out =
        on_slices!(py, [xy, lines, frames] => gnomon_core::line_times(xy, lines, frames, steps))?;
    Ok(out.into_pyarray(py))
}
