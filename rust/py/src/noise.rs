//! The image-noise estimate's samples and the steps of its clipped fit (see `gnomon-core`'s
//! `noise`).

use gnomon_core::Sample;
use numpy::{IntoPyArray, PyArray1, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, on_slices, Dtype};
use crate::errors::KernelParameterError;

/// What `noise_samples` returns: the differences and centred levels (float32), the median and MAD.
type NoiseSamplesResult<'py> =
    Option<(Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>, f64, f64)>;

fn noise_samples_of<'py, T: Sample + Dtype>(
    py: Python<'py>, a: &Bound<'py, PyAny>, b: &Bound<'py, PyAny>, min_inside: usize,
) -> PyResult<NoiseSamplesResult<'py>> {
    let a = borrow::<T, 1>(a, "a", [Any("N")])?;
    let b = borrow::<T, 1>(b, "b", [Exactly(a.len())])?;
    let samples = on_slices!(py, [a, b] => gnomon_core::noise_samples(a, b, min_inside))?;
    Ok(samples.map(|s| (s.diff.into_pyarray(py), s.level.into_pyarray(py), s.median, s.mad)))
}

/// The samples of a uint8 or uint16 frame pair (flat, one dtype) the noise estimate fits, and
/// its starting median and MAD (see `gnomon_core::noise_samples`); None when fewer than
/// `min_inside` pixels are inside the range.
#[pyfunction]
#[pyo3(signature = (a, b, min_inside))]
pub(crate) fn noise_samples<'py>(
    py: Python<'py>, a: &Bound<'py, PyAny>, b: &Bound<'py, PyAny>, min_inside: usize,
) -> PyResult<NoiseSamplesResult<'py>> {
    let dtype: String = a.getattr("dtype")?.getattr("name")?.extract()?;
    match dtype.as_str() {
        "uint8" => noise_samples_of::<u8>(py, a, b, min_inside),
        "uint16" => noise_samples_of::<u16>(py, a, b, min_inside),
        other => Err(KernelParameterError::new_err(format!(
            "a: expected uint8 or uint16 samples, got {other:?}"
        ))),
    }
}

/// One step of the image-noise estimate's clipped fit (see `gnomon_core::clipped_fit_step`):
/// `(kept, offset, gain, rms)` (the three float32 values as floats), or None when fewer than
/// `min_kept` pixels are kept.
#[pyfunction]
#[pyo3(signature = (diff, level, offset, gain, limit, min_kept))]
pub(crate) fn clipped_fit_step<'py>(
    py: Python<'py>, diff: &Bound<'py, PyAny>, level: &Bound<'py, PyAny>, offset: f64, gain: f64,
    limit: f64, min_kept: usize,
) -> PyResult<Option<(usize, f64, f64, f64)>> {
    let diff = borrow::<f32, 1>(diff, "diff", [Any("N")])?;
    let level = borrow::<f32, 1>(level, "level", [Exactly(diff.len())])?;
    let fit = on_slices!(py, [diff, level] => {
        gnomon_core::clipped_fit_step(diff, level, offset, gain, limit, min_kept)
    })?;
    Ok(fit.map(|f| (f.kept, f64::from(f.offset), f64::from(f.gain), f64::from(f.rms))))
}
