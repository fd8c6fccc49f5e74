//! A compressed video's shadow times between its codec blocks' centres (see `gnomon-core`'s
//! `deblock`).

use numpy::PyArray2;
use pyo3::prelude::*;

use crate::arrays::{grid, image, on_slices};

/// Each pixel of `times` (H, W) float32 interpolated between the four centres of the blocks of
/// `value` (blocks_y, blocks_x) float64 around it (see `gnomon_core::deblock_interpolate`): (H, W)
/// float32.
#[pyfunction]
#[pyo3(signature = (times, value, size, u0, v0, span_max))]
pub(crate) fn deblock_interpolate<'py>(
    py: Python<'py>, times: &Bound<'py, PyAny>, value: &Bound<'py, PyAny>, size: usize, u0: usize,
    v0: usize, span_max: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (times, h, w) = grid::<f32>(times, "times")?;
    let (value, blocks_y, blocks_x) = grid::<f64>(value, "value")?;
    let layout = gnomon_core::BlockLayout { size, u0, v0, blocks_x, blocks_y };
    let out = on_slices!(py, [times, value] => {
        gnomon_core::deblock_interpolate(times, w.max(1), value, layout, span_max)
    })?;
    image(py, out, h, w)
}
