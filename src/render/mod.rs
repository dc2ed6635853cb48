//! Render modes. All three share the same two primitives, "trace and shade a packet"
//! ([`trace::trace_and_shade`]) and "shade one sample site" ([`shade_site`]); they differ only in
//! where the sample sites are:
//!
//! - `pinhole`: one ray per pixel through the lens centre. It yields the depth and CoC maps
//!   and is the first pass of the other two modes.
//! - `dense` (Cook's distributed ray tracing): every pixel is a site.
//! - `adaptive` (the seed's method): sites on power-of-two lattices whose spacing follows the
//!   CoC; the pixels between them are interpolated.
//!
//! A site whose pixel is reached by blur (see [`maps::blurred`]) traces `spp` lens samples
//! as 16-wide packets; other sites reuse their pinhole sample.

pub mod film;
pub mod interpolate;
pub mod maps;
pub mod trace;

use std::time::Instant;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::embree::{LANES, RayHint, RayPacket16};
use crate::sampler::{LensFilter, PixelSampler, aperture_points16};
use crate::scene::World;
pub use film::Film;
pub use trace::{RayCounts, RayKind, RecordedPacket, Tally, replay};

/// Where sample sites are placed.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    Pinhole,
    Dense,
    Adaptive,
}

impl Mode {
    pub fn name(self) -> &'static str {
        match self {
            Self::Pinhole => "pinhole",
            Self::Dense => "dense",
            Self::Adaptive => "adaptive",
        }
    }
}

/// How to render.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    pub mode: Mode,
    /// Lens samples per defocused sample site (16 fill one packet).
    pub spp: u32,
    /// The seed's k: sample interval = k x CoC in defocused regions.
    pub interval_factor: f32,
    /// Use the seed's plain per-pixel interval rule instead of the conservative one.
    pub paper_exact: bool,
    /// Largest interval (power of two).
    pub max_interval: u32,
    pub seed: u64,
    pub filter: LensFilter,
    /// Mirror bounces after the first hit.
    pub bounces: u32,
    /// Keep every traced packet in [`RenderStats::ray_log`] (for intersect-only benchmarks).
    pub record_rays: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            mode: Mode::Adaptive,
            spp: 16,
            interval_factor: 0.4,
            paper_exact: false,
            max_interval: 64,
            seed: 0,
            filter: LensFilter::Box,
            bounces: 1,
            record_rays: false,
        }
    }
}

/// Why a render could not start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    #[error("spp must be at least 1")]
    ZeroSpp,
    #[error("interval factor must be a finite number > 0, got {0}")]
    BadIntervalFactor(f32),
    #[error("max interval must be a power of two >= 1, got {0}")]
    BadMaxInterval(u32),
}

impl RenderSettings {
    pub fn validate(&self) -> Result<(), RenderError> {
        if self.spp == 0 {
            return Err(RenderError::ZeroSpp);
        }
        if !(self.interval_factor.is_finite() && self.interval_factor > 0.0) {
            return Err(RenderError::BadIntervalFactor(self.interval_factor));
        }
        if !self.max_interval.is_power_of_two() {
            return Err(RenderError::BadMaxInterval(self.max_interval));
        }
        Ok(())
    }
}

/// What a render did and how long it took.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RenderStats {
    pub seconds: f64,
    /// Time of the pinhole pass alone (included in `seconds`).
    pub pinhole_seconds: f64,
    /// Time spent building the blur, interval and site maps (included in `seconds`).
    pub maps_seconds: f64,
    /// Time spent shading sample sites with lens samples (included in `seconds`).
    pub sites_seconds: f64,
    /// Time spent interpolating between sites (included in `seconds`).
    pub interpolate_seconds: f64,
    pub rays: RayCounts,
    /// Pixels shaded directly (the rest were interpolated).
    pub sample_sites: u64,
    /// Sites that traced `spp` lens samples (the rest reused the pinhole sample).
    pub defocused_sites: u64,
    /// Every packet traced, in a deterministic order, when `record_rays` was set.
    #[serde(skip)]
    pub ray_log: Option<Vec<RecordedPacket>>,
}

