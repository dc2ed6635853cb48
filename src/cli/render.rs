//! `dofray render` and `dofray merge`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use dofray::batch::shard::Shard;
use dofray::output;
use dofray::overrides::SettingsOverrides;
use dofray::render::{self, Mode, Region, RenderSettings, SiteRule};
use dofray::scene::SceneDesc;

use super::args::{MergeArgs, RenderArgs};
use super::report::{embree_json, json_f32};
use super::{Bar, Prepared, cli_error, prepare};

/// The render settings the flags and the scene ask for.
pub(crate) fn render_settings(a: &RenderArgs, desc: &SceneDesc) -> Result<RenderSettings> {
    let flags = SettingsOverrides {
        mode: Some(a.mode),
        spp: a.spp,
        aa: a.aa,
        pixel_filter: a.pixel_filter,
        pixel_filter_width: a.pixel_filter_width,
        tolerance: a.tolerance,
        interval_factor: a.interval_factor,
        paper_exact: a.paper_exact,
        transparent: a.transparent,
        exposure: a.exposure,
        seed: Some(a.scene.seed),
        lens_filter: Some(a.filter),
    };
    Ok(flags
        .settings(desc)
        .map_err(|e| dofray::exit::UsageError(cli_message(&e)))?)
}

/// The frames the flags (or, for a frame pattern, the scene's animation) ask for; `None` for
/// a single image.
pub(crate) fn frame_list(a: &RenderArgs, desc: &SceneDesc) -> Result<Option<Vec<i64>>> {
    use dofray::batch::{frames, pattern};
    let range = desc.animation.as_ref().map(|an| an.frames());
    let frames = if let Some(spec) = &a.frames {
        Some(
            frames::parse_frames(spec)
                .map_err(|e| dofray::exit::UsageError(format!("--frames: {e}")))?,
        )
    } else if a.frame_start.is_some() || a.frame_end.is_some() || a.frame_jump.is_some() {
        let start = match (a.frame_start, &range) {
            (Some(s), _) => s,
            (None, Some(r)) => *r.start(),
            (None, None) => usage!(
                "-e/--frame-end and -j/--frame-jump need -s/--frame-start: the scene has no \
                 [animation] with a frame range"
            ),
        };
        let end = a
            .frame_end
            .or(range.as_ref().map(|r| *r.end()))
            .unwrap_or(start);
        Some(
            frames::frame_range(start, end, a.frame_jump.unwrap_or(1))
                .map_err(|e| dofray::exit::UsageError(e.to_string()))?,
        )
    } else if pattern::has_frame_pattern(&a.output) {
        match range {
            Some(r) => Some(r.collect()),
            None => usage!(
                "-o {} has a frame pattern, but the scene has no [animation]: give the frames \
                 with --frames (e.g. --frames 1-48)",
                a.output.display()
            ),
        }
    } else {
        None
    };
    if let Some(list) = &frames
        && list.len() > 1
        && !pattern::has_frame_pattern(&a.output)
    {
        usage!(
            "{} frames would all be written to -o {}: put the frame number in the name with \
             #### (e.g. -o out/shot_####.exr)",
            list.len(),
            a.output.display()
        );
    }
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

/// This run's share of the work: --shard, else the scheduler's environment.
pub(crate) fn shard(a: &RenderArgs) -> Result<Option<(Shard, String)>> {
    if let Some(s) = a.shard {
        return Ok(Some((s, "--shard".into())));
    }
    let found = Shard::from_env(|k| std::env::var(k).ok())
        .map_err(|e| dofray::exit::UsageError(e.to_string()))?;
    Ok(found.map(|(s, source)| (s, source.to_string())))
}

/// What became of one job.
pub(crate) enum Outcome {
    Rendered(serde_json::Value),
    Skipped,
    Failed(anyhow::Error),
}

pub(crate) fn run_render(a: &RenderArgs) -> Result<ExitCode> {
    use dofray::batch::jobs;
    super::signals::clean_up_on_signals(a.json)?;
    // EXR-only flags would be silently ignored for a PNG.
    if (a.exr_half || a.exr_compression.is_some())
        && output::ImageFormat::from_path(&a.output).is_ok_and(|f| f == output::ImageFormat::Png)
    {
        usage!(
            "--exr-half and --exr-compression apply to .exr output only, and -o {} is a PNG",
            a.output.display()
        );
    }
    if a.png_16
        && output::ImageFormat::from_path(&a.output).is_ok_and(|f| f == output::ImageFormat::Exr)
    {
        usage!(
            "--png-16 applies to .png output only, and -o {} is an EXR (always float; \
             --exr-half for half float)",
            a.output.display()
        );
    }
    let p = prepare(&a.scene)?;
    let settings = render_settings(a, p.renderer.desc())?;
    let frames = frame_list(a, p.renderer.desc())?;
    let (width, height) = (
        p.renderer.desc().camera.width,
        p.renderer.desc().camera.height,
    );
    let tiles = match (a.tiles, a.region) {
        (Some((columns, rows)), _) => Some(
            Region::grid(width, height, columns, rows)
                .map_err(|e| dofray::exit::UsageError(format!("--tiles: {e}")))?,
        ),
        (None, Some(r)) => {
            r.check(width, height)
                .map_err(|e| dofray::exit::UsageError(format!("--region: {e}")))?;
            None
        }
        (None, None) => None,
    };
    let shard = shard(a)?;
    // Anything that may render several jobs, or none, reports as a run of jobs.
    let sequence = frames.is_some() || tiles.is_some() || shard.is_some() || a.skip_existing;
    if sequence && a.aov_dir.is_some() {
        usage!(
            "--aov-dir writes the maps of one image; with frames, tiles or shards write EXR \
             outputs, which carry depth, interval and samples as passes"
        );
    }
    let all = jobs::plan(&a.output, frames.as_deref(), tiles.as_deref());
    let mine = match &shard {
        Some((s, source)) => {
            if !a.quiet && !a.json {
                eprintln!(
                    "shard {s} ({source}): {} of {} jobs",
                    s.pick(&all).len(),
                    all.len()
                );
            }
            s.pick(&all)
        }
        None => all.clone(),
    };
    if !sequence {
        // One image: its targets (and --aov-dir) are checked before rendering.
        output::check_render_outputs(&a.output, a.aov_dir.as_deref())?;
        let job = &mine[0];
        refuse_existing(a, job)?;
        let summary = render_job(a, &p, &settings, job)?;
        if a.json {
            println!("{summary}");
        }
        return Ok(ExitCode::SUCCESS);
    }

    // Like Blender, a sequence's output folders are made (every job's, before any renders:
    // a folder that cannot be made fails the run once, not every frame).
    for job in &mine {
        if let Some(dir) = job.output.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| output::OutputError::Io {
                path: dir.to_path_buf(),
                source,
            })?;
        }
    }
    let start = std::time::Instant::now();
    let mut results = Vec::new();
    let mut first_failure: Option<dofray::exit::ErrorKind> = None;
    // Jobs rendered so far and their time, for the estimate of what is left.
    let (mut done, mut busy) = (0u32, 0.0f64);
    for (i, job) in mine.iter().enumerate() {
        let label = job.label();
        let outcome = if a.skip_existing && (job.output.is_file() || job.image.is_file()) {
            Outcome::Skipped
        } else {
            if !a.quiet && !a.json {
                let left = match busy / f64::from(done.max(1)) * (mine.len() - i) as f64 {
                    _ if done == 0 => String::new(),
                    t if t < 10.0 => format!(", about {t:.1} s left"),
                    t => format!(", about {t:.0} s left"),
                };
                eprintln!("[{}/{}] {label}{left}", i + 1, mine.len());
            }
            let began = std::time::Instant::now();
            let outcome = match refuse_existing(a, job).and_then(|()| {
                output::check_render_outputs(&job.output, None)?;
                render_job(a, &p, &settings, job)
            }) {
                Ok(summary) => Outcome::Rendered(summary),
                Err(e) => Outcome::Failed(e),
            };
            done += 1;
            busy += began.elapsed().as_secs_f64();
            outcome
        };
        let (status, detail) = match outcome {
            Outcome::Rendered(summary) => ("rendered", summary),
            Outcome::Skipped => {
                if !a.quiet && !a.json {
                    eprintln!("{label}: {} exists, skipped", job.output.display());
                }
                ("skipped", serde_json::json!({}))
            }
            Outcome::Failed(e) => {
                let kind = dofray::exit::classify(e.as_ref());
                eprintln!("error: {label}: {e:#}");
                first_failure.get_or_insert(kind);
                (
                    "failed",
                    serde_json::json!({
                        "error": dofray::exit::error_object(kind, &format!("{e:#}"))
                    }),
                )
            }
        };
        let mut entry = serde_json::json!({
            "frame": job.frame,
            "tile": job.tile.map(|t| t.index),
            "region": job.tile.map(|t| t.region.to_string()),
            "output": job.output,
            "status": status,
        });
        if let (Some(entry), Some(detail)) = (entry.as_object_mut(), detail.as_object()) {
            for (k, v) in detail {
                entry.entry(k.clone()).or_insert(v.clone());
            }
        }
        results.push(entry);
        if first_failure.is_some() && a.fail_fast {
            eprintln!(
                "stopping after the failure (--fail-fast): {} of {} jobs not run",
                mine.len() - i - 1,
                mine.len()
            );
            break;
        }
    }

    // Tiles of a frame are assembled here when this run rendered all of them (no shard).
    let mut merged = Vec::new();
    if tiles.is_some() && shard.is_none() && first_failure.is_none() {
        for (image, parts) in jobs::by_image(&mine) {
            if image.is_file() && parts.iter().all(|t| !t.output.is_file()) {
                continue; // skipped whole: the image exists
            }
            let paths: Vec<PathBuf> = parts.iter().map(|t| t.output.clone()).collect();
            match output::merge::merge(&paths, &image) {
                Ok(m) => {
                    for path in &paths {
                        let _ = std::fs::remove_file(path);
                    }
                    if !a.quiet && !a.json {
                        eprintln!("{}: merged {} tiles", image.display(), m.tiles);
                    }
                    merged.push(image.clone());
                }
                Err(e) => {
                    let e = anyhow::Error::new(e);
                    let kind = dofray::exit::classify(e.as_ref());
                    eprintln!("error: {}: {e:#}", image.display());
                    first_failure.get_or_insert(kind);
                }
            }
        }
    }
    let count = |s: &str| results.iter().filter(|r| r["status"] == s).count();
    let (rendered, skipped, failed) = (count("rendered"), count("skipped"), count("failed"));
    if a.json {
        let mut summary = serde_json::json!({
            "schema_version": dofray::exit::SCHEMA_VERSION,
            "dofray_version": dofray::VERSION,
            "git_commit": dofray::GIT_COMMIT,
            "scene": p.renderer.desc().name,
            "output": a.output,
            "shard": shard.as_ref().map(|(s, _)| s.to_string()),
            "shard_source": shard.as_ref().map(|(_, source)| source),
            "jobs": all.len(),
            "rendered": rendered,
            "skipped": skipped,
            "failed": failed,
            "not_run": mine.len() - results.len(),
            "merged": merged,
            "seconds": start.elapsed().as_secs_f64(),
            "frames": results,
            "warnings": p.renderer.desc().warnings,
        });
        if let (Some(kind), Some(map)) = (first_failure, summary.as_object_mut()) {
            map.insert(
                "error".into(),
                dofray::exit::error_object(
                    kind,
                    &format!("{failed} of {} jobs failed", mine.len()),
                ),
            );
        }
        println!("{summary}");
    } else if !a.quiet {
        eprintln!(
            "{rendered} rendered, {skipped} skipped, {failed} failed of {} jobs in {:.1} s",
            mine.len(),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(match first_failure {
        Some(kind) => ExitCode::from(kind.exit_code()),
        None => ExitCode::SUCCESS,
    })
}

/// With --no-overwrite, an existing output (a tile's, or the image it would be merged into)
/// is an error.
pub(crate) fn refuse_existing(a: &RenderArgs, job: &dofray::batch::jobs::Job) -> Result<()> {
    let existing = [&job.output, &job.image].into_iter().find(|p| p.exists());
    if a.no_overwrite
        && let Some(path) = existing
    {
        return Err(anyhow::Error::new(dofray::exit::KindError {
            kind: dofray::exit::ErrorKind::Io,
            message: format!(
                "{} exists and --no-overwrite refuses to replace it",
                path.display()
            ),
        }));
    }
    Ok(())
}

/// Renders one job (a frame, a tile of one, or the single image) and writes it; returns its
/// JSON summary.
pub(crate) fn render_job(
    a: &RenderArgs,
    p: &Prepared,
    settings: &RenderSettings,
    job: &dofray::batch::jobs::Job,
) -> Result<serde_json::Value> {
    let camera = p.renderer.camera(job.frame).map_err(cli_error)?;
    let region = job
        .tile
        .map(|t| t.region)
        .or(a.region)
        .unwrap_or(Region::full(camera.width, camera.height));
    let bar = Bar::new(a.quiet || a.json);
    let (film, stats) = p
        .pool
        .install(|| render::render_region(p.renderer.world(), &camera, settings, &region, &bar))?;

    // The scene's file, when it is one, is recorded and hashed in the image's metadata.
    let scene_file = Path::new(&a.scene.scene);
    let mut metadata = output::Metadata::for_render(
        &p.renderer.desc().name,
        scene_file.is_file().then_some(scene_file),
        &camera,
        settings,
        &stats,
        &p.renderer.world().scene.device().embree_version(),
    );
    if let Some(frame) = job.frame {
        metadata.push("dofray:frame", frame);
    }
    let full = Region::full(camera.width, camera.height);
    let options = output::WriteOptions {
        metadata,
        png_16bit: a.png_16,
        png_alpha: settings.transparent,
        exr_half: a.exr_half,
        exr_compression: a.exr_compression.unwrap_or_default(),
        region: (region != full).then_some((region, (camera.width, camera.height))),
    };
    output::write_film_with(&job.output, &film, &options)?;
    if let Some(dir) = &a.aov_dir {
        let (w, h) = (film.width, film.height);
        let depth = output::depth_picture(&film);
        output::write_png_rgb(&dir.join(output::AOV_DEPTH), w, h, &depth)?;
        output::write_png_rgb(
            &dir.join(output::AOV_INTERVAL),
            w,
            h,
            &output::interval_picture(&film),
        )?;
        output::write_png_rgb(
            &dir.join(output::AOV_SAMPLES),
            w,
            h,
            &output::samples_picture(&film),
        )?;
    }
    if !a.quiet && !a.json {
        eprintln!(
            "{}: {} {}x{} in {:.2} s, {} rays ({:.1} Mrays/s), {} sample sites",
            job.output.display(),
            a.mode.name(),
            film.width,
            film.height,
            stats.seconds,
            stats.rays.total(),
            stats.mrays_per_s(),
            stats.sample_sites
        );
    }
    Ok(serde_json::json!({
        "schema_version": dofray::exit::SCHEMA_VERSION,
        "dofray_version": dofray::VERSION,
        "git_commit": dofray::GIT_COMMIT,
        "scene": p.renderer.desc().name,
        "output": job.output,
        "frame": job.frame,
        "region": (region != full).then(|| region.to_string()),
        "mode": a.mode.name(),
        "width": film.width,
        "height": film.height,
        "spp": settings.spp,
        "aa": settings.aa,
        "pixel_filter": settings.pixel_filter.kind,
        "pixel_filter_width": json_f32(settings.pixel_filter.width),
        "rule": settings.rule,
        "tolerance": (settings.mode == Mode::Adaptive && settings.rule == SiteRule::Error)
            .then(|| json_f32(settings.tolerance())),
        "interval_factor": (settings.rule == SiteRule::Seed).then(|| json_f32(settings.interval_factor)),
        "paper_exact": a.paper_exact,
        "transparent": settings.transparent,
        "exposure": json_f32(settings.exposure),
        "rounds": stats.rounds,
        "seed": settings.seed,
        "seconds": stats.seconds,
        "pinhole_seconds": stats.pinhole_seconds,
        "maps_seconds": stats.maps_seconds,
        "sites_seconds": stats.sites_seconds,
        "interpolate_seconds": stats.interpolate_seconds,
        "rays": stats.rays.total(),
        "primary_rays": stats.rays.primary,
        "shadow_rays": stats.rays.shadow,
        "secondary_rays": stats.rays.secondary,
        "sample_sites": stats.sample_sites,
        "defocused_sites": stats.defocused_sites,
        "mrays_per_s": stats.mrays_per_s(),
        "aperture_radius": json_f32(camera.aperture_radius),
        "focus_distance": json_f32(camera.focus_distance),
        "threads": p.pool.current_num_threads(),
        "process_threads": dofray::limits::process_threads(),
        "embree": embree_json(&p.renderer.world().scene),
        "warnings": p.renderer.desc().warnings,
    }))
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

/// Render-setting errors worded for the command line (flag names, not field names).
pub(crate) fn cli_message(e: &render::RenderError) -> String {
    match e {
        render::RenderError::BadSpp(n) => {
            format!(
                "--spp must be 1 to {}, got {n}",
                render::RenderSettings::MAX_SAMPLES
            )
        }
        render::RenderError::BadAa(n) => {
            format!(
                "--aa must be 1 to {}, got {n}",
                render::RenderSettings::MAX_SAMPLES
            )
        }
        render::RenderError::BadPixelFilterWidth(w) => format!(
            "--pixel-filter-width must be a number in (0, {}], got {w}",
            dofray::filter::PixelFilter::MAX_WIDTH
        ),
        render::RenderError::BadIntervalFactor(k) => {
            format!("--interval-factor must be a finite number > 0, got {k}")
        }
        render::RenderError::BadExposure(e) => format!(
            "--exposure must be a finite number of stops from -{max} to {max}, got {e}",
            max = render::RenderSettings::MAX_EXPOSURE
        ),
        render::RenderError::BadTolerance(t) => format!(
            "--tolerance must be a finite number > 0 (8-bit sRGB code values, e.g. 1), got {t}"
        ),
        other => other.to_string(),
    }
}
