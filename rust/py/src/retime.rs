//! A fast sweep's shadow times re-timed between the isochrones, their σ, and their average
//! across the sweep (see `gnomon-core`'s `retime`).

use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, grid, image, mask, on_slices, rows, Borrowed};

/// Borrow the (H, W) float64 times of a retiming with their `index` (int64) and `wanted`
/// (uint8) maps of the same shape: the three, H and W.
type Retiming<'py> =
    (Borrowed<'py, f64, 2>, Borrowed<'py, i64, 2>, Borrowed<'py, u8, 2>, usize, usize);

fn retiming<'py>(
    times: &Bound<'py, PyAny>, index: &Bound<'py, PyAny>, wanted: &Bound<'py, PyAny>,
) -> PyResult<Retiming<'py>> {
    let (times, h, w) = grid::<f64>(times, "times")?;
    let index = borrow::<i64, 2>(index, "index", [Exactly(h), Exactly(w)])?;
    let wanted = borrow::<u8, 2>(wanted, "wanted", [Exactly(h), Exactly(w)])?;
    Ok((times, index, wanted, h, w))
}

/// The rows of an oriented shadow-time map re-timed between its isochrones (see
/// `gnomon_core::retime_rows`): `(times (H, W) float32, done (H, W) bool, pixel (P,) int64,
/// left (P, 2) int64, right (P, 2) int64, phase (P, 2), rise (P, 2), gap (P,), f (P,))`.
#[pyfunction]
#[pyo3(signature = (times, index, wanted, n_frames, max_gap, min_gap, backstep))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn retime_rows<'py>(
    py: Python<'py>, times: &Bound<'py, PyAny>, index: &Bound<'py, PyAny>,
    wanted: &Bound<'py, PyAny>, n_frames: i64, max_gap: f64, min_gap: f64, backstep: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let (times, index, wanted, h, w) = retiming(times, index, wanted)?;
    let params = gnomon_core::RetimeParams { n_frames, max_gap, min_gap, backstep };
    let r = on_slices!(py, [times, index, wanted] => {
        gnomon_core::retime_rows(times, index, wanted, w.max(1), params)
    })?;
    PyTuple::new(
        py,
        [
            image(py, r.times, h, w)?.into_any(),
            mask(py, r.done, h, w)?.into_any(),
            r.pixel.into_pyarray(py).into_any(),
            rows(py, r.left)?.into_any(),
            rows(py, r.right)?.into_any(),
            rows(py, r.phase)?.into_any(),
            rows(py, r.rise)?.into_any(),
            r.gap.into_pyarray(py).into_any(),
            r.f.into_pyarray(py).into_any(),
        ],
    )
}

/// `retime_rows` and the σ of every pixel's time, without the crossings' details (see
/// `gnomon_core::retime_rows_sigma`): (times float32, re-timed bool, σ float32), each (H, W).
#[pyfunction]
#[pyo3(signature = (times, index, wanted, sigma, n_frames, max_gap, min_gap, backstep))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn retime_rows_sigma<'py>(
    py: Python<'py>, times: &Bound<'py, PyAny>, index: &Bound<'py, PyAny>,
    wanted: &Bound<'py, PyAny>, sigma: &Bound<'py, PyAny>, n_frames: i64, max_gap: f64,
    min_gap: f64, backstep: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let (times, index, wanted, h, w) = retiming(times, index, wanted)?;
    let sigma = borrow::<f64, 1>(sigma, "sigma", [Any("N")])?;
    let params = gnomon_core::RetimeParams { n_frames, max_gap, min_gap, backstep };
    let r = on_slices!(py, [times, index, wanted, sigma] => {
        gnomon_core::retime_rows_sigma(times, index, wanted, sigma, w.max(1), params)
    })?;
    let (times, done, sigma) =
        (image(py, r.times, h, w)?, mask(py, r.done, h, w)?, image(py, r.sigma, h, w)?);
    PyTuple::new(py, [times.into_any(), done.into_any(), sigma.into_any()])
}

/// (H, W) float32: re-timed times averaged across the sweep (see `gnomon_core::average_across`);
/// `retimed` (H, W) uint8 (non-zero = re-timed).
#[pyfunction]
#[pyo3(signature = (times, retimed, across_rows, half, bend))]
pub(crate) fn average_across<'py>(
    py: Python<'py>, times: &Bound<'py, PyAny>, retimed: &Bound<'py, PyAny>, across_rows: bool,
    half: usize, bend: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (times, h, w) = grid::<f32>(times, "times")?;
    let retimed = borrow::<u8, 2>(retimed, "retimed", [Exactly(h), Exactly(w)])?;
    let out = on_slices!(py, [times, retimed] => {
        gnomon_core::average_across(times, retimed, w.max(1), across_rows, half, bend)
    })?;
    image(py, out, h, w)
}
