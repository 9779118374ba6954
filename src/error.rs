//! The one error type of the crate; the C ABI maps each variant to an OIDN-style code.

/// Everything that can go wrong in temc.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A caller passed a value outside its documented domain.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A call was made in the wrong state (e.g. execute before commit).
    #[error("invalid operation: {0}")]
    InvalidOperation(String),
    /// A model could not be parsed, lacks required metadata, or does not fit the contract.
    #[error("model: {0}")]
    Model(String),
    /// tract failed while planning or running a model.
    #[error("inference: {0}")]
    Inference(String),
    /// The progress monitor asked to stop; nothing was written.
    #[error("cancelled by the progress monitor")]
    Cancelled,
    /// A buffer could not be allocated.
    #[error("out of memory: {0}")]
    OutOfMemory(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file involved.
        path: std::path::PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
}

impl From<std::convert::Infallible> for Error {
    /// Lets the setters that take a name or a typed value (`impl TryInto<ImageName>`)
    /// take the typed value, whose conversion cannot fail.
    fn from(never: std::convert::Infallible) -> Self {
        match never {}
    }
}

/// Shorthand for results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
