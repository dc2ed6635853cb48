//! Status codes, this thread's last error message, and the guard that keeps panics out of C.

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char, c_int};
use std::panic::{AssertUnwindSafe, catch_unwind};

use dofray::exit::{ErrorKind, HasKind};

/// What a function did. `DOFRAY_INTERNAL` to `DOFRAY_RESOURCE_LIMIT` have the values of the
/// `dofray` command's exit codes for the same kinds of failure. Later versions may add
/// statuses: treat any value but `DOFRAY_OK` as a failure.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DofrayStatus {
    /// Success.
    DOFRAY_OK = 0,
    /// Anything not classified otherwise (a bug, a non-finite render, a failed Embree call).
    DOFRAY_INTERNAL = 1,
    /// A bad override or setting (its message names the setter and what was expected),
    /// an unknown image extension.
    DOFRAY_USAGE = 2,
    /// A scene, model or texture that cannot be read or is invalid.
    DOFRAY_BAD_INPUT = 3,
    /// An image that cannot be written.
    DOFRAY_IO = 4,
    /// An image too large for memory, an input beyond a loading limit, Embree out of memory.
    DOFRAY_RESOURCE_LIMIT = 5,
    /// The render was cancelled (by the progress callback or a `DofrayCancel` token); no image
    /// was made.
    DOFRAY_CANCELLED = 6,
    /// A NULL handle or out-pointer, a string that is not UTF-8, an unknown name.
    DOFRAY_INVALID_ARGUMENT = 7,
    /// dofray panicked (a bug): the panic was caught at the boundary.
    DOFRAY_PANIC = 8,
}

impl DofrayStatus {
    fn name(self) -> &'static CStr {
        match self {
            Self::DOFRAY_OK => c"ok",
            Self::DOFRAY_INTERNAL => c"internal",
            Self::DOFRAY_USAGE => c"usage",
            Self::DOFRAY_BAD_INPUT => c"bad_input",
            Self::DOFRAY_IO => c"io",
            Self::DOFRAY_RESOURCE_LIMIT => c"resource_limit",
            Self::DOFRAY_CANCELLED => c"cancelled",
            Self::DOFRAY_INVALID_ARGUMENT => c"invalid_argument",
            Self::DOFRAY_PANIC => c"panic",
        }
    }

    pub(crate) fn from_kind(kind: ErrorKind) -> Self {
        match kind {
            ErrorKind::Usage => Self::DOFRAY_USAGE,
            ErrorKind::BadInput => Self::DOFRAY_BAD_INPUT,
            ErrorKind::Io => Self::DOFRAY_IO,
            ErrorKind::ResourceLimit => Self::DOFRAY_RESOURCE_LIMIT,
            ErrorKind::Interrupted(_) => Self::DOFRAY_CANCELLED,
            ErrorKind::Internal => Self::DOFRAY_INTERNAL,
        }
    }
}

/// A failure on its way to C: the status and the message.
pub(crate) struct Failure {
    status: DofrayStatus,
    message: String,
}

impl Failure {
    pub(crate) fn new(status: DofrayStatus, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    pub(crate) fn invalid(message: impl Into<String>) -> Self {
        Self::new(DofrayStatus::DOFRAY_INVALID_ARGUMENT, message)
    }

    /// A library error: its kind, as the command line has it, and its message with its sources
    /// (`outer: inner: innermost`).
    fn of(error: &impl HasKind) -> Self {
        Self::new(
            DofrayStatus::from_kind(error.kind()),
            dofray::exit::full_message(error),
        )
    }
}

/// Only errors with a kind: a new library error type does not compile here until it has one.
impl<E: HasKind> From<E> for Failure {
    fn from(error: E) -> Self {
        Self::of(&error)
    }
}

thread_local! {
    /// This thread's message of the last status-returning call.
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    // A message with a NUL byte (from a file name, say) is cut there.
    let bytes = message.as_bytes();
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    let text = CString::new(&bytes[..end]).unwrap_or_default();
    // try_with: during thread teardown the slot may be gone; the message is then dropped.
    let _ = LAST_ERROR.try_with(|slot| *slot.borrow_mut() = text);
}

/// The message of a caught panic.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    let what = dofray::exit::panic_text(payload);
    format!("internal error: dofray panicked: {what}")
}

