//! The command line's arguments: clap's structs and the value parsers of their flags.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use dofray::batch::shard::Shard;
use dofray::camera::LensFilter;
use dofray::filter::PixelFilterKind;
use dofray::output;
use dofray::render::{Mode, Region};
use dofray::shade::Light;
use dofray::view::{Look, View, ViewError};
use glam::Vec3;

/// Depth-of-field ray tracer on Intel Embree.
///
/// dofray renders thin-lens depth of field by distributed ray tracing, and speeds it up with
/// the method of Kumamoto's "A Faster Technique for Rendering Depth of Field Images": lens
/// samples are traced only at adaptive sample sites (every pixel where the image is in focus,
/// sparser as the circle of confusion grows) and the pixels between them are interpolated.
#[derive(Parser)]
#[command(name = "dofray", version, about, long_about)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
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
pub(crate) struct SceneArgs {
    /// What to render: a built-in scene name (see `dofray scenes`), a TOML scene file
    /// (docs/scene-format.md), or a model file (.obj, .gltf, .glb) framed by a default camera.
    #[arg(default_value = "paper")]
    pub(crate) scene: String,
    /// Image width in pixels (default: the scene's; height follows the aspect if not given).
    #[arg(long)]
    pub(crate) width: Option<u32>,
    /// Image height in pixels (default: the scene's; width follows the aspect if not given).
    #[arg(long)]
    pub(crate) height: Option<u32>,
    /// Worker threads, 1 to 1024 (default: all cores). Bounds Embree's BVH build threads too
    /// (the main thread and N - 1 workers, never running while the render does), so at most N
    /// threads compute at any time.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=dofray::limits::MAX_THREADS as i64))]
    pub(crate) threads: Option<u16>,
    /// Random seed of the samples (pixel and lens); the same seed gives the same image bit for
    /// bit, whatever --threads.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Aperture radius in scene units (replaces the scene's lens).
    #[arg(long, conflicts_with_all = ["f_number", "focal_length", "sensor_width"])]
    pub(crate) aperture_radius: Option<f32>,
    /// Photographic lens: f-number (replaces the scene's lens). The focal length and sensor
    /// width come from --focal-length and --sensor-width, else from the scene's photographic
    /// lens; else the sensor is 36 mm and the focal length the one that keeps the scene's
    /// field of view on it (a new aperture does not reframe the shot).
    #[arg(long)]
    pub(crate) f_number: Option<f32>,
    /// Photographic lens: focal length in mm (sets the field of view). Changes the scene's
    /// photographic lens; with any other lens it needs --f-number [default: the scene's, else 50].
    #[arg(long)]
    pub(crate) focal_length: Option<f32>,
    /// Photographic lens: sensor width in mm (sets the field of view). Changes the scene's
    /// photographic lens; with any other lens it needs --f-number [default: the scene's, else 36].
    #[arg(long)]
    pub(crate) sensor_width: Option<f32>,
    /// A real lens: a lens prescription file traced element by element (pbrt's lens format,
    /// one surface a line: radius, thickness, ior, aperture diameter in mm; see lenses/ and
    /// docs/lenses.md). Replaces the scene's lens; its focal length sets the field of view,
    /// --f-number stops it down, --sensor-width sizes the film (default 36 mm).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["aperture_radius", "focal_length", "sharp_range", "blades", "blade_rotation", "anamorphic"])]
    pub(crate) lens: Option<std::path::PathBuf>,
    /// The seed's lens: depths within this distance (scene units) in front of and behind the
    /// focus stay nearly sharp (replaces the scene's lens; needs --spread). The aperture is
    /// chosen so the blur at the range's ends is --spread pixels across and grows from there.
    #[arg(long, requires = "spread", conflicts_with_all = ["aperture_radius", "f_number", "focal_length", "sensor_width"])]
    pub(crate) sharp_range: Option<f32>,
    /// The seed's lens: blur diameter in pixels at the ends of --sharp-range (how fast blur
    /// spreads outside it; needs --sharp-range).
    #[arg(long, requires = "sharp_range")]
    pub(crate) spread: Option<f32>,
    /// Distance along the view axis that is in focus (overrides the scene's focus); `inf`
    /// focuses at infinity (any huge distance behaves the same).
    #[arg(long, conflicts_with = "autofocus")]
    pub(crate) focus_distance: Option<f32>,
    /// Autofocus on the surface seen through pixel X,Y (e.g. 320,240; overrides the scene's
    /// focus).
    #[arg(long, value_parser = parse_pixel)]
    pub(crate) autofocus: Option<(u32, u32)>,
    /// Aperture blades for polygonal bokeh (0 = circular).
    #[arg(long)]
    pub(crate) blades: Option<u32>,
    /// Rotation of a polygonal aperture in degrees.
    #[arg(long)]
    pub(crate) blade_rotation: Option<f32>,
    /// Anamorphic ratio: aperture height over width (1 = round bokeh).
    #[arg(long)]
    pub(crate) anamorphic: Option<f32>,
    /// A light replacing the scene's lights (repeat for several):
    /// `point:X,Y,Z[:INTENSITY]` (a point light, radiant intensity, default 100) or
    /// `sun:DX,DY,DZ[:IRRADIANCE]` (a directional light shining along DX,DY,DZ, default 2) or
    /// `spot:X,Y,Z:DX,DY,DZ[:INTENSITY[:OUTER[:INNER]]]` (a spot light at X,Y,Z shining along
    /// DX,DY,DZ; intensity default 100, cone half-angles in degrees, default 45 and 0).
    #[arg(long = "light", value_name = "KIND:X,Y,Z[:POWER]", value_parser = parse_light)]
    pub(crate) lights: Vec<Light>,
    /// Ambient light level of the direct integrator (replaces the scene's); the path tracer
    /// is lit by the scene's world instead.
    #[arg(long)]
    pub(crate) ambient: Option<f32>,
    /// Let a model read MTL libraries, textures and buffers outside its folder (absolute
    /// paths, `..` leading out of it); refused by default.
    #[arg(long)]
    pub(crate) allow_outside_paths: bool,
    /// Largest input file (scene, mesh, MTL, buffer, texture) read, in MiB [default: 4096].
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) max_input_mib: Option<u64>,
    /// Largest memory one decoded texture may need, in MiB [default: 1024].
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) max_texture_mib: Option<u64>,
    /// Most triangles a glTF file may instance through its node tree [default: 50000000].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) max_instanced_triangles: Option<u64>,
}

