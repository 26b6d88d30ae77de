//! The one public error type, split by cause.

use std::fmt;

/// Every fallible vtz operation returns this error. The variant says *why* it failed so
/// callers (and the CLI's exit code) can react: bad bytes, an unsupported variant, a bad
/// argument, a limit hit, or the operating system.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("I/O error: {context}: {source}")]
    Io {
        /// What was being done, e.g. the path.
        context: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The input bytes are not valid: truncated, corrupted, checksum mismatch, out-of-range
    /// metadata. `what` names the place (file, section, field).
    #[error("corrupt input: {what}")]
    Corrupt {
        /// What is wrong, and where.
        what: String,
    },
    /// The input is well-formed but uses a variant vtz does not implement (a 3-band TIFF,
    /// an unknown required section, a newer format version).
    #[error("unsupported: {what}")]
    Unsupported {
        /// What is not supported.
        what: String,
    },
    /// The caller asked for something impossible or inconsistent (a negative error bound,
    /// a window outside the raster, an unknown format name).
    #[error("invalid argument: {what}")]
    InvalidArgument {
        /// What is wrong with the request.
        what: String,
    },
    /// The request is valid but this method cannot meet it on this data (FIS at a bound no
    /// spacing reaches, sibson with a bound that resolves to 0 on a constant raster). An
    /// encode of several methods skips such a method with a note instead of failing.
    #[error("cannot meet the request: {what}")]
    Unmet {
        /// Which method, which request, and how close it came.
        what: String,
    },
    /// The input would need more memory or work than the configured limits allow.
    #[error("limit exceeded: {what}")]
    LimitExceeded {
        /// What would exceed which limit.
        what: String,
    },
}

/// Short alias used throughout the crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// An [`Error::Corrupt`].
    pub fn corrupt(what: impl Into<String>) -> Self {
        Error::Corrupt { what: what.into() }
    }
    /// An [`Error::Unsupported`].
    pub fn unsupported(what: impl Into<String>) -> Self {
        Error::Unsupported { what: what.into() }
    }
    /// An [`Error::InvalidArgument`].
    pub fn invalid(what: impl Into<String>) -> Self {
        Error::InvalidArgument { what: what.into() }
    }
    /// An [`Error::Unmet`].
    pub fn unmet(what: impl Into<String>) -> Self {
        Error::Unmet { what: what.into() }
    }
    /// An [`Error::LimitExceeded`].
    pub fn limit(what: impl Into<String>) -> Self {
        Error::LimitExceeded { what: what.into() }
    }
    /// An [`Error::Io`] while doing `context`.
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Error::Io {
            context: context.into(),
            source,
        }
    }
    /// Prefix the description with where the error happened (e.g. a file name), unless it
    /// already starts with that place (a reader that named its file itself): a message
    /// names its file once.
    pub fn context(self, ctx: impl fmt::Display) -> Self {
        let ctx = ctx.to_string();
        let pre = |s: String| {
            let named = s
                .strip_prefix(ctx.as_str())
                .is_some_and(|rest| rest.is_empty() || rest.starts_with(':'));
            if named { s } else { format!("{ctx}: {s}") }
        };
        match self {
            Error::Io { context, source } => Error::Io {
                context: pre(context),
                source,
            },
            Error::Corrupt { what } => Error::Corrupt { what: pre(what) },
            Error::Unsupported { what } => Error::Unsupported { what: pre(what) },
            Error::InvalidArgument { what } => Error::InvalidArgument { what: pre(what) },
            Error::LimitExceeded { what } => Error::LimitExceeded { what: pre(what) },
            Error::Unmet { what } => Error::Unmet { what: pre(what) },
        }
    }
}
