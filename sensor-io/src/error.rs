//! The error type of `sensor-io`.

use std::path::PathBuf;

/// Errors of frames, cameras, recordings and preprocessing.
#[derive(Debug, thiserror::Error)]
pub enum SensorError {
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// A file is corrupt, truncated or of the wrong kind.
    #[error("{file}: {reason}")]
    Format {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A field of a metadata file is missing or invalid.
    #[error("{file}: field `{field}`: {reason}")]
    Field {
        /// The file.
        file: PathBuf,
        /// The field.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// An argument is out of range or images disagree in size.
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// The argument.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
}

impl SensorError {
    pub(crate) fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SensorError::Io {
            file: file.into(),
            source,
        }
    }

    pub(crate) fn format(file: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        SensorError::Format {
            file: file.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn field(
        file: impl Into<PathBuf>,
        field: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        SensorError::Field {
            file: file.into(),
            field: field.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn arg(name: &'static str, reason: impl Into<String>) -> Self {
        SensorError::InvalidArgument {
            name,
            reason: reason.into(),
        }
    }
}

/// The crate's result type.
pub type Result<T, E = SensorError> = std::result::Result<T, E>;
