//! Cancellation tokens.

use dofray::render::CancelFlag;

use crate::args::{free, out_arg, put};
use crate::status::{DofrayStatus, guard};

/// A cancellation token: `dofray_cancel` from any thread stops the renders given it.
pub struct DofrayCancel {
    pub(crate) flag: CancelFlag,
}

/// Creates a cancellation token, not cancelled.
///
/// # Safety
/// `out` is NULL or points to writable storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_cancel_new(out: *mut *mut DofrayCancel) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        let token = DofrayCancel {
            flag: CancelFlag::new(),
        };
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, token) };
        Ok(())
    })
}

/// Cancels: a render given this token stops soon (within about a row's work per thread) and
/// returns `DOFRAY_CANCELLED`; one started later stops at once. Safe to call from any
/// thread (and from a signal handler: it only sets a flag) while a render runs.
///
/// # Safety
/// `token` is NULL (nothing happens) or a live token.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_cancel(token: *const DofrayCancel) {
    // SAFETY: the function's contract: NULL or a live token (only read atomically).
    if let Some(token) = unsafe { token.as_ref() } {
        token.flag.cancel();
    }
}

/// Makes the token not cancelled again, for the next render.
///
/// # Safety
/// `token` is NULL (nothing happens) or a live token.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_cancel_reset(token: *const DofrayCancel) {
    // SAFETY: the function's contract: NULL or a live token (only written atomically).
    if let Some(token) = unsafe { token.as_ref() } {
        token.flag.reset();
    }
}

/// Frees a token (NULL: nothing). No render may be using it.
///
/// # Safety
/// `token` is NULL or a token from `dofray_cancel_new`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_cancel_free(token: *mut DofrayCancel) {
    // SAFETY: the function's contract.
    unsafe { free(token) }
}
