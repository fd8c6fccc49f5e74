//! `gnomon._kernel`: thin PyO3 bindings of `gnomon-core`.
//!
//! Arrays are borrowed (copied only when not C-contiguous) and the GIL is
//! released around every kernel call. Errors are the exception classes of
//! `gnomon.errors`, one per `KernelError` variant (all `GnomonError`s and
//! `ValueError`s), each message naming what was expected and what was given:
//! bad arrays raise `KernelArrayError`. The tracker's results are a typed
//! `ShadowTimes` object. No numerics here: see `gnomon-core`.

use gnomon_core::{
    FinishedPixel, KernelError, Sample, SecondDips, ShadowTimes, TemporalTracker as Tracker,
    TrackerParams, WatchParams,
};
use numpy::ndarray::{Array1, Array2, Array3, ArrayView, Dimension, Ix1, Ix2, Ix3};
use numpy::{
    Element, IntoPyArray, PyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

pyo3::import_exception!(gnomon.errors, KernelParameterError);
pyo3::import_exception!(gnomon.errors, KernelArrayError);
pyo3::import_exception!(gnomon.errors, KernelLutError);
pyo3::import_exception!(gnomon.errors, KernelFramesError);

/// Each `KernelError` variant as its `gnomon.errors` exception class.
fn kernel_error(err: KernelError) -> PyErr {
    let text = err.to_string();
    match err {
        KernelError::InvalidParameter { .. } => KernelParameterError::new_err(text),
        KernelError::LengthMismatch { .. } => KernelArrayError::new_err(text),
        KernelError::InvalidLut { .. } => KernelLutError::new_err(text),
        KernelError::NoFrames | KernelError::TooManyFrames => KernelFramesError::new_err(text),
    }
}

fn shape_text(shape: &[usize]) -> String {
    let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
    match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    }
}

/// "a uint8 array of shape (480, 640)", or the Python type of a non-array.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    match obj.cast::<PyUntypedArray>() {
        Ok(array) => format!(
            "a {} array of shape {}",
            array.dtype(),
            shape_text(array.shape())
        ),
        Err(_) => match obj.get_type().name() {
            Ok(name) => format!("an object of type {name}"),
            Err(_) => "an object of unknown type".to_owned(),
        },
    }
}

/// The extent an array must have along one axis.
#[derive(Clone, Copy)]
enum Extent {
    /// Any length, named in messages (e.g. "N").
    Any(&'static str),
    Exactly(usize),
}

impl Extent {
    fn accepts(self, n: usize) -> bool {
        match self {
            Extent::Any(_) => true,
            Extent::Exactly(m) => m == n,
        }
    }

    fn text(self) -> String {
        match self {
            Extent::Any(name) => name.to_owned(),
            Extent::Exactly(m) => m.to_string(),
        }
    }
}

/// Borrow `obj` as a read-only array of `T` with the given extents, or a
/// `ValueError` naming `what` was expected and what was given.
fn borrow_array<'py, T: Element, D: Dimension>(
    obj: &Bound<'py, PyAny>,
    what: &str,
    dtype: &str,
    shape: &[Extent],
) -> PyResult<PyReadonlyArray<'py, T, D>> {
    let expected = || {
        let dims: Vec<String> = shape.iter().map(|e| e.text()).collect();
        let dims = if dims.len() == 1 {
            format!("({},)", dims[0])
        } else {
            format!("({})", dims.join(", "))
        };
        format!(
            "{what}: expected a {dtype} array of shape {dims}, got {}",
            describe(obj)
        )
    };
    let array = obj
        .cast::<PyArray<T, D>>()
        .map_err(|_| KernelArrayError::new_err(expected()))?;
    let matches = array.ndim() == shape.len()
        && array
            .shape()
            .iter()
            .zip(shape)
            .all(|(&got, want)| want.accepts(got));
    if !matches {
        return Err(KernelArrayError::new_err(expected()));
    }
    array
        .try_readonly()
        .map_err(|err| KernelArrayError::new_err(format!("{what}: {err}")))
}

/// Run `f` on the view's elements as one row-major slice (copied if the view
/// is not C-contiguous).
fn with_slice<T: Copy, D: Dimension, R>(
    view: &ArrayView<'_, T, D>,
    f: impl FnOnce(&[T]) -> R,
) -> R {
    match view.as_slice() {
        Some(slice) => f(slice),
        None => f(&view.iter().copied().collect::<Vec<T>>()),
    }
}

/// A core result whose length does not match the shape the binding asked for: a kernel bug.
fn shape_error(err: numpy::ndarray::ShapeError) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {err}"))
}

fn image<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    height: usize,
    width: usize,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    let array = Array2::from_shape_vec((height, width), data).map_err(shape_error)?;
    Ok(array.into_pyarray(py))
}

/// A row-major (height, width, 3) core result as a numpy array.
fn grid3<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    height: usize,
    width: usize,
) -> PyResult<Bound<'py, PyArray3<T>>> {
    let array = Array3::from_shape_vec((height, width, 3), data).map_err(shape_error)?;
    Ok(array.into_pyarray(py))
}

fn mask<'py>(
    py: Python<'py>,
    data: Vec<u8>,
    height: usize,
    width: usize,
) -> PyResult<Bound<'py, PyArray2<bool>>> {
    image(
        py,
        data.into_iter().map(|v| v != 0).collect(),
        height,
        width,
    )
}