impl RenderStats {
    pub fn mrays_per_s(&self) -> f64 {
        if self.seconds > 0.0 {
            self.rays.total() as f64 / self.seconds / 1e6
        } else {
            0.0
        }
    }
}

/// Receives progress; all methods may be called from several threads.
pub trait Progress: Sync {
    /// A new phase with `total` units of work begins.
    fn start(&self, _phase: &str, _total: u64) {}
    fn advance(&self, _units: u64) {}
    fn finish(&self) {}
}

/// Progress that goes nowhere.
pub struct NoProgress;
impl Progress for NoProgress {}

/// Pinhole pass: one ray per pixel through the lens centre, 16 pixels (a 4 x 4 block) per
/// packet. Fills the film's colour, depth and CoC, a band of 4 rows per task, in place.
fn pinhole_pass(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    film: &mut Film,
    tally: &mut Tally,
    progress: &dyn Progress,
) {
    const BAND: usize = 4;
    let (w, h) = (film.width, film.height);
    progress.start("pinhole", h.div_ceil(BAND) as u64);
    let tallies: Vec<Tally> = film
        .color
        .par_chunks_mut(BAND * w)
        .zip(film.depth.par_chunks_mut(BAND * w))
        .zip(film.coc.par_chunks_mut(BAND * w))
        .enumerate()
        .map(|(band, ((color, depth), coc))| {
            let y_start = band * BAND;
            let rows = color.len() / w;
            let mut packet = RayPacket16::new();
            let mut scratch = trace::Scratch::new();
            let mut radiance = [Vec3::ZERO; LANES];
            let mut t_hit = [0.0f32; LANES];
            let mut local = Tally::new(settings.record_rays);
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
                trace::trace_and_shade(
                    world,
                    &mut packet,
                    RayKind::Primary,
                    RayHint::Coherent,
                    &mut radiance,
                    &mut t_hit,
                    settings.bounces,
                    &mut scratch,
                    &mut local,
                );
                for (lane, &p) in lanes.iter().enumerate() {
                    if p != usize::MAX {
                        color[p] = radiance[lane];
                        depth[p] = if t_hit[lane].is_finite() {
                            camera.depth_along_axis(&packet.ray(lane), t_hit[lane])
                        } else {
                            f32::INFINITY
                        };
                    }
                }
            }
            for (c, &d) in coc.iter_mut().zip(depth.iter()) {
                *c = camera.coc_px(d);
            }
            progress.advance(1);
            local
        })
        .collect();
    for local in tallies {
        tally.merge(local);
    }
}

/// Per-thread scratch space for [`shade_site`]: a packet for the lens samples and
/// [`trace_and_shade`](trace::trace_and_shade)'s own.
#[derive(Default)]
pub struct SiteScratch {
    packet: RayPacket16,
    trace: trace::Scratch,
}

impl SiteScratch {
    pub fn new() -> Self {
        Self::default()
    }
}

