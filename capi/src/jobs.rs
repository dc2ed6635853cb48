//! Rendering frames and tiles to files: the library's job loop (`dofray::batch::Batch::run`,
//! as `dofray render` runs it) with skip-existing, no-overwrite, fail-fast and a shard, the
//! per-job callback, and the summary it returns.

use std::cell::RefCell;
use std::ffi::{CString, c_char, c_int, c_void};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use dofray::batch::jobs::Job;
use dofray::batch::run::{JobFailure, RunProgress};
use dofray::batch::{Batch, FrameRequest, ImageOptions, JobError, JobOutcome, JobRequest};
use dofray::batch::{RunOptions, RunReport, Shard};
use dofray::params::Param;
use dofray::render::Progress;

use crate::args::{arg_mut, free, out_arg, put, str_arg, value_of};
use crate::cached::usage;
use crate::cancel::DofrayCancel;
use crate::device::DofrayDevice;
use crate::scene::DofrayScene;
use crate::status::{DofrayStatus, Failure, guard};

/// What `dofray_render_jobs` renders and how: the flags of `dofray render` of the same
/// names. All zero (`DofrayJobOptions options = {0};`, or a NULL pointer) renders what the
/// output path names: every frame of the scene's animation for a path with a frame pattern,
/// else one image; whole images; replacing existing files; going on after a failure.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DofrayJobOptions {
    /// The frames, as `--frames` takes them (`"1-48"`, `"1-240x2"`, `"1,5,10..20"`,
    /// `"-5--1"`): NULL for the animation's frames (or one image), as above. Several frames
    /// need a frame pattern in the output path.
    pub frames: *const c_char,
    /// Each image as `tile_columns` x `tile_rows` tiles (`--tiles`), each written next to the
    /// image (`still.tile-003.exr`), merged into it once all are rendered (without a shard)
    /// and removed. Both 0: whole images.
    pub tile_columns: u32,
    /// See `tile_columns`.
    pub tile_rows: u32,
    /// Nonzero: skip a job whose output (or whole image) exists (`--skip-existing`).
    pub skip_existing: c_int,
    /// Nonzero: a job whose output (or whole image) exists fails (`--no-overwrite`).
    pub no_overwrite: c_int,
    /// Nonzero: stop at the first failed job (`--fail-fast`).
    pub fail_fast: c_int,
    /// Render only jobs `shard_index`, `shard_index + shard_count`, ... (`--shard I/N`; the
    /// scheduler's environment is not read). `shard_count` 0: every job.
    pub shard_index: u32,
    /// See `shard_index`.
    pub shard_count: u32,
}

/// Before each job that renders (not a skipped one): `index` (0-based) of the `count` jobs
/// of this run, its frame (`has_frame` nonzero; else `frame` is 0 and the job is a single
/// image or a tile of one), the file it writes (a NUL-terminated string valid during the
/// call), and the `user_data` given to `dofray_render_jobs`. Return 0 to go on, nonzero to
/// cancel the run. It is called on the thread that called `dofray_render_jobs`, and must not
/// unwind into dofray.
pub type DofrayJobProgressFn = Option<
    unsafe extern "C" fn(
        index: usize,
        count: usize,
        frame: i64,
        has_frame: c_int,
        output: *const c_char,
        user_data: *mut c_void,
    ) -> c_int,
>;

/// What became of one job of a run.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DofrayJobStatus {
    /// Rendered and written.
    DOFRAY_JOB_RENDERED = 0,
    /// Its output existed (`skip_existing`).
    DOFRAY_JOB_SKIPPED = 1,
    /// It failed (`dofray_jobs_error` and `dofray_jobs_error_message` say why).
    DOFRAY_JOB_FAILED = 2,
    /// Not attempted: the run stopped at an earlier failure (`fail_fast`). Also what
    /// `dofray_jobs_status` returns for a NULL summary or an index out of range.
    DOFRAY_JOB_NOT_RUN = 3,
}

/// One job of a summary.
struct JobEntry {
    output: CString,
    frame: Option<i64>,
    status: DofrayJobStatus,
    error: DofrayStatus,
    message: CString,
}

