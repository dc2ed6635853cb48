//! The job loop: render each planned job ([`super::jobs::plan`]) of a [`Renderer`], write it
//! atomically, skip or refuse what exists, go on after a failure (or stop), and assemble a
//! frame's tiles once all of them are written. Front ends (the command line, C, Python) call
//! it and only present what it reports ([`RunProgress`], [`RunReport`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::jobs::{self, Job};
use super::request::{JobRequest, RequestError, RequestPlan};
use super::summary::{EmbreeSummary, JobFacts, JobSummary};
use crate::error_kind::{self, ErrorKind, HasKind};
use crate::output::{self, ExrCompression, OutputError, RenderTargets};
use crate::params::Param;
use crate::render::{self, NoProgress, Progress, Region, RenderError, RenderSettings};
use crate::renderer::{Renderer, RendererError};

/// Why one job failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// `no_overwrite` and the job's output (or the image its tile is merged into) exists.
    #[error("{} exists and --no-overwrite refuses to replace it", path.display())]
    Exists {
        /// The existing file.
        path: PathBuf,
    },
    /// The output cannot be written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The frame's camera cannot be made.
    #[error(transparent)]
    Renderer(#[from] RendererError),
    /// The render failed (or was cancelled).
    #[error(transparent)]
    Render(#[from] RenderError),
}

impl HasKind for JobError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Exists { .. } => ErrorKind::Io,
            Self::Output(e) => e.kind(),
            Self::Renderer(e) => e.kind(),
            Self::Render(e) => e.kind(),
        }
    }
}

impl JobError {
    /// The whole message (with its sources), parameters named by `name` (e.g. [`Param::flag`]).
    pub fn message(&self, name: impl Fn(Param) -> &'static str) -> String {
        match self {
            Self::Renderer(e) => e
                .param_message(name)
                .unwrap_or_else(|| error_kind::full_message(self)),
            Self::Render(RenderError::Setting(e)) => e.message(name),
            e => error_kind::full_message(e),
        }
    }
}

/// How a job's images are written, beyond the format their extension names.
#[derive(Debug, Clone, Default)]
pub struct ImageOptions {
    /// PNG: 16 bits per channel.
    pub png_16bit: bool,
    /// PNG: the display view (view transform, look, exposure, gamma); `None`: the scene's
    /// own (`[view]`; plain sRGB without one).
    pub view: Option<crate::view::DisplayView>,
    /// EXR: the beauty as half floats.
    pub exr_half: bool,
    /// EXR: the compression.
    pub exr_compression: ExrCompression,
    /// The scene as given: recorded and hashed in the metadata when it names a file.
    pub scene_file: Option<PathBuf>,
    /// Also write the depth, interval and samples pictures here (one image only).
    pub aov_dir: Option<PathBuf>,
}

/// What to do about existing outputs and failures.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunOptions {
    /// A job whose output (or whole image) exists is skipped.
    pub skip_existing: bool,
    /// A job whose output (or whole image) exists fails.
    pub no_overwrite: bool,
    /// Stop at the first failure.
    pub fail_fast: bool,
    /// Assemble each image from its tiles once this run has them all (not for a shard).
    pub merge_tiles: bool,
}

/// What a run tells its front end as it goes. Every method does nothing by default.
pub trait RunProgress {
    /// Job `index` (0-based) of `count` is about to render; `seconds_left` estimates the rest
    /// from the jobs rendered so far (`None` before the first).
    fn starting(&self, _index: usize, _count: usize, _job: &Job, _seconds_left: Option<f64>) {}
    /// The progress of one job's render.
    fn job_progress(&self, _job: &Job) -> Box<dyn Progress + '_> {
        Box::new(NoProgress)
    }
    /// A job was rendered and written.
    fn rendered(&self, _job: &Job, _summary: &JobSummary) {}
    /// A job was skipped: its output exists.
    fn skipped(&self, _job: &Job) {}
    /// `--skip-existing` found `path` for `job` but it is not a finished image (`reason`):
    /// the job renders again.
    fn incomplete(&self, _job: &Job, _path: &Path, _reason: &str) {}
    /// A job failed.
    fn failed(&self, _job: &Job, _failure: &JobFailure) {}
    /// `fail_fast` stops the run after a failure, with `not_run` of `count` jobs left.
    fn stopping(&self, _not_run: usize, _count: usize) {}
    /// An image was assembled from its tiles (and the tiles removed).
    fn merged(&self, _image: &Path, _tiles: usize) {}
    /// An image could not be assembled from its tiles.
    fn merge_failed(&self, _image: &Path, _failure: &JobFailure) {}
    /// Another run of the same tiles assembled `image` (and removed the tiles) while this run
    /// was merging them: the image is finished, nothing failed.
    fn merged_elsewhere(&self, _image: &Path) {}
}

