//! `dofray render` and `dofray merge`: the flags made into the library's job loop
//! ([`dofray::batch::run`]), and what it reports printed.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Result;
use dofray::batch::jobs::{self, Job};
use dofray::batch::run::{JobFailure, RunOptions, RunProgress};
use dofray::batch::shard::Shard;
use dofray::batch::{Batch, FrameRequest, FrameSelectError, ImageOptions, JobError, JobSummary};
use dofray::output;
use dofray::params::Param;
use dofray::render::{Progress, Region, RenderSettings};
use dofray::render::{RulePatch, SettingsPatch};
use dofray::scene::SceneDesc;
use dofray::view::{DisplayView, ViewError};

use super::args::{MergeArgs, RenderArgs, Switch};
use super::{Bar, cli_error, prepare};

/// The render settings the flags and the scene ask for.
pub(crate) fn render_settings(a: &RenderArgs, desc: &SceneDesc) -> Result<RenderSettings> {
    // clap keeps --tolerance apart from -k and --paper-exact.
    let rule = match (a.tolerance, a.interval_factor, a.paper_exact) {
        (Some(t), ..) => Some(RulePatch::ErrorControlled { tolerance: Some(t) }),
        (None, None, false) => None,
        (None, k, paper_exact) => Some(RulePatch::Seed {
            interval_factor: k,
            paper_exact,
        }),
    };
    let flags = SettingsPatch {
        mode: Some(a.mode),
        spp: a.spp,
        aa: a.aa,
        pixel_filter: a.pixel_filter,
        pixel_filter_width: a.pixel_filter_width,
        rule,
        transparent: a.transparent,
        exposure: a.exposure,
        seed: Some(a.scene.seed),
        lens_filter: Some(a.filter),
        integrator: a.integrator,
        max_bounces: a.max_bounces,
        diffuse_bounces: a.diffuse_bounces,
        glossy_bounces: a.glossy_bounces,
        transmission_bounces: a.transmission_bounces,
        clamp_indirect: a.clamp_indirect,
        filter_glossy: a.filter_glossy,
        light_tracing: Switch::flag(a.light_tracing),
        reuse: Switch::flag(a.reuse),
    };
    Ok(flags
        .over(&desc.settings)
        .resolve()
        .map_err(|e| dofray::exit::UsageError(e.message(Param::flag)))?)
}

/// The frames the flags (or, for a frame pattern, the scene's animation) ask for; `None` for
/// a single image.
pub(crate) fn frame_list(a: &RenderArgs, desc: &SceneDesc) -> Result<Option<Vec<i64>>> {
    let request = FrameRequest {
        list: a.frames.clone(),
        start: a.frame_start,
        end: a.frame_end,
        step: a.frame_jump,
    };
    let range = desc.animation.as_ref().map(|an| an.frames());
    let frames = dofray::batch::select_frames(&request, &a.output, range)
        .map_err(|e| dofray::exit::UsageError(frames_message(&e)))?;
    if let Some(list) = &frames
        && list.len() > 1
        && desc.animation.is_none()
    {
        eprintln!(
            "warning: {} has no [animation]: its {} frames will be identical",
            a.scene.scene,
            list.len()
        );
    }
    Ok(frames)
}

/// A frame selection's error worded for the command line (flag names).
fn frames_message(e: &FrameSelectError) -> String {
    match e {
        FrameSelectError::List(e) => format!("--frames: {e}"),
        FrameSelectError::Range(e) => e.to_string(),
        FrameSelectError::NoStart => "-e/--frame-end and -j/--frame-jump need -s/--frame-start: \
                                      the scene has no [animation] with a frame range"
            .into(),
        FrameSelectError::PatternWithoutAnimation { output } => format!(
            "-o {} has a frame pattern, but the scene has no [animation]: give the frames with \
             --frames (e.g. --frames 1-48)",
            output.display()
        ),
        FrameSelectError::NoPattern { count, output } => format!(
            "{count} frames would all be written to -o {}: put the frame number in the name \
             with #### (e.g. -o out/shot_####.exr)",
            output.display()
        ),
        FrameSelectError::Pattern(e) => format!("-o: {e}"),
    }
}

/// This run's share of the work: --shard, else the scheduler's environment.
pub(crate) fn shard(a: &RenderArgs) -> Result<Option<(Shard, String)>> {
    if let Some(s) = a.shard {
        return Ok(Some((s, "--shard".into())));
    }
    let found = Shard::from_env(|k| std::env::var(k).ok())
        .map_err(|e| dofray::exit::UsageError(e.to_string()))?;
    Ok(found.map(|(s, source)| (s, source.to_string())))
}