/// The summary of a run of `dofray_render_jobs`: how many jobs were rendered, skipped and
/// failed, and each job's output path, frame, status and error. Freed by `dofray_jobs_free`.
pub struct DofrayJobs {
    jobs: Vec<JobEntry>,
    merged: usize,
    /// The first failure (a job's, or an image's that could not be assembled from its tiles).
    first_failure: Option<(DofrayStatus, CString)>,
}

/// A C string of `text`, cut at a NUL byte (a path from C has none).
fn c_string(text: &str) -> CString {
    let end = text.bytes().position(|b| b == 0).unwrap_or(text.len());
    CString::new(&text[..end]).unwrap_or_default()
}

impl DofrayJobs {
    /// The summary of `jobs` (all the run was given) after `report`, with the failures to
    /// merge images.
    fn new(jobs: &[Job], report: &RunReport, merge_failures: Vec<(DofrayStatus, String)>) -> Self {
        let entries = jobs.iter().enumerate().map(|(i, job)| {
            let (status, error, message) = match report.results.get(i).map(|r| &r.outcome) {
                Some(JobOutcome::Rendered(_)) => {
                    (DofrayJobStatus::DOFRAY_JOB_RENDERED, None, String::new())
                }
                Some(JobOutcome::Skipped) => {
                    (DofrayJobStatus::DOFRAY_JOB_SKIPPED, None, String::new())
                }
                Some(JobOutcome::Failed(f)) => (
                    DofrayJobStatus::DOFRAY_JOB_FAILED,
                    Some(DofrayStatus::from_kind(f.kind)),
                    failure_message(f),
                ),
                None => (DofrayJobStatus::DOFRAY_JOB_NOT_RUN, None, String::new()),
            };
            JobEntry {
                output: c_string(&job.output.to_string_lossy()),
                frame: job.frame,
                status,
                error: error.unwrap_or(DofrayStatus::DOFRAY_OK),
                message: c_string(&message),
            }
        });
        let jobs: Vec<JobEntry> = entries.collect();
        let first_failure = jobs
            .iter()
            .find(|j| j.status == DofrayJobStatus::DOFRAY_JOB_FAILED)
            .map(|j| (j.error, j.message.clone()))
            .or_else(|| {
                let (status, message) = merge_failures.into_iter().next()?;
                Some((status, c_string(&message)))
            });
        Self {
            jobs,
            merged: report.merged.len(),
            first_failure,
        }
    }

    fn count(&self, status: DofrayJobStatus) -> usize {
        self.jobs.iter().filter(|j| j.status == status).count()
    }
}

/// A job's failure message, the option refusing to overwrite named as here.
fn failure_message(failure: &JobFailure) -> String {
    match &failure.error {
        Some(JobError::Exists { path }) => {
            format!(
                "{} exists and no_overwrite refuses to replace it",
                path.display()
            )
        }
        _ => failure.message.clone(),
    }
}

/// Whether the run must stop: the callback asked, or the token was cancelled.
#[derive(Clone, Copy)]
struct Stop<'a> {
    asked: &'a AtomicBool,
    token: Option<&'a DofrayCancel>,
}

impl Stop<'_> {
    fn requested(&self) -> bool {
        self.asked.load(Ordering::SeqCst) || self.token.is_some_and(|t| t.flag.is_cancelled())
    }
}

impl Progress for Stop<'_> {
    fn cancelled(&self) -> bool {
        self.requested()
    }
}

/// [`RunProgress`] over the C callback: it is called as each job starts; a job's render
/// stops when it (or the token) asks.
struct CallbackProgress<'a> {
    callback: DofrayJobProgressFn,
    user_data: *mut c_void,
    stop: Stop<'a>,
    merge_failures: RefCell<Vec<(DofrayStatus, String)>>,
}

