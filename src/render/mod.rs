//! Render modes. All three share the same two primitives, "trace and shade a packet"
//! ([`trace::trace_and_shade`]) and "shade sample sites, each with its own number of samples of
//! pixel x lens" ([`site::SiteShader`]); they differ only in where the sites are and how many
//! samples each takes:
//!
//! - `pinhole`: every pixel is a site; `aa` samples of the pixel filter through the lens
//!   centre (no depth of field).
//! - `dense` (Cook's distributed ray tracing): every pixel is a site.
//! - `adaptive` (the seed's method): sites on power-of-two lattices whose spacing follows the
//!   CoC; the pixels between them are interpolated. By default an error estimate sets the
//!   spacing and each site's samples ([`refine`], [`SamplingRule::ErrorControlled`]);
//!   [`SamplingRule::Seed`] is the seed's fixed rule ([`maps::interval_map`], [`interpolate`]).
//!
//! Every mode starts with the depth pass: one ray per pixel through the pixel centre and the
//! lens centre, intersected only, for the depth and CoC maps. In dense and adaptive mode a site
//! that blur reaches (see [`maps::blurred`]) takes up to `spp` samples (exactly `spp` except
//! under the error-controlled rule, which stops converged sites early), any other site `aa`.
//! Each site keeps an [`estimate::Estimate`] (mean and uncertainty). Both are
//! full samples of pixel x lens, so the depth pass (which misses whatever is smaller than a
//! pixel) only moves effort: every site's expected value is the filtered, lens-integrated
//! radiance that dense converges to, and adaptive's one approximation is the interpolation.

pub mod allocation;
pub mod estimate;
pub mod film;
pub mod gather;
pub mod glossy_light;
pub mod interpolate;
pub mod light_choice;
pub mod light_trace;
pub mod maps;
pub mod path;
pub mod refine;
pub mod region;
pub mod reuse;
pub mod site;
pub mod trace;
pub mod unseen;

use std::time::Instant;

use rayon::prelude::*;

use crate::camera::Camera;
use crate::embree::{LANES, RayHint, RayPacket16};
use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::{MemoryError, try_collect, try_vec};
use crate::scene::World;
pub use crate::settings::{
    Integrator, Mode, PathLimits, RenderSettings, RulePatch, SamplingRule, SettingError,
    SettingsPatch, SiteRule, Strategy, UnknownMode,
};
use estimate::Estimate;
pub use film::Film;
pub use light_choice::LightTraced;
pub use region::{Region, RegionError};
pub use site::{SiteScratch, SiteShader};
pub use trace::{RayCounts, RayKind, RecordedPacket, Tally, replay};

/// Why a render could not start (or did not finish).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// [`Progress::cancelled`] returned true; no image was made. Its [`HasKind`] kind is
    /// `interrupted` (exit code 130, as SIGINT): the caller stopped it.
    #[error("the render was cancelled")]
    Cancelled,
    /// A setting is out of range ([`RenderSettings::validate`]).
    #[error(transparent)]
    Setting(#[from] SettingError),
    /// The region to render is empty or reaches beyond the image.
    #[error(transparent)]
    BadRegion(#[from] RegionError),
    /// A buffer of the render (the film, a map) could not be allocated.
    #[error(transparent)]
    Memory(#[from] MemoryError),
    /// The last line of defence: input checks should make this impossible.
    #[error(
        "the render produced {count} pixels that are not finite numbers (the first at x = {x}, \
         y = {y}); no image was written. Scene values beyond dofray's documented ranges cause this"
    )]
    NonFinite {
        /// How many pixels' colours are not finite.
        count: usize,
        /// Column of the first such pixel (in row-major order), in full-image coordinates.
        x: usize,
        /// Row of the first such pixel, in full-image coordinates.
        y: usize,
    },
}