/// A run that reports nothing as it goes.
impl RunProgress for () {}

/// A failure: the typed error (when there is one), its kind and its message.
#[derive(Debug)]
pub struct JobFailure {
    /// What went wrong (a merge's error is only in `message`).
    pub error: Option<JobError>,
    /// Its kind (exit code, JSON kind).
    pub kind: ErrorKind,
    /// The whole message.
    pub message: String,
}

/// What became of one job.
#[derive(Debug)]
pub enum JobOutcome {
    /// Rendered and written.
    Rendered(Box<JobSummary>),
    /// Its output exists (`skip_existing`).
    Skipped,
    /// It failed.
    Failed(JobFailure),
}

/// One job and what became of it; serialises as an entry of the run's `frames`.
#[derive(Debug)]
pub struct JobResult {
    /// The job.
    pub job: Job,
    /// What became of it.
    pub outcome: JobOutcome,
}

impl JobResult {
    /// `rendered`, `skipped` or `failed`.
    pub fn status(&self) -> &'static str {
        match self.outcome {
            JobOutcome::Rendered(_) => "rendered",
            JobOutcome::Skipped => "skipped",
            JobOutcome::Failed(_) => "failed",
        }
    }
}

impl serde::Serialize for JobResult {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut entry = serde_json::Map::new();
        entry.insert("frame".into(), self.job.frame.into());
        entry.insert("tile".into(), self.job.tile.map(|t| t.index).into());
        let region = self.job.tile.map(|t| t.region.to_string());
        entry.insert("region".into(), region.into());
        let output = serde_json::to_value(&self.job.output).map_err(serde::ser::Error::custom)?;
        entry.insert("output".into(), output);
        entry.insert("status".into(), self.status().into());
        let detail = match &self.outcome {
            JobOutcome::Rendered(summary) => {
                serde_json::to_value(summary).map_err(serde::ser::Error::custom)?
            }
            JobOutcome::Skipped => serde_json::json!({}),
            JobOutcome::Failed(f) => {
                serde_json::json!({ "error": error_kind::error_object(f.kind, &f.message) })
            }
        };
        // The job's own fields win over the summary's (a frame's region is its tile's).
        if let Some(detail) = detail.as_object() {
            for (k, v) in detail {
                entry.entry(k.clone()).or_insert(v.clone());
            }
        }
        serde_json::Value::Object(entry).serialize(serializer)
    }
}

/// What a run did.
#[derive(Debug)]
pub struct RunReport {
    /// Every job attempted, in order.
    pub results: Vec<JobResult>,
    /// The jobs this run was given (attempted or not).
    pub count: usize,
    /// Images assembled from their tiles.
    pub merged: Vec<PathBuf>,
    /// Wall time from the first job.
    pub seconds: f64,
    /// The kind of the first failure (a job's or a merge's).
    pub first_failure: Option<ErrorKind>,
}

impl RunReport {
    fn count(&self, status: &str) -> usize {
        self.results.iter().filter(|r| r.status() == status).count()
    }
    /// Jobs rendered.
    pub fn rendered(&self) -> usize {
        self.count("rendered")
    }
    /// Jobs skipped.
    pub fn skipped(&self) -> usize {
        self.count("skipped")
    }
    /// Jobs failed.
    pub fn failed(&self) -> usize {
        self.count("failed")
    }
    /// Jobs not attempted (`fail_fast`, or cancelled).
    pub fn not_run(&self) -> usize {
        self.count - self.results.len()
    }
    /// Whether the run was cancelled: its last job's render was ([`RenderError::Cancelled`],
    /// from the job's [`Progress::cancelled`]), and the run stopped there.
    pub fn cancelled(&self) -> bool {
        self.results.last().is_some_and(|r| match &r.outcome {
            JobOutcome::Failed(f) => {
                matches!(f.error, Some(JobError::Render(RenderError::Cancelled)))
            }
            _ => false,
        })
    }

