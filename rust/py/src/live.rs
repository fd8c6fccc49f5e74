//! The live watch's results: the pixels whose dip ended, as `FinishedPixels`.

use gnomon_core::FinishedPixel;
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;

use crate::results::result_class;

result_class! {
    /// Pixels whose dip ended (the live watch): 1-D arrays, one entry per pixel.
    "FinishedPixels" PyFinishedPixels: columns of FinishedPixel {
        /// Row-major pixel index `y * width + x` (int64).
        index: i64,
        /// Frame at which the recovery was confirmed (int64).
        frame: i64,
        /// Lit level before the dip (DN of the input).
        imax: f32,
        /// The dip's darkest sample (DN of the input).
        imin: f32,
        /// Mid-level in linear irradiance.
        threshold: f32,
        /// Provisional entering-edge time (frames), NaN = not in the ring.
        enter: f32,
        /// Provisional leaving-edge time (frames).
        leave: f32,
        /// Linear irradiance change per frame at the entering crossing.
        enter_slope: f32,
        /// Same at the leaving crossing.
        leave_slope: f32,
    }
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
