//! The `dofray` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use dofray::camera::{Focus, LensSpec};
use dofray::embree::Device;
use dofray::output;
use dofray::render::{self, Mode, Progress, RenderSettings};
use dofray::sampler::LensFilter;
use dofray::scene::{SceneDesc, World, builtin};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Depth-of-field ray tracer on Intel Embree.
///
/// dofray renders thin-lens depth of field by distributed ray tracing, and speeds it up with
/// the method of Kumamoto's "A Faster Technique for Rendering Depth of Field Images": lens
/// samples are traced only at adaptive sample sites (every pixel where the image is in focus,
/// sparser as the circle of confusion grows) and the pixels between them are interpolated.
#[derive(Parser)]
#[command(name = "dofray", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to an image (PNG: 8-bit sRGB; EXR: linear float with Z/coc/interval/samples).
    Render(RenderArgs),
    /// List the built-in scenes.
    Scenes,
}

#[derive(Args)]
struct RenderArgs {
    /// A built-in scene name (see `dofray scenes`).
    #[arg(default_value = "paper")]
    scene: String,
    /// Output image: .png (8-bit sRGB) or .exr (linear RGB plus Z, coc, interval, samples).
    #[arg(short, long, default_value = "dofray.png")]
    output: PathBuf,
    /// pinhole: no depth of field; dense: lens samples at every pixel (Cook's distributed ray
    /// tracing); adaptive: the seed's sparse sample sites with interpolation.
    #[arg(long, value_enum, default_value_t = Mode::Adaptive)]
    mode: Mode,
    /// Lens samples per defocused sample site (16 fill one ray packet).
    /// [default: the scene's, else 16]
    #[arg(long)]
    spp: Option<u32>,
    /// Sample interval as a fraction of the CoC diameter in defocused regions (the seed's k;
    /// 0.4 is fast, 0.2 is near-identical to dense).
    /// [default: the scene's, else 0.4]
    #[arg(long, short = 'k')]
    interval_factor: Option<f32>,
    /// Use the seed's plain per-pixel interval rule instead of the conservative one that never
    /// interpolates across an in-focus edge.
    #[arg(long)]
    paper_exact: bool,
    /// Image width in pixels (default: the scene's; height follows the aspect if not given).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels (default: the scene's; width follows the aspect if not given).
    #[arg(long)]
    height: Option<u32>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Random seed of the lens samples; the same seed gives the same image bit for bit.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Weighting of lens samples over the aperture.
    #[arg(long, value_enum, default_value_t = LensFilter::Box)]
    filter: LensFilter,
    /// Aperture radius in scene units (overrides the scene's lens).
    #[arg(long)]
    aperture_radius: Option<f32>,
    /// Photographic lens: f-number (with --focal-length and --sensor-width).
    #[arg(long)]
    f_number: Option<f32>,
    /// Photographic lens: focal length in mm (sets the field of view).
    #[arg(long, default_value_t = 50.0)]
    focal_length: f32,
    /// Photographic lens: sensor width in mm.
    #[arg(long, default_value_t = 36.0)]
    sensor_width: f32,
    /// Distance along the view axis that is in focus (overrides the scene's).
    #[arg(long)]
    focus_distance: Option<f32>,
    /// Autofocus on the surface seen through pixel X,Y (e.g. 320,240).
    #[arg(long, value_parser = parse_pixel)]
    autofocus: Option<(u32, u32)>,
    /// Aperture blades for polygonal bokeh (0 = circular).
    #[arg(long)]
    blades: Option<u32>,
    /// Rotation of a polygonal aperture in degrees.
    #[arg(long)]
    blade_rotation: Option<f32>,
    /// Anamorphic ratio: aperture height over width (1 = round bokeh).
    #[arg(long)]
    anamorphic: Option<f32>,
    /// Also write the depth map and interval map as PNG pictures into this directory.
    #[arg(long)]
    aov_dir: Option<PathBuf>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    json: bool,
    /// No progress bar and no summary line.
    #[arg(long, short)]
    quiet: bool,
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = s.split_once(',').ok_or("expected X,Y (e.g. 320,240)")?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    Ok((parse(x)?, parse(y)?))
}

/// An indicatif bar on stderr; it draws nothing when stderr is not a terminal.
struct Bar(ProgressBar);

