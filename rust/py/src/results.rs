//! The kernel's result types as frozen classes of read-only numpy arrays, each class's fields
//! declared once ([`result_class!`]): the tracker's `ShadowTimes` and `SecondDips` here, the
//! live watch's `FinishedPixels` in [`crate::live`].

use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;

use gnomon_core::{SecondDips, ShadowTimes};

/// A frozen class (its docs and `name` given) whose read-only attributes are numpy arrays,
/// one per field (its docs the attribute's), with `new` making it from the kernel's result:
///
/// * `grid of Type`: (height, width) arrays of the fields grouped by how they are made,
///   `image f32 { … }` (values) or `mask bool { … }` (0/1 flags; see [`crate::arrays`]), from
///   `Type`'s row-major fields of the same names and its `height`, `width` (groups of one
///   kind may follow each other: the levels, the crossings);
/// * `columns of Item`: 1-D arrays, one entry per `Item` of a slice, each its field of the
///   same name (converted with `From`).
macro_rules! result_class {
    (
        $(#[$doc:meta])* $name:literal $class:ident: grid of $source:ty {
            $($array:ident $elem:ty { $($(#[$field_doc:meta])* $field:ident,)+ })+
        }
    ) => {
        $crate::results::result_class!(@class $(#[$doc])* $name $class: PyArray2 {
            $($($(#[$field_doc])* $field: $elem,)+)+
        });

        impl $class {
            /// The kernel's result as numpy arrays.
            pub(crate) fn new(py: Python<'_>, result: $source) -> PyResult<Self> {
                let (h, w) = (result.height, result.width);
                Ok($class {
                    $($($field: $crate::arrays::$array(py, result.$field, h, w)?.unbind(),)+)+
                })
            }
        }
    };
    (
        $(#[$doc:meta])* $name:literal $class:ident: columns of $source:ty {
            $($(#[$field_doc:meta])* $field:ident: $elem:ty,)+
        }
    ) => {
        $crate::results::result_class!(@class $(#[$doc])* $name $class: PyArray1 {
            $($(#[$field_doc])* $field: $elem,)+
        });

        impl $class {
            /// The kernel's items as columns.
            pub(crate) fn new(py: Python<'_>, items: &[$source]) -> Self {
                use numpy::{ndarray::Array1, IntoPyArray};
                $class {
                    $($field: Array1::from_iter(items.iter().map(|i| <$elem>::from(i.$field)))
                        .into_pyarray(py)
                        .unbind(),)+
                }
            }
        }
    };
    (
        @class $(#[$doc:meta])* $name:literal $class:ident: $dims:ident {
            $($(#[$field_doc:meta])* $field:ident: $elem:ty,)+
        }
    ) => {
        $(#[$doc])*
        #[pyclass(module = "gnomon._kernel", name = $name, frozen)]
        pub(crate) struct $class {
            $($(#[$field_doc])* #[pyo3(get)] $field: Py<numpy::$dims<$elem>>,)+
        }
    };
}
pub(crate) use result_class;

result_class! {
    /// The tracker's per-pixel results: (H, W) arrays, read-only attributes.
    "ShadowTimes" PyShadowTimes: grid of ShadowTimes {
        image f32 {
            /// Brightest level of the deepest dip (DN of the input; fractional when normalised).
            imax,
            /// Darkest sample of the dip (DN of the input).
            imin,
            /// `imax - imin` (DN), 0 = no dip.
            contrast,
            /// Mid-level in linear irradiance (in the light of the dip).
            threshold,
        }
        image f32 {
            /// Entering-edge time (frames), NaN = none.
            enter,
            /// Leaving-edge time (frames), NaN = none.
            leave,
            /// Linear irradiance change per frame at the entering crossing.
            enter_slope,
            /// Linear irradiance change per frame at the leaving crossing.
            leave_slope,
        }
        image f32 {
            /// Depth of the deepest other dip (DN), 0 = none.
            rival,
        }
        mask bool {
            /// A dip with `contrast >= min_contrast` that is not ambiguous.
            valid,
            /// `contrast >= min_contrast` and the rival dip at least `ambiguity` times as deep.
            ambiguous,
            /// The dip's levels or an interpolated sample at 0 or the dtype's maximum.
            clipped,
        }
    }
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

result_class! {
    /// Every pixel's second candidate dip: (H, W) arrays, read-only attributes
    /// (same meanings as `ShadowTimes`'; NaN times and 0 levels where there is none).
    "SecondDips" PySecondDips: grid of SecondDips {
        image f32 {
            imax, imin, contrast, threshold, enter, leave, enter_slope, leave_slope,
            /// The best dip's times and slopes wherever it exists (also ambiguous ones).
            best_enter,
            best_leave, best_enter_slope, best_leave_slope,
        }
    }
}