/// What a render did and how long it took.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RenderStats {
    /// Wall-clock time of the whole render (depth pass to finished film), in seconds.
    pub seconds: f64,
    /// Time of the depth pass (one pinhole ray per pixel for the depth and CoC maps) alone
    /// (included in `seconds`).
    pub pinhole_seconds: f64,
    /// Time spent building the blur, interval and site maps (included in `seconds`).
    pub maps_seconds: f64,
    /// Time spent shading sample sites (included in `seconds`).
    pub sites_seconds: f64,
    /// Of `sites_seconds`, the time spent lending samples between sites (sample reuse,
    /// adaptive mode): that phase's wall-clock time times lending's share of its worker
    /// threads' time. 0 without reuse.
    pub reuse_seconds: f64,
    /// Time spent interpolating between sites (included in `seconds`).
    pub interpolate_seconds: f64,
    /// Time spent tracing light from small emitters to the lens (included in `seconds`).
    pub light_seconds: f64,
    /// Light paths traced from small emitters to the lens ([`light_trace`]): each one shadow
    /// ray, counted in `rays`.
    pub light_paths: u64,
    /// Rays traced, by kind (for a region render, the rays traced for it, the full-frame depth pass
    /// included).
    pub rays: RayCounts,
    /// Pixels shaded directly (the rest were interpolated).
    pub sample_sites: u64,
    /// Sites that blur reaches, which took `spp` samples (the others took `aa`).
    pub defocused_sites: u64,
    /// Sites whose value rests on their neighbours' lent samples as well as their own (sample
    /// reuse, adaptive mode; [`RenderSettings`]'s `path.reuse`).
    pub borrowing_sites: u64,
    /// Rounds of shading and checking of the error-controlled rule (0 for other rules).
    pub rounds: u32,
    /// Every packet traced, in a deterministic order, when `record_rays` was set.
    #[serde(skip)]
    pub ray_log: Option<Vec<RecordedPacket>>,
}

impl RenderStats {
    /// Millions of rays (of every kind) traced per second of [`RenderStats::seconds`]; 0 when no
    /// time was measured.
    pub fn mrays_per_s(&self) -> f64 {
        if self.seconds > 0.0 {
            self.rays.total() as f64 / self.seconds / 1e6
        } else {
            0.0
        }
    }
}

/// Receives progress, and may cancel the render; all methods may be called from several
/// threads.
///
/// ```rust
/// use std::sync::atomic::{AtomicU64, Ordering};
/// use dofray::render::{Progress, RenderError};
/// use dofray::renderer::{Renderer, RendererError};
///
/// /// Counts the work done, and stops the render after `budget` units of it.
/// struct Budget { done: AtomicU64, budget: u64 }
///
/// impl Progress for Budget {
///     fn start(&self, phase: &str, total: u64) {
///         eprintln!("{phase}: {total} units");
///     }
///     fn advance(&self, units: u64) {
///         self.done.fetch_add(units, Ordering::Relaxed);
///     }
///     fn cancelled(&self) -> bool {
///         self.done.load(Ordering::Relaxed) >= self.budget
///     }
/// }
///
/// let renderer = Renderer::new(dofray::scene::load("paper")?, &dofray::embree::Device::new()?)?;
/// let settings = renderer.settings(&Default::default())?;
/// let progress = Budget { done: AtomicU64::new(0), budget: 10 };
/// let result = renderer.render(&settings, &progress);
/// assert!(matches!(result, Err(RendererError::Render(RenderError::Cancelled))));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait Progress: Sync {
    /// A new phase with `total` units of work begins.
    fn start(&self, _phase: &str, _total: u64) {}
    /// `units` more units of the current phase's work are done.
    fn advance(&self, _units: u64) {}
    /// The render has finished (called once, at the end of a render that succeeded).
    fn finish(&self) {}
    /// Whether to stop: polled before every band of 4 rows of the depth pass, every row of
    /// pinhole, dense and the seed's rule, and every round of every bucket of the
    /// error-controlled rule. Once it returns true the render skips the work not yet started
    /// and returns [`RenderError::Cancelled`] (within about a row's or a round's time per
    /// thread). It should stay true once it has been. Default: never.
    fn cancelled(&self) -> bool {
        false
    }
}

