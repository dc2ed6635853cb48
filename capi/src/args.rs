//! The pointers C passes in: handles, strings and out-pointers, checked, and handles freed.

use std::ffi::{CStr, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

use crate::status::{Failure, guard_value};

/// `ptr` as a reference, or an invalid-argument failure naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a live `T` that nothing else mutates for `'a`.
pub(crate) unsafe fn arg<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller's contract: NULL (rejected by as_ref) or a live T.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::invalid(format!("{what} is NULL")))
}

/// `ptr` as a mutable reference, or an invalid-argument failure naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a live `T` that nothing else uses for `'a`.
pub(crate) unsafe fn arg_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller's contract: NULL (rejected by as_mut) or a live, unaliased T.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::invalid(format!("{what} is NULL")))
}

/// A NUL-terminated UTF-8 string argument.
///
/// # Safety
/// `ptr` is NULL or a NUL-terminated string alive for `'a`.
pub(crate) unsafe fn str_arg<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Failure> {
    if ptr.is_null() {
        return Err(Failure::invalid(format!("{what} is NULL")));
    }
    // SAFETY: non-NULL, and the caller's contract makes it a NUL-terminated string.
    let s = unsafe { CStr::from_ptr(ptr) };
    s.to_str()
        .map_err(|_| Failure::invalid(format!("{what} is not valid UTF-8")))
}

/// Stores `value` as a new handle in `*out`.
///
/// # Safety
/// `out` is a valid pointer to a `*mut T` (checked non-NULL by the caller).
pub(crate) unsafe fn put<T>(out: *mut *mut T, value: T) {
    // SAFETY: the caller checked out non-NULL; it points to writable storage for a pointer.
    unsafe { *out = Box::into_raw(Box::new(value)) };
}

/// Sets `*out` to NULL (when `out` is not NULL) and returns it back checked.
///
/// # Safety
/// `out` is NULL or a valid pointer to a `*mut T`.
pub(crate) unsafe fn out_arg<T>(out: *mut *mut T) -> Result<*mut *mut T, Failure> {
    if out.is_null() {
        return Err(Failure::invalid("the out-pointer is NULL"));
    }
    // SAFETY: non-NULL, and the caller's contract makes it a valid pointer to a pointer.
    unsafe { *out = std::ptr::null_mut() };
    Ok(out)
}

/// Frees a boxed handle (NULL: nothing).
///
/// # Safety
/// `ptr` is NULL or came from `Box::into_raw` of a `T` and is not used afterwards.
pub(crate) unsafe fn free<T>(ptr: *mut T) {
    if !ptr.is_null() {
        // A panic while dropping (a bug) is caught; the handle may then leak.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: the caller's contract: a live box that is not used afterwards.
            drop(unsafe { Box::from_raw(ptr) });
        }));
    }
}

/// Runs `get` on the handle behind `ptr`, or returns `fallback` for NULL (or a panic): what
/// every getter that cannot report a status does.
///
/// # Safety
/// `ptr` is NULL or points to a live `T` that nothing mutates during the call.
pub(crate) unsafe fn value_of<T, V>(ptr: *const T, fallback: V, get: impl FnOnce(&T) -> V) -> V {
    // SAFETY: the caller's contract: NULL (rejected by as_ref) or a live T, only read.
    match unsafe { ptr.as_ref() } {
        Some(handle) => guard_value(fallback, || get(handle)),
        None => fallback,
    }
}