impl RunProgress for CallbackProgress<'_> {
    fn starting(&self, index: usize, count: usize, job: &Job, _seconds_left: Option<f64>) {
        let Some(callback) = self.callback.filter(|_| !self.stop.requested()) else {
            return;
        };
        let output = c_string(&job.output.to_string_lossy());
        let (frame, has_frame) = job.frame.map_or((0, 0), |f| (f, 1));
        // SAFETY: the caller of dofray_render_jobs gave a callback of this signature; the
        // output string lives through the call.
        let stop = unsafe {
            callback(
                index,
                count,
                frame,
                has_frame,
                output.as_ptr(),
                self.user_data,
            )
        };
        if stop != 0 {
            self.stop.asked.store(true, Ordering::SeqCst);
        }
    }

    fn job_progress(&self, _job: &Job) -> Box<dyn Progress + '_> {
        Box::new(self.stop)
    }

    fn merge_failed(&self, _image: &Path, failure: &JobFailure) {
        let status = DofrayStatus::from_kind(failure.kind);
        self.merge_failures
            .borrow_mut()
            .push((status, failure.message.clone()));
    }
}

/// The request and run options of `options` (NULL: all defaults).
///
/// # Safety
/// `options` is NULL or points to a live `DofrayJobOptions` whose `frames` is NULL or a
/// NUL-terminated string.
unsafe fn read_options(
    options: *const DofrayJobOptions,
) -> Result<(JobRequest, RunOptions), Failure> {
    // SAFETY: the caller's contract: NULL or a live options struct, only read.
    let Some(o) = (unsafe { options.as_ref() }) else {
        return Ok((JobRequest::default(), RunOptions::default()));
    };
    let usage = |message: String| Failure::new(DofrayStatus::DOFRAY_USAGE, message);
    let frames = if o.frames.is_null() {
        None
    } else {
        // SAFETY: non-NULL, NUL-terminated by the caller's contract.
        Some(unsafe { str_arg(o.frames, "frames") }?.to_owned())
    };
    let tiles = (o.tile_columns, o.tile_rows);
    let shard = match (o.shard_index, o.shard_count) {
        (0, 0) => None,
        (index, count) => Some(Shard::new(index, count).map_err(|e| usage(format!("shard: {e}")))?),
    };
    if o.skip_existing != 0 && o.no_overwrite != 0 {
        return Err(usage(
            "skip_existing and no_overwrite exclude each other".into(),
        ));
    }
    let request = JobRequest {
        frames: FrameRequest {
            list: frames,
            ..Default::default()
        },
        tiles: (tiles != (0, 0)).then_some(tiles),
        shard,
    };
    let run = RunOptions {
        skip_existing: o.skip_existing != 0,
        no_overwrite: o.no_overwrite != 0,
        fail_fast: o.fail_fast != 0,
        merge_tiles: false, // the plan says
    };
    Ok((request, run))
}

/// Renders the scene, with its overrides and settings, to image files: one per frame, or per
/// tile of each frame, as `options` ask (NULL: what `output` names; see `DofrayJobOptions`),
/// as `dofray render -o OUTPUT` with the same flags does. `output` is the image's path,
/// PNG or EXR by its extension; a run of `#` in it becomes the zero-padded frame number
/// (`shot_####.exr` -> `shot_0007.exr`). Folders are made as needed; each file is written
/// to a temporary file and renamed, so a file that exists is complete.
///
/// `device`: as for `dofray_render` (NULL: the scene's own). `progress` (may be NULL) is
/// called before each job that renders, with `user_data`, as `DofrayJobProgressFn` says; a
/// nonzero return cancels the run. `cancel` (may be NULL) is a token another thread may
/// cancel.
///
/// A run that goes through returns `DOFRAY_OK` and its summary in `*out`, even when jobs
/// failed: `dofray_jobs_failed` counts them and `dofray_jobs_first_failure` gives the first
/// failure's status. A bad option, override or setting fails with `DOFRAY_USAGE`, a folder
/// that cannot be made with `DOFRAY_IO`; a cancelled run returns `DOFRAY_CANCELLED` and no
/// summary (the files written so far stay; `skip_existing` resumes).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread; `device` is NULL or a live
/// device; `output` is NULL or a NUL-terminated string; `options` is NULL or points to a
/// `DofrayJobOptions` whose `frames` is NULL or a NUL-terminated string; `progress` is NULL
/// or a function of that signature; `cancel` is NULL or a live token; `out` is NULL or points
/// to writable storage for a pointer.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn dofray_render_jobs(
    scene: *mut DofrayScene,
    device: *const DofrayDevice,
    output: *const c_char,
    options: *const DofrayJobOptions,
    progress: DofrayJobProgressFn,
    user_data: *mut c_void,
    cancel: *const DofrayCancel,
    out: *mut *mut DofrayJobs,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        // SAFETY: the function's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        // SAFETY: the function's contract.
        let output = unsafe { str_arg(output, "output") }?;
        // SAFETY: the function's contract.
        let (request, run) = unsafe { read_options(options) }?;
        let asked = AtomicBool::new(false);
        let progress = CallbackProgress {
            callback: progress,
            user_data,
            stop: Stop {
                asked: &asked,
                // SAFETY: the function's contract: NULL or a live token, only read atomically.
                token: unsafe { cancel.as_ref() },
            },
            merge_failures: RefCell::default(),
        };
        // SAFETY: the function's contract: NULL or a live device, only read.
        let device = unsafe { device.as_ref() };
        let jobs = render_jobs(scene, device, Path::new(output), &request, run, progress)?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, jobs) };
        Ok(())
    })
}

