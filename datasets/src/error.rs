//! The error type of the `datasets` crate.

use hand_model::ModelError;

/// Everything that can go wrong when building motions, subjects or sequences.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A motion name that the library does not know.
    #[error("unknown motion `{name}` (known: {known})")]
    UnknownMotion {
        /// The name asked for.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// A subject name that is neither a named subject nor `random`.
    #[error("unknown subject `{name}` (known: {known})")]
    UnknownSubject {
        /// The name asked for.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// A skeleton lacks a degree of freedom the motion drives.
    #[error("the skeleton has no DOF `{dof}` needed by motion `{motion}`")]
    MissingDof {
        /// The motion.
        motion: String,
        /// The missing DOF name.
        dof: String,
    },
    /// A numeric argument is not finite or out of range.
    #[error("invalid argument `{name}`: {reason}")]
    InvalidArgument {
        /// The argument name.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A data file could not be parsed.
    #[error("{}{}: {reason}", file.display(), line.map(|l| format!(", line {l}")).unwrap_or_default())]
    Parse {
        /// The file (or `<memory>`).
        file: std::path::PathBuf,
        /// The 1-based line, when the problem is on one line.
        line: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: std::path::PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// An image or camera of `sensor-io` could not be read (PNG files of a sequence).
    #[error(transparent)]
    Sensor(#[from] sensor_io::SensorError),
    /// An error of the hand model (template, shape vector).
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A sphere-mesh that cannot be prepared for distance queries (e.g. a block naming a
    /// missing sphere).
    #[error(transparent)]
    Geometry(#[from] hand_model::query::GeometryError),
}

impl DatasetError {
    /// Shorthand for [`DatasetError::InvalidArgument`].
    pub fn arg(name: &'static str, reason: impl Into<String>) -> Self {
        DatasetError::InvalidArgument {
            name,
            reason: reason.into(),
        }
    }
}

/// The crate's result type.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;
