//! [`render_jobs`]: a scene's frames and tiles rendered to files by the library's job loop
//! (`dofray::batch::Batch::run`, as `dofray render` runs it), on a thread of its own while the
//! calling thread waits without the GIL (as [`super::render`] does). The result is the
//! object `dofray render --json` prints for a run of jobs, as a dict.

use std::path::PathBuf;
use std::sync::{Condvar, Mutex, PoisonError};

use dofray::batch::jobs::Job;
use dofray::batch::run::RunProgress;
use dofray::batch::{Batch, FrameRequest, ImageOptions, JobError, JobOutcome, JobRequest};
use dofray::batch::{RunOptions, Shard};
use dofray::exit::ErrorKind;
use dofray::overrides::Overrides;
use dofray::params::Param;
use dofray::render::{CancelFlag, NoProgress, Progress, SettingsPatch};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::keywords::{SceneKeywords, to_u32};
use crate::{Failure, json_to_py, prepare, run_detached, scene_name};

/// `frames=`: a frame list as `--frames` takes it (`"1-48x2"`), or frame numbers.
#[derive(FromPyObject)]
pub(crate) enum Frames {
    Spec(String),
    Numbers(Vec<i64>),
}

/// What the render thread does: load, build, plan and run.
struct JobsCall {
    scene: String,
    output: PathBuf,
    overrides: Overrides,
    settings: SettingsPatch,
    request: JobRequest,
    run: RunOptions,
}

/// A job as it starts: the progress callback's arguments (index, count, frame, output).
type JobStart = (usize, usize, Option<i64>, String);

/// The jobs started and not yet reported, and how many of them were.
#[derive(Default)]
struct Queue {
    waiting: Vec<JobStart>,
    sent: usize,
    reported: usize,
}

/// The jobs started, handed from the render thread to the Python thread, which reports each
/// to the callback before the job renders; and the flag that cancels the run.
#[derive(Default)]
struct Started {
    cancel: CancelFlag,
    /// Whether there is a callback to wait for.
    callback: bool,
    queue: Mutex<Queue>,
    reported: Condvar,
}

/// [`RunProgress`] on the render thread: each job waits for the callback to have seen it.
struct Announce<'a> {
    started: &'a Started,
    /// Wakes the Python thread.
    wake: &'a (dyn Fn() + Sync),
}

impl RunProgress for Announce<'_> {
    fn starting(&self, index: usize, count: usize, job: &Job, _seconds_left: Option<f64>) {
        let started = self.started;
        if !started.callback {
            return;
        }
        let output = job.output.to_string_lossy().into_owned();
        let mut queue = started.queue.lock().unwrap_or_else(PoisonError::into_inner);
        queue.waiting.push((index, count, job.frame, output));
        queue.sent += 1;
        let mine = queue.sent;
        (self.wake)();
        // Until reported, or cancelled (the callback raised: the job's render stops at once).
        while queue.reported < mine && !started.cancel.is_cancelled() {
            let waited = started.reported.wait_timeout(queue, crate::POLL);
            queue = waited.unwrap_or_else(PoisonError::into_inner).0;
        }
    }

    fn job_progress(&self, _job: &Job) -> Box<dyn Progress + '_> {
        Box::new(self.started.cancel.with(&NoProgress))
    }
}

impl JobsCall {
    /// Loads, builds and renders the jobs (on the calling thread), reporting to `announce`:
    /// the run's summary as JSON.
    fn run(self, announce: &Announce<'_>) -> Result<serde_json::Value, Failure> {
        let (renderer, settings) = prepare(&self.scene, self.overrides, &self.settings)?;
        let batch = Batch {
            renderer: &renderer,
            settings: &settings,
            pool: None,
            image: ImageOptions {
                scene_file: Some(self.scene.clone().into()),
                ..Default::default()
            },
            region: None,
            param_name: Param::keyword_name,
        };
        let plan = batch
            .plan(&self.output, &self.request)
            .map_err(|e| Failure::from_error(&e))?;
        let run = RunOptions {
            merge_tiles: plan.merge_tiles,
            ..self.run
        };
        let report = batch
            .run(&plan.mine, run, announce)
            .map_err(|e| Failure::from_error(&e))?;
        if report.cancelled() {
            return Err(Failure {
                kind: ErrorKind::Interrupted(2),
                message: "the run was cancelled".into(),
            });
        }
        let shard = self.request.shard.as_ref().map(|s| (s, "shard"));
        let summary = report.summary(&renderer, &self.output, shard, plan.all.len());
        let mut value = serde_json::to_value(&summary).map_err(|e| Failure {
            kind: ErrorKind::Internal,
            message: format!("internal error in dofray: the summary: {e}"),
        })?;
        // The option refusing to overwrite, named as the keyword.
        let entries = value["frames"].as_array_mut().into_iter().flatten();
        for (result, entry) in report.results.iter().zip(entries) {
            if let JobOutcome::Failed(f) = &result.outcome
                && let Some(JobError::Exists { path }) = &f.error
            {
                entry["error"]["message"] = format!(
                    "{} exists and no_overwrite refuses to replace it",
                    path.display()
                )
                .into();
            }
        }
        Ok(value)
    }
}