#[derive(Args)]
pub(crate) struct RenderArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
    /// Output image: .png (8-bit sRGB) or .exr (Blender-style multilayer: linear RGBA in
    /// ViewLayer.Combined, depth in ViewLayer.Depth.Z, and CoC, interval and samples passes;
    /// docs/outputs.md).
    #[arg(short, long, default_value = "dofray.png")]
    pub(crate) output: PathBuf,
    /// pinhole: no depth of field; dense: lens samples at every pixel (Cook's distributed ray
    /// tracing); adaptive: the seed's sparse sample sites with interpolation.
    #[arg(long, value_enum, default_value_t = Mode::Adaptive)]
    pub(crate) mode: Mode,
    /// Samples per sample site that blur reaches, each a point in pixel x lens (16 fill one
    /// ray packet), 1 to 65536 [default: the scene's, else 16].
    #[arg(long)]
    pub(crate) spp: Option<u32>,
    /// Anti-aliasing: samples per in-focus sample site, and per pixel in pinhole mode, each a
    /// point in pixel x lens, 1 to 65536. With the path tracer, adaptive mode's in-focus sites
    /// take 16 to the larger of --aa and --spp, more where their neighbours are noisier
    /// [default: the scene's, else --spp with the path tracer (its light is as noisy in focus
    /// as in the blur), 4 with --integrator direct].
    #[arg(long)]
    pub(crate) aa: Option<u32>,
    /// The pixel filter that sample positions are drawn from: blackman-harris (smooth and
    /// sharp), gaussian (softer), or box (each pixel's own square, at width 1) [default: the
    /// scene's, else blackman-harris].
    #[arg(long, value_enum)]
    pub(crate) pixel_filter: Option<PixelFilterKind>,
    /// Full width of the pixel filter in pixels, up to 16 [default: the scene's for its filter,
    /// else 3 for blackman-harris and gaussian, 1 for box].
    #[arg(long)]
    pub(crate) pixel_filter_width: Option<f32>,
    /// Adaptive mode: the largest error accepted where pixels are interpolated or a site stops
    /// sampling early, in 8-bit sRGB code values (1 = one step of 255; values above 1.0
    /// linear count on the same curve continued). Sites, intervals and samples per site
    /// follow from it [default: the scene's, else 4 / sqrt(spp): 1 at 16 spp, 0.5 at 64].
    #[arg(long, conflicts_with_all = ["interval_factor", "paper_exact"])]
    pub(crate) tolerance: Option<f32>,
    /// Leave the background out (Blender's Film > Transparent): alpha is the coverage (the
    /// filtered fraction of camera samples that hit geometry) and the colour is premultiplied
    /// by it, so the render composites over a plate. PNGs get an alpha channel (straight
    /// alpha), EXRs a coverage A. Without it, alpha is 1 [default: the scene's, else off].
    #[arg(long)]
    pub(crate) transparent: bool,
    /// Exposure in stops: radiance is scaled by 2^STOPS before anything is averaged or written
    /// (PNG and EXR alike), as a camera's exposure would. Use it for scenes whose lights are
    /// in physical units (a Blender light of P watts is P / (4 pi) W/sr: bright), e.g.
    /// `--exposure -3` [default: 0].
    #[arg(long, value_name = "STOPS", allow_negative_numbers = true)]
    pub(crate) exposure: Option<f32>,
    /// How light is carried: `path` (physically based: every light kind, soft shadows,
    /// indirect light, glass; agrees with Cycles) or `direct` (the seed's quick shading: direct
    /// light with hard shadows, ambient from the world, mirror bounces) [default: the scene's,
    /// else path].
    #[arg(long, value_enum)]
    pub(crate) integrator: Option<dofray::render::Integrator>,
    /// Path tracer: most bounces of any kind (Cycles' Light Paths > Total) [default: the
    /// scene's, else 12].
    #[arg(long, value_name = "N")]
    pub(crate) max_bounces: Option<u32>,
    /// Path tracer: most diffuse bounces [default: the scene's, else 4].
    #[arg(long, value_name = "N")]
    pub(crate) diffuse_bounces: Option<u32>,
    /// Path tracer: most glossy bounces [default: the scene's, else 4].
    #[arg(long, value_name = "N")]
    pub(crate) glossy_bounces: Option<u32>,
    /// Path tracer: most transmission bounces [default: the scene's, else 12].
    #[arg(long, value_name = "N")]
    pub(crate) transmission_bounces: Option<u32>,
    /// Path tracer: no indirect sample contributes more than this radiance in any channel
    /// (Cycles' Clamping > Indirect Light, whose default is 10). Removes fireflies at the cost
    /// of bias (bright indirect light gets darker) [default: the scene's, else no clamp].
    #[arg(long, value_name = "RADIANCE")]
    pub(crate) clamp_indirect: Option<f32>,
    /// Path tracer: Cycles' Filter Glossy. After a diffuse or rough bounce, glossy and
    /// refractive surfaces are made rougher, the more so the less likely that bounce's
    /// direction was: caustics (a lamp reflected by a near-mirror or refracted by glass onto a
    /// rough surface) come out smooth instead of as fireflies, at the cost of bias (blurred
    /// caustics). 1 is Cycles' default; 0 filters nothing [default: the scene's, else 0].
    #[arg(long, value_name = "AMOUNT")]
    pub(crate) filter_glossy: Option<f32>,
    /// Path tracer: lamps much smaller on screen than their blur (and sub-pixel ones) are seen
    /// through the lens by tracing light from them to the lens, so their bokeh discs come out
    /// clean instead of speckled, and adaptive sites cannot miss them; lamps' (point and spot
    /// lights', emitters') highlights on polished surfaces out of focus are traced from the
    /// lamp too, and so are caustics: the light a polished surface (roughness up to 0.3)
    /// throws from a lamp or a sharp sun onto a rough one, which camera rays find as
    /// fireflies. Unbiased either way; `off` leaves them to camera rays alone (for
    /// comparisons) [default: the scene's, else on].
    #[arg(long, value_name = "on|off")]
    pub(crate) light_tracing: Option<Switch>,
    /// Path tracer, adaptive: a blurred site still noisy after its own samples also takes the
    /// samples of the sites around it whose apertures saw the same surface points (at a
    /// depth edge only the nearer surface's: what lies behind its rim stays with each site),
    /// combined by multiple importance sampling; of a glossy surface only the diffuse light
    /// is lent, its reflection stays with each site. It cuts noise
    /// where blurred matte or glossy surfaces carry it (walls behind a sharp subject,
    /// receding floors: 1 to 4 dB at the same samples) for 20-90% more time, less than the
    /// samples it saves; mirrors and glass gain nothing; its small bias is a self-normalised
    /// estimate's (thin lens of any aperture shape, box lens filter). It keeps the blurred sites'
    /// samples (up to 256 each) for a few rows of 64 px buckets: with little blur at high
    /// counts that is gigabytes (1920 px wide at 256 spp: about 6 GB), and a render that would
    /// outgrow the memory limit stops with exit 5 instead. `off` shows the sites' own
    /// samples alone and keeps none (for comparisons, for a shot whose blur is all mirrors
    /// and glass, or for less memory). In adaptive mode, with either integrator and any lens,
    /// the sites that no blur reaches also gather their neighbours' samples through the
    /// pixel filter (in-focus noise about 1.6 times lower; `off` stops that too) [default:
    /// the scene's, else on].
    #[arg(long, value_name = "on|off")]
    pub(crate) reuse: Option<Switch>,
    /// Adaptive mode with the seed's fixed rule instead of the error-controlled one: sample
    /// interval = max(2, k x CoC) in defocused regions, spp samples per defocused site (0.4 is
    /// the paper's; reproduces its table) [default: the scene's].
    #[arg(long, short = 'k')]
    pub(crate) interval_factor: Option<f32>,
    /// The seed's fixed rule (k = 0.4 unless -k is given), applied per pixel exactly as the
    /// paper does, without the conservative step that never interpolates across an in-focus
    /// edge.
    #[arg(long)]
    pub(crate) paper_exact: bool,
    /// Weighting of lens samples over the aperture (the filter over the CoC; box is a real
    /// lens's evenly bright bokeh).
    #[arg(long, value_enum, default_value_t = LensFilter::Box)]
    pub(crate) filter: LensFilter,
    /// Also write the depth map, interval map and samples map (samples traced per pixel,
    /// black = interpolated) as PNG pictures into this directory (created if missing).
    #[arg(long)]
    pub(crate) aov_dir: Option<PathBuf>,
    /// PNG output: 16 bits per channel instead of 8 (EXR is always float).
    #[arg(long)]
    pub(crate) png_16: bool,
    /// PNG output: the view transform, as Blender's colour management names it: standard
    /// (the sRGB curve, clipped), agx (Blender 4's default: highlights roll off instead of
    /// clipping), khronos-pbr-neutral, or raw (linear, for data). Matches a Blender PNG of
    /// the same image to the code value. EXR stays scene-linear. [default: the scene's
    /// [view], else standard]
    #[arg(long, value_name = "NAME", value_parser = parse_view)]
    pub(crate) view: Option<View>,
    /// PNG output: an AgX look (needs --view agx): very-high-contrast, high-contrast,
    /// medium-high-contrast, base-contrast, medium-low-contrast, low-contrast,
    /// very-low-contrast, greyscale, or none; Blender's names ("AgX - High Contrast") work too.
    #[arg(long, value_name = "NAME", value_parser = parse_look)]
    pub(crate) look: Option<Look>,
    /// PNG output: stops applied before the view, as Blender's view exposure (unlike
    /// --exposure, the EXR is not changed) [default: the scene's [view], else 0].
    #[arg(long, value_name = "STOPS", allow_negative_numbers = true)]
    pub(crate) view_exposure: Option<f32>,
    /// PNG output: display gamma applied after the view, as Blender's view gamma, in (0, 5]
    /// [default: the scene's [view], else 1].
    #[arg(long, value_name = "GAMMA")]
    pub(crate) view_gamma: Option<f32>,
    /// EXR output: the beauty (ViewLayer.Combined.R/G/B/A) as 16-bit half float, clamped to
    /// +-65504; depth (ViewLayer.Depth.Z) and dofray's passes (ViewLayer.CoC.X,
    /// ViewLayer.Interval.X, ViewLayer.Samples.X) stay 32-bit float. See docs/outputs.md.
    #[arg(long)]
    pub(crate) exr_half: bool,
    /// EXR output: pixel compression, one of none, rle, zip (deflate, 16 scan lines), zips
    /// (deflate, 1 line), piz (wavelet) - all lossless - or pxr24 (float channels to 24 bits),
    /// b44, b44a (half channels only), dwaa, dwab (lossy DCT on the colour) [default: zip].
    #[arg(long, value_name = "METHOD", value_parser = parse_exr_compression)]
    pub(crate) exr_compression: Option<output::ExrCompression>,
    /// Frames to render: a list of frames and ranges, e.g. 1-48, 1-240x2 (every other
    /// frame), 1,5,10..20 (Blender's ..) or -5--1. Each frame's camera and lens come from the
    /// scene's [animation] (docs/scene-format.md). Several frames need a frame pattern in -o:
    /// a run of # becomes the zero-padded frame number (shot_####.exr -> shot_0007.exr).
    /// Without --frames, -s/-e/-j, an -o with a pattern renders the scene's whole frame range,
    /// and one without renders its first frame.
    #[arg(long, short = 'f', value_name = "LIST", conflicts_with_all = ["frame_start", "frame_end", "frame_jump"])]
    pub(crate) frames: Option<String>,
    /// First frame of a range (Blender's -s) [default: the scene's frame_start].
    #[arg(long, short = 's', value_name = "N", allow_negative_numbers = true)]
    pub(crate) frame_start: Option<i64>,
    /// Last frame of a range (Blender's -e) [default: the scene's frame_end].
    #[arg(long, short = 'e', value_name = "N", allow_negative_numbers = true)]
    pub(crate) frame_end: Option<i64>,
    /// Frame step of a range (Blender's -j) [default: 1].
    #[arg(long, short = 'j', value_name = "N")]
    pub(crate) frame_jump: Option<i64>,
    /// Skip every frame (or tile) whose output file exists. Outputs are written to a
    /// temporary file and renamed, so a file that exists is complete: re-running a killed
    /// job with --skip-existing renders only what is missing.
    #[arg(long, conflicts_with = "no_overwrite")]
    pub(crate) skip_existing: bool,
    /// Refuse to replace an existing output: that frame fails (the others still render).
    #[arg(long)]
    pub(crate) no_overwrite: bool,
    /// Stop at the first frame that fails instead of going on to the others (a run with a
    /// failure exits non-zero either way).
    #[arg(long)]
    pub(crate) fail_fast: bool,
    /// Render only the pixels x0..x1, y0..y1 (x1, y1 excluded) of the image, bit for bit as the
    /// full render has them, into a tile file that records its place (EXR: as its data
    /// window); `dofray merge` assembles tiles. E.g. --region 0,0,320,240.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_region, conflicts_with = "tiles")]
    pub(crate) region: Option<Region>,
    /// Render the image as COLUMNSxROWS tiles (e.g. 4x4), each written as its own file next
    /// to -o (still.exr -> still.tile-000.exr, ...), then merged into -o and removed. With
    /// --skip-existing a killed run resumes from the tiles already written; on a farm
    /// (--shard or a scheduler's array) each worker renders its share of the tiles and
    /// `dofray merge` assembles them.
    #[arg(long, value_name = "COLSxROWS", value_parser = parse_grid)]
    pub(crate) tiles: Option<(u32, u32)>,
    /// Render only share I of N (0 <= I < N) of the frames, or of the tiles: jobs I, I + N,
    /// I + 2N, ... Without it, Slurm job arrays (SLURM_ARRAY_TASK_ID with
    /// SLURM_ARRAY_TASK_MIN/MAX/COUNT/STEP) and Kubernetes Indexed Jobs (JOB_COMPLETION_INDEX
    /// with DOFRAY_SHARD_COUNT set to the completions) choose it; docs/farm.md.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub(crate) shard: Option<Shard>,
    /// Print a JSON summary on stdout (for frames, tiles or shards: one object with an entry
    /// per job).
    #[arg(long)]
    pub(crate) json: bool,
    /// No progress bar and no summary line.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    /// Progress on stderr: auto (a bar on a terminal, else a line every 5 seconds and at each
    /// phase, as farm logs need; nothing with --json or --quiet), bar, plain, or none.
    #[arg(long, value_enum, default_value_t = super::ProgressMode::Auto)]
    pub(crate) progress: super::ProgressMode,
}

