//! `dofray bench`: the seed's table and the equal-error study.

use std::path::PathBuf;

use anyhow::{Context, Result};
use dofray::bench::{self, BenchConfig, equal_error};
use dofray::camera::Camera;
use dofray::output;
use dofray::render::{RenderSettings, SettingsPatch};

use super::args::{BenchArgs, Switch};
use super::report::{print_equal_error, print_table, versioned_json};
use super::{Bar, Prepared, cli_error, prepare};

pub(crate) fn default_cache_dir() -> PathBuf {
    std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir)
        .join("dofray")
}

pub(crate) fn run_bench(a: &BenchArgs) -> Result<()> {
    super::signals::clean_up_on_signals(a.json)?;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create --out directory {}", dir.display()))?;
    }
    let p = prepare(&a.scene)?;
    let camera = p.renderer.camera(None).map_err(cli_error)?;
    if a.equal_error {
        return run_equal_error(a, &p, &camera);
    }
    // The flags' sample counts, else the scene's, else the defaults; checked as a render's.
    let samples = SettingsPatch {
        spp: a.spp,
        aa: a.aa,
        integrator: a.integrator,
        reuse: Switch::flag(a.reuse),
        ..Default::default()
    };
    let settings = p.renderer.settings(&samples).map_err(cli_error)?;
    let config = BenchConfig {
        spp: settings.spp,
        aa: settings.aa,
        measure: measure(a, settings),
    };
    let max = RenderSettings::MAX_SAMPLES;
    if a.reference_spp == 0 || a.reference_spp > max {
        usage!(
            "--reference-spp must be 1 to {max}, got {}",
            a.reference_spp
        );
    }
    if a.repeat == 0 {
        usage!("--repeat must be at least 1");
    }
    let bar = Bar::new(a.progress.resolve(a.quiet, a.json));
    let (report, images) = p.pool.install(|| {
        bench::run(
            p.renderer.desc(),
            p.renderer.world(),
            &camera,
            &config,
            &bar,
        )
    })?;
    // Images first: a failure then reports one JSON object (the error), never two.
    if let Some(dir) = &a.out {
        write_bench_images(dir, &report, &images)?;
    }
    if a.json {
        println!("{}", versioned_json(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

/// The flags' repeats, reference and seed over the scene's settings `base`; the reference
/// cached in the default directory unless `--cache-dir` names another.
fn measure(a: &BenchArgs, base: RenderSettings) -> bench::Measure {
    bench::Measure {
        base,
        repeat: a.repeat,
        reference_spp: a.reference_spp,
        seed: a.scene.seed,
        cache_dir: Some(a.cache_dir.clone().unwrap_or_else(default_cache_dir)),
    }
}

pub(crate) fn run_equal_error(a: &BenchArgs, p: &Prepared, camera: &Camera) -> Result<()> {
    let max = RenderSettings::MAX_SAMPLES;
    for (flag, n) in [("--aa", a.aa), ("--reference-spp", Some(a.reference_spp))] {
        if let Some(n) = n
            && (n == 0 || n > max)
        {
            usage!("{flag} must be 1 to {max}, got {n}");
        }
    }
    if let Some(&n) = a.ladder.iter().find(|&&n| n == 0 || n > max) {
        usage!("--ladder takes sample counts of 1 to {max}, got {n}");
    }
    if let Some(l) = a.levels.iter().find(|l| !l.is_finite()) {
        usage!("--levels takes finite PSNR values in dB, got {l}");
    }
    if a.repeat == 0 {
        usage!("--repeat must be at least 1");
    }
    let top = a.ladder.iter().copied().max().unwrap_or(0);
    if a.reference_spp <= top {
        usage!(
            "--reference-spp ({}) must exceed the ladder's largest rung ({top}); several \
             times more is better",
            a.reference_spp
        );
    }
    let scene = p
        .renderer
        .settings(&SettingsPatch {
            integrator: a.integrator,
            reuse: Switch::flag(a.reuse),
            ..Default::default()
        })
        .map_err(cli_error)?;
    // The scene's in-focus to defocused ratio of samples (4 : 16 by default), at every rung.
    let aa = match a.aa {
        Some(n) => equal_error::RungAa::Fixed(n),
        None => equal_error::RungAa::Ratio(scene.aa as f64 / scene.spp as f64),
    };
    let config = equal_error::EqualErrorConfig {
        ladder: a.ladder.clone(),
        levels: a.levels.clone(),
        aa,
        measure: measure(a, scene),
    };
    let bar = Bar::new(a.progress.resolve(a.quiet, a.json));
    let mut report = p.pool.install(|| {
        equal_error::run(p.renderer.desc(), p.renderer.world(), camera, &config, &bar)
    })?;
    if let Some(dir) = &a.out {
        bench::plot::write_plot(&mut report, dir)?;
    }
    if a.json {
        println!("{}", versioned_json(&report)?);
    } else {
        print_equal_error(&report);
    }
    Ok(())
}

pub(crate) fn write_bench_images(
    dir: &std::path::Path,
    report: &bench::BenchReport,
    images: &bench::BenchImages,
) -> Result<()> {
    let (w, h) = (report.width, report.height);
    let to_vec3 = |rgb: &[[f32; 3]]| rgb.iter().map(|&c| glam::Vec3::from(c)).collect::<Vec<_>>();
    let reference = to_vec3(&images.reference);
    output::write_png_rgb(&dir.join("reference.png"), w, h, &reference)?;
    for (label, film) in &images.films {
        output::write_png_rgb(&dir.join(format!("{label}.png")), w, h, &film.color)?;
    }
    let film_of = |label: &str| {
        images
            .films
            .iter()
            .find(|(l, _)| l == label)
            .map(|(_, f)| f)
    };
    let (Some(dense), Some(adaptive)) = (film_of("dense"), film_of("adaptive")) else {
        return Ok(());
    };
    output::write_png_rgb(
        &dir.join("depth.png"),
        w,
        h,
        &output::depth_picture(adaptive)?,
    )?;
    output::write_png_rgb(
        &dir.join("interval.png"),
        w,
        h,
        &output::interval_picture(adaptive)?,
    )?;
    output::write_png_rgb(
        &dir.join("samples.png"),
        w,
        h,
        &output::samples_picture(adaptive)?,
    )?;
    // Side by side: reference | dense | adaptive (error-controlled).
    let panels = [&reference, &dense.color, &adaptive.color];
    let mut side = Vec::with_capacity(w * h * panels.len());
    for y in 0..h {
        for panel in panels {
            side.extend_from_slice(&panel[y * w..(y + 1) * w]);
        }
    }
    output::write_png_rgb(&dir.join("comparison.png"), w * panels.len(), h, &side)?;
    for (label, film) in [("adaptive", adaptive), ("dense", dense)] {
        let errors = dofray::metrics::error_map(
            &film.rgb(),
            &images.reference,
            w,
            h,
            dofray::metrics::Space::Srgb,
        )?;
        output::write_png_rgb(
            &dir.join(format!("error-{label}.png")),
            w,
            h,
            &output::heat_picture(&errors, 0.25)?,
        )?;
    }
    Ok(())
}