/// The tracker's per-pixel results: (H, W) arrays, read-only attributes.
#[pyclass(module = "gnomon._kernel", name = "ShadowTimes", frozen)]
struct PyShadowTimes {
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

fn shadow_times(py: Python<'_>, times: ShadowTimes) -> PyResult<PyShadowTimes> {
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

/// Every pixel's second candidate dip: (H, W) arrays, read-only attributes
/// (same meanings as `ShadowTimes`'; NaN times and 0 levels where there is none).
#[pyclass(module = "gnomon._kernel", name = "SecondDips", frozen)]
struct PySecondDips {
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

fn second_dips(py: Python<'_>, d: SecondDips) -> PyResult<PySecondDips> {
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

/// Pixels whose dip ended (the live watch): 1-D arrays, one entry per pixel.
#[pyclass(module = "gnomon._kernel", name = "FinishedPixels", frozen)]
struct PyFinishedPixels {
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

fn finished_pixels(py: Python<'_>, pixels: Vec<FinishedPixel>) -> PyFinishedPixels {
    let column_i = |f: fn(&FinishedPixel) -> i64| {
        Array1::from_iter(pixels.iter().map(f))
            .into_pyarray(py)
            .unbind()
    };
    let column_f = |f: fn(&FinishedPixel) -> f32| {
        Array1::from_iter(pixels.iter().map(f))
            .into_pyarray(py)
            .unbind()
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

/// The core tracker of the samples it stores: the input's DN (`U8`, `U16`),
/// or normalised codes (`U16`, built with `Tracker::normalised`).
enum AnyTracker {
    U8(Tracker<u8>),
    U16(Tracker<u16>),
}

/// Streaming per-pixel shadow tracker (see `gnomon-core`'s `TemporalTracker`).
#[pyclass(module = "gnomon._kernel", name = "TemporalTracker")]
struct TemporalTracker {
    inner: AnyTracker,
    /// The frames' dtype: "uint8" or "uint16".
    dtype: &'static str,
}

/// Borrow the decoding table of a `dtype` input (`len` entries).
fn table<'py>(lut: &Bound<'py, PyAny>, len: usize) -> PyResult<PyReadonlyArray<'py, f32, Ix1>> {
    borrow_array::<f32, Ix1>(lut, "lut", "float32", &[Extent::Exactly(len)])
}

fn plain<T: Sample>(
    height: usize,
    width: usize,
    params: TrackerParams,
    lut: Option<&Bound<'_, PyAny>>,
) -> PyResult<Tracker<T>> {
    let tracker = match lut {
        None => Tracker::new(height, width, params),
        Some(lut) => {
            let lut = table(lut, T::LUT_LEN)?;
            let view = lut.as_array();
            with_slice(&view, |t| Tracker::with_table(height, width, params, t))
        }
    };
    tracker.map_err(kernel_error)
}

fn update_normalised<I: Sample + Element>(
    py: Python<'_>,
    tracker: &mut Tracker<u16>,
    frame: &Bound<'_, PyAny>,
    gain: f64,
) -> PyResult<()> {
    let shape = [
        Extent::Exactly(tracker.height()),
        Extent::Exactly(tracker.width()),
    ];
    let frame = borrow_array::<I, Ix2>(frame, "frame", I::DTYPE, &shape)?;
    let view = frame.as_array();
    py.detach(|| with_slice(&view, |data| tracker.update_with_gain(data, gain)))
        .map_err(kernel_error)
}

fn update_levelled<I: Sample + Element>(
    py: Python<'_>,
    tracker: &mut Tracker<u16>,
    frame: &Bound<'_, PyAny>,
    gain: f64,
    levels: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let shape = [
        Extent::Exactly(tracker.height()),
        Extent::Exactly(tracker.width()),
    ];
    let frame = borrow_array::<I, Ix2>(frame, "frame", I::DTYPE, &shape)?;
    let levels = borrow_array::<f32, Ix2>(levels, "levels", "float32", &shape)?;
    let view = frame.as_array();
    let lview = levels.as_array();
    py.detach(|| {
        with_slice(&view, |data| {
            with_slice(&lview, |lev| tracker.update_with_levels(data, gain, lev))
        })
    })
    .map_err(kernel_error)
}

fn update_any<T: Sample + Element>(
    py: Python<'_>,
    tracker: &mut Tracker<T>,
    frame: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let shape = [
        Extent::Exactly(tracker.height()),
        Extent::Exactly(tracker.width()),
    ];
    let frame = borrow_array::<T, Ix2>(frame, "frame", T::DTYPE, &shape)?;
    let view = frame.as_array();
    py.detach(|| with_slice(&view, |data| tracker.update(data)))
        .map_err(kernel_error)
}

#[pymethods]
impl TemporalTracker {
    #[new]
    #[pyo3(signature = (height, width, dtype = "uint8", window = 4, max_width = 32, ambiguity = 0.6,
                        lut = None, normalise = false, second_dips = false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        height: usize,
        width: usize,
        dtype: &str,
        window: usize,
        max_width: usize,
        ambiguity: f32,
        lut: Option<&Bound<'_, PyAny>>,
        normalise: bool,
        second_dips: bool,
    ) -> PyResult<Self> {
        let params = TrackerParams {
            window,
            max_width,
            ambiguity,
            second_dips,
        };
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
            let view = lut.as_array();
            let tracker = with_slice(&view, |t| Tracker::normalised(height, width, params, t));
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
        &mut self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        gain: Option<f64>,
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
        let times = match &self.inner {
            AnyTracker::U8(t) => py.detach(|| t.finish(min_contrast)),
            AnyTracker::U16(t) => py.detach(|| t.finish(min_contrast)),
        }
        .map_err(kernel_error)?;
        shadow_times(py, times)
    }

    /// Every pixel's second candidate dip (the event whose depth is `rival`),
    /// for the frames seen so far, in `finish`'s units. Needs a tracker built
    /// with `second_dips=True` (KernelParameterError otherwise).
    fn finish_second(&self, py: Python<'_>) -> PyResult<PySecondDips> {
        let dips = match &self.inner {
            AnyTracker::U8(t) => py.detach(|| t.finish_second()),
            AnyTracker::U16(t) => py.detach(|| t.finish_second()),
        }
        .map_err(kernel_error)?;
        second_dips(py, dips)
    }

    /// Start the live watch from the next frame on (see `gnomon-core`'s `live`).
    #[pyo3(signature = (min_contrast, recover = 3))]
    fn watch(&mut self, min_contrast: f32, recover: usize) -> PyResult<()> {
        let params = WatchParams {
            min_contrast,
            recover,
        };
        match &mut self.inner {
            AnyTracker::U8(t) => t.watch(params),
            AnyTracker::U16(t) => t.watch(params),
        }
        .map_err(kernel_error)
    }

    /// The pixels whose dip ended since the last call, with provisional times.
    fn take_finished(&mut self, py: Python<'_>) -> PyResult<PyFinishedPixels> {
        let pixels = match &mut self.inner {
            AnyTracker::U8(t) => t.take_finished(),
            AnyTracker::U16(t) => t.take_finished(),
        }
        .map_err(kernel_error)?;
        Ok(finished_pixels(py, pixels))
    }

    /// `(lit, in_dip, finished)` pixel counts of the live watch, None before `watch`.
    #[getter]
    fn watch_counts(&self) -> Option<(usize, usize, usize)> {
        match &self.inner {
            AnyTracker::U8(t) => t.watch_counts(),
            AnyTracker::U16(t) => t.watch_counts(),
        }
    }

    #[getter]
    fn frames_seen(&self) -> usize {
        match &self.inner {
            AnyTracker::U8(t) => t.frames_seen(),
            AnyTracker::U16(t) => t.frames_seen(),
        }
    }

    /// `(height, width)` of the frames.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        match &self.inner {
            AnyTracker::U8(t) => (t.height(), t.width()),
            AnyTracker::U16(t) => (t.height(), t.width()),
        }
    }

    /// The frames' dtype.
    #[getter]
    fn dtype(&self) -> &'static str {
        self.dtype
    }

    /// Whether each frame comes with a gain (normalised illumination).
    #[getter]
    fn normalised(&self) -> bool {
        match &self.inner {
            AnyTracker::U8(t) => t.is_normalised(),
            AnyTracker::U16(t) => t.is_normalised(),
        }
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
        match &self.inner {
            AnyTracker::U8(t) => t.simd_path().name(),
            AnyTracker::U16(t) => t.simd_path().name(),
        }
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
        match &self.inner {
            AnyTracker::U8(t) => t.params(),
            AnyTracker::U16(t) => t.params(),
        }
    }
}

/// `(points (H, W, 3) float32, valid (H, W) bool)`.
type RaysAndMask<'py> = (Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<bool>>);
type PointsAndMask<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<bool>>);
type FacesAndSources<'py> = (Bound<'py, PyArray2<i32>>, Bound<'py, PyArray1<i64>>);