/// EXR-only and PNG-only flags would be silently ignored for the other format.
fn check_format_flags(a: &RenderArgs) -> Result<()> {
    let format = output::ImageFormat::from_path(&a.output).ok();
    if (a.exr_half || a.exr_compression.is_some()) && format == Some(output::ImageFormat::Png) {
        usage!(
            "--exr-half and --exr-compression apply to .exr output only, and -o {} is a PNG",
            a.output.display()
        );
    }
    let view_flags =
        a.view.is_some() || a.look.is_some() || a.view_exposure.is_some() || a.view_gamma.is_some();
    if view_flags && format == Some(output::ImageFormat::Exr) {
        usage!(
            "--view, --look, --view-exposure and --view-gamma apply to .png output only, and \
             -o {} is an EXR (scene-linear; Blender applies its view when it shows it)",
            a.output.display()
        );
    }
    if a.png_16 && format == Some(output::ImageFormat::Exr) {
        usage!(
            "--png-16 applies to .png output only, and -o {} is an EXR (always float; \
             --exr-half for half float)",
            a.output.display()
        );
    }
    Ok(())
}

/// The scene's `[view]` with the view flags over it.
fn display_view(a: &RenderArgs, scene: DisplayView) -> Result<DisplayView> {
    let view = DisplayView {
        view: a.view.unwrap_or(scene.view),
        look: a.look.unwrap_or(scene.look),
        exposure: a.view_exposure.unwrap_or(scene.exposure),
        gamma: a.view_gamma.unwrap_or(scene.gamma),
    };
    // The scene's own [view] was checked when it loaded: what fails here is a flag's.
    view.validate().map_err(|e| {
        let flag = match e {
            ViewError::Exposure(_) => "--view-exposure",
            ViewError::Gamma(_) => "--view-gamma",
            _ if a.look.is_some() => "--look",
            _ => "--view",
        };
        dofray::exit::UsageError(format!("{flag}: {e}"))
    })?;
    Ok(view)
}

/// The tiles of `--tiles` (checking `--region` instead when it is given).
fn tiles(a: &RenderArgs, width: u32, height: u32) -> Result<Option<Vec<Region>>> {
    match (a.tiles, a.region) {
        (Some((columns, rows)), _) => Ok(Some(
            Region::grid(width, height, columns, rows)
                .map_err(|e| dofray::exit::UsageError(format!("--tiles: {e}")))?,
        )),
        (None, Some(r)) => {
            r.check(width, height)
                .map_err(|e| dofray::exit::UsageError(format!("--region: {e}")))?;
            Ok(None)
        }
        (None, None) => Ok(None),
    }
}

/// A job's error as the command line reports it (its kind found by `classify`).
fn job_error(e: JobError) -> anyhow::Error {
    match e {
        e @ JobError::Exists { .. } => anyhow::Error::new(dofray::exit::KindError {
            kind: dofray::exit::ErrorKind::Io,
            message: e.to_string(),
        }),
        JobError::Output(e) => e.into(),
        JobError::Renderer(e) => cli_error(e),
        JobError::Render(e) => e.into(),
    }
}

pub(crate) fn run_render(a: &RenderArgs) -> Result<ExitCode> {
    super::signals::clean_up_on_signals(a.json)?;
    check_format_flags(a)?;
    let p = prepare(&a.scene)?;
    let settings = render_settings(a, p.renderer.desc())?;
    let frames = frame_list(a, p.renderer.desc())?;
    let camera = &p.renderer.desc().camera;
    let tiles = tiles(a, camera.width, camera.height)?;
    let shard = shard(a)?;
    // Anything that may render several jobs, or none, reports as a run of jobs.
    let sequence = frames.is_some() || tiles.is_some() || shard.is_some() || a.skip_existing;
    if sequence && a.aov_dir.is_some() {
        usage!(
            "--aov-dir writes the maps of one image; with frames, tiles or shards write EXR \
             outputs, which carry depth, interval and samples as passes"
        );
    }
    let batch = Batch {
        renderer: &p.renderer,
        settings: &settings,
        pool: Some(&p.pool),
        image: ImageOptions {
            png_16bit: a.png_16,
            view: Some(display_view(a, p.renderer.desc().view)?),
            exr_half: a.exr_half,
            exr_compression: a.exr_compression.unwrap_or_default(),
            scene_file: Some(a.scene.scene.clone().into()),
            aov_dir: a.aov_dir.clone(),
        },
        region: a.region,
        param_name: Param::flag,
    };
    let all = jobs::plan(&a.output, frames.as_deref(), tiles.as_deref());
    if !sequence {
        // One image: its targets (and --aov-dir) are checked before rendering.
        let job = &all[0];
        let targets = batch.targets(job)?;
        dofray::batch::run::refuse_existing(job, a.no_overwrite).map_err(job_error)?;
        let summary = batch
            .render_job_to(
                job,
                &targets,
                &Bar::new(a.progress.resolve(a.quiet, a.json)),
            )
            .map_err(job_error)?;
        if !a.quiet && !a.json {
            print_rendered(job, &summary);
        }
        if a.json {
            println!("{}", serde_json::to_value(&summary)?);
        }
        return Ok(ExitCode::SUCCESS);
    }
    let mine = match &shard {
        Some((s, source)) => {
            if !a.quiet && !a.json {
                let (share, of) = (s.pick(&all).len(), all.len());
                eprintln!("shard {s} ({source}): {share} of {of} jobs");
            }
            s.pick(&all)
        }
        None => all.clone(),
    };
    let options = RunOptions {
        skip_existing: a.skip_existing,
        no_overwrite: a.no_overwrite,
        fail_fast: a.fail_fast,
        merge_tiles: tiles.is_some() && shard.is_none(),
    };
    let quiet = a.quiet || a.json;
    let progress = a.progress.resolve(a.quiet, a.json);
    let report = batch.run(&mine, options, &CliProgress { quiet, progress })?;
    if a.json {
        let shard = shard.as_ref().map(|(s, source)| (s, source.as_str()));
        let summary = report.summary(&p.renderer, &a.output, shard, all.len());
        println!("{}", serde_json::to_value(&summary)?);
    } else if !a.quiet {
        eprintln!(
            "{} rendered, {} skipped, {} failed of {} jobs in {:.1} s",
            report.rendered(),
            report.skipped(),
            report.failed(),
            mine.len(),
            report.seconds
        );
    }
    Ok(match report.first_failure {
        Some(kind) => ExitCode::from(kind.exit_code()),
        None => ExitCode::SUCCESS,
    })
}

