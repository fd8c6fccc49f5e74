//! `TemporalTracker`: the streaming per-pixel shadow tracker (see `gnomon-core`'s
//! `TemporalTracker`), over frames of either dtype, and its live watch.

use gnomon_core::{Sample, TemporalTracker as Tracker, TrackerParams, WatchParams};
use pyo3::prelude::*;

use crate::arrays::Extent::Exactly;
use crate::arrays::{borrow, on_slices, Borrowed, Dtype};
use crate::errors::{kernel_error, KernelParameterError};
use crate::live::PyFinishedPixels;
use crate::results::{PySecondDips, PyShadowTimes};

/// The core tracker of the samples it stores: the input's DN (`U8`, `U16`),
/// or normalised codes (`U16`, built with `Tracker::normalised`).
enum AnyTracker {
    U8(Tracker<u8>),
    U16(Tracker<u16>),
}

/// `$body` on the core tracker of either sample type, bound to `$t`.
macro_rules! either {
    ($inner:expr, $t:ident => $body:expr) => {
        match $inner {
            AnyTracker::U8($t) => $body,
            AnyTracker::U16($t) => $body,
        }
    };
}

/// Streaming per-pixel shadow tracker (see `gnomon-core`'s `TemporalTracker`).
#[pyclass(module = "gnomon._kernel", name = "TemporalTracker")]
pub(crate) struct TemporalTracker {
    inner: AnyTracker,
    /// The frames' dtype: "uint8" or "uint16".
    dtype: &'static str,
}

/// Borrow the decoding table of a `dtype` input (`len` entries).
fn table<'py>(lut: &Bound<'py, PyAny>, len: usize) -> PyResult<Borrowed<'py, f32, 1>> {
    borrow::<f32, 1>(lut, "lut", [Exactly(len)])
}

fn plain<T: Sample>(
    height: usize, width: usize, params: TrackerParams, lut: Option<&Bound<'_, PyAny>>,
) -> PyResult<Tracker<T>> {
    let tracker = match lut {
        None => Tracker::new(height, width, params),
        Some(lut) => {
            let lut = table(lut, T::LUT_LEN)?;
            on_slices!([lut] => Tracker::with_table(height, width, params, lut))
        }
    };
    tracker.map_err(kernel_error)
}

/// Borrow `frame` as the next (height, width) frame of `tracker`.
fn frame_of<'py, I: Dtype, T: Sample>(
    tracker: &Tracker<T>, frame: &Bound<'py, PyAny>,
) -> PyResult<Borrowed<'py, I, 2>> {
    borrow::<I, 2>(frame, "frame", [Exactly(tracker.height()), Exactly(tracker.width())])
}

fn update_normalised<I: Sample + Dtype>(
    py: Python<'_>, tracker: &mut Tracker<u16>, frame: &Bound<'_, PyAny>, gain: f64,
) -> PyResult<()> {
    let frame = frame_of::<I, _>(tracker, frame)?;
    on_slices!(py, [frame] => tracker.update_with_gain(frame, gain))
}

fn update_levelled<I: Sample + Dtype>(
    py: Python<'_>, tracker: &mut Tracker<u16>, frame: &Bound<'_, PyAny>, gain: f64,
    levels: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let frame = frame_of::<I, _>(tracker, frame)?;
    let shape = [Exactly(tracker.height()), Exactly(tracker.width())];
    let levels = borrow::<f32, 2>(levels, "levels", shape)?;
    on_slices!(py, [frame, levels] => tracker.update_with_levels(frame, gain, levels))
}

fn update_any<T: Sample + Dtype>(
    py: Python<'_>, tracker: &mut Tracker<T>, frame: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let frame = frame_of::<T, _>(tracker, frame)?;
    on_slices!(py, [frame] => tracker.update(frame))
}

