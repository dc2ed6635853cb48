//! The `dofray` command line.

#![deny(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use dofray::batch::shard::Shard;
use dofray::bench::{self, BenchConfig, equal_error};
use dofray::camera::Camera;
use dofray::embree::Device;
use dofray::filter::PixelFilterKind;
use dofray::output;
use dofray::overrides::{Overrides, Param, SettingsOverrides};
use dofray::render::{self, Mode, Progress, Region, RenderSettings, SiteRule};
use dofray::renderer::{Renderer, RendererError};
use dofray::sampler::LensFilter;
use dofray::scene::{SceneDesc, builtin};
use dofray::shade::Light;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Returns a usage error (exit status 2): a flag's value or a combination of flags is wrong.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new(dofray::exit::UsageError(format!($($arg)*))))
    };
}

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
    /// Render a scene to an image (PNG: 8-bit sRGB; EXR: linear float RGBA with depth, CoC,
    /// interval and samples passes).
    Render(RenderArgs),
    /// Reproduce the seed's table: time pinhole, dense and adaptive modes, count their rays, and
    /// measure their quality against dense and a converged reference; or, with --equal-error,
    /// the time dense and adaptive need to reach given PSNR levels.
    ///
    /// The seed's table times pinhole, dense and adaptive (the seed's rule at k = 0.4 and 0.2,
    /// and --paper-exact) at one sample count and compares them with dense and with a converged
    /// reference (dense at --reference-spp samples per pixel, cached in --cache-dir).
    ///
    /// --equal-error instead renders dense and adaptive (the error-controlled rule at its
    /// default tolerance, 4 / sqrt(spp) 8-bit code values) at every rung of --ladder, and
    /// reports for each of --levels the seconds each needs to reach that PSNR against the
    /// reference (interpolated linearly in PSNR against log seconds between the two rungs that
    /// bracket it; "not reached" beyond the ladder; "<=" when the cheapest rung already reaches
    /// it), the speedup dense / adaptive, and the same for the highest level both reach. With
    /// --out it draws equal-error.png there: PSNR against seconds, both curves, guides at the
    /// levels. Example: dofray bench paper --equal-error --ladder 4,16,64 --out bench/
    Bench(BenchArgs),
    /// Assemble tiles rendered with --region or --tiles into one image, checking that they
    /// are tiles of one render (same scene, settings and versions) that cover the image
    /// exactly once. The pixels are copied as stored: the result is bit for bit the image
    /// one render would have written. Example: dofray merge out/still.tile-*.exr -o still.exr
    Merge(MergeArgs),
    /// List the built-in scenes.
    Scenes,
}

