//! The tracker's result types as frozen classes of read-only numpy arrays: `ShadowTimes` and
//! `SecondDips` (the live watch's `FinishedPixels` is in [`crate::live`]).

use gnomon_core::{SecondDips, ShadowTimes};
use numpy::{PyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{image, mask};

/// The tracker's per-pixel results: (H, W) arrays, read-only attributes.
#[pyclass(module = "gnomon._kernel", name = "ShadowTimes", frozen)]
pub(crate) struct PyShadowTimes {
    /// Brightest level of the deepest dip (DN of the input; fractional when normalised).
    #[pyo3(get)]
    imax: Py<PyArray2<f32>>,
    /// Darkest sample of the dip (DN of the input).
    #[pyo3(get)]
    imin: Py<PyArray2<f32>>,
    /// `imax - imin` (DN), 0 = no dip.
    #[pyo3(get)]
    contrast: Py<PyArray2<f32>>,
    /// Mid-level in linear irradiance (in the light of the dip).
    #[pyo3(get)]
    threshold: Py<PyArray2<f32>>,
    /// Entering-edge time (frames), NaN = none.
    #[pyo3(get)]
    enter: Py<PyArray2<f32>>,
    /// Leaving-edge time (frames), NaN = none.
    #[pyo3(get)]
    leave: Py<PyArray2<f32>>,
    /// Linear irradiance change per frame at the entering crossing.
    #[pyo3(get)]
    enter_slope: Py<PyArray2<f32>>,
    /// Linear irradiance change per frame at the leaving crossing.
    #[pyo3(get)]
    leave_slope: Py<PyArray2<f32>>,
    /// Depth of the deepest other dip (DN), 0 = none.
    #[pyo3(get)]
    rival: Py<PyArray2<f32>>,
    /// A dip with `contrast >= min_contrast` that is not ambiguous.
    #[pyo3(get)]
    valid: Py<PyArray2<bool>>,
    /// `contrast >= min_contrast` and the rival dip at least `ambiguity` times as deep.
    #[pyo3(get)]
    ambiguous: Py<PyArray2<bool>>,
    /// The dip's levels or an interpolated sample at 0 or the dtype's maximum.
    #[pyo3(get)]
    clipped: Py<PyArray2<bool>>,
}

#[pymethods]
impl PyShadowTimes {
    /// `(height, width)`.
    #[getter]
    fn shape(&self, py: Python<'_>) -> (usize, usize) {
        let s = self.enter.bind(py).shape();
        (s[0], s[1])
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let (h, w) = self.shape(py);
        format!("ShadowTimes(height={h}, width={w})")
    }
}

impl PyShadowTimes {
    /// The kernel's result as numpy arrays.
    pub(crate) fn new(py: Python<'_>, times: ShadowTimes) -> PyResult<Self> {
        let (h, w) = (times.height, times.width);
        Ok(PyShadowTimes {
            imax: image(py, times.imax, h, w)?.unbind(),
            imin: image(py, times.imin, h, w)?.unbind(),
            contrast: image(py, times.contrast, h, w)?.unbind(),
            threshold: image(py, times.threshold, h, w)?.unbind(),
            enter: image(py, times.enter, h, w)?.unbind(),
            leave: image(py, times.leave, h, w)?.unbind(),
            enter_slope: image(py, times.enter_slope, h, w)?.unbind(),
            leave_slope: image(py, times.leave_slope, h, w)?.unbind(),
            rival: image(py, times.rival, h, w)?.unbind(),
            valid: mask(py, times.valid, h, w)?.unbind(),
            ambiguous: mask(py, times.ambiguous, h, w)?.unbind(),
            clipped: mask(py, times.clipped, h, w)?.unbind(),
        })
    }
}

/// Every pixel's second candidate dip: (H, W) arrays, read-only attributes
/// (same meanings as `ShadowTimes`'; NaN times and 0 levels where there is none).
#[pyclass(module = "gnomon._kernel", name = "SecondDips", frozen)]
pub(crate) struct PySecondDips {
    #[pyo3(get)]
    imax: Py<PyArray2<f32>>,
    #[pyo3(get)]
    imin: Py<PyArray2<f32>>,
    #[pyo3(get)]
    contrast: Py<PyArray2<f32>>,
    #[pyo3(get)]
    threshold: Py<PyArray2<f32>>,
    #[pyo3(get)]
    enter: Py<PyArray2<f32>>,
    #[pyo3(get)]
    leave: Py<PyArray2<f32>>,
    #[pyo3(get)]
    enter_slope: Py<PyArray2<f32>>,
    #[pyo3(get)]
    leave_slope: Py<PyArray2<f32>>,
    /// The best dip's times and slopes wherever it exists (also ambiguous ones).
    #[pyo3(get)]
    best_enter: Py<PyArray2<f32>>,
    #[pyo3(get)]
    best_leave: Py<PyArray2<f32>>,
    #[pyo3(get)]
    best_enter_slope: Py<PyArray2<f32>>,
    #[pyo3(get)]
    best_leave_slope: Py<PyArray2<f32>>,
}

impl PySecondDips {
    /// The kernel's result as numpy arrays.
    pub(crate) fn new(py: Python<'_>, d: SecondDips) -> PyResult<Self> {
        let (h, w) = (d.height, d.width);
        Ok(PySecondDips {
            imax: image(py, d.imax, h, w)?.unbind(),
            imin: image(py, d.imin, h, w)?.unbind(),
            contrast: image(py, d.contrast, h, w)?.unbind(),
            threshold: image(py, d.threshold, h, w)?.unbind(),
            enter: image(py, d.enter, h, w)?.unbind(),
            leave: image(py, d.leave, h, w)?.unbind(),
            enter_slope: image(py, d.enter_slope, h, w)?.unbind(),
            leave_slope: image(py, d.leave_slope, h, w)?.unbind(),
            best_enter: image(py, d.best_enter, h, w)?.unbind(),
            best_leave: image(py, d.best_leave, h, w)?.unbind(),
            best_enter_slope: image(py, d.best_enter_slope, h, w)?.unbind(),
            best_leave_slope: image(py, d.best_leave_slope, h, w)?.unbind(),
        })
    }
}