impl Bar {
    fn new(quiet: bool) -> Self {
        let target = if quiet {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        };
        let bar = ProgressBar::with_draw_target(None, target);
        bar.set_style(
            ProgressStyle::with_template(
                "{msg:>9} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        Bar(bar)
    }
}

impl Progress for Bar {
    fn start(&self, phase: &str, total: u64) {
        self.0.reset();
        self.0.set_length(total);
        self.0.set_message(phase.to_string());
    }
    fn advance(&self, units: u64) {
        self.0.inc(units);
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

fn load_scene(name: &str) -> Result<SceneDesc> {
    builtin::builtin(name).with_context(|| {
        let names: Vec<&str> = builtin::BUILTIN.iter().map(|(n, _)| *n).collect();
        format!(
            "unknown scene {name:?}: expected one of {}",
            names.join(", ")
        )
    })
}

/// Applies command-line overrides of size and lens to the scene's camera.
fn apply_overrides(desc: &mut SceneDesc, a: &RenderArgs) -> Result<()> {
    let cam = &mut desc.camera;
    for (name, v) in [("--width", a.width), ("--height", a.height)] {
        if v == Some(0) {
            bail!("{name} must be at least 1 pixel");
        }
    }
    match (a.width, a.height) {
        (Some(w), Some(h)) => (cam.width, cam.height) = (w, h),
        (Some(w), None) => {
            cam.height = ((w as u64 * cam.height as u64) as f64 / cam.width as f64)
                .round()
                .max(1.0) as u32;
            cam.width = w;
        }
        (None, Some(h)) => {
            cam.width = ((h as u64 * cam.width as u64) as f64 / cam.height as f64)
                .round()
                .max(1.0) as u32;
            cam.height = h;
        }
        (None, None) => {}
    }
    if let Some(r) = a.aperture_radius {
        if !(r.is_finite() && r >= 0.0) {
            bail!("--aperture-radius must be a finite number >= 0, got {r}");
        }
        cam.lens = LensSpec::Aperture { radius: r };
    }
    if let Some(n) = a.f_number {
        cam.lens = LensSpec::Photographic {
            focal_length_mm: a.focal_length,
            f_number: n,
            sensor_width_mm: a.sensor_width,
        };
    }
    if let Some(d) = a.focus_distance {
        if !(d.is_finite() && d > 0.0) {
            bail!("--focus-distance must be a finite number > 0, got {d}");
        }
        cam.focus = Focus::Distance(d);
    }
    if let Some((x, y)) = a.autofocus {
        cam.focus = Focus::Pixel { x, y };
    }
    if let Some(b) = a.blades {
        cam.aperture.blades = b;
    }
    if let Some(r) = a.blade_rotation {
        cam.aperture.rotation_deg = r;
    }
    if let Some(r) = a.anamorphic {
        cam.aperture.anamorphic = r;
    }
    Ok(())
}

fn run_render(a: &RenderArgs) -> Result<()> {
    let mut desc = load_scene(&a.scene)?;
    let settings = RenderSettings {
        mode: a.mode,
        spp: a.spp.or(desc.spp).unwrap_or(16),
        interval_factor: a.interval_factor.or(desc.interval_factor).unwrap_or(0.4),
        paper_exact: a.paper_exact,
        seed: a.seed,
        filter: a.filter,
        ..Default::default()
    };
    settings
        .validate()
        .map_err(|e| anyhow::anyhow!("{}", cli_message(&e)))?;
    output::check_writable(&a.output)
        .with_context(|| format!("cannot write the output image {}", a.output.display()))?;
    if let Some(dir) = &a.aov_dir {
        if !dir.is_dir() {
            bail!("--aov-dir {} is not a directory", dir.display());
        }
    }
    apply_overrides(&mut desc, a)?;

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    let device = Device::new().context("cannot create the Embree device")?;
    let world =
        World::build(&desc, &device).with_context(|| format!("invalid scene {}", desc.name))?;
    let camera = desc
        .camera
        .build(|ray| {
            let hit = world.scene.intersect1(ray)?;
            Some(
                (ray.at(hit.t) - ray.origin)
                    .dot((desc.camera.look_at - desc.camera.eye).normalize()),
            )
        })
        .context("invalid camera")?;
    let bar = Bar::new(a.quiet || a.json);
    let (film, stats) = pool.install(|| render::render(&world, &camera, &settings, &bar))?;

    output::write_film(&a.output, &film)?;
    if let Some(dir) = &a.aov_dir {
        let (w, h) = (film.width, film.height);
        output::write_png_rgb(&dir.join("depth.png"), w, h, &output::depth_picture(&film))?;
        output::write_png_rgb(
            &dir.join("interval.png"),
            w,
            h,
            &output::interval_picture(&film),
        )?;
    }
    if a.json {
        let summary = serde_json::json!({
            "scene": desc.name,
            "output": a.output,
            "mode": a.mode.name(),
            "width": film.width,
            "height": film.height,
            "spp": settings.spp,
            "interval_factor": json_f32(settings.interval_factor),
            "paper_exact": a.paper_exact,
            "seed": a.seed,
            "seconds": stats.seconds,
            "pinhole_seconds": stats.pinhole_seconds,
            "rays": stats.rays.total(),
            "primary_rays": stats.rays.primary,
            "shadow_rays": stats.rays.shadow,
            "secondary_rays": stats.rays.secondary,
            "sample_sites": stats.sample_sites,
            "defocused_sites": stats.defocused_sites,
            "mrays_per_s": stats.mrays_per_s(),
            "aperture_radius": json_f32(camera.aperture_radius),
            "focus_distance": json_f32(camera.focus_distance),
        });
        println!("{summary}");
    } else if !a.quiet {
        eprintln!(
            "{}: {} {}x{} in {:.2} s, {} rays ({:.1} Mrays/s), {} sample sites",
            a.output.display(),
            a.mode.name(),
            film.width,
            film.height,
            stats.seconds,
            stats.rays.total(),
            stats.mrays_per_s(),
            stats.sample_sites
        );
    }
    Ok(())
}

/// An f32 as the f64 with the same shortest decimal form (0.4, not 0.4000000059604645).
fn json_f32(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::NAN)
}

/// Render-setting errors worded for the command line (flag names, not field names).
fn cli_message(e: &render::RenderError) -> String {
    match e {
        render::RenderError::ZeroSpp => "--spp must be at least 1".into(),
        render::RenderError::BadIntervalFactor(k) => {
            format!("--interval-factor must be a finite number > 0, got {k}")
        }
        other => other.to_string(),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Render(a) => run_render(a),
        Command::Scenes => {
            for (name, about) in builtin::BUILTIN {
                println!("{name:<10} {about}");
            }
            Ok(())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