/// Shades one sample site with `spp` lens samples traced as 16-wide packets, weighted by the
/// lens filter. Deterministic in (seed, pixel, sample index); `scratch` only saves building
/// packets per site (its contents on entry do not matter).
pub fn shade_site(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    (x, y): (usize, usize),
    scratch: &mut SiteScratch,
    tally: &mut Tally,
) -> Vec3 {
    let SiteScratch { packet, trace } = scratch;
    let sampler = PixelSampler::new(settings.seed, (y * camera.width as usize + x) as u64);
    let focus = camera.focus_point(x as f32 + 0.5, y as f32 + 0.5);
    let mut radiance = [Vec3::ZERO; LANES];
    let mut t_hit = [0.0f32; LANES];
    let mut origin = [[0.0f32; LANES]; 3];
    let mut dir = [[0.0f32; LANES]; 3];
    let mut sum = Vec3::ZERO;
    let mut weight_sum = 0.0f32;
    let mut index = 0;
    while index < settings.spp {
        let n = (settings.spp - index).min(LANES as u32) as usize;
        // All 16 lanes are computed (lanes past `n` are simply not traced).
        let (u, v) = sampler.get16(index);
        let (lens_x, lens_y) = aperture_points16(&u, &v, &camera.aperture);
        camera.lens_rays16(focus, &lens_x, &lens_y, &mut origin, &mut dir);
        packet.set_lanes(n, &origin, &dir);
        trace::trace_and_shade(
            world,
            packet,
            RayKind::Primary,
            RayHint::Coherent,
            &mut radiance,
            &mut t_hit,
            settings.bounces,
            trace,
            tally,
        );
        if settings.filter == LensFilter::Box {
            // Every weight is 1 (and c * 1 == c exactly).
            for c in &radiance[..n] {
                sum += *c;
                weight_sum += 1.0;
            }
        } else {
            for lane in 0..n {
                let lens = Vec2::new(lens_x[lane], lens_y[lane]);
                let w = settings.filter.weight(lens, camera.aperture.anamorphic);
                sum += radiance[lane] * w;
                weight_sum += w;
            }
        }
        index += n as u32;
    }
    sum / weight_sum
}

/// Renders `world` through `camera`. The result is bit-identical for any thread count.
pub fn render(
    world: &World,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Film, RenderStats), RenderError> {
    settings.validate()?;
    let start = Instant::now();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut film = Film::new(w, h);
    let mut tally = Tally::new(settings.record_rays);
    pinhole_pass(world, camera, settings, &mut film, &mut tally, progress);
    let pinhole_seconds = start.elapsed().as_secs_f64();
    let mut stats = RenderStats {
        pinhole_seconds,
        ..Default::default()
    };

    if settings.mode == Mode::Pinhole {
        film.samples.fill(1);
        stats.sample_sites = (w * h) as u64;
    } else {
        let phase = Instant::now();
        let blurred = maps::blurred(&film.coc, w, h);
        film.interval = match settings.mode {
            Mode::Adaptive => maps::interval_map(
                &film.coc,
                w,
                h,
                settings.interval_factor,
                settings.paper_exact,
                settings.max_interval,
            ),
            _ => vec![1; w * h],
        };
        let sites = maps::site_mask(&film.interval, w, h);
        stats.maps_seconds = phase.elapsed().as_secs_f64();
        let phase = Instant::now();
        progress.start(settings.mode.name(), h as u64);
        // Rows are shaded in place (each row's colour starts as its pinhole colour); their
        // tallies are merged in row order, so the ray log does not depend on scheduling.
        let tallies: Vec<Tally> = film
            .color
            .par_chunks_mut(w)
            .zip(film.samples.par_chunks_mut(w))
            .enumerate()
            .map(|(y, (color, samples))| {
                let mut local = Tally::new(settings.record_rays);
                let mut scratch = SiteScratch::new();
                for x in 0..w {
                    let p = y * w + x;
                    if !sites[p] {
                        continue;
                    }
                    if blurred[p] {
                        color[x] =
                            shade_site(world, camera, settings, (x, y), &mut scratch, &mut local);
                        samples[x] = settings.spp;
                    } else {
                        samples[x] = 1;
                    }
                }
                progress.advance(1);
                local
            })
            .collect();
        for local in tallies {
            tally.merge(local);
        }
        stats.sites_seconds = phase.elapsed().as_secs_f64();
        let phase = Instant::now();
        interpolate::interpolate(&mut film.color, &film.interval, &sites, w, h);
        stats.interpolate_seconds = phase.elapsed().as_secs_f64();
        stats.sample_sites = sites.iter().filter(|&&s| s).count() as u64;
        stats.defocused_sites = film.samples.iter().filter(|&&s| s > 1).count() as u64;
    }
    progress.finish();
    stats.rays = tally.counts;
    stats.ray_log = tally.log;
    stats.seconds = start.elapsed().as_secs_f64();
    Ok((film, stats))
}