#[derive(Args)]
pub(crate) struct MergeArgs {
    /// The tile files (dofray render --region or --tiles), all EXR or all PNG.
    #[arg(required = true, num_args = 1..)]
    pub(crate) tiles: Vec<PathBuf>,
    /// The assembled image, in the tiles' format.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub(crate) json: bool,
    /// No summary line.
    #[arg(long, short)]
    pub(crate) quiet: bool,
}

#[derive(Args)]
pub(crate) struct BenchArgs {
    #[command(flatten)]
    pub(crate) scene: SceneArgs,
    /// Samples per sample site that blur reaches, in every mode [default: the scene's, else
    /// 16]. Not with --equal-error (its --ladder gives the sample counts).
    #[arg(long, conflicts_with = "equal_error")]
    pub(crate) spp: Option<u32>,
    /// Samples per in-focus sample site (and per pixel in pinhole mode), in every mode
    /// [default: the scene's, else spp with the path tracer, 4 with the direct integrator].
    /// With --equal-error: the same at every rung [default: the rung's spp times the scene's
    /// aa / spp (1 with the path tracer, 4 / 16 with the direct one), rounded, at least 1].
    #[arg(long)]
    pub(crate) aa: Option<u32>,
    /// How light is carried in every render and the reference: `path` (the physically based
    /// path tracer) or `direct` (the seed's quick shading, as in its table). Every other
    /// setting of the scene's [render] table (bounce limits, clamp, filters, exposure) applies
    /// too [default: the scene's, else path].
    #[arg(long, value_enum)]
    pub(crate) integrator: Option<dofray::render::Integrator>,
    /// Sample reuse in the adaptive renders (as `dofray render --reuse`; dense and the
    /// reference are the same either way, so one cached reference serves both) [default: the
    /// scene's, else on].
    #[arg(long, value_name = "on|off")]
    pub(crate) reuse: Option<Switch>,
    /// Timed repeats of each mode (or rung); medians are reported.
    #[arg(long, default_value_t = 3)]
    pub(crate) repeat: usize,
    /// Samples per pixel of the converged reference image (dense, in focus or not). With
    /// --equal-error it must exceed the ladder's largest rung (several times is better). It is
    /// rendered as two halves with independent seeds, whose difference tells how far its own
    /// noise lets a PSNR against it go (reported; raise this when PSNRs come near it).
    #[arg(long, default_value_t = 1024)]
    pub(crate) reference_spp: u32,
    /// Where the reference is cached between runs [default: $XDG_CACHE_HOME/dofray or
    /// ~/.cache/dofray].
    #[arg(long)]
    pub(crate) cache_dir: Option<PathBuf>,
    /// Write every image, the depth (figure 2) and interval (figure 3) maps, a side-by-side
    /// comparison and an error heat map into this directory; with --equal-error, the
    /// PSNR-versus-seconds plot equal-error.png and equal-time.png: the reference, dense and
    /// adaptive at about equal time, whole and the window where they err most enlarged.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Run the equal-error study instead of the seed's table: the time dense and adaptive
    /// need to reach each PSNR level of --levels over the spp rungs of --ladder.
    #[arg(long)]
    pub(crate) equal_error: bool,
    /// With --equal-error: the samples per defocused site of each rung, for both methods.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "SPP,...",
        requires = "equal_error",
        default_value = "4,8,16,32,64,128"
    )]
    pub(crate) ladder: Vec<u32>,
    /// With --equal-error: the PSNR levels in dB (sRGB, against the reference).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "DB,...",
        requires = "equal_error",
        default_value = "30,35,40"
    )]
    pub(crate) levels: Vec<f64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub(crate) json: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    /// Progress on stderr: auto (a bar on a terminal, else a line every 5 seconds and at each
    /// phase; nothing with --json or --quiet), bar, plain, or none.
    #[arg(long, value_enum, default_value_t = super::ProgressMode::Auto)]
    pub(crate) progress: super::ProgressMode,
}