#[pymethods]
impl TemporalTracker {
    #[new]
    #[pyo3(signature = (height, width, dtype = "uint8", window = 4, max_width = 32, ambiguity = 0.6,
                        lut = None, normalise = false, second_dips = false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        height: usize, width: usize, dtype: &str, window: usize, max_width: usize, ambiguity: f32,
        lut: Option<&Bound<'_, PyAny>>, normalise: bool, second_dips: bool,
    ) -> PyResult<Self> {
        let params = TrackerParams { window, max_width, ambiguity, second_dips };
        let (dtype, len) = match dtype {
            "uint8" => (u8::DTYPE, u8::LUT_LEN),
            "uint16" => (u16::DTYPE, u16::LUT_LEN),
            other => {
                return Err(KernelParameterError::new_err(format!(
                    "dtype: expected \"uint8\" or \"uint16\", got {other:?}"
                )))
            }
        };
        let inner = if normalise {
            let Some(lut) = lut else {
                return Err(KernelParameterError::new_err(
                    "lut: a normalised tracker needs the input's decoding table",
                ));
            };
            let lut = table(lut, len)?;
            let tracker = on_slices!([lut] => Tracker::normalised(height, width, params, lut));
            AnyTracker::U16(tracker.map_err(kernel_error)?)
        } else if dtype == u8::DTYPE {
            AnyTracker::U8(plain(height, width, params, lut)?)
        } else {
            AnyTracker::U16(plain(height, width, params, lut)?)
        };
        Ok(TemporalTracker { inner, dtype })
    }

    /// Add the next frame: a 2-D array of the tracker's dtype and shape, and
    /// with a normalised tracker its gain (> 0).
    #[pyo3(signature = (frame, gain = None, levels = None))]
    fn update(
        &mut self, py: Python<'_>, frame: &Bound<'_, PyAny>, gain: Option<f64>,
        levels: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        if let Some(levels) = levels {
            return match (&mut self.inner, gain) {
                (AnyTracker::U16(t), Some(gain)) if t.is_normalised() => match self.dtype {
                    "uint8" => update_levelled::<u8>(py, t, frame, gain, levels),
                    _ => update_levelled::<u16>(py, t, frame, gain, levels),
                },
                _ => Err(KernelParameterError::new_err(
                    "levels: only a normalised tracker takes per-pixel levels, with the frame's gain",
                )),
            };
        }
        match (&mut self.inner, gain) {
            (AnyTracker::U16(t), Some(gain)) if t.is_normalised() => match self.dtype {
                "uint8" => update_normalised::<u8>(py, t, frame, gain),
                _ => update_normalised::<u16>(py, t, frame, gain),
            },
            (AnyTracker::U16(t), None) if t.is_normalised() => Err(KernelParameterError::new_err(
                "gain: a normalised tracker needs each frame's gain",
            )),
            (_, Some(_)) => Err(KernelParameterError::new_err(
                "gain: only a normalised tracker takes a gain with each frame",
            )),
            (AnyTracker::U8(t), None) => update_any(py, t, frame),
            (AnyTracker::U16(t), None) => update_any(py, t, frame),
        }
    }

    /// Per-pixel results for the frames seen so far (the tracker is unchanged);
    /// `min_contrast` in DN of the input.
    fn finish(&self, py: Python<'_>, min_contrast: f32) -> PyResult<PyShadowTimes> {
        let times = either!(&self.inner, t => py.detach(|| t.finish(min_contrast)));
        PyShadowTimes::new(py, times.map_err(kernel_error)?)
    }

    /// Every pixel's second candidate dip (the event whose depth is `rival`),
    /// for the frames seen so far, in `finish`'s units. Needs a tracker built
    /// with `second_dips=True` (KernelParameterError otherwise).
    fn finish_second(&self, py: Python<'_>) -> PyResult<PySecondDips> {
        let dips = either!(&self.inner, t => py.detach(|| t.finish_second()));
        PySecondDips::new(py, dips.map_err(kernel_error)?)
    }

    /// Start the live watch from the next frame on (see `gnomon-core`'s `live`).
    #[pyo3(signature = (min_contrast, recover = 3))]
    fn watch(&mut self, min_contrast: f32, recover: usize) -> PyResult<()> {
        let params = WatchParams { min_contrast, recover };
        either!(&mut self.inner, t => t.watch(params)).map_err(kernel_error)
    }

    /// The pixels whose dip ended since the last call, with provisional times.
    fn take_finished(&mut self, py: Python<'_>) -> PyResult<PyFinishedPixels> {
        let pixels = either!(&mut self.inner, t => t.take_finished()).map_err(kernel_error)?;
        Ok(PyFinishedPixels::new(py, &pixels))
    }

    /// `(lit, in_dip, finished)` pixel counts of the live watch, None before `watch`.
    #[getter]
    fn watch_counts(&self) -> Option<(usize, usize, usize)> {
        either!(&self.inner, t => t.watch_counts())
    }

    #[getter]
    fn frames_seen(&self) -> usize {
        either!(&self.inner, t => t.frames_seen())
    }

    /// `(height, width)` of the frames.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        either!(&self.inner, t => (t.height(), t.width()))
    }

    /// The frames' dtype.
    #[getter]
    fn dtype(&self) -> &'static str {
        self.dtype
    }

    /// Whether each frame comes with a gain (normalised illumination).
    #[getter]
    fn normalised(&self) -> bool {
        either!(&self.inner, t => t.is_normalised())
    }

    #[getter]
    fn window(&self) -> usize {
        self.params().window
    }

    #[getter]
    fn max_width(&self) -> usize {
        self.params().max_width
    }

    #[getter]
    fn ambiguity(&self) -> f32 {
        self.params().ambiguity
    }

    /// Whether the tracker keeps second candidate dips (`finish_second`).
    #[getter(second_dips)]
    fn keeps_second_dips(&self) -> bool {
        self.params().second_dips
    }

    /// The instruction set this tracker's hot loops run on.
    #[getter]
    fn simd_path(&self) -> &'static str {
        either!(&self.inner, t => t.simd_path().name())
    }

    fn __repr__(&self) -> String {
        let (h, w) = self.shape();
        let p = self.params();
        format!(
            "TemporalTracker(height={h}, width={w}, dtype={:?}, window={}, max_width={}, ambiguity={}, normalised={}, frames_seen={})",
            self.dtype(),
            p.window,
            p.max_width,
            p.ambiguity,
            if self.normalised() { "True" } else { "False" },
            self.frames_seen()
        )
    }
}

impl TemporalTracker {
    fn params(&self) -> TrackerParams {
        either!(&self.inner, t => t.params())
    }
}

/// The instruction set new trackers' hot loops run on: `"avx2"`, `"sse2"` or
/// `"portable"` (detected at run time; `GNOMON_SIMD` may force a lower one).
#[pyfunction]
pub(crate) fn simd_path() -> &'static str {
    gnomon_core::SimdPath::active().name()
}

/// Every instruction set this CPU can run the hot loops on, best first.
#[pyfunction]
pub(crate) fn simd_paths() -> Vec<&'static str> {
    gnomon_core::SimdPath::supported().into_iter().map(|p| p.name()).collect()
}