fn render_jobs(
    scene: &mut DofrayScene,
    device: Option<&DofrayDevice>,
    output: &Path,
    request: &JobRequest,
    run: RunOptions,
    progress: CallbackProgress<'_>,
) -> Result<DofrayJobs, Failure> {
    let cancelled = || Failure::new(DofrayStatus::DOFRAY_CANCELLED, "the run was cancelled");
    if progress.stop.requested() {
        return Err(cancelled());
    }
    let patch = scene.settings.clone();
    let renderer = scene.renderer(device)?;
    let settings = renderer.settings(&patch).map_err(usage)?;
    let batch = Batch {
        renderer,
        settings: &settings,
        pool: None,
        image: ImageOptions::default(),
        region: None,
        param_name: Param::setter_name,
    };
    let plan = batch.plan(output, request)?;
    let run = RunOptions {
        merge_tiles: plan.merge_tiles,
        ..run
    };
    let report = batch.run(&plan.mine, run, &progress)?;
    if report.cancelled() || progress.stop.requested() {
        return Err(cancelled());
    }
    let merge_failures = progress.merge_failures.into_inner();
    Ok(DofrayJobs::new(&plan.mine, &report, merge_failures))
}

/// Frees a run's summary (NULL: nothing); its strings go with it.
///
/// # Safety
/// `jobs` is NULL or a summary from `dofray_render_jobs`, not used afterwards (nor its
/// strings).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_free(jobs: *mut DofrayJobs) {
    // SAFETY: the function's contract.
    unsafe { free(jobs) }
}

/// The number of jobs the run was given (its shard's share; 0 for NULL): the indexes of the
/// per-job functions go from 0 to this, in the order the jobs were planned.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_count(jobs: *const DofrayJobs) -> usize {
    // SAFETY: the function's contract.
    unsafe { value_of(jobs, 0, |j| j.jobs.len()) }
}

/// The number of jobs rendered (0 for NULL).
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_rendered(jobs: *const DofrayJobs) -> usize {
    // SAFETY: the function's contract.
    unsafe { value_of(jobs, 0, |j| j.count(DofrayJobStatus::DOFRAY_JOB_RENDERED)) }
}

/// The number of jobs skipped because their output existed (0 for NULL).
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_skipped(jobs: *const DofrayJobs) -> usize {
    // SAFETY: the function's contract.
    unsafe { value_of(jobs, 0, |j| j.count(DofrayJobStatus::DOFRAY_JOB_SKIPPED)) }
}

/// The number of jobs that failed (0 for NULL).
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_failed(jobs: *const DofrayJobs) -> usize {
    // SAFETY: the function's contract.
    unsafe { value_of(jobs, 0, |j| j.count(DofrayJobStatus::DOFRAY_JOB_FAILED)) }
}

/// The number of images assembled from their tiles (and the tiles removed; 0 for NULL).
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_merged(jobs: *const DofrayJobs) -> usize {
    // SAFETY: the function's contract.
    unsafe { value_of(jobs, 0, |j| j.merged) }
}