/// Which scene, at what size, through which lens: shared by `render` and `bench`.
#[derive(Args)]
struct SceneArgs {
    /// What to render: a built-in scene name (see `dofray scenes`), a TOML scene file
    /// (docs/scene-format.md), or a model file (.obj, .gltf, .glb) framed by a default camera.
    #[arg(default_value = "paper")]
    scene: String,
    /// Image width in pixels (default: the scene's; height follows the aspect if not given).
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels (default: the scene's; width follows the aspect if not given).
    #[arg(long)]
    height: Option<u32>,
    /// Worker threads, 1 to 1024 (default: all cores). Bounds Embree's BVH build threads too
    /// (the main thread and N - 1 workers, never running while the render does), so at most N
    /// threads compute at any time.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=dofray::limits::MAX_THREADS as i64))]
    threads: Option<u16>,
    /// Random seed of the samples (pixel and lens); the same seed gives the same image bit for
    /// bit, whatever --threads.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Aperture radius in scene units (replaces the scene's lens).
    #[arg(long, conflicts_with_all = ["f_number", "focal_length", "sensor_width"])]
    aperture_radius: Option<f32>,
    /// Photographic lens: f-number (replaces the scene's lens). The focal length and sensor
    /// width come from --focal-length and --sensor-width, else from the scene's photographic
    /// lens, else 50 mm and 36 mm; the field of view follows from them (replacing the scene's
    /// vfov when its lens was not photographic).
    #[arg(long)]
    f_number: Option<f32>,
    /// Photographic lens: focal length in mm (sets the field of view). Changes the scene's
    /// photographic lens; with any other lens it needs --f-number [default: the scene's, else 50].
    #[arg(long)]
    focal_length: Option<f32>,
    /// Photographic lens: sensor width in mm (sets the field of view). Changes the scene's
    /// photographic lens; with any other lens it needs --f-number [default: the scene's, else 36].
    #[arg(long)]
    sensor_width: Option<f32>,
    /// The seed's lens: depths within this distance (scene units) in front of and behind the
    /// focus stay nearly sharp (replaces the scene's lens; needs --spread). The aperture is
    /// chosen so the blur at the range's ends is --spread pixels across and grows from there.
    #[arg(long, requires = "spread", conflicts_with_all = ["aperture_radius", "f_number", "focal_length", "sensor_width"])]
    sharp_range: Option<f32>,
    /// The seed's lens: blur diameter in pixels at the ends of --sharp-range (how fast blur
    /// spreads outside it; needs --sharp-range).
    #[arg(long, requires = "sharp_range")]
    spread: Option<f32>,
    /// Distance along the view axis that is in focus (overrides the scene's focus); `inf`
    /// focuses at infinity (any huge distance behaves the same).
    #[arg(long, conflicts_with = "autofocus")]
    focus_distance: Option<f32>,
    /// Autofocus on the surface seen through pixel X,Y (e.g. 320,240; overrides the scene's
    /// focus).
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
    /// A light replacing the scene's lights (repeat for several):
    /// `point:X,Y,Z[:INTENSITY]` (a point light, radiant intensity, default 100) or
    /// `sun:DX,DY,DZ[:IRRADIANCE]` (a directional light shining along DX,DY,DZ, default 2) or
    /// `spot:X,Y,Z:DX,DY,DZ[:INTENSITY[:OUTER[:INNER]]]` (a spot light at X,Y,Z shining along
    /// DX,DY,DZ; intensity default 100, cone half-angles in degrees, default 45 and 0).
    #[arg(long = "light", value_name = "KIND:X,Y,Z[:POWER]", value_parser = parse_light)]
    lights: Vec<Light>,
    /// Ambient light level (replaces the scene's).
    #[arg(long)]
    ambient: Option<f32>,
    /// Let a model read MTL libraries, textures and buffers outside its folder (absolute
    /// paths, `..` leading out of it); refused by default.
    #[arg(long)]
    allow_outside_paths: bool,
    /// Largest input file (scene, mesh, MTL, buffer, texture) read, in MiB [default: 4096].
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..))]
    max_input_mib: Option<u64>,
    /// Largest memory one decoded texture may need, in MiB [default: 1024].
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..))]
    max_texture_mib: Option<u64>,
    /// Most triangles a glTF file may instance through its node tree [default: 50000000].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    max_instanced_triangles: Option<u64>,
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Output image: .png (8-bit sRGB) or .exr (Blender-style multilayer: linear RGBA in
    /// ViewLayer.Combined, depth in ViewLayer.Depth.Z, and CoC, interval and samples passes;
    /// docs/outputs.md).
    #[arg(short, long, default_value = "dofray.png")]
    output: PathBuf,
    /// pinhole: no depth of field; dense: lens samples at every pixel (Cook's distributed ray
    /// tracing); adaptive: the seed's sparse sample sites with interpolation.
    #[arg(long, value_enum, default_value_t = Mode::Adaptive)]
    mode: Mode,
    /// Samples per sample site that blur reaches, each a point in pixel x lens (16 fill one
    /// ray packet), 1 to 65536 [default: the scene's, else 16].
    #[arg(long)]
    spp: Option<u32>,
    /// Anti-aliasing: samples per in-focus sample site, and per pixel in pinhole mode, each a
    /// point in pixel x lens, 1 to 65536 [default: the scene's, else 4].
    #[arg(long)]
    aa: Option<u32>,
    /// The pixel filter that sample positions are drawn from: blackman-harris (smooth and
    /// sharp), gaussian (softer), or box (each pixel's own square, at width 1) [default: the
    /// scene's, else blackman-harris].
    #[arg(long, value_enum)]
    pixel_filter: Option<PixelFilterKind>,
    /// Full width of the pixel filter in pixels, up to 16 [default: the scene's for its filter,
    /// else 3 for blackman-harris and gaussian, 1 for box].
    #[arg(long)]
    pixel_filter_width: Option<f32>,
    /// Adaptive mode: the largest error accepted where pixels are interpolated or a site stops
    /// sampling early, in 8-bit sRGB code values (1 = one step of 255; values above 1.0
    /// linear count on the same curve continued). Sites, intervals and samples per site
    /// follow from it [default: the scene's, else 4 / sqrt(spp): 1 at 16 spp, 0.5 at 64].
    #[arg(long, conflicts_with_all = ["interval_factor", "paper_exact"])]
    tolerance: Option<f32>,
    /// Leave the background out (Blender's Film > Transparent): alpha is the coverage (the
    /// filtered fraction of camera samples that hit geometry) and the colour is premultiplied
    /// by it, so the render composites over a plate. PNGs get an alpha channel (straight
    /// alpha), EXRs a coverage A. Without it, alpha is 1 [default: the scene's, else off].
    #[arg(long)]
    transparent: bool,
    /// Exposure in stops: radiance is scaled by 2^STOPS before anything is averaged or written
    /// (PNG and EXR alike), as a camera's exposure would. Use it for scenes whose lights are
    /// in physical units (a Blender light of P watts is P / (4 pi) W/sr: bright), e.g.
    /// `--exposure -3` [default: 0].
    #[arg(long, value_name = "STOPS", allow_negative_numbers = true)]
    exposure: Option<f32>,
    /// Adaptive mode with the seed's fixed rule instead of the error-controlled one: sample
    /// interval = max(2, k x CoC) in defocused regions, spp samples per defocused site (0.4 is
    /// the paper's; reproduces its table) [default: the scene's].
    #[arg(long, short = 'k')]
    interval_factor: Option<f32>,
    /// The seed's fixed rule (k = 0.4 unless -k is given), applied per pixel exactly as the
    /// paper does, without the conservative step that never interpolates across an in-focus
    /// edge.
    #[arg(long)]
    paper_exact: bool,
    /// Weighting of lens samples over the aperture (the filter over the CoC; box is a real
    /// lens's evenly bright bokeh).
    #[arg(long, value_enum, default_value_t = LensFilter::Box)]
    filter: LensFilter,
    /// Also write the depth map, interval map and samples map (samples traced per pixel,
    /// black = interpolated) as PNG pictures into this directory (created if missing).
    #[arg(long)]
    aov_dir: Option<PathBuf>,
    /// PNG output: 16 bits per channel instead of 8 (still sRGB; EXR is always float).
    #[arg(long)]
    png_16: bool,
    /// EXR output: the beauty (ViewLayer.Combined.R/G/B/A) as 16-bit half float, clamped to
    /// +-65504; depth (ViewLayer.Depth.Z) and dofray's passes (ViewLayer.CoC.X,
    /// ViewLayer.Interval.X, ViewLayer.Samples.X) stay 32-bit float. See docs/outputs.md.
    #[arg(long)]
    exr_half: bool,
    /// EXR output: pixel compression, one of none, rle, zip (deflate, 16 scan lines), zips
    /// (deflate, 1 line), piz (wavelet) - all lossless - or pxr24 (float channels to 24 bits),
    /// b44, b44a (half channels only), dwaa, dwab (lossy DCT on the colour) [default: zip].
    #[arg(long, value_name = "METHOD", value_parser = parse_exr_compression)]
    exr_compression: Option<output::ExrCompression>,
    /// Frames to render: a list of frames and ranges, e.g. 1-48, 1-240x2 (every other
    /// frame), 1,5,10..20 (Blender's ..) or -5--1. Each frame's camera and lens come from the
    /// scene's [animation] (docs/scene-format.md). Several frames need a frame pattern in -o:
    /// a run of # becomes the zero-padded frame number (shot_####.exr -> shot_0007.exr).
    /// Without --frames, -s/-e/-j, an -o with a pattern renders the scene's whole frame range,
    /// and one without renders its first frame.
    #[arg(long, short = 'f', value_name = "LIST", conflicts_with_all = ["frame_start", "frame_end", "frame_jump"])]
    frames: Option<String>,
    /// First frame of a range (Blender's -s) [default: the scene's frame_start].
    #[arg(long, short = 's', value_name = "N", allow_negative_numbers = true)]
    frame_start: Option<i64>,
    /// Last frame of a range (Blender's -e) [default: the scene's frame_end].
    #[arg(long, short = 'e', value_name = "N", allow_negative_numbers = true)]
    frame_end: Option<i64>,
    /// Frame step of a range (Blender's -j) [default: 1].
    #[arg(long, short = 'j', value_name = "N")]
    frame_jump: Option<i64>,
    /// Skip every frame (or tile) whose output file exists. Outputs are written to a
    /// temporary file and renamed, so a file that exists is complete: re-running a killed
    /// job with --skip-existing renders only what is missing.
    #[arg(long, conflicts_with = "no_overwrite")]
    skip_existing: bool,
    /// Refuse to replace an existing output: that frame fails (the others still render).
    #[arg(long)]
    no_overwrite: bool,
    /// Stop at the first frame that fails instead of going on to the others (a run with a
    /// failure exits non-zero either way).
    #[arg(long)]
    fail_fast: bool,
    /// Render only the pixels x0..x1, y0..y1 (x1, y1 excluded) of the image, bit for bit as the
    /// full render has them, into a tile file that records its place (EXR: as its data
    /// window); `dofray merge` assembles tiles. E.g. --region 0,0,320,240.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_region, conflicts_with = "tiles")]
    region: Option<Region>,
    /// Render the image as COLUMNSxROWS tiles (e.g. 4x4), each written as its own file next
    /// to -o (still.exr -> still.tile-000.exr, ...), then merged into -o and removed. With
    /// --skip-existing a killed run resumes from the tiles already written; on a farm
    /// (--shard or a scheduler's array) each worker renders its share of the tiles and
    /// `dofray merge` assembles them.
    #[arg(long, value_name = "COLSxROWS", value_parser = parse_grid)]
    tiles: Option<(u32, u32)>,
    /// Render only share I of N (0 <= I < N) of the frames, or of the tiles: jobs I, I + N,
    /// I + 2N, ... Without it, Slurm job arrays (SLURM_ARRAY_TASK_ID with
    /// SLURM_ARRAY_TASK_MIN/MAX/COUNT/STEP) and Kubernetes Indexed Jobs (JOB_COMPLETION_INDEX
    /// with DOFRAY_SHARD_COUNT set to the completions) choose it; docs/farm.md.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    shard: Option<Shard>,
    /// Print a JSON summary on stdout (for frames, tiles or shards: one object with an entry
    /// per job).
    #[arg(long)]
    json: bool,
    /// No progress bar and no summary line.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Args)]
struct MergeArgs {
    /// The tile files (dofray render --region or --tiles), all EXR or all PNG.
    #[arg(required = true, num_args = 1..)]
    tiles: Vec<PathBuf>,
    /// The assembled image, in the tiles' format.
    #[arg(short, long)]
    output: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    json: bool,
    /// No summary line.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Args)]
struct BenchArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Samples per sample site that blur reaches, in every mode [default: the scene's, else
    /// 16]. Not with --equal-error (its --ladder gives the sample counts).
    #[arg(long, conflicts_with = "equal_error")]
    spp: Option<u32>,
    /// Samples per in-focus sample site (and per pixel in pinhole mode), in every mode
    /// [default: the scene's, else 4]. With --equal-error: the same at every rung [default:
    /// the rung's spp times the scene's aa / spp (4 / 16), rounded, at least 1].
    #[arg(long)]
    aa: Option<u32>,
    /// Timed repeats of each mode (or rung); medians are reported.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Samples per pixel of the converged reference image (dense, in focus or not). With
    /// --equal-error it must exceed the ladder's largest rung (several times is better).
    #[arg(long, default_value_t = 1024)]
    reference_spp: u32,
    /// Where the reference is cached between runs [default: $XDG_CACHE_HOME/dofray or
    /// ~/.cache/dofray].
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Write every image, the depth (figure 2) and interval (figure 3) maps, a side-by-side
    /// comparison and an error heat map into this directory; with --equal-error, the
    /// PSNR-versus-seconds plot equal-error.png.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run the equal-error study instead of the seed's table: the time dense and adaptive
    /// need to reach each PSNR level of --levels over the spp rungs of --ladder.
    #[arg(long)]
    equal_error: bool,
    /// With --equal-error: the samples per defocused site of each rung, for both methods.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "SPP,...",
        requires = "equal_error",
        default_value = "4,8,16,32,64,128"
    )]
    ladder: Vec<u32>,
    /// With --equal-error: the PSNR levels in dB (sRGB, against the reference).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "DB,...",
        requires = "equal_error",
        default_value = "30,35,40"
    )]
    levels: Vec<f64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = s.split_once(',').ok_or("expected X,Y (e.g. 320,240)")?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    Ok((parse(x)?, parse(y)?))
}

