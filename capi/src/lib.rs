//! The C ABI of dofray: `libdofray.so` and `libdofray.a`, declared by `include/dofray.h`
//! (generated from this file by cbindgen; `cargo test -p dofray-capi --test header` fails when
//! it is stale, `DOFRAY_BLESS=1` rewrites it).
//!
//! Conventions of every function:
//!
//! - Handles are opaque: `DofrayDevice` (an Embree device), `DofrayScene` (a loaded scene and
//!   the overrides set on it), `DofrayImage` (a rendered image and its statistics) and
//!   `DofrayCancel` (a cancellation token). Each is freed by its own `*_free` function;
//!   freeing NULL does nothing.
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

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use dofray::embree::Device;
use dofray::exit::ErrorKind;
use dofray::output::WriteOptions;
use dofray::overrides::{Overrides, SettingsOverrides};
use dofray::render::{Film, Mode, Progress, RenderStats};
use dofray::renderer::Renderer;
use dofray::scene::SceneDesc;

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
    /// A bad override or setting (its message names the parameter and what was expected),
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

    fn from_kind(kind: ErrorKind) -> Self {
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
struct Failure {
    status: DofrayStatus,
    message: String,
}

impl Failure {
    fn new(status: DofrayStatus, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    fn invalid(message: impl Into<String>) -> Self {
        Self::new(DofrayStatus::DOFRAY_INVALID_ARGUMENT, message)
    }

    /// A library error: classified as the command line does, its message with its sources
    /// (`outer: inner: innermost`).
    fn of(error: &(dyn std::error::Error + 'static)) -> Self {
        let mut message = error.to_string();
        let mut source = error.source();
        while let Some(e) = source {
            message.push_str(": ");
            message.push_str(&e.to_string());
            source = e.source();
        }
        Self::new(
            DofrayStatus::from_kind(dofray::exit::classify(error)),
            message,
        )
    }
}

impl<E: std::error::Error + 'static> From<E> for Failure {
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
    let what = payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(no message)");
    format!("internal error: dofray panicked: {what}")
}

/// Runs the body of a status-returning function: catches any panic, sets this thread's
/// message, returns the status.
fn guard(body: impl FnOnce() -> Result<(), Failure>) -> DofrayStatus {
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
fn guard_value<T>(fallback: T, body: impl FnOnce() -> T) -> T {
    catch_unwind(AssertUnwindSafe(body)).unwrap_or(fallback)
}

/// `ptr` as a reference, or an invalid-argument failure naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a live `T` that nothing else mutates for `'a`.
unsafe fn arg<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller's contract: NULL (rejected by as_ref) or a live T.
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::invalid(format!("{what} is NULL")))
}

/// `ptr` as a mutable reference, or an invalid-argument failure naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a live `T` that nothing else uses for `'a`.
unsafe fn arg_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller's contract: NULL (rejected by as_mut) or a live, unaliased T.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::invalid(format!("{what} is NULL")))
}

/// A NUL-terminated UTF-8 string argument.
///
/// # Safety
/// `ptr` is NULL or a NUL-terminated string alive for `'a`.
unsafe fn str_arg<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Failure> {
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
unsafe fn put<T>(out: *mut *mut T, value: T) {
    // SAFETY: the caller checked out non-NULL; it points to writable storage for a pointer.
    unsafe { *out = Box::into_raw(Box::new(value)) };
}

/// Sets `*out` to NULL (when `out` is not NULL) and returns it back checked.
///
/// # Safety
/// `out` is NULL or a valid pointer to a `*mut T`.
unsafe fn out_arg<T>(out: *mut *mut T) -> Result<*mut *mut T, Failure> {
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
unsafe fn free<T>(ptr: *mut T) {
    if !ptr.is_null() {
        // A panic while dropping (a bug) is caught; the handle may then leak.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: the caller's contract: a live box that is not used afterwards.
            drop(unsafe { Box::from_raw(ptr) });
        }));
    }
}

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

// ------------------------------------------------------------------------------------------
// Devices

/// An Embree device: builds and traces scenes. Share one among all scenes and threads.
pub struct DofrayDevice {
    device: Device,
    /// Unique per device created here, so a scene knows whether its cached world is its.
    id: u64,
}