    /// The run's JSON summary: `scene` and its `warnings`, `output` as given, this run's
    /// `shard` and where it came from, and `jobs` of the whole run (every shard's).
    pub fn summary<'a>(
        &'a self,
        renderer: &'a Renderer,
        output: &'a Path,
        shard: Option<(&super::Shard, &'a str)>,
        jobs: usize,
    ) -> RunSummary<'a> {
        let failed = self.failed();
        RunSummary {
            schema_version: error_kind::SCHEMA_VERSION,
            dofray_version: crate::VERSION,
            git_commit: crate::GIT_COMMIT,
            scene: &renderer.desc().name,
            output,
            shard: shard.map(|(s, _)| s.to_string()),
            shard_source: shard.map(|(_, source)| source),
            jobs,
            rendered: self.rendered(),
            skipped: self.skipped(),
            failed,
            not_run: self.not_run(),
            merged: &self.merged,
            seconds: self.seconds,
            frames: &self.results,
            warnings: &renderer.desc().warnings,
            error: self.first_failure.map(|kind| {
                error_kind::error_object(kind, &format!("{failed} of {} jobs failed", self.count))
            }),
        }
    }
}

/// A scene ready to render jobs: the renderer, its settings, where the work runs and how the
/// images are written.
pub struct Batch<'a> {
    /// The scene, its overrides and its world.
    pub renderer: &'a Renderer,
    /// The render settings of every job.
    pub settings: &'a RenderSettings,
    /// The worker threads (`None`: rayon's global pool).
    pub pool: Option<&'a rayon::ThreadPool>,
    /// How images are written.
    pub image: ImageOptions,
    /// The pixels of a job that is not a tile (`None`: the whole image).
    pub region: Option<Region>,
    /// How messages name a parameter ([`Param::flag`] for the command line).
    pub param_name: fn(Param) -> &'static str,
}

/// With `no_overwrite`, an existing output (a tile's, or the image it would be merged into) is
/// an error.
pub fn refuse_existing(job: &Job, no_overwrite: bool) -> Result<(), JobError> {
    let existing = [&job.output, &job.image].into_iter().find(|p| p.exists());
    match existing {
        Some(path) if no_overwrite => Err(JobError::Exists { path: path.clone() }),
        _ => Ok(()),
    }
}

