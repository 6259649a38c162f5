//! The error type of the `eval` crate's metrics and reproductions.

use datasets::DatasetError;

/// Everything that can make a metric refuse its input.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Two images (or an image and the camera) that must have the same size do not.
    #[error("size mismatch: {what} is {found_w}×{found_h}, expected {expected_w}×{expected_h}")]
    SizeMismatch {
        /// Which image.
        what: &'static str,
        /// Expected width (px).
        expected_w: u32,
        /// Expected height (px).
        expected_h: u32,
        /// Found width (px).
        found_w: u32,
        /// Found height (px).
        found_h: u32,
    },
    /// A depth value that is not a finite, non-negative number of millimetres.
    #[error("{what}: invalid depth {value} at pixel ({u}, {v})")]
    InvalidDepth {
        /// Which image.
        what: &'static str,
        /// Column.
        u: u32,
        /// Row.
        v: u32,
        /// The offending value.
        value: f32,
    },
    /// An argument out of its domain (lengths differ, index out of range, bad camera…).
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// The argument.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A dataset file could not be read.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
}

impl EvalError {
    /// Shorthand for [`EvalError::InvalidArgument`].
    pub fn arg(name: &'static str, reason: impl Into<String>) -> Self {
        EvalError::InvalidArgument {
            name,
            reason: reason.into(),
        }
    }

    /// [`EvalError::SizeMismatch`] unless `found == expected`.
    pub fn check_size(what: &'static str, expected: (u32, u32), found: (u32, u32)) -> Result<()> {
        if expected == found {
            Ok(())
        } else {
            Err(EvalError::SizeMismatch {
                what,
                expected_w: expected.0,
                expected_h: expected.1,
                found_w: found.0,
                found_h: found.1,
            })
        }
    }
}

/// The crate's result type.
pub type Result<T, E = EvalError> = std::result::Result<T, E>;