/// Progress that goes nowhere.
pub struct NoProgress;
impl Progress for NoProgress {}

/// A cancellation token: [`CancelFlag::cancel`] it from any thread (a UI's stop button, a
/// signal handler) and a render given it (as its [`Progress`], or another progress wrapped with
/// [`CancelFlag::with`]) stops with [`RenderError::Cancelled`].
///
/// ```rust
/// use dofray::render::{CancelFlag, NoProgress, RenderError};
/// use dofray::renderer::{Renderer, RendererError};
///
/// let renderer = Renderer::new(dofray::scene::load("paper")?, &dofray::embree::Device::new()?)?;
/// let settings = renderer.settings(&Default::default())?;
/// let stop = CancelFlag::new();
/// let result = std::thread::scope(|s| {
///     let render = s.spawn(|| renderer.render(&settings, &stop.with(&NoProgress)));
///     stop.cancel(); // e.g. a UI's stop button
///     render.join().unwrap()
/// });
/// // Cancelled, unless the render won the race and finished first.
/// assert!(matches!(result, Err(RendererError::Render(RenderError::Cancelled)) | Ok(_)));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Default)]
pub struct CancelFlag(std::sync::atomic::AtomicBool);

impl CancelFlag {
    /// A flag that is not (yet) cancelled.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks every render polling this flag to stop.
    pub fn cancel(&self) {
        self.0.store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether [`CancelFlag::cancel`] has been called.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Clears the flag, for the next render.
    pub fn reset(&self) {
        self.0.store(false, std::sync::atomic::Ordering::Relaxed);
    }

    /// `progress`, also cancelled by this flag.
    pub fn with<'a>(&'a self, progress: &'a dyn Progress) -> Cancellable<'a> {
        Cancellable {
            progress,
            flag: self,
        }
    }
}

impl Progress for CancelFlag {
    fn cancelled(&self) -> bool {
        self.is_cancelled()
    }
}

/// A progress reporter with a [`CancelFlag`] ([`CancelFlag::with`]).
pub struct Cancellable<'a> {
    progress: &'a dyn Progress,
    flag: &'a CancelFlag,
}

impl Progress for Cancellable<'_> {
    fn start(&self, phase: &str, total: u64) {
        self.progress.start(phase, total);
    }
    fn advance(&self, units: u64) {
        self.progress.advance(units);
    }
    fn finish(&self) {
        self.progress.finish();
    }
    fn cancelled(&self) -> bool {
        self.flag.is_cancelled() || self.progress.cancelled()
    }
}

/// `Err(RenderError::Cancelled)` when `progress` asks to stop.
pub(crate) fn check_cancelled(progress: &dyn Progress) -> Result<(), RenderError> {
    if progress.cancelled() {
        Err(RenderError::Cancelled)
    } else {
        Ok(())
    }
}