impl Batch<'_> {
    /// The jobs of `request` writing to `output`, for this scene's animation and image size.
    pub fn plan(&self, output: &Path, request: &JobRequest) -> Result<RequestPlan, RequestError> {
        let desc = self.renderer.desc();
        let animation = desc.animation.as_ref().map(|a| a.frames());
        request.plan(output, animation, (desc.camera.width, desc.camera.height))
    }

    /// The files `job` writes (its image and, with [`ImageOptions::aov_dir`], the AOV
    /// pictures), each checked ([`RenderTargets::new`]).
    pub fn targets(&self, job: &Job) -> Result<RenderTargets, OutputError> {
        RenderTargets::new(&job.output, self.image.aov_dir.as_deref())
    }

    /// Renders one job (a frame, a tile of one, or the single image) and writes it, its
    /// outputs checked first ([`Batch::targets`]).
    pub fn render_job(&self, job: &Job, progress: &dyn Progress) -> Result<JobSummary, JobError> {
        self.render_job_to(job, &self.targets(job)?, progress)
    }

    /// [`Batch::render_job`] to targets already checked: the image and, when `targets` has
    /// them, the AOV pictures.
    pub fn render_job_to(
        &self,
        job: &Job,
        targets: &RenderTargets,
        progress: &dyn Progress,
    ) -> Result<JobSummary, JobError> {
        let renderer = self.renderer;
        let camera = renderer.camera(job.frame)?;
        let full = Region::full(camera.width, camera.height);
        let region = job.tile.map(|t| t.region).or(self.region).unwrap_or(full);
        // A tile (or a --region) records its place even when it covers the whole image
        // (--tiles 1x1), so the merge can take it like any other tile.
        let placed = (job.tile.is_some() || self.region.is_some()).then_some(region);
        let render =
            || render::render_region(renderer.world(), &camera, self.settings, &region, progress);
        let (film, stats) = match self.pool {
            Some(pool) => pool.install(render),
            None => render(),
        }?;
        let embree = EmbreeSummary::of(&renderer.world().scene);
        let mut metadata = output::Metadata::for_render(
            &renderer.desc().name,
            self.image.scene_file.as_deref().filter(|p| p.is_file()),
            &camera,
            self.settings,
            &stats,
            &embree.version,
        );
        if let Some(frame) = job.frame {
            metadata.push("dofray:frame", frame);
        }
        let options = output::WriteOptions {
            metadata,
            png_16bit: self.image.png_16bit,
            png_alpha: self.settings.transparent,
            view: self.image.view.unwrap_or(renderer.desc().view),
            exr_half: self.image.exr_half,
            exr_compression: self.image.exr_compression,
            region: placed.map(|r| (r, (camera.width, camera.height))),
        };
        output::write_film_to(&targets.image, &film, &options)?;
        if let Some(aovs) = &targets.aovs {
            output::write_aov_pictures(aovs, &film)?;
        }
        let facts = JobFacts {
            scene: renderer.desc().name.clone(),
            output: job.output.clone(),
            frame: job.frame,
            region: placed.map(|r| r.to_string()),
            size: (film.width, film.height),
            threads: self
                .pool
                .map_or_else(rayon::current_num_threads, |p| p.current_num_threads()),
            embree,
            warnings: renderer.desc().warnings.clone(),
        };
        Ok(JobSummary::new(facts, self.settings, &camera, stats))
    }

    /// Renders `jobs` (this run's share of a plan) one after the other. Every job's output
    /// folder is made first (a folder that cannot be made fails the run once, not every job);
    /// then each job is skipped, refused, rendered or failed as `options` say, and with
    /// `merge_tiles` each image whose tiles all rendered is assembled and its tiles removed.
    /// A job whose render is cancelled (its progress's [`Progress::cancelled`]) ends the run
    /// there ([`RunReport::cancelled`]).
    pub fn run(
        &self,
        jobs: &[Job],
        options: RunOptions,
        progress: &dyn RunProgress,
    ) -> Result<RunReport, OutputError> {
        for job in jobs {
            if let Some(dir) = job.output.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|source| OutputError::Io {
                    path: dir.to_path_buf(),
                    source,
                })?;
            }
        }
        let start = Instant::now();
        let mut report = RunReport {
            results: Vec::new(),
            count: jobs.len(),
            merged: Vec::new(),
            seconds: 0.0,
            first_failure: None,
        };
        // Jobs rendered so far and their time, for the estimate of what is left.
        let (mut done, mut busy) = (0u32, 0.0f64);
        for (i, job) in jobs.iter().enumerate() {
            let outcome = if options.skip_existing && self.finished(job, progress) {
                progress.skipped(job);
                JobOutcome::Skipped
            } else {
                let left = busy / f64::from(done.max(1)) * (jobs.len() - i) as f64;
                progress.starting(i, jobs.len(), job, (done > 0).then_some(left));
                let began = Instant::now();
                let outcome = self.attempt(job, options, progress);
                done += 1;
                busy += began.elapsed().as_secs_f64();
                outcome
            };
            if let JobOutcome::Failed(failure) = &outcome {
                report.first_failure.get_or_insert(failure.kind);
            }
            report.results.push(JobResult {
                job: job.clone(),
                outcome,
            });
            if report.cancelled() {
                break; // the front end asked to stop: no more jobs, no merge
            }
            if report.first_failure.is_some() && options.fail_fast {
                progress.stopping(jobs.len() - i - 1, jobs.len());
                break;
            }
        }
        if options.merge_tiles && report.first_failure.is_none() {
            self.merge_tiles(jobs, &mut report, progress);
        }
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// Whether `job`'s output (or, for a tile, its whole image) exists and is complete: a
    /// readable image of the size the job would write ([`output::verify`]). A file that is
    /// not is reported ([`RunProgress::incomplete`]) and rendered again.
    fn finished(&self, job: &Job, progress: &dyn RunProgress) -> bool {
        let Ok(camera) = self.renderer.camera(job.frame) else {
            return false; // the render will report why
        };
        let full = (camera.width, camera.height);
        let own = job
            .tile
            .map_or(full, |t| (t.region.width(), t.region.height()));
        let mut candidates = vec![(&job.output, own)];
        if job.image != job.output {
            candidates.push((&job.image, full));
        }
        for (path, (w, h)) in candidates {
            if !path.exists() {
                continue;
            }
            match output::verify::check_complete(path, w, h) {
                Ok(()) => return true,
                Err(reason) => progress.incomplete(job, path, &reason),
            }
        }
        false
    }

    /// Refuses, checks, renders and writes one job of a run.
    fn attempt(&self, job: &Job, options: RunOptions, progress: &dyn RunProgress) -> JobOutcome {
        let result = refuse_existing(job, options.no_overwrite)
            .and_then(|()| self.render_job(job, &*progress.job_progress(job)));
        match result {
            Ok(summary) => {
                progress.rendered(job, &summary);
                JobOutcome::Rendered(Box::new(summary))
            }
            Err(e) => {
                let failure = JobFailure {
                    kind: e.kind(),
                    message: e.message(self.param_name),
                    error: Some(e),
                };
                progress.failed(job, &failure);
                JobOutcome::Failed(failure)
            }
        }
    }

    /// Assembles each image whose tiles this run rendered (or found), then removes the tiles.
    fn merge_tiles(&self, jobs: &[Job], report: &mut RunReport, progress: &dyn RunProgress) {
        for (image, parts) in jobs::by_image(jobs) {
            if image.is_file() && parts.iter().all(|t| !t.output.is_file()) {
                continue; // skipped whole: the image exists
            }
            let paths: Vec<PathBuf> = parts.iter().map(|t| t.output.clone()).collect();
            match output::merge::merge(&paths, &image) {
                Ok(m) => {
                    for path in &paths {
                        let _ = std::fs::remove_file(path);
                    }
                    progress.merged(&image, m.tiles);
                    report.merged.push(image.clone());
                }
                Err(_) if self.twin_merged(&image, &parts) => {
                    // This run's tiles are the twin's (the same render): not left behind.
                    for path in &paths {
                        let _ = std::fs::remove_file(path);
                    }
                    progress.merged_elsewhere(&image);
                    report.merged.push(image.clone());
                }
                Err(e) => {
                    let failure = JobFailure {
                        error: None,
                        kind: e.kind(),
                        message: error_kind::full_message(&e),
                    };
                    progress.merge_failed(&image, &failure);
                    report.first_failure.get_or_insert(failure.kind);
                }
            }
        }
    }

    /// Whether another run of the same tiles (a requeued task overlapping its original)
    /// assembled `image` while this one was merging: some of the tiles are gone and the
    /// image is there, complete and of the frame's size. A run removes its tiles only after
    /// its image is in place, so a missing tile with a finished image is that, not a loss.
    fn twin_merged(&self, image: &Path, parts: &[&Job]) -> bool {
        let Some(first) = parts.first() else {
            return false;
        };
        let Ok(camera) = self.renderer.camera(first.frame) else {
            return false;
        };
        parts.iter().any(|t| !t.output.exists())
            && output::verify::check_complete(image, camera.width, camera.height).is_ok()
    }
}

/// A run of jobs: `dofray render --json`'s object for frames, tiles and shards.
#[derive(Debug, Clone, serde::Serialize)]
#[allow(missing_docs)] // the fields are documented in docs/json.md, one row each
pub struct RunSummary<'a> {
    pub schema_version: u32,
    pub dofray_version: &'static str,
    pub git_commit: &'static str,
    pub scene: &'a str,
    pub output: &'a std::path::Path,
    pub shard: Option<String>,
    pub shard_source: Option<&'a str>,
    pub jobs: usize,
    pub rendered: usize,
    pub skipped: usize,
    pub failed: usize,
    pub not_run: usize,
    pub merged: &'a [PathBuf],
    pub seconds: f64,
    pub frames: &'a [JobResult],
    pub warnings: &'a [String],
    /// The first failure's kind and exit code, with a message counting the failed jobs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<serde_json::Value>,
}