/// Camera rays ∩ shadow planes interpolated at each pixel's shadow time.
#[pyfunction]
#[pyo3(signature = (rays, times, planes, min_cos = 1e-3))]
fn triangulate<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    min_cos: f64,
) -> PyResult<PointsAndMask<'py>> {
    let times = borrow_array::<f32, Ix2>(
        times,
        "times",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let planes = borrow_array::<f64, Ix2>(
        planes,
        "planes",
        "float64",
        &[Extent::Any("N"), Extent::Exactly(4)],
    )?;
    let (rays, times, planes) = (rays.as_array(), times.as_array(), planes.as_array());
    let (points, valid) = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&times, |times| {
                    with_slice(&planes, |planes| {
                        gnomon_core::triangulate(rays, times, planes, min_cos)
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    let points = grid3(py, points, h, w)?;
    Ok((points, mask(py, valid, h, w)?))
}

/// (H, W) float32 camera Z of [`triangulate`]'s points, NaN where it gives none (see
/// `gnomon_core::triangulate_depth`).
#[pyfunction]
#[pyo3(signature = (rays, times, planes, min_cos = 1e-3))]
fn triangulate_depth<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    min_cos: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let times = borrow_array::<f32, Ix2>(
        times,
        "times",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let planes = borrow_array::<f64, Ix2>(
        planes,
        "planes",
        "float64",
        &[Extent::Any("N"), Extent::Exactly(4)],
    )?;
    let (rays, times, planes) = (rays.as_array(), times.as_array(), planes.as_array());
    let depth = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&times, |times| {
                    with_slice(&planes, |planes| {
                        gnomon_core::triangulate_depth(rays, times, planes, min_cos)
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    image(py, depth, h, w)
}

/// σZ, ∂Z/∂t and the line's time σ of every pixel, each (H, W) float32 (see
/// `gnomon_core::depth_sigma`).
#[pyfunction]
#[pyo3(signature = (rays, times, planes, depth, sigma_t_pixel, line_sigma, line_fill, step, min_cos = 1e-3))]
#[allow(clippy::too_many_arguments)]
fn depth_sigma<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    sigma_t_pixel: &Bound<'py, PyAny>,
    line_sigma: &Bound<'py, PyAny>,
    line_fill: f64,
    step: f64,
    min_cos: f64,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let times = borrow_array::<f32, Ix2>(
        times,
        "times",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let grid = [Extent::Exactly(h), Extent::Exactly(w)];
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let planes = borrow_array::<f64, Ix2>(
        planes,
        "planes",
        "float64",
        &[Extent::Any("N"), Extent::Exactly(4)],
    )?;
    let depth = borrow_array::<f32, Ix2>(depth, "depth", "float32", &grid)?;
    let sigma_t_pixel = borrow_array::<f32, Ix2>(sigma_t_pixel, "sigma_t_pixel", "float32", &grid)?;
    let line_sigma =
        borrow_array::<f64, Ix1>(line_sigma, "line_sigma", "float64", &[Extent::Any("N")])?;
    let (rays, times, planes, depth, sigma_t_pixel, line_sigma) = (
        rays.as_array(),
        times.as_array(),
        planes.as_array(),
        depth.as_array(),
        sigma_t_pixel.as_array(),
        line_sigma.as_array(),
    );
    let out = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&times, |times| {
                    with_slice(&planes, |planes| {
                        with_slice(&depth, |depth| {
                            with_slice(&sigma_t_pixel, |sp| {
                                with_slice(&line_sigma, |ls| {
                                    gnomon_core::depth_sigma(
                                        rays, times, planes, depth, sp, ls, line_fill, step,
                                        min_cos,
                                    )
                                })
                            })
                        })
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    pyo3::types::PyTuple::new(
        py,
        [
            image(py, out.sigma_z, h, w)?,
            image(py, out.dz_dt, h, w)?,
            image(py, out.sigma_t_line, h, w)?,
        ],
    )
}

/// The σZ a completed plane's own error adds at each pixel, (H, W) float32 (see
/// `gnomon_core::completion_sigma`).
#[pyfunction]
#[pyo3(signature = (rays, times, depth, planes, line_point, line_direction, sigma_rad, min_cos = 1e-3))]
#[allow(clippy::too_many_arguments)]
fn completion_sigma<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    line_point: &Bound<'py, PyAny>,
    line_direction: &Bound<'py, PyAny>,
    sigma_rad: f64,
    min_cos: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let times = borrow_array::<f64, Ix2>(
        times,
        "times",
        "float64",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let depth = borrow_array::<f64, Ix2>(
        depth,
        "depth",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let planes = borrow_array::<f64, Ix2>(
        planes,
        "planes",
        "float64",
        &[Extent::Any("N"), Extent::Exactly(4)],
    )?;
    let rows = planes.shape()[0];
    let lines = [Extent::Exactly(rows), Extent::Exactly(3)];
    let line_point = borrow_array::<f64, Ix2>(line_point, "line_point", "float64", &lines)?;
    let line_direction =
        borrow_array::<f64, Ix2>(line_direction, "line_direction", "float64", &lines)?;
    let (rays, times, depth, planes, line_point, line_direction) = (
        rays.as_array(),
        times.as_array(),
        depth.as_array(),
        planes.as_array(),
        line_point.as_array(),
        line_direction.as_array(),
    );
    let sigma = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&times, |times| {
                    with_slice(&depth, |depth| {
                        with_slice(&planes, |planes| {
                            with_slice(&line_point, |lp| {
                                with_slice(&line_direction, |ld| {
                                    let completion = gnomon_core::Completion {
                                        line_point: lp,
                                        line_direction: ld,
                                        sigma_rad,
                                    };
                                    gnomon_core::completion_sigma(
                                        rays, times, depth, planes, completion, min_cos,
                                    )
                                })
                            })
                        })
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    image(py, sigma, h, w)
}

/// Where a shadow-time map (H, W) float32 crosses each integer frame (see
/// `gnomon_core::isochrone_crossings`): `(frame (K,) int64, u (K,), v (K,))`.
#[pyfunction]
#[pyo3(signature = (times, n_frames, unique = true))]
fn isochrone_crossings<'py>(
    py: Python<'py>,
    times: &Bound<'py, PyAny>,
    n_frames: i64,
    unique: bool,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let times = borrow_array::<f32, Ix2>(
        times,
        "times",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let w = times.shape()[1];
    let times = times.as_array();
    let out = py
        .detach(|| {
            with_slice(&times, |t| {
                gnomon_core::isochrone_crossings(t, w.max(1), n_frames, unique)
            })
        })
        .map_err(kernel_error)?;
    pyo3::types::PyTuple::new(
        py,
        [
            out.frame.into_pyarray(py).into_any(),
            out.u.into_pyarray(py).into_any(),
            out.v.into_pyarray(py).into_any(),
        ],
    )
}

/// Every frame's own shadow line on a reference plane (see `gnomon_core::frame_lines`):
/// `(accepted (N,) bool, centre (N, 2), direction (N, 2), rms (N,), count (N,) int64,
/// extent (N,), inliers (K,) bool)`.
#[pyfunction]
#[pyo3(signature = (xy, bounds, k, iterations, min_points, min_extent_to_rms, min_extent_fraction))]
#[allow(clippy::too_many_arguments)]
fn frame_lines<'py>(
    py: Python<'py>,
    xy: &Bound<'py, PyAny>,
    bounds: &Bound<'py, PyAny>,
    k: f64,
    iterations: usize,
    min_points: usize,
    min_extent_to_rms: f64,
    min_extent_fraction: f64,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let xy =
        borrow_array::<f64, Ix2>(xy, "xy", "float64", &[Extent::Any("K"), Extent::Exactly(2)])?;
    let bounds = borrow_array::<i64, Ix1>(bounds, "bounds", "int64", &[Extent::Any("N + 1")])?;
    let params = gnomon_core::LineParams {
        k,
        iterations,
        min_points,
        min_extent_to_rms,
        min_extent_fraction,
    };
    let (xy, bounds) = (xy.as_array(), bounds.as_array());
    let out = py
        .detach(|| {
            with_slice(&xy, |xy| {
                with_slice(&bounds, |b| gnomon_core::frame_lines(xy, b, &params))
            })
        })
        .map_err(kernel_error)?;
    let n = out.accepted.len();
    let pairs = |v: Vec<[f64; 2]>| image(py, v.into_iter().flatten().collect(), n, 2);
    pyo3::types::PyTuple::new(
        py,
        [
            out.accepted
                .iter()
                .map(|&a| a != 0)
                .collect::<Vec<bool>>()
                .into_pyarray(py)
                .into_any(),
            pairs(out.centre)?.into_any(),
            pairs(out.direction)?.into_any(),
            out.rms.into_pyarray(py).into_any(),
            out.count.into_pyarray(py).into_any(),
            out.extent.into_pyarray(py).into_any(),
            out.inliers
                .iter()
                .map(|&a| a != 0)
                .collect::<Vec<bool>>()
                .into_pyarray(py)
                .into_any(),
        ],
    )
}

/// Angles (degrees) between the selected pixels' rays and their shadow planes (see
/// `gnomon_core::ray_plane_angles`), row-major.
#[pyfunction]
#[pyo3(signature = (rays, times, planes, selected))]
fn ray_plane_angles<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    times: &Bound<'py, PyAny>,
    planes: &Bound<'py, PyAny>,
    selected: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let times = borrow_array::<f64, Ix2>(
        times,
        "times",
        "float64",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let planes = borrow_array::<f64, Ix2>(
        planes,
        "planes",
        "float64",
        &[Extent::Any("N"), Extent::Exactly(4)],
    )?;
    let selected = borrow_array::<u8, Ix2>(
        selected,
        "selected",
        "uint8",
        &[Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let (rays, times, planes, selected) = (
        rays.as_array(),
        times.as_array(),
        planes.as_array(),
        selected.as_array(),
    );
    let angles = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&times, |times| {
                    with_slice(&planes, |planes| {
                        with_slice(&selected, |selected| {
                            gnomon_core::ray_plane_angles(rays, times, planes, selected)
                        })
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    Ok(angles.into_pyarray(py))
}

/// Faces (F, 3) int32 of the grid mesh of the valid pixels (see `gnomon_core::grid_faces`).
#[pyfunction]
#[pyo3(signature = (valid, depth, sigma, max_relative_jump, sigma_factor = 5.0))]
fn grid_faces<'py>(
    py: Python<'py>,
    valid: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    sigma: &Bound<'py, PyAny>,
    max_relative_jump: f32,
    sigma_factor: f32,
) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let valid = borrow_array::<u8, Ix2>(
        valid,
        "valid",
        "uint8",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (valid.shape()[0], valid.shape()[1]);
    let grid = [Extent::Exactly(h), Extent::Exactly(w)];
    let depth = borrow_array::<f32, Ix2>(depth, "depth", "float32", &grid)?;
    let sigma = borrow_array::<f32, Ix2>(sigma, "sigma", "float32", &grid)?;
    let (valid, depth, sigma) = (valid.as_array(), depth.as_array(), sigma.as_array());
    let faces = py
        .detach(|| {
            with_slice(&valid, |valid| {
                with_slice(&depth, |depth| {
                    with_slice(&sigma, |sigma| {
                        gnomon_core::grid_faces(
                            valid,
                            depth,
                            sigma,
                            w.max(1),
                            max_relative_jump,
                            sigma_factor,
                        )
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    rows(py, faces)
}

fn rows<'py>(py: Python<'py>, faces: Vec<[i32; 3]>) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let n = faces.len();
    image(py, faces.into_flattened(), n, 3)
}

/// Drop small pieces and split non-manifold vertices (see `gnomon_core::clean_faces`):
/// the new faces (F', 3) int32 and the source vertex of each new vertex (V',) int64.
#[pyfunction]
#[pyo3(signature = (n_vertices, faces, min_vertices))]
fn clean_faces<'py>(
    py: Python<'py>,
    n_vertices: usize,
    faces: &Bound<'py, PyAny>,
    min_vertices: usize,
) -> PyResult<FacesAndSources<'py>> {
    let faces = borrow_array::<i32, Ix2>(
        faces,
        "faces",
        "int32",
        &[Extent::Any("F"), Extent::Exactly(3)],
    )?;
    let faces = faces.as_array();
    let clean = py
        .detach(|| {
            with_slice(&faces, |flat| {
                gnomon_core::clean_faces(n_vertices, gnomon_core::triangles(flat)?, min_vertices)
            })
        })
        .map_err(kernel_error)?;
    Ok((rows(py, clean.faces)?, clean.source.into_pyarray(py)))
}

/// The body of a Wavefront OBJ file (see `gnomon_core::obj_text`): bytes, or with `as_parts` a
/// list of uint8 arrays (its blocks of lines, in order, not copied).
#[pyfunction]
#[pyo3(signature = (vertices, vertex_decimals, uv, normals, faces, as_parts = false))]
fn obj_text<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    vertex_decimals: usize,
    uv: Option<&Bound<'py, PyAny>>,
    normals: Option<&Bound<'py, PyAny>>,
    faces: &Bound<'py, PyAny>,
    as_parts: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let vertices = borrow_array::<f64, Ix2>(
        vertices,
        "vertices",
        "float64",
        &[Extent::Any("V"), Extent::Exactly(3)],
    )?;
    let nv = vertices.shape()[0];
    let uv = uv
        .map(|a| {
            borrow_array::<f64, Ix2>(
                a,
                "uv",
                "float64",
                &[Extent::Exactly(nv), Extent::Exactly(2)],
            )
        })
        .transpose()?;
    let normals = normals
        .map(|a| {
            borrow_array::<f64, Ix2>(
                a,
                "normals",
                "float64",
                &[Extent::Exactly(nv), Extent::Exactly(3)],
            )
        })
        .transpose()?;
    let faces = borrow_array::<i64, Ix2>(
        faces,
        "faces",
        "int64",
        &[Extent::Any("F"), Extent::Exactly(3)],
    )?;
    let owned =
        |a: &PyReadonlyArray<'py, f64, Ix2>| a.as_array().iter().copied().collect::<Vec<f64>>();
    let (v, t, n, f) = (
        owned(&vertices),
        uv.as_ref().map(owned),
        normals.as_ref().map(owned),
        faces.as_array().iter().copied().collect::<Vec<i64>>(),
    );
    let parts = py
        .detach(|| gnomon_core::obj_text_parts(&v, vertex_decimals, t.as_deref(), n.as_deref(), &f))
        .map_err(kernel_error)?;
    if as_parts {
        // no copy: each block of lines becomes a uint8 array that owns it
        return Ok(
            pyo3::types::PyList::new(py, parts.into_iter().map(|p| p.into_pyarray(py)))?.into_any(),
        );
    }
    // one copy, straight into the bytes object
    let len = parts.iter().map(Vec::len).sum();
    pyo3::types::PyBytes::new_with(py, len, |buf| {
        let mut at = 0;
        for p in &parts {
            buf[at..at + p.len()].copy_from_slice(p);
            at += p.len();
        }
        Ok(())
    })
    .map(Bound::into_any)
}

/// The rows of an oriented shadow-time map re-timed between its isochrones (see
/// `gnomon_core::retime_rows`): `(times (H, W) float32, done (H, W) bool, pixel (P,) int64,
/// left (P, 2) int64, right (P, 2) int64, phase (P, 2), rise (P, 2), gap (P,), f (P,))`.
#[pyfunction]
#[pyo3(signature = (times, index, wanted, n_frames, max_gap, min_gap, backstep))]
#[allow(clippy::too_many_arguments)]
fn retime_rows<'py>(
    py: Python<'py>,
    times: &Bound<'py, PyAny>,
    index: &Bound<'py, PyAny>,
    wanted: &Bound<'py, PyAny>,
    n_frames: i64,
    max_gap: f64,
    min_gap: f64,
    backstep: f64,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let times = borrow_array::<f64, Ix2>(
        times,
        "times",
        "float64",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let grid = [Extent::Exactly(h), Extent::Exactly(w)];
    let index = borrow_array::<i64, Ix2>(index, "index", "int64", &grid)?;
    let wanted = borrow_array::<u8, Ix2>(wanted, "wanted", "uint8", &grid)?;
    let (times, index, wanted) = (times.as_array(), index.as_array(), wanted.as_array());
    let params = gnomon_core::RetimeParams {
        n_frames,
        max_gap,
        min_gap,
        backstep,
    };
    let r = py
        .detach(|| {
            with_slice(&times, |t| {
                with_slice(&index, |i| {
                    with_slice(&wanted, |m| {
                        gnomon_core::retime_rows(t, i, m, w.max(1), params)
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    let pairs_i = |v: Vec<[i64; 2]>| {
        let n = v.len();
        Array2::from_shape_vec((n, 2), v.into_iter().flatten().collect())
            .map(|a| a.into_pyarray(py))
    };
    let pairs_f = |v: Vec<[f64; 2]>| {
        let n = v.len();
        Array2::from_shape_vec((n, 2), v.into_iter().flatten().collect())
            .map(|a| a.into_pyarray(py))
    };
    let done: Vec<bool> = r.done.iter().map(|&d| d != 0).collect();
    pyo3::types::PyTuple::new(
        py,
        [
            image(py, r.times, h, w)?.into_any(),
            image(py, done, h, w)?.into_any(),
            r.pixel.into_pyarray(py).into_any(),
            pairs_i(r.left).map_err(shape_error)?.into_any(),
            pairs_i(r.right).map_err(shape_error)?.into_any(),
            pairs_f(r.phase).map_err(shape_error)?.into_any(),
            pairs_f(r.rise).map_err(shape_error)?.into_any(),
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
fn retime_rows_sigma<'py>(
    py: Python<'py>,
    times: &Bound<'py, PyAny>,
    index: &Bound<'py, PyAny>,
    wanted: &Bound<'py, PyAny>,
    sigma: &Bound<'py, PyAny>,
    n_frames: i64,
    max_gap: f64,
    min_gap: f64,
    backstep: f64,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let times = borrow_array::<f64, Ix2>(
        times,
        "times",
        "float64",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let grid = [Extent::Exactly(h), Extent::Exactly(w)];
    let index = borrow_array::<i64, Ix2>(index, "index", "int64", &grid)?;
    let wanted = borrow_array::<u8, Ix2>(wanted, "wanted", "uint8", &grid)?;
    let sigma = borrow_array::<f64, Ix1>(sigma, "sigma", "float64", &[Extent::Any("N")])?;
    let (times, index, wanted, sigma) = (
        times.as_array(),
        index.as_array(),
        wanted.as_array(),
        sigma.as_array(),
    );
    let params = gnomon_core::RetimeParams {
        n_frames,
        max_gap,
        min_gap,
        backstep,
    };
    let r = py
        .detach(|| {
            with_slice(&times, |t| {
                with_slice(&index, |i| {
                    with_slice(&wanted, |m| {
                        with_slice(&sigma, |s| {
                            gnomon_core::retime_rows_sigma(t, i, m, s, w.max(1), params)
                        })
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    let done: Vec<bool> = r.done.iter().map(|&d| d != 0).collect();
    pyo3::types::PyTuple::new(
        py,
        [
            image(py, r.times, h, w)?.into_any(),
            image(py, done, h, w)?.into_any(),
            image(py, r.sigma, h, w)?.into_any(),
        ],
    )
}

/// (H, W) float32: re-timed times averaged across the sweep (see `gnomon_core::average_across`);
/// `retimed` (H, W) uint8 (non-zero = re-timed).
#[pyfunction]
#[pyo3(signature = (times, retimed, across_rows, half, bend))]
fn average_across<'py>(
    py: Python<'py>,
    times: &Bound<'py, PyAny>,
    retimed: &Bound<'py, PyAny>,
    across_rows: bool,
    half: usize,
    bend: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let times = borrow_array::<f32, Ix2>(
        times,
        "times",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (times.shape()[0], times.shape()[1]);
    let retimed = borrow_array::<u8, Ix2>(
        retimed,
        "retimed",
        "uint8",
        &[Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let (times, retimed) = (times.as_array(), retimed.as_array());
    let out = py
        .detach(|| {
            with_slice(&times, |t| {
                with_slice(&retimed, |r| {
                    gnomon_core::average_across(t, r, w.max(1), across_rows, half, bend)
                })
            })
        })
        .map_err(kernel_error)?;
    image(py, out, h, w)
}

/// Fused depth and σ of K estimates per pixel, neighbour-supported only, and each pixel's code
/// (0 none, 1 kept, 2 conflict, 3 unsupported), each (H, W) (see `gnomon_core::fuse_supported`).
#[pyfunction]
#[pyo3(signature = (depths, sigmas, max_relative_jump, min_support = 2))]
fn fuse_supported<'py>(
    py: Python<'py>,
    depths: &Bound<'py, PyAny>,
    sigmas: &Bound<'py, PyAny>,
    max_relative_jump: f64,
    min_support: usize,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let depths = borrow_array::<f32, Ix3>(
        depths,
        "depths",
        "float32",
        &[Extent::Any("K"), Extent::Any("H"), Extent::Any("W")],
    )?;
    let (k, h, w) = (depths.shape()[0], depths.shape()[1], depths.shape()[2]);
    let sigmas = borrow_array::<f32, Ix3>(
        sigmas,
        "sigmas",
        "float32",
        &[Extent::Exactly(k), Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let (depths, sigmas) = (depths.as_array(), sigmas.as_array());
    let (depth, sigma, code) = py
        .detach(|| {
            with_slice(&depths, |d| {
                with_slice(&sigmas, |s| {
                    gnomon_core::fuse_supported(d, s, k, w.max(1), max_relative_jump, min_support)
                })
            })
        })
        .map_err(kernel_error)?;
    pyo3::types::PyTuple::new(
        py,
        [
            image(py, depth, h, w)?.into_any(),
            image(py, sigma, h, w)?.into_any(),
            image(py, code, h, w)?.into_any(),
        ],
    )
}

/// What `noise_samples` returns: the differences and centred levels (float32), the median and MAD.
type NoiseSamplesResult<'py> = Option<(
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray1<f32>>,
    f64,
    f64,
)>;

fn noise_samples_of<'py, T: Sample + Element>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    min_inside: usize,
) -> PyResult<NoiseSamplesResult<'py>> {
    let a = borrow_array::<T, Ix1>(a, "a", T::DTYPE, &[Extent::Any("N")])?;
    let n = a.len();
    let b = borrow_array::<T, Ix1>(b, "b", T::DTYPE, &[Extent::Exactly(n)])?;
    let (a, b) = (a.as_array(), b.as_array());
    let samples = py
        .detach(|| {
            with_slice(&a, |a| {
                with_slice(&b, |b| gnomon_core::noise_samples(a, b, min_inside))
            })
        })
        .map_err(kernel_error)?;
    Ok(samples.map(|s| {
        (
            s.diff.into_pyarray(py),
            s.level.into_pyarray(py),
            s.median,
            s.mad,
        )
    }))
}

/// The samples of a uint8 or uint16 frame pair (flat, one dtype) the noise estimate fits, and
/// its starting median and MAD (see `gnomon_core::noise_samples`); None when fewer than
/// `min_inside` pixels are inside the range.
#[pyfunction]
#[pyo3(signature = (a, b, min_inside))]
fn noise_samples<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    min_inside: usize,
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
fn clipped_fit_step<'py>(
    py: Python<'py>,
    diff: &Bound<'py, PyAny>,
    level: &Bound<'py, PyAny>,
    offset: f64,
    gain: f64,
    limit: f64,
    min_kept: usize,
) -> PyResult<Option<(usize, f64, f64, f64)>> {
    let diff = borrow_array::<f32, Ix1>(diff, "diff", "float32", &[Extent::Any("N")])?;
    let n = diff.len();
    let level = borrow_array::<f32, Ix1>(level, "level", "float32", &[Extent::Exactly(n)])?;
    let (diff, level) = (diff.as_array(), level.as_array());
    let fit = py
        .detach(|| {
            with_slice(&diff, |diff| {
                with_slice(&level, |level| {
                    gnomon_core::clipped_fit_step(diff, level, offset, gain, limit, min_kept)
                })
            })
        })
        .map_err(kernel_error)?;
    Ok(fit.map(|f| {
        (
            f.kept,
            f64::from(f.offset),
            f64::from(f.gain),
            f64::from(f.rms),
        )
    }))
}

/// Per pixel and channel, the median of the frames it is lit in: (H, W, 3) uint8 (see
/// `gnomon_core::lit_median`).
#[pyfunction]
#[pyo3(signature = (stack, lit))]
fn lit_median<'py>(
    py: Python<'py>,
    stack: &Bound<'py, PyAny>,
    lit: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let lit = borrow_array::<u8, Ix3>(
        lit,
        "lit",
        "uint8",
        &[Extent::Any("K"), Extent::Any("H"), Extent::Any("W")],
    )?;
    let (k, h, w) = (lit.shape()[0], lit.shape()[1], lit.shape()[2]);
    let stack = borrow_array::<u8, numpy::ndarray::Ix4>(
        stack,
        "stack",
        "uint8",
        &[
            Extent::Exactly(k),
            Extent::Exactly(h),
            Extent::Exactly(w),
            Extent::Exactly(3),
        ],
    )?;
    let (lit, stack) = (lit.as_array(), stack.as_array());
    let rgb = py
        .detach(|| {
            with_slice(&stack, |stack| {
                with_slice(&lit, |lit| gnomon_core::lit_median(stack, lit, k))
            })
        })
        .map_err(kernel_error)?;
    let rgb = grid3(py, rgb, h, w)?;
    Ok(rgb)
}

/// World-frame points (H, W, 3) float32 of a depth map, NaN off the surface (see
/// `gnomon_core::world_points`).
#[pyfunction]
#[pyo3(signature = (rays, depth, valid, rotation, translation))]
fn world_points<'py>(
    py: Python<'py>,
    rays: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    valid: &Bound<'py, PyAny>,
    rotation: [[f64; 3]; 3],
    translation: [f64; 3],
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let depth = borrow_array::<f32, Ix2>(
        depth,
        "depth",
        "float32",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (depth.shape()[0], depth.shape()[1]);
    let valid = borrow_array::<u8, Ix2>(
        valid,
        "valid",
        "uint8",
        &[Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let rays = borrow_array::<f64, Ix3>(
        rays,
        "rays",
        "float64",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let (depth, valid, rays) = (depth.as_array(), valid.as_array(), rays.as_array());
    let points = py
        .detach(|| {
            with_slice(&rays, |rays| {
                with_slice(&depth, |depth| {
                    with_slice(&valid, |valid| {
                        gnomon_core::world_points(
                            rays,
                            depth,
                            valid,
                            w.max(1),
                            rotation,
                            translation,
                        )
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    let points = grid3(py, points, h, w)?;
    Ok(points)
}

/// Unit rays (H, W, 3) float64 of every pixel of OpenCV's 5-coefficient camera and their
/// solved mask (see `gnomon_core::ray_map`).
#[pyfunction]
#[pyo3(signature = (width, height, intrinsics, dist, tol_px, max_steps))]
fn ray_map<'py>(
    py: Python<'py>,
    width: usize,
    height: usize,
    intrinsics: [f64; 4],
    dist: [f64; 5],
    tol_px: f64,
    max_steps: u32,
) -> PyResult<RaysAndMask<'py>> {
    let (rays, solved) = py
        .detach(|| gnomon_core::ray_map(width, height, intrinsics, dist, tol_px, max_steps))
        .map_err(kernel_error)?;
    let rays = grid3(py, rays, height, width)?;
    Ok((rays, mask(py, solved, height, width)?))
}

/// Unit normals (H, W, 3) float32 of the surface on the pixel grid (see `gnomon_core::grid_normals`).
#[pyfunction]
#[pyo3(signature = (points, depth, valid, camera_centre, max_relative_jump))]
fn grid_normals<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    valid: &Bound<'py, PyAny>,
    camera_centre: [f64; 3],
    max_relative_jump: f64,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let valid = borrow_array::<u8, Ix2>(
        valid,
        "valid",
        "uint8",
        &[Extent::Any("H"), Extent::Any("W")],
    )?;
    let (h, w) = (valid.shape()[0], valid.shape()[1]);
    let depth = borrow_array::<f32, Ix2>(
        depth,
        "depth",
        "float32",
        &[Extent::Exactly(h), Extent::Exactly(w)],
    )?;
    let points = borrow_array::<f32, Ix3>(
        points,
        "points",
        "float32",
        &[Extent::Exactly(h), Extent::Exactly(w), Extent::Exactly(3)],
    )?;
    let (valid, depth, points) = (valid.as_array(), depth.as_array(), points.as_array());
    let normals = py
        .detach(|| {
            with_slice(&points, |points| {
                with_slice(&depth, |depth| {
                    with_slice(&valid, |valid| {
                        gnomon_core::grid_normals(
                            points,
                            depth,
                            valid,
                            w.max(1),
                            camera_centre,
                            max_relative_jump,
                        )
                    })
                })
            })
        })
        .map_err(kernel_error)?;
    let normals = grid3(py, normals, h, w)?;
    Ok(normals)
}

/// The records of a binary STL file (F·50,) uint8 (see `gnomon_core::stl_records`).
#[pyfunction]
#[pyo3(signature = (vertices, faces))]
fn stl_records<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<u8>>> {
    let vertices = borrow_array::<f32, Ix2>(
        vertices,
        "vertices",
        "float32",
        &[Extent::Any("V"), Extent::Exactly(3)],
    )?;
    let faces = borrow_array::<i32, Ix2>(
        faces,
        "faces",
        "int32",
        &[Extent::Any("F"), Extent::Exactly(3)],
    )?;
    let (vertices, faces) = (vertices.as_array(), faces.as_array());
    let records = py
        .detach(|| {
            with_slice(&vertices, |v| {
                with_slice(&faces, |f| gnomon_core::stl_records(v, f))
            })
        })
        .map_err(kernel_error)?;
    Ok(records.into_pyarray(py))
}

/// The instruction set new trackers' hot loops run on: `"avx2"`, `"sse2"` or
/// `"portable"` (detected at run time; `GNOMON_SIMD` may force a lower one).
#[pyfunction]
fn simd_path() -> &'static str {
    gnomon_core::SimdPath::active().name()
}

/// Every instruction set this CPU can run the hot loops on, best first.
#[pyfunction]
fn simd_paths() -> Vec<&'static str> {
    gnomon_core::SimdPath::supported()
        .into_iter()
        .map(|p| p.name())
        .collect()
}

#[pymodule]
fn _kernel(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<TemporalTracker>()?;
    m.add_class::<PyShadowTimes>()?;
    m.add_class::<PySecondDips>()?;
    m.add_class::<PyFinishedPixels>()?;
    m.add_function(wrap_pyfunction!(triangulate, m)?)?;
    m.add_function(wrap_pyfunction!(ray_plane_angles, m)?)?;
    m.add_function(wrap_pyfunction!(depth_sigma, m)?)?;
    m.add_function(wrap_pyfunction!(completion_sigma, m)?)?;
    m.add_function(wrap_pyfunction!(frame_lines, m)?)?;
    m.add_function(wrap_pyfunction!(isochrone_crossings, m)?)?;
    m.add_function(wrap_pyfunction!(grid_faces, m)?)?;
    m.add_function(wrap_pyfunction!(clean_faces, m)?)?;
    m.add_function(wrap_pyfunction!(obj_text, m)?)?;
    m.add_function(wrap_pyfunction!(grid_normals, m)?)?;
    m.add_function(wrap_pyfunction!(stl_records, m)?)?;
    m.add_function(wrap_pyfunction!(retime_rows, m)?)?;
    m.add_function(wrap_pyfunction!(retime_rows_sigma, m)?)?;
    m.add_function(wrap_pyfunction!(average_across, m)?)?;
    m.add_function(wrap_pyfunction!(triangulate_depth, m)?)?;
    m.add_function(wrap_pyfunction!(world_points, m)?)?;
    m.add_function(wrap_pyfunction!(ray_map, m)?)?;
    m.add_function(wrap_pyfunction!(lit_median, m)?)?;
    m.add_function(wrap_pyfunction!(clipped_fit_step, m)?)?;
    m.add_function(wrap_pyfunction!(noise_samples, m)?)?;
    m.add_function(wrap_pyfunction!(fuse_supported, m)?)?;
    m.add_function(wrap_pyfunction!(simd_path, m)?)?;
    m.add_function(wrap_pyfunction!(simd_paths, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
