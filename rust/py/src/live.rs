//! The live watch's results: the pixels whose dip ended, as `FinishedPixels`.

use gnomon_core::FinishedPixel;
use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// Pixels whose dip ended (the live watch): 1-D arrays, one entry per pixel.
#[pyclass(module = "gnomon._kernel", name = "FinishedPixels", frozen)]
pub(crate) struct PyFinishedPixels {
    /// Row-major pixel index `y * width + x` (int64).
    #[pyo3(get)]
    index: Py<PyArray1<i64>>,
    /// Frame at which the recovery was confirmed (int64).
    #[pyo3(get)]
    frame: Py<PyArray1<i64>>,
    /// Lit level before the dip (DN of the input).
    #[pyo3(get)]
    imax: Py<PyArray1<f32>>,
    /// The dip's darkest sample (DN of the input).
    #[pyo3(get)]
    imin: Py<PyArray1<f32>>,
    /// Mid-level in linear irradiance.
    #[pyo3(get)]
    threshold: Py<PyArray1<f32>>,
    /// Provisional entering-edge time (frames), NaN = not in the ring.
    #[pyo3(get)]
    enter: Py<PyArray1<f32>>,
    /// Provisional leaving-edge time (frames).
    #[pyo3(get)]
    leave: Py<PyArray1<f32>>,
    /// Linear irradiance change per frame at the entering crossing.
    #[pyo3(get)]
    enter_slope: Py<PyArray1<f32>>,
    /// Same at the leaving crossing.
    #[pyo3(get)]
    leave_slope: Py<PyArray1<f32>>,
}

#[pymethods]
impl PyFinishedPixels {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.index.bind(py).len()
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("FinishedPixels(n={})", self.__len__(py))
    }
}

impl PyFinishedPixels {
    /// The kernel's items as columns.
    pub(crate) fn new(py: Python<'_>, pixels: &[FinishedPixel]) -> Self {
        let column_i = |f: fn(&FinishedPixel) -> i64| {
            Array1::from_iter(pixels.iter().map(f)).into_pyarray(py).unbind()
        };
        let column_f = |f: fn(&FinishedPixel) -> f32| {
            Array1::from_iter(pixels.iter().map(f)).into_pyarray(py).unbind()
        };
        PyFinishedPixels {
            index: column_i(|p| i64::from(p.index)),
            frame: column_i(|p| i64::from(p.frame)),
            imax: column_f(|p| p.imax),
            imin: column_f(|p| p.imin),
            threshold: column_f(|p| p.threshold),
            enter: column_f(|p| p.enter),
            leave: column_f(|p| p.leave),
            enter_slope: column_f(|p| p.enter_slope),
            leave_slope: column_f(|p| p.leave_slope),
        }
    }
}