/// Runs the body of a status-returning function: catches any panic, sets this thread's
/// message, returns the status.
pub(crate) fn guard(body: impl FnOnce() -> Result<(), Failure>) -> DofrayStatus {
    let failure = match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => {
            set_last_error("");
            return DofrayStatus::DOFRAY_OK;
        }
        Ok(Err(failure)) => failure,
        Err(payload) => Failure::new(DofrayStatus::DOFRAY_PANIC, panic_message(&*payload)),
    };
    // The message itself must not unwind either (it allocates).
    let _ = catch_unwind(AssertUnwindSafe(|| set_last_error(&failure.message)));
    failure.status
}

/// Runs the body of a function that returns a plain value: `fallback` if it panics.
pub(crate) fn guard_value<T>(fallback: T, body: impl FnOnce() -> T) -> T {
    catch_unwind(AssertUnwindSafe(body)).unwrap_or(fallback)
}

/// The message of this thread's last call that returns a `DofrayStatus`: empty after a
/// success, else why it failed (naming the file, parameter or value at fault). Never NULL.
///
/// The string belongs to dofray and stays valid until the next status-returning dofray call
/// on this thread; copy it to keep it.
#[unsafe(no_mangle)]
pub extern "C" fn dofray_last_error_message() -> *const c_char {
    guard_value(c"".as_ptr(), || {
        LAST_ERROR
            .try_with(|slot| slot.borrow().as_ptr())
            .unwrap_or(c"".as_ptr())
    })
}

/// The name of a status (`"ok"`, `"usage"`, `"bad_input"`, `"io"`, `"resource_limit"`,
/// `"cancelled"`, `"invalid_argument"`, `"panic"`, `"internal"`), or `"unknown"` for a value
/// that is none of them: a static string, never freed.
#[unsafe(no_mangle)]
pub extern "C" fn dofray_status_name(status: c_int) -> *const c_char {
    use DofrayStatus::*;
    let all = [
        DOFRAY_OK,
        DOFRAY_INTERNAL,
        DOFRAY_USAGE,
        DOFRAY_BAD_INPUT,
        DOFRAY_IO,
        DOFRAY_RESOURCE_LIMIT,
        DOFRAY_CANCELLED,
        DOFRAY_INVALID_ARGUMENT,
        DOFRAY_PANIC,
    ];
    all.iter()
        .find(|s| **s as c_int == status)
        .map_or(c"unknown".as_ptr(), |s| s.name().as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_names_round_trip() {
        for code in 0..=8 {
            // SAFETY: a static NUL-terminated string.
            let name = unsafe { CStr::from_ptr(dofray_status_name(code)) };
            assert_ne!(name.to_str().unwrap(), "unknown", "{code}");
        }
        // SAFETY: likewise.
        let name = unsafe { CStr::from_ptr(dofray_status_name(99)) };
        assert_eq!(name.to_str().unwrap(), "unknown");
    }

    /// The last error message of this thread.
    fn message() -> String {
        // SAFETY: dofray_last_error_message returns a NUL-terminated string, valid until the
        // next status-returning call on this thread.
        unsafe { CStr::from_ptr(dofray_last_error_message()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn a_panic_becomes_a_status_and_a_message() {
        let status = guard(|| panic!("boom"));
        assert_eq!(status, DofrayStatus::DOFRAY_PANIC);
        assert!(message().contains("panicked: boom"), "{}", message());
        assert_eq!(guard(|| Ok(())), DofrayStatus::DOFRAY_OK);
        assert_eq!(message(), "");
        assert_eq!(guard_value(7, || panic!("boom")), 7);
    }

    #[test]
    fn errors_are_classified_with_their_sources() {
        let status = guard(|| {
            Err(dofray::scene::load("/nonexistent/x.toml")
                .unwrap_err()
                .into())
        });
        assert_eq!(status, DofrayStatus::DOFRAY_BAD_INPUT);
        assert!(message().contains("/nonexistent/x.toml"), "{}", message());
        let status = guard(|| Err(Failure::invalid("a message with a \0 NUL")));
        assert_eq!(status, DofrayStatus::DOFRAY_INVALID_ARGUMENT);
        assert_eq!(message(), "a message with a ");
    }
}