/// Calls `callback(index, count, frame, output)` for each job started since the last call,
/// then lets them render.
fn report_started(py: Python<'_>, callback: Option<&Py<PyAny>>, started: &Started) -> PyResult<()> {
    let Some(callback) = callback else {
        return Ok(());
    };
    let jobs = {
        let mut queue = started.queue.lock().unwrap_or_else(PoisonError::into_inner);
        std::mem::take(&mut queue.waiting)
    };
    let count = jobs.len();
    for job in jobs {
        callback.call1(py, job)?;
    }
    let mut queue = started.queue.lock().unwrap_or_else(PoisonError::into_inner);
    queue.reported += count;
    started.reported.notify_all();
    Ok(())
}

/// The job request and run options of the keywords.
fn request(
    frames: Option<Frames>,
    tiles: Option<(i64, i64)>,
    shard: Option<(i64, i64)>,
    skip_existing: bool,
    no_overwrite: bool,
    fail_fast: bool,
) -> Result<(JobRequest, RunOptions), Failure> {
    if skip_existing && no_overwrite {
        return Err(Failure::usage(
            "skip_existing and no_overwrite exclude each other".into(),
        ));
    }
    let list = frames.map(|f| match f {
        Frames::Spec(spec) => spec,
        Frames::Numbers(n) => n.iter().map(i64::to_string).collect::<Vec<_>>().join(","),
    });
    let pair = |name: &str, (a, b): (i64, i64)| -> Result<(u32, u32), Failure> {
        let a = to_u32(name, Some(a))?.unwrap_or(0);
        Ok((a, to_u32(name, Some(b))?.unwrap_or(0)))
    };
    let tiles = tiles.map(|t| pair("tiles", t)).transpose()?;
    let shard = match shard {
        Some(s) => {
            let (index, count) = pair("shard", s)?;
            let shard =
                Shard::new(index, count).map_err(|e| Failure::usage(format!("shard: {e}")))?;
            Some(shard)
        }
        None => None,
    };
    let request = JobRequest {
        frames: FrameRequest {
            list,
            ..Default::default()
        },
        tiles,
        shard,
    };
    let run = RunOptions {
        skip_existing,
        no_overwrite,
        fail_fast,
        merge_tiles: false, // the plan says
    };
    Ok((request, run))
}

/// Renders `scene`'s frames and tiles to `output`; see the Python package's
/// `dofray.render_jobs` for the keywords.
#[pyfunction]
#[pyo3(signature = (
    scene, output, *, frames=None, tiles=None, skip_existing=false, no_overwrite=false,
    fail_fast=false, shard=None, progress=None, **overrides
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_jobs<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    frames: Option<Frames>,
    tiles: Option<(i64, i64)>,
    skip_existing: bool,
    no_overwrite: bool,
    fail_fast: bool,
    shard: Option<(i64, i64)>,
    progress: Option<Py<PyAny>>,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(callback) = &progress
        && !callback.bind(py).is_callable()
    {
        return Err(PyTypeError::new_err(
            "progress must be callable (index, count, frame, output)",
        ));
    }
    let keywords = SceneKeywords::from_dict(overrides)?;
    let call = (|| -> Result<JobsCall, Failure> {
        let (overrides, settings) = keywords.parts()?;
        let (request, run) = request(frames, tiles, shard, skip_existing, no_overwrite, fail_fast)?;
        Ok(JobsCall {
            scene: scene_name(&scene)?,
            output,
            overrides,
            settings,
            request,
            run,
        })
    })()
    .map_err(|f| f.into_pyerr(py))?;
    let started = Started {
        callback: progress.is_some(),
        ..Default::default()
    };
    let outcome = run_detached(
        py,
        &started.cancel,
        |wake| {
            call.run(&Announce {
                started: &started,
                wake,
            })
        },
        |py| report_started(py, progress.as_ref(), &started),
    )?;
    match outcome {
        Err(failure) => Err(failure.into_pyerr(py)),
        Ok(summary) => json_to_py(py, &summary),
    }
}