fn parse_region(s: &str) -> Result<Region, String> {
    s.parse()
        .map_err(|e: dofray::render::RegionError| e.to_string())
}

fn parse_grid(s: &str) -> Result<(u32, u32), String> {
    dofray::render::region::parse_grid(s).map_err(|e| e.to_string())
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    Shard::parse(s).map_err(|e| e.to_string())
}

fn parse_exr_compression(s: &str) -> Result<output::ExrCompression, String> {
    s.parse()
        .map_err(|e: output::CompressionError| e.to_string())
}

/// `spot:X,Y,Z:DX,DY,DZ[:INTENSITY[:OUTER[:INNER]]]`.
fn parse_spot(s: &str) -> Result<Light, String> {
    const USAGE: &str = "expected spot:X,Y,Z:DX,DY,DZ[:INTENSITY[:OUTER[:INNER]]] (cone \
                         half-angles in degrees), e.g. spot:0,5,0:0,-1,0:200:30:20";
    let vector = |v: &str| xyz(v).map_err(|e| format!("{e}; {USAGE}"));
    let parts: Vec<&str> = s.split(':').skip(1).collect();
    if !(2..=5).contains(&parts.len()) {
        return Err(USAGE.into());
    }
    let position = vector(parts[0])?;
    let direction = vector(parts[1])?;
    if direction.length_squared() == 0.0 || !direction.normalize().is_finite() {
        return Err("a spot light's direction must not be 0,0,0".into());
    }
    let intensity = parts
        .get(2)
        .map(|v| number(v))
        .transpose()?
        .unwrap_or(100.0);
    let outer = parts.get(3).map(|v| number(v)).transpose()?.unwrap_or(45.0);
    let inner = parts.get(4).map(|v| number(v)).transpose()?.unwrap_or(0.0);
    if intensity < 0.0 {
        return Err("the light's power must be >= 0".into());
    }
    if !(outer > 0.0 && outer <= 90.0 && inner >= 0.0 && inner <= outer) {
        return Err(format!(
            "cone angles outer {outer} and inner {inner} degrees: expected 0 < outer <= 90 and \
             0 <= inner <= outer"
        ));
    }
    Ok(Light::Spot {
        position,
        direction: direction.normalize(),
        intensity: Vec3::splat(intensity),
        inner_angle: inner.to_radians(),
        outer_angle: outer.to_radians(),
    })
}

