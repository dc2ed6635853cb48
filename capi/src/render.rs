//! Rendering, and the progress callback.

use std::ffi::{CString, c_char, c_int, c_void};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use dofray::render::Progress;

use crate::args::{arg_mut, out_arg, put};
use crate::cached::usage;
use crate::cancel::DofrayCancel;
use crate::device::DofrayDevice;
use crate::image::DofrayImage;
use crate::scene::DofrayScene;
use crate::status::{DofrayStatus, Failure, guard};

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
        self.cancelled.load(Ordering::SeqCst) || self.token.is_some_and(|t| t.flag.is_cancelled())
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
    let (patch, frame) = (scene.settings.clone(), scene.frame);
    let renderer = scene.renderer(device)?;
    let settings = renderer.settings(&patch).map_err(usage)?;
    let (film, stats) = renderer
        .render_frame(frame, None, &settings, &progress)
        .map_err(usage)?;
    if progress.was_cancelled() {
        return Err(cancelled());
    }
    Ok(DofrayImage {
        rgba: film.try_rgba_interleaved()?,
        film,
        stats,
        transparent: settings.transparent,
    })
}