fn next_device_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Creates an Embree device. `config`: Embree's configuration string (such as
/// `"threads=2"` or `"isa=avx2"`); NULL or `""` takes it from the environment variable
/// `DOFRAY_EMBREE_CONFIG`, else Embree's defaults.
///
/// # Safety
/// `config` is NULL or a NUL-terminated string; `out` is NULL or points to writable storage
/// for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_device_new(
    config: *const c_char,
    out: *mut *mut DofrayDevice,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        let device = if config.is_null() {
            Device::new()?
        } else {
            // SAFETY: non-NULL, NUL-terminated by the function's contract.
            match unsafe { str_arg(config, "config") }? {
                "" => Device::new()?,
                config => Device::with_config(config)?,
            }
        };
        let id = next_device_id();
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayDevice { device, id }) };
        Ok(())
    })
}

/// Frees a device (NULL: nothing). Scenes rendered on it keep what they need of it alive.
///
/// # Safety
/// `device` is NULL or a device from `dofray_device_new`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_device_free(device: *mut DofrayDevice) {
    // SAFETY: the function's contract.
    unsafe { free(device) }
}

// ------------------------------------------------------------------------------------------
// Scenes

/// A scene with its overrides. Rendering builds its Embree world once and keeps it for the
/// next render on the same device while the scene overrides stay the same.
///
/// The `dofray_scene_set_*` functions store their value as given (they fail only for a NULL
/// scene or an unknown mode name); every value is checked when the scene is rendered, all
/// together (some depend on each other and on the scene): a bad one fails `dofray_render`
/// with `DOFRAY_USAGE` and a message naming the parameter (`f_number must be a finite number
/// > 0, got -1`). `dofray_scene_reset_overrides` clears them all.
pub struct DofrayScene {
    desc: SceneDesc,
    overrides: Overrides,
    settings: SettingsOverrides,
    frame: Option<i64>,
    /// The renderer of the last render: its device's id and overrides, then itself.
    cache: Option<(u64, Overrides, Renderer)>,
    /// The device made for renders given no device.
    own_device: Option<DofrayDevice>,
}

impl DofrayScene {
    fn new(desc: SceneDesc) -> Self {
        Self {
            desc,
            overrides: Overrides::default(),
            settings: SettingsOverrides::default(),
            frame: None,
            cache: None,
            own_device: None,
        }
    }
}

/// Loads a scene: a built-in scene by name (`"paper"`, ...), a `.toml` scene file, or a
/// `.obj`, `.gltf` or `.glb` model. Relative paths are relative to the working directory.
/// Fails with `DOFRAY_BAD_INPUT` (the message names the file and the fault) or
/// `DOFRAY_RESOURCE_LIMIT`.
///
/// # Safety
/// `path_or_name` is NULL or a NUL-terminated string; `out` is NULL or points to writable
/// storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_load(
    path_or_name: *const c_char,
    out: *mut *mut DofrayScene,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        // SAFETY: the function's contract.
        let name = unsafe { str_arg(path_or_name, "path_or_name") }?;
        let desc = dofray::scene::load(name)?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayScene::new(desc)) };
        Ok(())
    })
}

/// Parses a TOML scene (`docs/scene-format.md`) from the `len` bytes at `toml` (UTF-8; no
/// terminating NUL needed). `path` (NULL: `"<memory>.toml"`) names the scene in messages,
/// and the files it refers to by relative paths are looked up in `path`'s directory.
///
/// # Safety
/// `toml` is NULL or points to `len` readable bytes; `path` is NULL or a NUL-terminated
/// string; `out` is NULL or points to writable storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_parse(
    toml: *const c_char,
    len: usize,
    path: *const c_char,
    out: *mut *mut DofrayScene,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        if toml.is_null() {
            return Err(Failure::invalid("toml is NULL"));
        }
        // SAFETY: non-NULL and, by the function's contract, `len` readable bytes.
        let bytes = unsafe { std::slice::from_raw_parts(toml.cast::<u8>(), len) };
        let src = std::str::from_utf8(bytes)
            .map_err(|e| Failure::invalid(format!("toml is not valid UTF-8: {e}")))?;
        let path = if path.is_null() {
            "<memory>.toml"
        } else {
            // SAFETY: non-NULL, NUL-terminated by the function's contract.
            unsafe { str_arg(path, "path") }?
        };
        let desc = dofray::scene::file::parse(src, Path::new(path))?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayScene::new(desc)) };
        Ok(())
    })
}