/// Depth pass: one ray per pixel through the pixel centre and the lens centre, 16 pixels (a
/// 4 x 4 block) per packet, intersected only. Fills the film's depth and CoC, a band of 4 rows
/// per task, in place.
fn depth_pass(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    film: &mut Film,
    tally: &mut Tally,
    progress: &dyn Progress,
) -> Result<(), RenderError> {
    const BAND: usize = 4;
    let (w, h) = (film.width, film.height);
    progress.start("depth", h.div_ceil(BAND) as u64);
    let tallies: Vec<Tally> = film
        .depth
        .par_chunks_mut(BAND * w)
        .zip(film.coc.par_chunks_mut(BAND * w))
        .enumerate()
        .map(|(band, (depth, coc))| {
            let y_start = band * BAND;
            let rows = depth.len() / w;
            let mut packet = RayPacket16::new();
            let mut t_hit = [0.0f32; LANES];
            let mut local = Tally::new(settings.record_rays);
            if progress.cancelled() {
                return local;
            }
            for x_start in (0..w).step_by(4) {
                packet.clear();
                // Film index of each lane's pixel within the band.
                let mut lanes = [usize::MAX; LANES];
                for (lane, slot) in lanes.iter_mut().enumerate() {
                    let (x, y) = (x_start + lane % 4, lane / 4);
                    if x < w && y < rows {
                        let ray = camera.pinhole_ray(x as f32 + 0.5, (y_start + y) as f32 + 0.5);
                        packet.set(lane, &ray);
                        *slot = y * w + x;
                    }
                }
                trace::trace_depth(
                    world,
                    &mut packet,
                    RayKind::Primary,
                    RayHint::Coherent,
                    &mut t_hit,
                    &mut local,
                );
                for (lane, &p) in lanes.iter().enumerate() {
                    if p != usize::MAX {
                        depth[p] = if t_hit[lane].is_finite() {
                            camera.depth_along_axis(&packet.ray(lane), t_hit[lane])
                        } else {
                            f32::INFINITY
                        };
                    }
                }
            }
            // Each pixel's blur bound near its own film position (a real lens's differs
            // across the film).
            for (i, (c, &d)) in coc.iter_mut().zip(depth.iter()).enumerate() {
                let (x, y) = (i % w, y_start + i / w);
                *c = camera.coc_px_at(d, x as f32 + 0.5, y as f32 + 0.5);
            }
            progress.advance(1);
            local
        })
        .collect();
    for local in tallies {
        tally.merge(local);
    }
    check_cancelled(progress)
}

/// The blur the site rules decide from: the depth pass's, and what it cannot see.
fn blur_maps(shader: &SiteShader, film: &Film) -> Result<maps::Blur, MemoryError> {
    let settings = shader.settings;
    let unseen = if settings.mode == Mode::Pinhole {
        unseen::UnseenBlur::none(film.width, film.height)?
    } else {
        let margin = 0.5 * settings.pixel_filter.width;
        let (world, camera) = (shader.world, shader.camera);
        unseen::UnseenBlur::of(world, camera, &film.depth, margin, shader.light_traced)?
    };
    maps::Blur::with_unseen(&film.coc, film.width, film.height, &unseen)
}

/// Pinhole, dense, and adaptive with the seed's rule: fills `film.samples` (0 where the
/// pixel will be interpolated, or is not needed for `region`) and, for adaptive,
/// `film.interval`; returns the site mask when some pixels are interpolated.
fn fixed_sites(
    settings: &RenderSettings,
    film: &mut Film,
    blur: &maps::Blur,
    region: &Region,
) -> Result<Option<Vec<bool>>, MemoryError> {
    let (w, h) = (film.width, film.height);
    let per_site = |p: usize| {
        if settings.mode == Mode::Pinhole || !blur.blurred[p] {
            settings.aa
        } else {
            settings.spp
        }
    };
    // The pixels the region needs traced: its own, and the sites its pixels interpolate from.
    let mut need = try_vec(w * h, false, "the map of pixels to trace")?;
    let mut sites = None;
    if let (
        Mode::Adaptive,
        SamplingRule::Seed {
            interval_factor,
            paper_exact,
        },
    ) = (settings.mode, settings.rule)
    {
        // The seed's plain rule reads the depth pass alone, as the paper did.
        let coc = if paper_exact {
            &film.coc
        } else {
            &blur.sharpest
        };
        film.interval = maps::interval_map(
            coc,
            w,
            h,
            interval_factor,
            paper_exact,
            settings.max_interval,
        )?;
        let mask = maps::site_mask(&film.interval, w, h)?;
        for y in region.y0 as usize..region.y1 as usize {
            for x in region.x0 as usize..region.x1 as usize {
                let (x0, x1) = maps::cell(x, film.interval[y * w + x], w);
                let (y0, y1) = maps::cell(y, film.interval[y * w + x], h);
                for p in [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1] {
                    need[p] |= mask[p];
                }
                need[y * w + x] |= mask[y * w + x];
            }
        }
        sites = Some(mask);
    } else {
        for y in region.y0 as usize..region.y1 as usize {
            need[y * w + region.x0 as usize..y * w + region.x1 as usize].fill(true);
        }
    }
    for (p, samples) in film.samples.iter_mut().enumerate() {
        *samples = if need[p] { per_site(p) } else { 0 };
    }
    Ok(sites)
}

