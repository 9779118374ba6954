//! How the C ABI reports a failure: an OIDN error code and its message.

use super::{
    TEMCError, TEMC_ERROR_CANCELLED, TEMC_ERROR_INVALID_ARGUMENT, TEMC_ERROR_INVALID_OPERATION,
    TEMC_ERROR_OUT_OF_MEMORY, TEMC_ERROR_UNKNOWN, TEMC_ERROR_UNSUPPORTED_HARDWARE,
};
use crate::Error;

/// A failure to report through the C ABI: an OIDN error code and its message.
#[derive(Debug)]
pub(crate) struct Failure {
    pub code: TEMCError,
    pub message: String,
}

impl Failure {
    /// A failure with `code`.
    pub fn new(code: TEMCError, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }

    /// TEMC_ERROR_INVALID_ARGUMENT.
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(TEMC_ERROR_INVALID_ARGUMENT, message)
    }

    /// TEMC_ERROR_INVALID_OPERATION.
    pub fn operation(message: impl Into<String>) -> Self {
        Self::new(TEMC_ERROR_INVALID_OPERATION, message)
    }

    /// TEMC_ERROR_UNSUPPORTED_HARDWARE.
    pub fn unsupported(message: impl Into<String>) -> Self {
        Self::new(TEMC_ERROR_UNSUPPORTED_HARDWARE, message)
    }
}

impl From<Error> for Failure {
    fn from(e: Error) -> Self {
        let code = match &e {
            Error::InvalidArgument(_) | Error::Model(_) | Error::Io { .. } => {
                TEMC_ERROR_INVALID_ARGUMENT
            }
            Error::InvalidOperation(_) => TEMC_ERROR_INVALID_OPERATION,
            Error::Cancelled => TEMC_ERROR_CANCELLED,
            Error::OutOfMemory(_) => TEMC_ERROR_OUT_OF_MEMORY,
            Error::Inference(_) => TEMC_ERROR_UNKNOWN,
        };
        Self::new(code, e.to_string())
    }
}

/// What an entry point's body returns.
pub(crate) type Outcome<T> = Result<T, Failure>;
