//! The error type of the `hand-model` crate.

use std::path::PathBuf;

/// Everything that can go wrong when building, loading or validating a model.
///
/// Errors about files name the file, the field and the index so that a user can fix the input.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A field of a template or model file is invalid.
    #[error("{file}: field `{field}`{}: {reason}", index_suffix(*.index))]
    InvalidField {
        /// The file (or `<memory>` for in-memory templates).
        file: PathBuf,
        /// The field name, e.g. `spheres.radius`.
        field: String,
        /// The index inside the field, when the field is a list.
        index: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A file could not be parsed at all.
    #[error("{file}: {reason}")]
    Parse {
        /// The file.
        file: PathBuf,
        /// What failed.
        reason: String,
    },
    /// A numeric argument is not finite or out of range.
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// The argument name.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
}

fn index_suffix(index: Option<usize>) -> String {
    index.map(|i| format!("[{i}]")).unwrap_or_default()
}

impl ModelError {
    /// Shorthand for [`ModelError::InvalidField`].
    pub fn field(
        file: impl Into<PathBuf>,
        field: impl Into<String>,
        index: Option<usize>,
        reason: impl Into<String>,
    ) -> Self {
        ModelError::InvalidField {
            file: file.into(),
            field: field.into(),
            index,
            reason: reason.into(),
        }
    }
}

/// The crate's result type.
pub type Result<T, E = ModelError> = std::result::Result<T, E>;