/// A finite number of a `--light` argument.
fn number(v: &str) -> Result<f32, String> {
    match v.trim().parse::<f32>() {
        Ok(n) if n.is_finite() => Ok(n),
        _ => Err(format!("{v:?} is not a finite number")),
    }
}

/// `X,Y,Z` of a `--light` argument.
fn xyz(v: &str) -> Result<Vec3, String> {
    let c: Vec<f32> = v.split(',').map(number).collect::<Result<_, _>>()?;
    match c[..] {
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("expected three coordinates X,Y,Z, got {v:?}")),
    }
}

fn parse_light(s: &str) -> Result<Light, String> {
    if s.starts_with("spot:") {
        return parse_spot(s);
    }
    let mut parts = s.split(':');
    let kind = parts.next().unwrap_or_default();
    let xyz = parts
        .next()
        .ok_or("expected KIND:X,Y,Z[:POWER], e.g. point:0,5,0:100 or sun:-1,-2,1")?;
    let p = self::xyz(xyz)?;
    let power = parts.next().map(number).transpose()?;
    if parts.next().is_some() {
        return Err("expected at most KIND:X,Y,Z:POWER".into());
    }
    if power.is_some_and(|p| p < 0.0) {
        return Err("the light's power must be >= 0".into());
    }
    match kind {
        "point" => Ok(Light::Point {
            position: p,
            intensity: Vec3::splat(power.unwrap_or(100.0)),
        }),
        "sun" | "directional" => {
            if p.length_squared() == 0.0 {
                return Err("a sun's direction must not be 0,0,0".into());
            }
            Ok(Light::Directional {
                direction: p.normalize(),
                irradiance: Vec3::splat(power.unwrap_or(2.0)),
            })
        }
        other => Err(format!(
            "unknown light kind {other:?}: expected point, sun or spot"
        )),
    }
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

/// The scene overrides the flags ask for.
fn overrides(a: &SceneArgs) -> Overrides {
    Overrides {
        width: a.width,
        height: a.height,
        aperture_radius: a.aperture_radius,
        f_number: a.f_number,
        focal_length_mm: a.focal_length,
        sensor_width_mm: a.sensor_width,
        sharp_range: a.sharp_range.zip(a.spread),
        focus_distance: a.focus_distance,
        autofocus: a.autofocus,
        blades: a.blades,
        blade_rotation_deg: a.blade_rotation,
        anamorphic: a.anamorphic,
        lights: a.lights.clone(),
        ambient: a.ambient,
    }
}

/// A renderer's error, an override's worded for the command line (flag names).
fn cli_error(e: RendererError) -> anyhow::Error {
    match e {
        RendererError::Override(e) => dofray::exit::UsageError(e.message(Param::flag)).into(),
        e => e.into(),
    }
}

/// A scene ready to render with the flags' overrides, and the worker threads to render it on.
struct Prepared {
    renderer: Renderer,
    pool: rayon::ThreadPool,
}

fn prepare(a: &SceneArgs) -> Result<Prepared> {
    let defaults = dofray::scene::LoadOptions::default();
    let options = dofray::scene::LoadOptions {
        allow_outside_paths: a.allow_outside_paths,
        max_input_bytes: a
            .max_input_mib
            .map_or(defaults.max_input_bytes, |m| m.saturating_mul(1 << 20)),
        max_texture_bytes: a
            .max_texture_mib
            .map_or(defaults.max_texture_bytes, |m| m.saturating_mul(1 << 20)),
        max_instanced_triangles: a
            .max_instanced_triangles
            .unwrap_or(defaults.max_instanced_triangles),
        ..defaults
    };
    let desc = dofray::scene::load_with(&a.scene, &options)?;
    for warning in &desc.warnings {
        eprintln!("warning: {warning}");
    }
    let threads = a.threads.map(usize::from);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    // Embree's own thread pool (BVH builds) gets the same bound as rayon's.
    let device = match threads {
        Some(n) => Device::with_threads(n),
        None => Device::new(),
    }
    .context("cannot create the Embree device")?;
    let renderer = Renderer::with_overrides(desc, overrides(a), &device).map_err(cli_error)?;
    Ok(Prepared { renderer, pool })
}

/// The render settings the flags and the scene ask for.
fn render_settings(a: &RenderArgs, desc: &SceneDesc) -> Result<RenderSettings> {
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
fn frame_list(a: &RenderArgs, desc: &SceneDesc) -> Result<Option<Vec<i64>>> {
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
fn shard(a: &RenderArgs) -> Result<Option<(Shard, String)>> {
    if let Some(s) = a.shard {
        return Ok(Some((s, "--shard".into())));
    }
    let found = Shard::from_env(|k| std::env::var(k).ok())
        .map_err(|e| dofray::exit::UsageError(e.to_string()))?;
    Ok(found.map(|(s, source)| (s, source.to_string())))
}

/// What became of one job.
enum Outcome {
    Rendered(serde_json::Value),
    Skipped,
    Failed(anyhow::Error),
}

fn run_render(a: &RenderArgs) -> Result<ExitCode> {
    use dofray::batch::jobs;
    output::clean_up_on_signals(a.json)?;
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
fn refuse_existing(a: &RenderArgs, job: &dofray::batch::jobs::Job) -> Result<()> {
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
fn render_job(
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

fn run_merge(a: &MergeArgs) -> Result<()> {
    output::clean_up_on_signals(a.json)?;
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

/// Which Embree ran the render and how: version, device configuration, packet lanes per call.
fn embree_json(scene: &dofray::embree::Scene) -> serde_json::Value {
    let device = scene.device();
    serde_json::json!({
        "version": device.embree_version(),
        "config": device.config(),
        "native_packet_width": device.native_packet_width(),
        "isa": isa_family(device.native_packet_width()),
        "lanes_per_call": scene.lanes_per_call(),
    })
}

fn default_cache_dir() -> PathBuf {
    std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir)
        .join("dofray")
}

fn run_bench(a: &BenchArgs) -> Result<()> {
    output::clean_up_on_signals(a.json)?;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create --out directory {}", dir.display()))?;
    }
    let p = prepare(&a.scene)?;
    let camera = p.renderer.camera(None).map_err(cli_error)?;
    if a.equal_error {
        return run_equal_error(a, &p, &camera);
    }
    let config = BenchConfig {
        spp: a.spp.or(p.renderer.desc().spp).unwrap_or(16),
        aa: a.aa.or(p.renderer.desc().aa).unwrap_or(4),
        repeat: a.repeat,
        reference_spp: a.reference_spp,
        seed: a.scene.seed,
        cache_dir: Some(a.cache_dir.clone().unwrap_or_else(default_cache_dir)),
    };
    let max = RenderSettings::MAX_SAMPLES;
    for (flag, n) in [
        ("--spp", config.spp),
        ("--aa", config.aa),
        ("--reference-spp", config.reference_spp),
    ] {
        if n == 0 || n > max {
            usage!("{flag} must be 1 to {max}, got {n}");
        }
    }
    if config.repeat == 0 {
        usage!("--repeat must be at least 1");
    }
    let bar = Bar::new(a.quiet || a.json);
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

fn run_equal_error(a: &BenchArgs, p: &Prepared, camera: &Camera) -> Result<()> {
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
    // The scene's in-focus to defocused ratio of samples (4 : 16 by default), at every rung.
    let aa = match a.aa {
        Some(n) => equal_error::RungAa::Fixed(n),
        None => equal_error::RungAa::Ratio(
            p.renderer.desc().aa.unwrap_or(4) as f64 / p.renderer.desc().spp.unwrap_or(16) as f64,
        ),
    };
    let config = equal_error::EqualErrorConfig {
        ladder: a.ladder.clone(),
        levels: a.levels.clone(),
        aa,
        repeat: a.repeat,
        reference_spp: a.reference_spp,
        seed: a.scene.seed,
        cache_dir: Some(a.cache_dir.clone().unwrap_or_else(default_cache_dir)),
    };
    let bar = Bar::new(a.quiet || a.json);
    let mut report = p.pool.install(|| {
        equal_error::run(p.renderer.desc(), p.renderer.world(), camera, &config, &bar)
    })?;
    if let Some(dir) = &a.out {
        equal_error::write_plot(&mut report, dir)?;
    }
    if a.json {
        println!("{}", versioned_json(&report)?);
    } else {
        print_equal_error(&report);
    }
    Ok(())
}

/// Seconds for a table cell: "not reached", or "<=" before an upper bound.
fn crossing_cell(c: &equal_error::Crossing) -> String {
    match c.seconds {
        None => "not reached".into(),
        Some(s) if c.at_first_rung => format!("<={s:.4}"),
        Some(s) => format!("{s:.4}"),
    }
}

fn speedup_cell(l: &equal_error::Level) -> String {
    use equal_error::Bound;
    match l.speedup {
        None => "-".into(),
        Some(x) => match l.speedup_bound {
            Bound::Exact => format!("{x:.2}x"),
            Bound::AtMost => format!("<={x:.2}x"),
            Bound::AtLeast => format!(">={x:.2}x"),
            Bound::Unknown => format!("~{x:.2}x?"),
        },
    }
}

fn print_equal_error(r: &equal_error::EqualErrorReport) {
    println!(
        "dofray bench --equal-error: scene {}, {}x{}, median of {} runs, {} threads; reference {} spp{}",
        r.scene,
        r.width,
        r.height,
        r.repeat,
        r.threads,
        r.reference_spp,
        if r.reference_cached { " (cached)" } else { "" }
    );
    let aa = match r.aa {
        equal_error::RungAa::Fixed(n) => format!("{n} at every rung"),
        equal_error::RungAa::Ratio(x) => format!("{x} x spp, at least 1"),
    };
    println!(
        "adaptive: error-controlled rule, default tolerance 4/sqrt(spp) code values; aa: {aa}"
    );
    println!(
        "{:>6} {:>5} | {:>9} {:>11} {:>12} {:>8} | {:>9} {:>11} {:>12} {:>8} {:>6}",
        "spp",
        "aa",
        "dense s",
        "rays",
        "samples",
        "PSNR",
        "adapt. s",
        "rays",
        "samples",
        "PSNR",
        "tol."
    );
    for (d, ad) in r.dense.iter().zip(&r.adaptive) {
        println!(
            "{:>6} {:>5} | {:>9.4} {:>11} {:>12} {:>8.2} | {:>9.4} {:>11} {:>12} {:>8.2} {:>6.2}",
            d.spp,
            d.aa,
            d.seconds,
            d.rays,
            d.samples,
            d.psnr_vs_reference,
            ad.seconds,
            ad.rays,
            ad.samples,
            ad.psnr_vs_reference,
            ad.tolerance.unwrap_or(f32::NAN)
        );
    }
    println!("time to reach each PSNR level (seconds, interpolated in log time between rungs):");
    println!(
        "  {:>10} {:>12} {:>12} {:>10}",
        "level", "dense", "adaptive", "speedup"
    );
    let row = |name: String, l: &equal_error::Level| {
        println!(
            "  {:>10} {:>12} {:>12} {:>10}",
            name,
            crossing_cell(&l.dense),
            crossing_cell(&l.adaptive),
            speedup_cell(l)
        );
    };
    for l in &r.levels {
        row(format!("{} dB", l.psnr_db), l);
    }
    match &r.highest_common {
        Some(l) => {
            println!("highest level both reach:");
            row(format!("{:.2} dB", l.psnr_db), l);
        }
        None => println!("highest level both reach: none (no finite PSNR)"),
    }
    println!(
        "PSNR in sRGB against the reference; \"<=\": the cheapest rung already reaches the level \
         (an upper bound)."
    );
    if let Some(plot) = &r.plot {
        println!("plot: {}", plot.display());
    }
}

fn print_table(r: &bench::BenchReport) {
    println!(
        "dofray bench: scene {}, {}x{}, {} spp, {} aa, median of {} runs, {} threads; reference {} spp{}",
        r.scene,
        r.width,
        r.height,
        r.spp,
        r.aa,
        r.repeat,
        r.threads,
        r.reference_spp,
        if r.reference_cached { " (cached)" } else { "" }
    );
    println!(
        "{:<20} {:>8} {:>11} {:>8} {:>9} {:>8} {:>8} {:>9} {:>9} {:>8} {:>8}",
        "mode",
        "seconds",
        "rays",
        "Mrays/s",
        "sites",
        "x pinh.",
        "speedup",
        "PSNR dns",
        "PSNR ref",
        "SSIM ref",
        "max err"
    );
    for row in &r.rows {
        println!(
            "{:<20} {:>8.3} {:>11} {:>8.2} {:>9} {:>8.2} {:>8.2} {:>9.2} {:>9.2} {:>8.4} {:>8.3}",
            row.label,
            row.seconds,
            row.rays,
            row.mrays_per_s,
            row.sample_sites,
            row.time_vs_pinhole,
            row.speedup_vs_dense,
            row.psnr_vs_dense,
            row.psnr_vs_reference,
            row.ssim_vs_reference,
            row.max_error_vs_reference
        );
    }
    println!(
        "intersect-only replay of dense's rays: {:.2} Mrays/s; dense runs at {:.0}% of it",
        r.intersect_only_mrays_per_s,
        100.0 * r.dense_vs_intersect_only
    );
    println!("where the time goes (ms): depth pass + maps + sample sites + interpolation");
    for row in r
        .rows
        .iter()
        .filter(|row| row.mode != render::Mode::Pinhole)
    {
        println!(
            "  {:<20} {:>7.1} + {:>5.1} + {:>7.1} + {:>5.1}",
            row.label,
            row.pinhole_seconds * 1e3,
            row.maps_seconds * 1e3,
            row.sites_seconds * 1e3,
            row.interpolate_seconds * 1e3
        );
    }
    println!("PSNR/SSIM in sRGB (what a viewer sees); \"inf\" = identical images.");
}

fn write_bench_images(
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
        &output::depth_picture(adaptive),
    )?;
    output::write_png_rgb(
        &dir.join("interval.png"),
        w,
        h,
        &output::interval_picture(adaptive),
    )?;
    output::write_png_rgb(
        &dir.join("samples.png"),
        w,
        h,
        &output::samples_picture(adaptive),
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
            &output::heat_picture(&errors, 0.25),
        )?;
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

/// A bench report (or any serialisable object) with `schema_version`, `dofray_version` and
/// `git_commit` added at the top level.
fn versioned_json(report: &impl serde::Serialize) -> Result<String> {
    let mut value = serde_json::to_value(report)?;
    if let Some(map) = value.as_object_mut() {
        map.insert("schema_version".into(), dofray::exit::SCHEMA_VERSION.into());
        map.insert("dofray_version".into(), dofray::VERSION.into());
        map.insert("git_commit".into(), dofray::GIT_COMMIT.into());
    }
    Ok(serde_json::to_string(&value)?)
}

/// What `dofray --version` prints: dofray's version and commit, and the Embree it runs on.
fn version_text() -> String {
    let mut text = format!(
        "dofray {}\ncommit: {}\n",
        dofray::VERSION,
        dofray::GIT_COMMIT
    );
    match Device::new() {
        Ok(device) => {
            let width = device.native_packet_width();
            text += &format!(
                "embree: {}\nembree isa: {} (native packet width {width})\nembree config: {:?}\n",
                device.embree_version(),
                isa_family(width),
                device.config()
            );
        }
        Err(e) => text += &format!("embree: unavailable ({e})\n"),
    }
    text
}

/// The instruction-set family behind a native packet width (Embree reports the width, not the
/// exact ISA: 8 lanes are AVX or AVX2).
fn isa_family(width: u32) -> &'static str {
    match width {
        16 => "AVX-512",
        8 => "AVX/AVX2",
        4 if cfg!(target_arch = "aarch64") => "NEON",
        4 => "SSE",
        _ => "scalar",
    }
}

/// Prints a failure: the plain message on stderr and, with `--json`, the error object on stdout.
fn report_error(kind: dofray::exit::ErrorKind, message: &str, json: bool) -> ExitCode {
    eprintln!("error: {message}");
    if json {
        println!("{}", dofray::exit::json_error(kind, message));
    }
    ExitCode::from(kind.exit_code())
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind as Clap;
            return match e.kind() {
                Clap::DisplayVersion => {
                    print!("{}", version_text());
                    ExitCode::SUCCESS
                }
                // --help and friends print and exit 0; real errors exit 2 (clap's usage status).
                _ if !e.use_stderr() || !std::env::args().skip(1).any(|a| a == "--json") => {
                    e.exit()
                }
                _ => {
                    let _ = e.print();
                    let text = e.render().to_string();
                    let message = text
                        .lines()
                        .next()
                        .unwrap_or_default()
                        .trim_start_matches("error: ");
                    println!(
                        "{}",
                        dofray::exit::json_error(dofray::exit::ErrorKind::Usage, message)
                    );
                    ExitCode::from(dofray::exit::USAGE)
                }
            };
        }
    };
    let (result, json) = match &cli.command {
        Command::Render(a) => (run_render(a), a.json),
        Command::Bench(a) => (run_bench(a).map(|()| ExitCode::SUCCESS), a.json),
        Command::Merge(a) => (run_merge(a).map(|()| ExitCode::SUCCESS), a.json),
        Command::Scenes => {
            for (name, about) in builtin::BUILTIN {
                println!("{name:<10} {about}");
            }
            (Ok(ExitCode::SUCCESS), false)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => report_error(dofray::exit::classify(e.as_ref()), &format!("{e:#}"), json),
    }
}