/// Frees a scene (NULL: nothing).
///
/// # Safety
/// `scene` is NULL or a scene from `dofray_scene_load` or `dofray_scene_parse`, not used
/// afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_free(scene: *mut DofrayScene) {
    // SAFETY: the function's contract.
    unsafe { free(scene) }
}

/// Runs `change` on the scene behind `scene`.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
unsafe fn with_scene(
    scene: *mut DofrayScene,
    change: impl FnOnce(&mut DofrayScene) -> Result<(), Failure>,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        change(scene)
    })
}

/// Clears every override and setting of the scene: it renders as its file describes again.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_reset_overrides(scene: *mut DofrayScene) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides = Overrides::default();
            s.settings = SettingsOverrides::default();
            s.frame = None;
            Ok(())
        })
    }
}

/// Image size in pixels. 0 for one of them follows the scene's aspect ratio from the other;
/// 0 for both keeps the scene's size.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_size(
    scene: *mut DofrayScene,
    width: u32,
    height: u32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.width = (width > 0).then_some(width);
            s.overrides.height = (height > 0).then_some(height);
            Ok(())
        })
    }
}

/// A photographic lens of this f-number (> 0), replacing the scene's lens (focal length and
/// sensor width: those set here, else the scene's photographic lens's, else 50 mm on 36 mm).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_f_number(
    scene: *mut DofrayScene,
    f_number: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.f_number = Some(f_number);
            Ok(())
        })
    }
}

/// The focal length in mm (> 0) of a photographic lens (the scene's, or one an f-number
/// sets).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_focal_length_mm(
    scene: *mut DofrayScene,
    focal_length_mm: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.focal_length_mm = Some(focal_length_mm);
            Ok(())
        })
    }
}

/// A lens of this aperture radius in scene units (>= 0; 0: a pinhole), replacing the
/// scene's lens.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_aperture_radius(
    scene: *mut DofrayScene,
    radius: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.aperture_radius = Some(radius);
            Ok(())
        })
    }
}

/// Focus at this distance along the view axis in scene units (> 0; `INFINITY`: at
/// infinity). Clears an autofocus pixel set here.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_focus_distance(
    scene: *mut DofrayScene,
    distance: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.focus_distance = Some(distance);
            s.overrides.autofocus = None;
            Ok(())
        })
    }
}

/// Autofocus on the surface seen through pixel (`x`, `y`) of the image (after the size set
/// here); it must see a surface. Clears a focus distance set here.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_autofocus(
    scene: *mut DofrayScene,
    x: u32,
    y: u32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.autofocus = Some((x, y));
            s.overrides.focus_distance = None;
            Ok(())
        })
    }
}

/// Where sample sites go: `"pinhole"` (no depth of field), `"dense"` (every pixel) or
/// `"adaptive"` (the default). Another name is `DOFRAY_INVALID_ARGUMENT` at once.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread; `mode` is NULL or a
/// NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_mode(
    scene: *mut DofrayScene,
    mode: *const c_char,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        // SAFETY: the function's contract.
        let name = unsafe { str_arg(mode, "mode") }?;
        let mode = [Mode::Pinhole, Mode::Dense, Mode::Adaptive]
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                Failure::invalid(format!(
                    "mode must be \"pinhole\", \"dense\" or \"adaptive\", got {name:?}"
                ))
            })?;
        scene.settings.mode = Some(mode);
        Ok(())
    })
}

/// Samples (of pixel x lens) per sample site that blur reaches (1 to 65536).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_spp(scene: *mut DofrayScene, spp: u32) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.spp = Some(spp);
            Ok(())
        })
    }
}

/// Anti-aliasing samples per in-focus site, and per pixel in pinhole mode (1 to 65536).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_aa(scene: *mut DofrayScene, aa: u32) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.aa = Some(aa);
            Ok(())
        })
    }
}

