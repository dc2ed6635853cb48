//! What kind of failure an error is, the exit code that kind gives and the JSON object that
//! reports it: the bottom of the error layering. Every error type of the library says its own
//! kind with [`HasKind`], next to its definition; this module imports nothing from the rest of
//! dofray, so any layer may use it. [`crate::exit`] (the top) lists the types and classifies
//! an error's `source()` chain; it re-exports all of this.

use std::error::Error;

/// Exit status of a successful run.
pub const OK: u8 = 0;
/// Exit status of an internal error (anything not classified otherwise).
pub const INTERNAL: u8 = 1;
/// Exit status of a usage error (bad flags or flag values). clap uses it too.
pub const USAGE: u8 = 2;
/// Exit status of an input (scene, model, texture) that cannot be read or is invalid.
pub const BAD_INPUT: u8 = 3;
/// Exit status of an output that cannot be written.
pub const IO: u8 = 4;
/// Exit status of a resource limit (memory, input size caps).
pub const RESOURCE_LIMIT: u8 = 5;

/// What kind of failure stopped a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// Bad command-line flags or values.
    Usage,
    /// A scene, model or texture that cannot be read or is invalid.
    BadInput,
    /// An output that cannot be written.
    Io,
    /// A resource limit: the image's buffers exceed the available memory, or an input exceeds
    /// a [`crate::scene::LoadOptions`] limit, or Embree ran out of memory.
    ResourceLimit,
    /// Stopped by a signal (its number).
    Interrupted(i32),
    /// Anything else.
    Internal,
}

impl ErrorKind {
    /// The process exit status for this kind (see [`crate::exit`]).
    pub fn exit_code(self) -> u8 {
        match self {
            Self::Usage => USAGE,
            Self::BadInput => BAD_INPUT,
            Self::Io => IO,
            Self::ResourceLimit => RESOURCE_LIMIT,
            Self::Interrupted(signal) => u8::try_from(128 + signal.clamp(0, 127)).unwrap_or(255),
            Self::Internal => INTERNAL,
        }
    }

    /// The kind's name in JSON error objects (`"bad_input"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Usage => "usage",
            Self::BadInput => "bad_input",
            Self::Io => "io",
            Self::ResourceLimit => "resource_limit",
            Self::Interrupted(_) => "interrupted",
            Self::Internal => "internal",
        }
    }
}

/// The version of the `--json` objects' layout (`schema_version`, docs/json.md). Raised when a
/// field is removed or changes meaning; new fields may appear within a version.
pub const SCHEMA_VERSION: u32 = 1;

/// The JSON error object `dofray --json` prints on stdout when it fails:
/// `{"schema_version": 1, "error": {"kind": ..., "message": ..., "exit_code": ...}}`.
pub fn json_error(kind: ErrorKind, message: &str) -> serde_json::Value {
    serde_json::json!({
        "schema_version": SCHEMA_VERSION,
        "error": error_object(kind, message),
    })
}

/// The `error` member of [`json_error`]: `kind`, `message` and `exit_code` (also a failed
/// job's entry in a run's summary).
pub fn error_object(kind: ErrorKind, message: &str) -> serde_json::Value {
    serde_json::json!({
        "kind": kind.name(),
        "message": message,
        "exit_code": kind.exit_code(),
    })
}

/// `error`'s message followed by those of its sources, `outer: inner: innermost` (what the
/// command line prints, for bindings that report a message).
pub fn full_message(error: &(dyn Error + 'static)) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        message.push_str(": ");
        message.push_str(&e.to_string());
        source = e.source();
    }
    message
}

/// An error that knows its kind (hence its exit code and JSON `kind`).
///
/// Implemented next to each error type's definition, and only inside dofray: its sealed
/// supertrait is implemented by the `classified!` list in [`crate::exit`] alone, so an
/// `impl HasKind` for a type missing from that list does not compile, nor does a listed type
/// without one. [`crate::exit::classify`] thus recognises every error that has a kind.
pub trait HasKind: Error + sealed::Listed + 'static {
    /// What kind of failure this error is.
    fn kind(&self) -> ErrorKind;
}

pub(crate) mod sealed {
    /// A type in [`crate::exit`]'s list of the errors [`crate::exit::classify`] recognises.
    /// Implemented there only (by its `classified!` list), and private to dofray.
    #[diagnostic::on_unimplemented(
        message = "`{Self}` is not in the list of classified errors",
        note = "add it to the `classified!` list in src/exit.rs"
    )]
    pub trait Listed {}
}

impl HasKind for std::io::Error {
    fn kind(&self) -> ErrorKind {
        match self.kind() {
            std::io::ErrorKind::OutOfMemory => ErrorKind::ResourceLimit,
            std::io::ErrorKind::Interrupted => ErrorKind::Interrupted(2),
            _ => ErrorKind::Io,
        }
    }
}