pub(crate) fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = s.split_once(',').ok_or("expected X,Y (e.g. 320,240)")?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    Ok((parse(x)?, parse(y)?))
}

pub(crate) fn parse_region(s: &str) -> Result<Region, String> {
    s.parse()
        .map_err(|e: dofray::render::RegionError| e.to_string())
}

pub(crate) fn parse_grid(s: &str) -> Result<(u32, u32), String> {
    dofray::render::region::parse_grid(s).map_err(|e| e.to_string())
}

pub(crate) fn parse_shard(s: &str) -> Result<Shard, String> {
    Shard::parse(s).map_err(|e| e.to_string())
}

pub(crate) fn parse_exr_compression(s: &str) -> Result<output::ExrCompression, String> {
    s.parse()
        .map_err(|e: output::CompressionError| e.to_string())
}

pub(crate) fn parse_view(s: &str) -> Result<View, String> {
    s.parse().map_err(|e: ViewError| e.to_string())
}

pub(crate) fn parse_look(s: &str) -> Result<Look, String> {
    s.parse().map_err(|e: ViewError| e.to_string())
}

/// `spot:X,Y,Z:DX,DY,DZ[:INTENSITY[:OUTER[:INNER]]]`.
pub(crate) fn parse_spot(s: &str) -> Result<Light, String> {
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
        radius: 0.0,
    })
}

/// A finite number of a `--light` argument.
pub(crate) fn number(v: &str) -> Result<f32, String> {
    match v.trim().parse::<f32>() {
        Ok(n) if n.is_finite() => Ok(n),
        _ => Err(format!("{v:?} is not a finite number")),
    }
}

/// `X,Y,Z` of a `--light` argument.
pub(crate) fn xyz(v: &str) -> Result<Vec3, String> {
    let c: Vec<f32> = v.split(',').map(number).collect::<Result<_, _>>()?;
    match c[..] {
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("expected three coordinates X,Y,Z, got {v:?}")),
    }
}

pub(crate) fn parse_light(s: &str) -> Result<Light, String> {
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
                angle: 0.0,
            })
        }
        other => Err(format!(
            "unknown light kind {other:?}: expected point, sun or spot"
        )),
    }
}

/// An on/off flag value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Switch {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

impl Switch {
    /// The flag an optional switch sets: `None` when it was not given.
    pub(crate) fn flag(switch: Option<Self>) -> Option<bool> {
        switch.map(|s| s == Self::On)
    }
}