/// `out.png: adaptive 640x480 in 1.23 s, ...` for a rendered job.
fn print_rendered(job: &Job, s: &JobSummary) {
    let borrowed = match s.stats.borrowing_sites {
        0 => String::new(),
        n => format!(" ({n} borrowed their neighbours' samples)"),
    };
    eprintln!(
        "{}: {} {}x{} in {:.2} s, {} rays ({:.1} Mrays/s), {} sample sites{borrowed}",
        job.output.display(),
        s.mode,
        s.width,
        s.height,
        s.stats.seconds,
        s.stats.rays.total(),
        s.stats.mrays_per_s(),
        s.stats.sample_sites
    );
}

/// Prints a run's progress on stderr: each job as it starts and ends (unless quiet), failures
/// always.
struct CliProgress {
    quiet: bool,
    /// How each job's progress is shown.
    progress: super::ProgressMode,
}

impl RunProgress for CliProgress {
    fn starting(&self, index: usize, count: usize, job: &Job, seconds_left: Option<f64>) {
        if self.quiet {
            return;
        }
        let left = match seconds_left {
            None => String::new(),
            Some(t) if t < 10.0 => format!(", about {t:.1} s left"),
            Some(t) => format!(", about {t:.0} s left"),
        };
        eprintln!("[{}/{count}] {}{left}", index + 1, job.label());
    }
    fn job_progress(&self, _job: &Job) -> Box<dyn Progress + '_> {
        Box::new(Bar::new(self.progress))
    }
    fn rendered(&self, job: &Job, summary: &JobSummary) {
        if !self.quiet {
            print_rendered(job, summary);
        }
    }
    fn skipped(&self, job: &Job) {
        if !self.quiet {
            eprintln!("{}: {} exists, skipped", job.label(), job.output.display());
        }
    }
    fn incomplete(&self, job: &Job, path: &Path, reason: &str) {
        // Always said, even with -q: a broken frame on a farm is worth a line in the log.
        eprintln!(
            "warning: {}: {} exists but is not a finished image ({reason}); rendering it again",
            job.label(),
            path.display()
        );
    }
    fn failed(&self, job: &Job, failure: &JobFailure) {
        eprintln!("error: {}: {}", job.label(), failure.message);
    }
    fn stopping(&self, not_run: usize, count: usize) {
        eprintln!("stopping after the failure (--fail-fast): {not_run} of {count} jobs not run");
    }
    fn merged(&self, image: &Path, tiles: usize) {
        if !self.quiet {
            eprintln!("{}: merged {tiles} tiles", image.display());
        }
    }
    fn merge_failed(&self, image: &Path, failure: &JobFailure) {
        eprintln!("error: {}: {}", image.display(), failure.message);
    }
    fn merged_elsewhere(&self, image: &Path) {
        if !self.quiet {
            eprintln!(
                "{}: assembled by another run of the same tiles while this one merged",
                image.display()
            );
        }
    }
}

pub(crate) fn run_merge(a: &MergeArgs) -> Result<()> {
    super::signals::clean_up_on_signals(a.json)?;
    let merged = output::merge::merge(&a.tiles, &a.output)?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "schema_version": dofray::exit::SCHEMA_VERSION,
                "dofray_version": dofray::VERSION,
                "git_commit": dofray::GIT_COMMIT,
                "output": a.output,
                "width": merged.width,
                "height": merged.height,
                "tiles": merged.tiles,
                "seconds": merged.seconds,
                "rays": merged.rays,
            })
        );
    } else if !a.quiet {
        eprintln!(
            "{}: {}x{} from {} tiles ({:.2} s of rendering, {} rays)",
            a.output.display(),
            merged.width,
            merged.height,
            merged.tiles,
            merged.seconds,
            merged.rays
        );
    }
    Ok(())
}