/// The adaptive mode's error tolerance in 8-bit sRGB code values (> 0).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_tolerance(
    scene: *mut DofrayScene,
    tolerance: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.tolerance = Some(tolerance);
            Ok(())
        })
    }
}

/// The random seed (default 0): the same seed gives the same image.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_seed(scene: *mut DofrayScene, seed: u64) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.seed = Some(seed);
            Ok(())
        })
    }
}

/// Exposure in stops (-64 to 64; default 0): radiance is scaled by 2^exposure.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_exposure(
    scene: *mut DofrayScene,
    exposure: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.exposure = Some(exposure);
            Ok(())
        })
    }
}

/// Nonzero: a transparent background (RGBA premultiplied by coverage, PNGs written with
/// alpha); 0: as the scene says.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_transparent(
    scene: *mut DofrayScene,
    transparent: c_int,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.transparent = transparent != 0;
            Ok(())
        })
    }
}

/// The frame of an animated scene to render (default: its first frame; ignored by a scene
/// without animation).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_frame(
    scene: *mut DofrayScene,
    frame: i64,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.frame = Some(frame);
            Ok(())
        })
    }
}

// ------------------------------------------------------------------------------------------
// Cancellation

/// A cancellation token: `dofray_cancel` from any thread stops the renders given it.
pub struct DofrayCancel {
    flag: AtomicBool,
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
            flag: AtomicBool::new(false),
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
        token.flag.store(true, Ordering::SeqCst);
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
        token.flag.store(false, Ordering::SeqCst);
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

// ------------------------------------------------------------------------------------------
// Rendering

/// Progress of a render: `phase` (`"depth"`, then `"adaptive"`, `"dense"` or `"pinhole"`; a
/// NUL-terminated string valid during the call), `done` of `total` units of that phase, and
/// the `user_data` given to `dofray_render`. Return 0 to go on, nonzero to cancel the render
/// (it then returns `DOFRAY_CANCELLED`).
///
/// It is called when each phase starts (`done` = 0) and ends (`done` = `total`), and in
/// between at most every 50 ms; never again after it returned nonzero. It may be called from dofray's worker threads, never from two
/// threads at once. It must not unwind (throw a C++ exception or `longjmp`) into dofray.
pub type DofrayProgressFn = Option<
    unsafe extern "C" fn(
        phase: *const c_char,
        done: u64,
        total: u64,
        user_data: *mut c_void,
    ) -> c_int,
>;

/// How often the progress callback is called at most within a phase.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(50);

/// The progress callback's state: one call at a time.
struct CallbackState {
    phase: CString,
    done: u64,
    total: u64,
    last_call: Option<Instant>,
    /// The `done` of the last call in this phase.
    reported: Option<u64>,
}

/// [`Progress`] over a C callback and a token.
struct CProgress<'a> {
    callback: DofrayProgressFn,
    user_data: *mut c_void,
    token: Option<&'a DofrayCancel>,
    cancelled: AtomicBool,
    state: Mutex<CallbackState>,
}

// SAFETY: `user_data` is never dereferenced here, only handed back to the callback, and the
// callback is called with the state's mutex held, so never from two threads at once; the C
// caller is told the callback may run on dofray's worker threads.
unsafe impl Sync for CProgress<'_> {}

impl CProgress<'_> {
    /// Updates the state (`update` returns whether the callback must be called now), then
    /// calls the callback if it must, or if the last call is old enough and there is news.
    fn report(&self, update: impl FnOnce(&mut CallbackState) -> bool) {
        let Ok(mut state) = self.state.lock() else {
            return;
        };
        let force = update(&mut state);
        // Once cancelled, the callback is not called again.
        let Some(callback) = self.callback.filter(|_| !self.was_cancelled()) else {
            return;
        };
        let now = Instant::now();
        let done = state.done.min(state.total);
        let due = state.reported != Some(done)
            && state
                .last_call
                .is_none_or(|t| now.duration_since(t) >= PROGRESS_INTERVAL);
        if !(force || due) {
            return;
        }
        state.last_call = Some(now);
        state.reported = Some(done);
        // SAFETY: the caller of dofray_render gave a callback of this signature; the phase
        // string lives in the locked state during the call.
        let stop = unsafe { callback(state.phase.as_ptr(), done, state.total, self.user_data) };
        if stop != 0 {
            self.cancelled.store(true, Ordering::SeqCst);
        }
    }

    fn was_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::SeqCst)
            || self.token.is_some_and(|t| t.flag.load(Ordering::SeqCst))
    }
}

