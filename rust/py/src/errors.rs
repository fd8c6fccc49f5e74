//! The kernel's errors as the exception classes of `gnomon.errors` (all `GnomonError`s
//! and `ValueError`s), one per `KernelError` variant.

use gnomon_core::KernelError;
use pyo3::PyErr;

pyo3::import_exception!(gnomon.errors, KernelParameterError);
pyo3::import_exception!(gnomon.errors, KernelArrayError);
pyo3::import_exception!(gnomon.errors, KernelLutError);
pyo3::import_exception!(gnomon.errors, KernelFramesError);

/// Each `KernelError` variant as its `gnomon.errors` exception class.
pub(crate) fn kernel_error(err: KernelError) -> PyErr {
    let text = err.to_string();
    match err {
        KernelError::InvalidParameter { .. } => KernelParameterError::new_err(text),
        KernelError::LengthMismatch { .. } => KernelArrayError::new_err(text),
        KernelError::InvalidLut { .. } => KernelLutError::new_err(text),
        KernelError::NoFrames | KernelError::TooManyFrames => KernelFramesError::new_err(text),
    }
}
