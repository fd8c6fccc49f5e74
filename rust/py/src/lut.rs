//! A per-code table at each level's code in a sorted decoding table (see `gnomon-core`'s `lut`).

use numpy::{IntoPyArray, PyArray1, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, on_slices};

/// `(scale * table[clip(searchsorted(lut, values), 0, N - 1)]).astype(float32)` of the flat
/// float32 `values` (K,), `lut` (N,) float32 sorted, `table` (N,) float64 (see
/// `gnomon_core::lut_lookup`): (K,) float32.
#[pyfunction]
#[pyo3(signature = (lut, table, scale, values))]
pub(crate) fn lut_lookup<'py>(
    py: Python<'py>, lut: &Bound<'py, PyAny>, table: &Bound<'py, PyAny>, scale: f64,
    values: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let lut = borrow::<f32, 1>(lut, "lut", [Any("N")])?;
    let table = borrow::<f64, 1>(table, "table", [Exactly(lut.len())])?;
    let values = borrow::<f32, 1>(values, "values", [Any("K")])?;
    let out =
        on_slices!(py, [lut, table, values] => gnomon_core::lut_lookup(lut, table, scale, values))?;
    Ok(out.into_pyarray(py))
}
