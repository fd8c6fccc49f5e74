//! Numpy arrays in and out: arguments borrowed with their dtype and shape checked
//! ([`borrow`]), read as row-major slices around a kernel call ([`on_slices!`]), and
//! the kernel's flat results shaped back into arrays.

use std::borrow::Cow;

use numpy::ndarray::{Array2, Array3, ArrayView, Dim, Dimension};
use numpy::{
    Element, IntoPyArray, PyArray, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::KernelArrayError;

/// An element type of the arrays the kernel takes, and its numpy dtype's name (for messages).
pub(crate) trait Dtype: Element + Copy + Sync {
    const NAME: &'static str;
}

macro_rules! dtypes {
    ($($t:ty => $name:literal),+ $(,)?) => {$(
        impl Dtype for $t {
            const NAME: &'static str = $name;
        }
    )+};
}

dtypes!(u8 => "uint8", u16 => "uint16", i32 => "int32", i64 => "int64", f32 => "float32");
dtypes!(f64 => "float64");

/// The extent an array must have along one axis.
#[derive(Clone, Copy)]
pub(crate) enum Extent {
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

/// "(480, 640)", "(3,)".
fn shape_text(dims: &[String]) -> String {
    match dims {
        [one] => format!("({one},)"),
        _ => format!("({})", dims.join(", ")),
    }
}

/// "a uint8 array of shape (480, 640)", or the Python type of a non-array.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    match obj.cast::<PyUntypedArray>() {
        Ok(array) => {
            let dims: Vec<String> = array.shape().iter().map(usize::to_string).collect();
            format!("a {} array of shape {}", array.dtype(), shape_text(&dims))
        }
        Err(_) => match obj.get_type().name() {
            Ok(name) => format!("an object of type {name}"),
            Err(_) => "an object of unknown type".to_owned(),
        },
    }
}

/// A read-only array of `N` dimensions.
pub(crate) type Borrowed<'py, T, const N: usize> = PyReadonlyArray<'py, T, Dim<[usize; N]>>;

/// Borrow `obj` as a read-only array of `T` with the given extents, or a
/// `KernelArrayError` naming `what` was expected and what was given.
pub(crate) fn borrow<'py, T: Dtype, const N: usize>(
    obj: &Bound<'py, PyAny>, what: &str, shape: [Extent; N],
) -> PyResult<Borrowed<'py, T, N>>
where
    Dim<[usize; N]>: Dimension,
{
    let expected = || {
        let dims: Vec<String> = shape.iter().map(|e| e.text()).collect();
        let (dtype, dims) = (T::NAME, shape_text(&dims));
        let got = describe(obj);
        KernelArrayError::new_err(format!(
            "{what}: expected a {dtype} array of shape {dims}, got {got}"
        ))
    };
    let array = obj.cast::<PyArray<T, Dim<[usize; N]>>>().map_err(|_| expected())?;
    let matches =
        array.ndim() == N && array.shape().iter().zip(&shape).all(|(&got, want)| want.accepts(got));
    if !matches {
        return Err(expected());
    }
    array.try_readonly().map_err(|err| KernelArrayError::new_err(format!("{what}: {err}")))
}

/// The view's elements as one row-major slice: borrowed when it is C-contiguous, else copied.
pub(crate) fn contiguous<'a, T: Copy, D: Dimension>(view: &'a ArrayView<'_, T, D>) -> Cow<'a, [T]> {
    match view.as_slice() {
        Some(slice) => Cow::Borrowed(slice),
        None => Cow::Owned(view.iter().copied().collect()),
    }
}

/// `$kernel` with each named borrowed array (a [`borrow`]ed binding in scope) rebound to
/// its elements as one row-major slice ([`contiguous`]). With `py` first, the GIL is
/// released around the slicing and the call, and the kernel's error becomes its exception
/// ([`crate::errors::kernel_error`]); without, the GIL is held and the result is the kernel's.
macro_rules! on_slices {
    (@views [$($array:ident),+] => $kernel:expr) => {{
        $(let $array = $crate::arrays::contiguous(&$array);)+
        $(let $array: &[_] = &$array;)+
        $kernel
    }};
    ([$($array:ident),+] => $kernel:expr) => {{
        $(let $array = $array.as_array();)+
        $crate::arrays::on_slices!(@views [$($array),+] => $kernel)
    }};
    ($py:expr, [$($array:ident),+] => $kernel:expr) => {{
        $(let $array = $array.as_array();)+
        $py.detach(|| $crate::arrays::on_slices!(@views [$($array),+] => $kernel))
            .map_err($crate::errors::kernel_error)
    }};
}
pub(crate) use on_slices;

/// A core result whose length does not match the shape the binding asked for: a kernel bug.
pub(crate) fn shape_error(err: numpy::ndarray::ShapeError) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {err}"))
}

/// A row-major (height, width) core result as a numpy array.
pub(crate) fn image<'py, T: Element>(
    py: Python<'py>, data: Vec<T>, height: usize, width: usize,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    let array = Array2::from_shape_vec((height, width), data).map_err(shape_error)?;
    Ok(array.into_pyarray(py))
}

/// A row-major (height, width, 3) core result as a numpy array.
pub(crate) fn grid3<'py, T: Element>(
    py: Python<'py>, data: Vec<T>, height: usize, width: usize,
) -> PyResult<Bound<'py, PyArray3<T>>> {
    let array = Array3::from_shape_vec((height, width, 3), data).map_err(shape_error)?;
    Ok(array.into_pyarray(py))
}

/// A core 0/1 mask as a bool array.
pub(crate) fn flags(data: &[u8]) -> Vec<bool> {
    data.iter().map(|&v| v != 0).collect()
}

/// A row-major (height, width) core 0/1 mask as a bool array.
pub(crate) fn mask<'py>(
    py: Python<'py>, data: Vec<u8>, height: usize, width: usize,
) -> PyResult<Bound<'py, PyArray2<bool>>> {
    image(py, flags(&data), height, width)
}

/// Core rows of `K` values as a (rows, K) array.
pub(crate) fn rows<'py, T: Element + Copy, const K: usize>(
    py: Python<'py>, values: Vec<[T; K]>,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    let n = values.len();
    image(py, values.into_flattened(), n, K)
}

/// Borrow `obj` as an (H, W) array of any size: the array, H and W.
pub(crate) fn grid<'py, T: Dtype>(
    obj: &Bound<'py, PyAny>, what: &str,
) -> PyResult<(Borrowed<'py, T, 2>, usize, usize)> {
    let array = borrow::<T, 2>(obj, what, [Extent::Any("H"), Extent::Any("W")])?;
    let (h, w) = (array.shape()[0], array.shape()[1]);
    Ok((array, h, w))
}

/// Borrow `obj` as the (h, w, 3) float64 unit rays of an (h, w) grid.
pub(crate) fn camera_rays<'py>(
    obj: &Bound<'py, PyAny>, h: usize, w: usize,
) -> PyResult<Borrowed<'py, f64, 3>> {
    use Extent::Exactly;
    borrow::<f64, 3>(obj, "rays", [Exactly(h), Exactly(w), Exactly(3)])
}