impl Progress for CProgress<'_> {
    fn start(&self, phase: &str, total: u64) {
        self.report(|s| {
            s.phase = CString::new(phase).unwrap_or_default();
            (s.done, s.total, s.reported) = (0, total, None);
            true
        });
    }

    fn advance(&self, units: u64) {
        self.report(|s| {
            s.done = s.done.saturating_add(units);
            s.done >= s.total && s.reported != Some(s.total)
        });
    }

    fn finish(&self) {
        self.report(|s| {
            s.done = s.total;
            s.reported != Some(s.total)
        });
    }

    fn cancelled(&self) -> bool {
        // Already stopping: no more calls.
        if self.was_cancelled() {
            return true;
        }
        self.report(|_| false);
        self.was_cancelled()
    }
}

/// A rendered image: linear RGBA, depth and CoC per pixel, and the render's statistics.
pub struct DofrayImage {
    film: Film,
    stats: RenderStats,
    rgba: Vec<f32>,
    transparent: bool,
}

/// Renders the scene with its overrides into a new image in `*out`.
///
/// `device`: the device to build and trace on (NULL: one the scene makes and keeps). The
/// scene's Embree world is built at the first render and kept for later renders on the same
/// device with the same scene overrides (size, lens, focus), so renders that change only
/// samples, mode, seed, exposure or frame do not rebuild it.
///
/// `progress` (may be NULL) is called with `user_data` as `DofrayProgressFn` describes; a
/// nonzero return cancels. `cancel` (may be NULL) is a token another thread may cancel.
/// A cancelled render returns `DOFRAY_CANCELLED` and no image, even if it had finished.
///
/// Bad overrides fail with `DOFRAY_USAGE`, a camera the scene itself makes invalid with
/// `DOFRAY_BAD_INPUT`, an image too large for memory with `DOFRAY_RESOURCE_LIMIT`.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread; `device` is NULL or a live device;
/// `cancel` is NULL or a live token; `progress` is NULL or a function of that signature;
/// `out` is NULL or points to writable storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_render(
    scene: *mut DofrayScene,
    device: *const DofrayDevice,
    progress: DofrayProgressFn,
    user_data: *mut c_void,
    cancel: *const DofrayCancel,
    out: *mut *mut DofrayImage,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        // SAFETY: the function's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        // SAFETY: the function's contract: NULL or a live device, only read.
        let device = unsafe { device.as_ref() };
        // SAFETY: the function's contract: NULL or a live token, only read atomically.
        let token = unsafe { cancel.as_ref() };
        let image = render(scene, device, progress, user_data, token)?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, image) };
        Ok(())
    })
}

fn render(
    scene: &mut DofrayScene,
    device: Option<&DofrayDevice>,
    callback: DofrayProgressFn,
    user_data: *mut c_void,
    token: Option<&DofrayCancel>,
) -> Result<DofrayImage, Failure> {
    let progress = CProgress {
        callback,
        user_data,
        token,
        cancelled: AtomicBool::new(false),
        state: Mutex::new(CallbackState {
            phase: CString::default(),
            done: 0,
            total: 0,
            last_call: None,
            reported: None,
        }),
    };
    let cancelled = || Failure::new(DofrayStatus::DOFRAY_CANCELLED, "the render was cancelled");
    if progress.was_cancelled() {
        return Err(cancelled());
    }
    let device = match device {
        Some(d) => d,
        None => {
            if scene.own_device.is_none() {
                scene.own_device = Some(DofrayDevice {
                    device: Device::new()?,
                    id: next_device_id(),
                });
            }
            scene.own_device.as_ref().expect("just made")
        }
    };
    let cached =
        matches!(&scene.cache, Some((id, o, _)) if *id == device.id && *o == scene.overrides);
    if !cached {
        // Drop the old world before building the new one: only one in memory at a time.
        scene.cache = None;
        let renderer =
            Renderer::with_overrides(scene.desc.clone(), scene.overrides.clone(), &device.device)?;
        scene.cache = Some((device.id, scene.overrides.clone(), renderer));
    }
    let Some((_, _, renderer)) = &scene.cache else {
        unreachable!("set above")
    };
    let settings = scene.settings.settings(renderer.desc())?;
    let (film, stats) = renderer.render_frame(scene.frame, None, &settings, &progress)?;
    if progress.was_cancelled() {
        return Err(cancelled());
    }
    let rgba = film
        .color
        .iter()
        .zip(&film.alpha)
        .flat_map(|(c, &a)| [c.x, c.y, c.z, a])
        .collect();
    Ok(DofrayImage {
        film,
        stats,
        rgba,
        transparent: settings.transparent,
    })
}

