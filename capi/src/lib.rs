//! The C ABI of dofray: `libdofray.so` and `libdofray.a`, declared by `include/dofray.h`
//! (generated from this file by cbindgen; `cargo test -p dofray-capi --test header` fails when
//! it is stale, `DOFRAY_BLESS=1` rewrites it).
//!
//! Conventions of every function:
//!
//! - Handles are opaque: `DofrayDevice` (an Embree device), `DofrayScene` (a loaded scene and
//!   the overrides set on it), `DofrayImage` (a rendered image and its statistics),
//!   `DofrayCancel` (a cancellation token) and `DofrayJobs` (the summary of a run of frames
//!   and tiles rendered to files). Each is freed by its own `*_free` function; freeing NULL
//!   does nothing.
//! - Functions that can fail return a `DofrayStatus` (`DOFRAY_OK` = 0) and give their
//!   results through out-pointers, which are set to NULL (or left unchanged, for plain
//!   values) when they fail. Every such call also sets this thread's message
//!   (`dofray_last_error_message`): empty on success, the reason on failure.
//! - A NULL handle or out-pointer, or a string that is not UTF-8, is
//!   `DOFRAY_INVALID_ARGUMENT`, never a crash. A Rust panic never unwinds into C: it is
//!   caught and returned as `DOFRAY_PANIC`.
//! - Threads: a device may be shared by any number of threads; a scene or an image must be
//!   used by one thread at a time; a cancellation token may be used by any thread at any
//!   time.
#![warn(clippy::undocumented_unsafe_blocks)]
#![warn(missing_docs)]

// cbindgen emits include/dofray.h's functions module by module, in the order they are
// declared here (after dofray_version, below); the blank lines keep rustfmt from sorting them.
mod status;
pub use status::*;

mod args;

mod device;
pub use device::*;

mod scene;
pub use scene::*;

mod cancel;
pub use cancel::*;

mod render;
pub use render::*;

mod image;
pub use image::*;

mod cached;

mod jobs;
pub use jobs::*;

use std::ffi::{CString, c_char};
use std::sync::OnceLock;

use status::guard_value;

/// dofray's version, such as `"0.1.0"`: a static string, never freed.
#[unsafe(no_mangle)]
pub extern "C" fn dofray_version() -> *const c_char {
    static VERSION: OnceLock<CString> = OnceLock::new();
    guard_value(c"unknown".as_ptr(), || {
        VERSION
            .get_or_init(|| CString::new(dofray::VERSION).unwrap_or_default())
            .as_ptr()
    })
}