/// Renders `world` through `camera`. The result is bit-identical for any thread count.
///
/// The steps [`crate::renderer::Renderer`] takes for a scene, by hand:
///
/// ```rust
/// use dofray::render::{self, NoProgress, RenderSettings};
/// use dofray::scene::World;
///
/// let mut desc = dofray::scene::load("paper")?;
/// (desc.camera.width, desc.camera.height) = (64, 48);
/// let world = World::build(&desc, &dofray::embree::Device::new()?)?;
/// // Autofocus (a scene focused on a pixel) asks the world how far the pixel's surface is.
/// let forward = (desc.camera.look_at - desc.camera.eye).normalize();
/// let camera = desc.camera.build(|ray| {
///     let hit = world.scene.intersect1(ray)?;
///     Some((ray.at(hit.t) - ray.origin).dot(forward))
/// })?;
/// let settings = RenderSettings { spp: 32, ..Default::default() };
/// let (film, stats) = render::render(&world, &camera, &settings, &NoProgress)?;
/// assert_eq!(film.color.len(), 64 * 48);
/// assert!(stats.sample_sites <= 64 * 48);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats), RenderError> {
    let full = Region::full(camera.width, camera.height);
    render_region(world, camera, settings, &full, progress)
}

/// Renders the pixels of `region` only, bit for bit as [`render`] renders them: the film is
/// the region's size. The depth pass still covers the whole frame (one ray per pixel: the
/// maps every decision starts from), and sites outside the region are traced only where the
/// region's pixels interpolate from them. Statistics count the region's pixels and the rays
/// traced for it.
pub fn render_region(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    region: &Region,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats), RenderError> {
    settings.validate()?;
    region.check(camera.width, camera.height)?;
    let start = Instant::now();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut film = Film::try_new(w, h)?;
    let mut tally = Tally::new(settings.record_rays);
    depth_pass(world, camera, settings, &mut film, &mut tally, progress)?;
    let mut stats = RenderStats {
        pinhole_seconds: start.elapsed().as_secs_f64(),
        ..Default::default()
    };

    let phase = Instant::now();
    let pixel_filter = settings.pixel_filter.sampler();
    let light_traced = LightTraced::choose(world, camera, settings);
    let shader = SiteShader {
        world,
        camera,
        settings,
        pixel_filter: &pixel_filter,
        light_traced: &light_traced,
    };
    let blur = blur_maps(&shader, &film)?;
    // Choosing light-traced emitters and the blur maps count as maps.
    stats.maps_seconds = phase.elapsed().as_secs_f64();
    let phase = Instant::now();
    if let (Mode::Adaptive, Some(tolerance)) = (settings.mode, settings.tolerance()) {
        // Maps, sites and interpolation interleave in rounds: timed as shading.
        let refined = refine::refine(
            &shader,
            tolerance,
            (&blur, &film.depth),
            region,
            progress,
            &mut tally,
        )?;
        let lend_share = take_refined(refined, region, &mut film, &mut stats)?;
        stats.sites_seconds = phase.elapsed().as_secs_f64();
        stats.reuse_seconds = lend_share * stats.sites_seconds;
    } else {
        let sites = fixed_sites(settings, &mut film, &blur, region)?;
        stats.maps_seconds += phase.elapsed().as_secs_f64();
        shade_fixed(
            &shader,
            &mut film,
            sites.as_deref(),
            progress,
            &mut tally,
            &mut stats,
        )?;
    }
    let phase = Instant::now();
    light_trace::trace(
        &shader,
        &light_traced,
        region,
        progress,
        &mut tally,
        &mut film.color,
    )?;
    if let Some(glossy) = &light_traced.glossy {
        glossy.trace(&shader, region, progress, &mut tally, &mut film.color)?;
    }
    stats.light_paths = light_traced.paths();
    stats.light_seconds = phase.elapsed().as_secs_f64();
    let (mut film, blurred) = if *region == Region::full(camera.width, camera.height) {
        (film, blur.blurred)
    } else {
        let blurred = region.try_crop(&blur.blurred, w, "the region's blur map")?;
        (film.try_crop(region)?, blurred)
    };
    check_finite(&film, region)?;
    if !settings.transparent {
        // The background is part of the picture: every pixel is opaque.
        film.alpha.fill(1.0);
    }
    stats.sample_sites = film.samples.iter().filter(|&&n| n > 0).count() as u64;
    if settings.mode != Mode::Pinhole {
        stats.defocused_sites = (film.samples.iter().zip(&blurred))
            .filter(|&(&n, &b)| b && n > 0)
            .count() as u64;
    }
    progress.finish();
    stats.rays = tally.counts;
    stats.ray_log = tally.log;
    stats.seconds = start.elapsed().as_secs_f64();
    Ok((film, stats))
}