/// Frees an image (NULL: nothing); its buffers go with it.
///
/// # Safety
/// `image` is NULL or an image from `dofray_render`, not used afterwards (nor its buffers).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_free(image: *mut DofrayImage) {
    // SAFETY: the function's contract.
    unsafe { free(image) }
}

/// Runs `get` on the image behind `image`, or returns `fallback` for NULL (or a panic).
///
/// # Safety
/// `image` is NULL or a live image.
unsafe fn image_value<T>(
    image: *const DofrayImage,
    fallback: T,
    get: impl FnOnce(&DofrayImage) -> T,
) -> T {
    // SAFETY: the caller's contract: NULL or a live image, only read.
    match unsafe { image.as_ref() } {
        Some(image) => guard_value(fallback, || get(image)),
        None => fallback,
    }
}

/// The image's width in pixels (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_width(image: *const DofrayImage) -> u32 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, 0, |i| i.film.width as u32) }
}

/// The image's height in pixels (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_height(image: *const DofrayImage) -> u32 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, 0, |i| i.film.height as u32) }
}

/// The pixels: 4 floats per pixel (R, G, B, A), rows top to bottom, width x height pixels.
/// Linear radiance (not sRGB-encoded, not clamped); with a transparent background, RGB is
/// premultiplied by A (the coverage), else A is 1. Valid until `dofray_image_free`; NULL for
/// a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_rgba(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, std::ptr::null(), |i| i.rgba.as_ptr()) }
}

/// Depth per pixel (width x height floats, rows top to bottom): the distance along the view
/// axis to the surface seen through the pixel's centre, `INFINITY` where it sees the
/// background. Valid until `dofray_image_free`; NULL for a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_depth(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, std::ptr::null(), |i| i.film.depth.as_ptr()) }
}

/// Circle-of-confusion diameter in pixels per pixel (width x height floats, rows top to
/// bottom). Valid until `dofray_image_free`; NULL for a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_coc(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, std::ptr::null(), |i| i.film.coc.as_ptr()) }
}

/// Rays the render traced (camera, shadow and mirror rays; 0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_rays(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, 0, |i| i.stats.rays.total()) }
}

/// Pixels shaded directly, the sample sites (the rest were interpolated; 0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_sample_sites(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, 0, |i| i.stats.sample_sites) }
}

/// Wall-clock seconds the render took, without building the scene (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_seconds(image: *const DofrayImage) -> f64 {
    // SAFETY: the function's contract.
    unsafe { image_value(image, 0.0, |i| i.stats.seconds) }
}

/// Writes the image to `path`, replacing it atomically: `.png` (8-bit sRGB; RGBA with
/// straight alpha when the background was transparent) or `.exr` (float linear RGBA plus
/// depth, CoC and dofray's passes). Another extension is `DOFRAY_USAGE`; a file that cannot
/// be written `DOFRAY_IO`.
///
/// # Safety
/// `image` is NULL or a live image; `path` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_write(
    image: *const DofrayImage,
    path: *const c_char,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let image = unsafe { arg(image, "image") }?;
        // SAFETY: the function's contract.
        let path = unsafe { str_arg(path, "path") }?;
        let options = WriteOptions {
            png_alpha: image.transparent,
            ..Default::default()
        };
        dofray::output::write_film_with(Path::new(path), &image.film, &options)?;
        Ok(())
    })
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