/// The status of the run's first failure (a job's, or an image's that could not be assembled
/// from its tiles): `DOFRAY_OK` when nothing failed, `DOFRAY_INVALID_ARGUMENT` for NULL. Its
/// message is `dofray_jobs_first_failure_message`.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_first_failure(jobs: *const DofrayJobs) -> DofrayStatus {
    let invalid = DofrayStatus::DOFRAY_INVALID_ARGUMENT;
    // SAFETY: the function's contract.
    unsafe {
        value_of(jobs, invalid, |j| {
            j.first_failure
                .as_ref()
                .map_or(DofrayStatus::DOFRAY_OK, |(status, _)| *status)
        })
    }
}

/// The message of the run's first failure: empty when nothing failed (or for NULL). It
/// belongs to the summary and lives as long as it.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_first_failure_message(
    jobs: *const DofrayJobs,
) -> *const c_char {
    // SAFETY: the function's contract.
    unsafe {
        value_of(jobs, c"".as_ptr(), |j| {
            j.first_failure
                .as_ref()
                .map_or(c"".as_ptr(), |(_, message)| message.as_ptr())
        })
    }
}

/// Runs `get` on job `index` of the summary behind `jobs`, or returns `fallback` for NULL, an
/// index out of range (or a panic).
///
/// # Safety
/// `jobs` is NULL or a live summary.
unsafe fn job_value<T: Copy>(
    jobs: *const DofrayJobs,
    index: usize,
    fallback: T,
    get: impl FnOnce(&JobEntry) -> T,
) -> T {
    // SAFETY: the caller's contract.
    unsafe { value_of(jobs, fallback, |j| j.jobs.get(index).map_or(fallback, get)) }
}

/// The file job `index` writes (a tile's file for a tile); NULL for a NULL summary or an
/// index out of range. The string belongs to the summary and lives as long as it.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_output(
    jobs: *const DofrayJobs,
    index: usize,
) -> *const c_char {
    // SAFETY: the function's contract.
    unsafe { job_value(jobs, index, std::ptr::null(), |j| j.output.as_ptr()) }
}

/// Whether job `index` renders a frame of several (then `*frame`, when `frame` is not NULL,
/// is set to it): 1, else 0 (also for a NULL summary or an index out of range).
///
/// # Safety
/// `jobs` is NULL or a live summary; `frame` is NULL or points to writable storage for an
/// `int64_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_frame(
    jobs: *const DofrayJobs,
    index: usize,
    frame: *mut i64,
) -> c_int {
    // SAFETY: the function's contract.
    let found = unsafe { job_value(jobs, index, None, |j| j.frame) };
    match found {
        Some(f) => {
            if !frame.is_null() {
                // SAFETY: non-NULL, and writable by the function's contract.
                unsafe { *frame = f };
            }
            1
        }
        None => 0,
    }
}

/// What became of job `index`: `DOFRAY_JOB_NOT_RUN` also for a NULL summary or an index out
/// of range.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_status(
    jobs: *const DofrayJobs,
    index: usize,
) -> DofrayJobStatus {
    let not_run = DofrayJobStatus::DOFRAY_JOB_NOT_RUN;
    // SAFETY: the function's contract.
    unsafe { job_value(jobs, index, not_run, |j| j.status) }
}

/// Why job `index` failed, as a status (`DOFRAY_IO`, `DOFRAY_USAGE`, ...): `DOFRAY_OK` for a
/// job that did not fail, `DOFRAY_INVALID_ARGUMENT` for a NULL summary or an index out of
/// range.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_error(jobs: *const DofrayJobs, index: usize) -> DofrayStatus {
    let invalid = DofrayStatus::DOFRAY_INVALID_ARGUMENT;
    // SAFETY: the function's contract.
    unsafe { job_value(jobs, index, invalid, |j| j.error) }
}

/// Why job `index` failed (the whole message, naming the file or parameter at fault): empty
/// for a job that did not fail, a NULL summary or an index out of range. Never NULL; the
/// string belongs to the summary and lives as long as it.
///
/// # Safety
/// `jobs` is NULL or a live summary.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_jobs_error_message(
    jobs: *const DofrayJobs,
    index: usize,
) -> *const c_char {
    // SAFETY: the function's contract.
    unsafe { job_value(jobs, index, c"".as_ptr(), |j| j.message.as_ptr()) }
}