/// Shades the sites `fixed_sites` chose (every pixel with samples) and interpolates the
/// rest from them where `sites` marks some, timing each in `stats`.
fn shade_fixed(
    shader: &SiteShader,
    film: &mut Film,
    sites: Option<&[bool]>,
    progress: &dyn Progress,
    tally: &mut Tally,
    stats: &mut RenderStats,
) -> Result<(), RenderError> {
    let (w, h) = (film.width, film.height);
    let phase = Instant::now();
    progress.start(shader.settings.mode.name(), h as u64);
    let mut estimates = try_vec(w * h, Estimate::default(), "the pixels' estimates")?;
    let none = try_vec(w * h, 0, "the pixels' sample counts")?;
    shader.shade_rows(&none, &film.samples, &mut estimates, progress, tally)?;
    drop(none);
    let rgba = estimates.iter().map(|e| e.mean_rgba());
    let mut rgba = try_collect(rgba, "the pixels' colours")?;
    drop(estimates);
    stats.sites_seconds = phase.elapsed().as_secs_f64();
    let phase = Instant::now();
    if let Some(sites) = sites {
        interpolate::interpolate(&mut rgba, &film.interval, sites, w, h)?;
    }
    film.set_rgba(&rgba);
    stats.interpolate_seconds = phase.elapsed().as_secs_f64();
    Ok(())
}

/// The error-controlled rule's result into the film and the stats. Returns lending's share
/// of its work ([`refine::Refined::lend_share`]), for `reuse_seconds` once the phase's time
/// is known.
fn take_refined(
    refined: refine::Refined,
    region: &Region,
    film: &mut Film,
    stats: &mut RenderStats,
) -> Result<f64, MemoryError> {
    stats.rounds = refined.rounds;
    let lend_share = refined.lend_share();
    let w = film.width;
    let borrowed = region.try_crop(&refined.borrowed, w, "the region's borrowing sites")?;
    stats.borrowing_sites = borrowed.iter().filter(|&&b| b).count() as u64;
    film.set_rgba(&refined.color);
    film.interval = refined.interval;
    film.samples = refined.samples;
    Ok(lend_share)
}

/// [`RenderError::NonFinite`] when a pixel of `film` (the pixels of `region`) is not finite.
fn check_finite(film: &Film, region: &Region) -> Result<(), RenderError> {
    let bad = |c: &glam::Vec3| !c.is_finite();
    match film.color.iter().position(bad) {
        Some(first) => Err(RenderError::NonFinite {
            count: film.color.iter().filter(|c| bad(c)).count(),
            x: first % film.width + region.x0 as usize,
            y: first / film.width + region.y0 as usize,
        }),
        None => Ok(()),
    }
}

impl HasKind for RenderError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NonFinite { .. } => ErrorKind::Internal,
            // The caller stopped it, as SIGINT would.
            Self::Cancelled => ErrorKind::Interrupted(2),
            Self::Setting(e) => e.kind(),
            Self::BadRegion(e) => e.kind(),
            Self::Memory(e) => e.kind(),
        }
    }
}
