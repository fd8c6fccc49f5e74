//! The one error type of the kernel.
//!
//! Every function that takes user data returns `Result<_, KernelError>`; the
//! binding crate maps each variant to its own Python exception class (in
//! `gnomon.errors`, all `GnomonError`s) with the `Display` text, so each
//! message names what was expected and what was given.

use std::fmt;

/// A problem with the data or parameters handed to the kernel.
#[derive(Debug, Clone, PartialEq)]
pub enum KernelError {
    /// A parameter outside its documented range.
    InvalidParameter { name: &'static str, reason: String },
    /// A buffer whose length does not match the shape it must have.
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// A decoding look-up table that is not finite and non-decreasing.
    InvalidLut { reason: String },
    /// `finish` was called before any frame was seen.
    NoFrames,
    /// More frames than the tracker can index (`u32::MAX - 1`).
    TooManyFrames,
}

impl KernelError {
    pub(crate) fn parameter(name: &'static str, reason: impl Into<String>) -> Self {
        KernelError::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }

    /// Checks an image's per-pixel inputs: each `(what, expected, got)` length
    /// matches, and `width` divides the `n` pixels into whole rows.
    pub(crate) fn check_image(
        n: usize,
        width: usize,
        inputs: &[(&'static str, usize, usize)],
    ) -> Result<(), KernelError> {
        for &(what, expected, got) in inputs {
            if got != expected {
                return Err(KernelError::LengthMismatch {
                    what,
                    expected,
                    got,
                });
            }
        }
        if width == 0 || n % width != 0 {
            return Err(KernelError::parameter(
                "width",
                format!("{width} does not divide {n} pixels"),
            ));
        }
        Ok(())
    }
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KernelError::InvalidParameter { name, reason } => {
                write!(f, "invalid parameter `{name}`: {reason}")
            }
            KernelError::LengthMismatch {
                what,
                expected,
                got,
            } => write!(f, "{what}: expected {expected} elements, got {got}"),
            KernelError::InvalidLut { reason } => write!(f, "invalid decoding LUT: {reason}"),
            KernelError::NoFrames => write!(f, "no frames were given to the tracker"),
            KernelError::TooManyFrames => {
                write!(
                    f,
                    "too many frames for one tracker (at most {})",
                    u32::MAX - 1
                )
            }
        }
    }
}

impl std::error::Error for KernelError {}
