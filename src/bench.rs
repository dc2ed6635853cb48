//! `dofray bench`: the seed's table reproduced in one run on one machine. Every mode is
//! timed (median of several repeats), its rays counted, and its image compared with dense
//! and with a converged reference; an intersect-only replay of exactly the rays dense traces
//! shows how much of dense's time is the renderer's own work.
//!
//! [`equal_error`] is the other study: the time dense and adaptive need to reach given PSNR
//! levels, over a ladder of sample counts, with a PSNR-versus-seconds plot ([`plot`]).

pub mod equal_error;
pub mod equal_time;
pub mod plot;

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::camera::Camera;
use crate::error_kind::{ErrorKind, HasKind};
use crate::metrics::{self, Space};
use crate::output::TempFile;
use crate::output::metadata::Fnv1a;
use crate::render::{self, Film, Mode, Progress, RenderSettings, RenderStats, SamplingRule};
use crate::scene::{SceneDesc, World};

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    /// Samples per site that blur reaches, for every mode.
    pub spp: u32,
    /// Samples per in-focus site in dense and adaptive mode (the pinhole row takes one per
    /// pixel: the seed's plain ray tracing).
    pub aa: u32,
    /// Repeats, reference and seed.
    pub measure: Measure,
}

impl Default for BenchConfig {
    fn default() -> Self {
        Self {
            spp: 16,
            aa: 4,
            measure: Measure::default(),
        }
    }
}

/// How both studies measure: what every render starts from, repeats, the converged
/// reference, the seed.
#[derive(Debug, Clone)]
pub struct Measure {
    /// The settings every render of the study starts from: the integrator and its path
    /// limits, the pixel and lens filters, exposure, transparency (usually the scene's, with
    /// the command line's flags). Each render sets its own mode, sample counts, sampling
    /// rule and seed; the rest is taken from here, for the reference too.
    pub base: RenderSettings,
    /// Timed repeats of each render; the median is reported.
    pub repeat: usize,
    /// Samples per pixel of the converged reference (dense, in focus or not).
    pub reference_spp: u32,
    /// Seed of every render's sample streams (the reference's seed is derived from it).
    pub seed: u64,
    /// Where the reference is cached (None: not cached).
    pub cache_dir: Option<PathBuf>,
}

impl Default for Measure {
    fn default() -> Self {
        Self {
            base: RenderSettings::default(),
            repeat: 3,
            reference_spp: 1024,
            seed: 0,
            cache_dir: None,
        }
    }
}

/// Why a benchmark (or the equal-error study) could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A render failed (bad settings, cancelled, non-finite pixels).
    #[error(transparent)]
    Render(#[from] render::RenderError),
    /// An image could not be compared with another (the metrics refused it).
    #[error(transparent)]
    Metrics(#[from] metrics::MetricsError),
    /// `repeat` is 0.
    #[error("repeat must be at least 1")]
    ZeroRepeat,
    /// The equal-error ladder is empty or has a sample count of 0 or above
    /// [`RenderSettings::MAX_SAMPLES`].
    #[error(
        "the spp ladder must list at least one sample count, each 1 to {max}, got {0:?}",
        max = RenderSettings::MAX_SAMPLES
    )]
    BadLadder(Vec<u32>),
    /// The equal-error PSNR levels are empty or one is not finite.
    #[error("PSNR levels must be at least one finite number of dB, got {0:?}")]
    BadLevels(Vec<f64>),
    /// The equal-error reference has no more samples per pixel than the ladder's top rung.
    #[error(
        "the reference's samples per pixel ({reference_spp}) must exceed the ladder's largest \
         rung ({top}); several times more is better"
    )]
    ReferenceBelowLadder {
        /// The reference's samples per pixel.
        reference_spp: u32,
        /// The ladder's largest sample count.
        top: u32,
    },
    /// The reference could not be written to its cache file.
    #[error("reference cache {}: {error}", path.display())]
    Cache {
        /// The cache file.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// The cache directory cannot be created or written: found before anything is rendered.
    #[error(
        "cannot use {} as the reference cache directory (--cache-dir): {source}; expected a \
         directory dofray can create and write",
        dir.display()
    )]
    CacheDir {
        /// The directory given.
        dir: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// One mode's measurements (the row of the seed's table).
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchRow {
    /// Short label and file stem, e.g. `adaptive-k0.4`.
    pub label: String,
    /// The render mode.
    pub mode: Mode,
    /// The seed rule's k ([`SamplingRule::Seed`]); `None` for pinhole, dense and adaptive with
    /// the error-controlled rule.
    pub interval_factor: Option<f32>,
    /// Whether the seed rule ran with the seed's plain per-pixel interval rule
    /// ([`SamplingRule::Seed`]'s `paper_exact`).
    pub paper_exact: bool,
    /// Median wall time of the repeats.
    pub seconds: f64,
    /// Where the time goes (medians, each included in `seconds`): the depth pass, the blur /
    /// interval / site maps, shading the sample sites, and interpolation.
    pub pinhole_seconds: f64,
    /// Median seconds building the blur, interval and site maps.
    pub maps_seconds: f64,
    /// Median seconds shading sample sites.
    pub sites_seconds: f64,
    /// Median seconds of `sites_seconds` lending samples between sites (sample reuse).
    pub reuse_seconds: f64,
    /// Median seconds interpolating between sites.
    pub interpolate_seconds: f64,
    /// Rays traced per render, of every kind (the same in every repeat).
    pub rays: u64,
    /// Camera rays per render.
    pub primary_rays: u64,
    /// Shadow rays per render.
    pub shadow_rays: u64,
    /// Mirror reflection rays per render.
    pub secondary_rays: u64,
    /// Millions of rays per second: `rays` over the median `seconds`.
    pub mrays_per_s: f64,
    /// Pixels shaded directly (the rest were interpolated).
    pub sample_sites: u64,
    /// seconds / pinhole seconds (the seed reports 1 : 11.5 : 2.5).
    pub time_vs_pinhole: f64,
    /// Dense's median seconds / this mode's (above 1: faster than dense).
    pub speedup_vs_dense: f64,
    /// sRGB PSNR (dB) against dense; null (infinite) for dense itself.
    pub psnr_vs_dense: f64,
    /// sRGB PSNR (dB) against the converged reference.
    pub psnr_vs_reference: f64,
    /// sRGB SSIM against the converged reference.
    pub ssim_vs_reference: f64,
    /// Linear-RGB PSNR (dB) against the converged reference.
    pub psnr_vs_reference_linear: f64,
    /// Linear-RGB SSIM against the converged reference.
    pub ssim_vs_reference_linear: f64,
    /// Largest per-pixel, per-channel sRGB error against the reference.
    pub max_error_vs_reference: f64,
}

/// The whole benchmark.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchReport {
    /// The scene's name.
    pub scene: String,
    /// How light was carried in every render (and the reference).
    pub integrator: crate::render::Integrator,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Samples per site that blur reaches ([`BenchConfig::spp`]).
    pub spp: u32,
    /// Samples per in-focus site in dense and adaptive mode ([`BenchConfig::aa`]).
    pub aa: u32,
    /// Timed repeats of each mode.
    pub repeat: usize,
    /// Threads of the rayon pool the renders ran on.
    pub threads: usize,
    /// Samples per pixel of the converged reference.
    pub reference_spp: u32,
    /// Whether the reference was read from the cache instead of rendered.
    pub reference_cached: bool,
    /// Time to render the reference (0 when it came from the cache).
    pub reference_seconds: f64,
    /// The sRGB PSNR a noise-free render would measure against the reference, from the
    /// reference's own noise (estimated from two independent halves of its samples): PSNRs
    /// near it measure the reference's noise as much as the render's. Null when unknown.
    pub reference_ceiling_db: Option<f64>,
    /// Rays per second of the intersect-only replay of exactly the rays dense traces.
    pub intersect_only_mrays_per_s: f64,
    /// Median seconds of the intersect-only replay.
    pub intersect_only_seconds: f64,
    /// Dense's rays/s as a fraction of the intersect-only rate: the median over repeats of the
    /// ratio within each repeat.
    pub dense_vs_intersect_only: f64,
    /// One row per mode of the seed's table, in the table's order.
    pub rows: Vec<BenchRow>,
}

/// The images behind the report, for `--out`.
pub struct BenchImages {
    /// Each mode's label (as [`BenchRow::label`]) and its image from the first repeat, in the
    /// table's order.
    pub films: Vec<(String, Film)>,
    /// The converged reference: linear RGB, row-major, top row first.
    pub reference: Vec<[f32; 3]>,
}

/// The modes of the seed's table, in order: a `None` interval factor in adaptive mode is the
/// error-controlled rule at its default tolerance.
fn modes() -> Vec<(String, Mode, Option<f32>, bool)> {
    vec![
        ("pinhole".into(), Mode::Pinhole, None, false),
        ("dense".into(), Mode::Dense, None, false),
        ("adaptive".into(), Mode::Adaptive, None, false),
        ("adaptive-k0.4".into(), Mode::Adaptive, Some(0.4), false),
        ("adaptive-k0.2".into(), Mode::Adaptive, Some(0.2), false),
        (
            "adaptive-paper-k0.4".into(),
            Mode::Adaptive,
            Some(0.4),
            true,
        ),
    ]
}

/// The median (the mean of the middle two for an even count); NaN for an empty list.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Bumped whenever the renderer's estimate of a pixel changes (sampling, filters, shading),
/// so that a cached reference from an older renderer is not reused.
const RENDERER_REVISION: u32 = 3;

/// The cache key of a reference: everything that changes its pixels.
pub fn reference_key(desc: &SceneDesc, camera: &Camera, settings: &RenderSettings) -> String {
    let mut h = Fnv1a::default();
    // Every setting: the integrator, its limits, filters and exposure change the pixels as
    // much as the sample counts do.
    let _ = write!(
        h,
        "{}.{RENDERER_REVISION}|{desc:?}|{camera:?}|{settings:?}",
        env!("CARGO_PKG_VERSION"),
    );
    // The name becomes part of a file name: keep it to characters every file system accepts.
    let name: String = desc
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!(
        "{name}-{}x{}-{:016x}",
        camera.width,
        camera.height,
        h.finish()
    )
}

const MAGIC: &[u8; 8] = b"DOFREF02";
/// Magic, width, height, and the ceiling (f64; infinite when unknown).
const HEADER: usize = 24;

/// The converged reference every render is judged against.
#[derive(Debug, Clone)]
pub(crate) struct Reference {
    /// Linear RGB, row-major, top row first.
    pub rgb: Vec<[f32; 3]>,
    /// Read from the cache instead of rendered.
    pub cached: bool,
    /// Time to render it (0 when cached).
    pub seconds: f64,
    /// The sRGB PSNR a noise-free render would measure against it: its own noise, estimated
    /// from two independent halves. `None` when unknown (1 spp, or halves alike).
    pub ceiling_db: Option<f64>,
}

fn read_reference(
    path: &Path,
    width: usize,
    height: usize,
) -> Option<(Vec<[f32; 3]>, Option<f64>)> {
    let bytes = std::fs::read(path).ok()?;
    if bytes.len() != HEADER + width * height * 12 || &bytes[..8] != MAGIC {
        return None;
    }
    let dim = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    if dim(8) != width || dim(12) != height {
        return None;
    }
    let ceiling = f64::from_le_bytes(bytes[16..24].try_into().unwrap());
    if ceiling.is_nan() {
        return None;
    }
    let floats: Vec<f32> = bytes[HEADER..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    if floats.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let rgb = floats.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Some((rgb, ceiling.is_finite().then_some(ceiling)))
}

fn write_reference(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[[f32; 3]],
    ceiling_db: Option<f64>,
) -> std::io::Result<()> {
    let mut bytes = Vec::with_capacity(HEADER + rgb.len() * 12);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(width as u32).to_le_bytes());
    bytes.extend_from_slice(&(height as u32).to_le_bytes());
    bytes.extend_from_slice(&ceiling_db.unwrap_or(f64::INFINITY).to_le_bytes());
    for v in rgb.iter().flatten() {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    // A registered temporary file: removed on error and by SIGINT / SIGTERM.
    let mut tmp = TempFile::create(path)?;
    tmp.file().write_all(&bytes)?;
    tmp.persist()
}

/// Creates the cache directory if needed and checks that a file can be created in it, so an
/// unusable `--cache-dir` fails before the reference is rendered, not after.
pub fn check_cache_dir(dir: &Path) -> Result<(), BenchError> {
    let err = |source| BenchError::CacheDir {
        dir: dir.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(err)?;
    // Created and removed again (on drop).
    TempFile::create(&dir.join("probe.ref")).map_err(err)?;
    Ok(())
}

/// The converged reference: dense with `reference_spp` samples per pixel and seeds of its own
/// (derived from `seed`, so its noise is independent of the renders it judges), from the cache
/// in `cache_dir` when possible (an unusable `cache_dir` fails here, before anything is
/// rendered).
///
/// It is rendered as two independent halves (`reference_spp / 2` samples and the rest, with
/// different seeds) and their weighted mean, which is a dense render at `reference_spp` like
/// any other. The halves' difference measures the reference's own noise: a reference that has
/// not converged (rare bright paths, caustics) caps every PSNR measured against it.
pub(crate) fn reference(
    desc: &SceneDesc,
    world: &World,
    camera: &Camera,
    measure: &Measure,
    progress: &dyn Progress,
) -> Result<Reference, BenchError> {
    let (reference_spp, seed) = (measure.reference_spp, measure.seed);
    let cache_dir = measure.cache_dir.as_deref();
    if let Some(dir) = cache_dir {
        check_cache_dir(dir)?;
    }
    // Every pixel converges: in-focus ones take as many samples as defocused ones.
    // Reuse is adaptive mode's alone: cleared, so one reference serves it on and off.
    let settings = |spp: u32, salt: u64| RenderSettings {
        mode: Mode::Dense,
        spp,
        aa: spp,
        rule: SamplingRule::ErrorControlled { tolerance: None },
        seed: crate::sampler::hash64(crate::sampler::hash64(seed ^ 0x5eed_5eed) ^ salt),
        record_rays: false,
        path: crate::settings::PathLimits {
            reuse: false,
            ..measure.base.path
        },
        ..measure.base.clone()
    };
    let (w, h) = (camera.width as usize, camera.height as usize);
    let key = reference_key(desc, camera, &settings(reference_spp, 0));
    let path = cache_dir.map(|dir| dir.join(format!("{key}.ref")));
    if let Some((rgb, ceiling_db)) = path.as_deref().and_then(|p| read_reference(p, w, h)) {
        return Ok(Reference {
            rgb,
            cached: true,
            seconds: 0.0,
            ceiling_db,
        });
    }
    let (a, b) = (reference_spp / 2, reference_spp - reference_spp / 2);
    let (rgb, ceiling_db, seconds) = if a == 0 {
        let (film, stats) = render::render(world, camera, &settings(b, 0), progress)?;
        (film.rgb(), None, stats.seconds)
    } else {
        let (first, s1) = render::render(world, camera, &settings(a, 0), progress)?;
        let (second, s2) = render::render(world, camera, &settings(b, 1), progress)?;
        let (first, second) = (first.rgb(), second.rgb());
        let (wa, wb) = (
            a as f32 / reference_spp as f32,
            b as f32 / reference_spp as f32,
        );
        let rgb = first
            .iter()
            .zip(&second)
            .map(|(p, q)| std::array::from_fn(|c| wa * p[c] + wb * q[c]))
            .collect();
        // The halves differ by noise of variance s^2 (1/a + 1/b) per pixel; the mean carries
        // s^2 / (a + b) of it, a fraction a b / (a + b)^2 of the difference's.
        let halves_db = metrics::psnr(&first, &second, w, h, Space::Srgb)?;
        let ab = f64::from(a) * f64::from(b);
        let ceiling = halves_db + 10.0 * (f64::from(reference_spp).powi(2) / ab).log10();
        (
            rgb,
            ceiling.is_finite().then_some(ceiling),
            s1.seconds + s2.seconds,
        )
    };
    if let Some(path) = path {
        write_reference(&path, w, h, &rgb, ceiling_db)
            .map_err(|error| BenchError::Cache { path, error })?;
    }
    Ok(Reference {
        rgb,
        cached: false,
        seconds,
        ceiling_db,
    })
}

/// Runs the benchmark. `desc` is only used for the reference cache key.
pub fn run(
    desc: &SceneDesc,
    world: &World,
    camera: &Camera,
    config: &BenchConfig,
    progress: &dyn Progress,
) -> Result<(BenchReport, BenchImages), BenchError> {
    if config.measure.repeat == 0 {
        return Err(BenchError::ZeroRepeat);
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    let reference = reference(desc, world, camera, &config.measure, progress)?;

    // Intersect-only: replay exactly the packets dense traces, without shading or sampling.
    let recording = RenderSettings {
        record_rays: true,
        ..row_settings(config, Mode::Dense, None, false)
    };
    let (_, recorded) = render::render(world, camera, &recording, progress)?;
    let log = recorded.ray_log.unwrap_or_default();

    // Interleave the modes and the replay within each repeat, so machine noise (these are
    // shared machines) spreads over all of them, and compare dense with the replay of the same
    // repeat.
    let modes = modes();
    // Per mode: the stats of every repeat, and the image of the first.
    let mut runs: Vec<Vec<RenderStats>> = vec![Vec::new(); modes.len()];
    let mut images: Vec<Option<Film>> = vec![None; modes.len()];
    let mut replay_times = Vec::new();
    let mut dense_vs_replay = Vec::new();
    let mut replayed = 0;
    for _ in 0..config.measure.repeat {
        for (i, (_, mode, k, exact)) in modes.iter().enumerate() {
            let settings = row_settings(config, *mode, *k, *exact);
            let (film, stats) = render::render(world, camera, &settings, progress)?;
            runs[i].push(stats);
            images[i].get_or_insert(film);
        }
        let start = Instant::now();
        replayed = render::replay(&world.scene, &log);
        let replay_seconds = start.elapsed().as_secs_f64();
        replay_times.push(replay_seconds);
        // Same rays, so the ratio of rates is the inverse ratio of times.
        let dense = runs[1].last().expect("dense ran this repeat");
        dense_vs_replay.push(replay_seconds / dense.seconds);
    }
    drop(log);
    let intersect_only_seconds = median(replay_times);
    let intersect_only_mrays_per_s = replayed as f64 / intersect_only_seconds / 1e6;

    let compare = Compare {
        reference: &reference.rgb,
        dense_rgb: images[1].as_ref().map(Film::rgb).unwrap_or_default(),
        size: (w, h),
        pinhole_seconds: median_of(&runs[0], |s| s.seconds),
        dense_seconds: median_of(&runs[1], |s| s.seconds),
    };
    let mut rows = Vec::new();
    let mut films = Vec::new();
    for (i, (label, mode, k, exact)) in modes.into_iter().enumerate() {
        let film = images[i].take().expect("every mode ran at least once");
        rows.push(compare.row((label.clone(), mode, k, exact), &runs[i], &film)?);
        films.push((label, film));
    }
    Ok((
        BenchReport {
            scene: desc.name.clone(),
            integrator: config.measure.base.integrator,
            width: w,
            height: h,
            spp: config.spp,
            aa: config.aa,
            repeat: config.measure.repeat,
            threads: rayon::current_num_threads(),
            reference_spp: config.measure.reference_spp,
            reference_cached: reference.cached,
            reference_seconds: reference.seconds,
            reference_ceiling_db: reference.ceiling_db,
            intersect_only_mrays_per_s,
            intersect_only_seconds,
            dense_vs_intersect_only: median(dense_vs_replay),
            rows,
        },
        BenchImages {
            films,
            reference: reference.rgb,
        },
    ))
}

/// The settings of one row of the table: `mode`, with the seed's rule at `k` (the error-controlled
/// rule without one).
fn row_settings(config: &BenchConfig, mode: Mode, k: Option<f32>, exact: bool) -> RenderSettings {
    RenderSettings {
        mode,
        spp: config.spp,
        // The seed's "plain ray tracing": one ray per pixel.
        aa: if mode == Mode::Pinhole { 1 } else { config.aa },
        rule: match k {
            Some(interval_factor) => SamplingRule::Seed {
                interval_factor,
                paper_exact: exact,
            },
            None => SamplingRule::ErrorControlled { tolerance: None },
        },
        seed: config.measure.seed,
        record_rays: false,
        ..config.measure.base.clone()
    }
}

/// The median over repeats of one figure of one mode's runs.
fn median_of(runs: &[RenderStats], figure: fn(&RenderStats) -> f64) -> f64 {
    median(runs.iter().map(figure).collect())
}

/// What every row of the table is compared with.
struct Compare<'a> {
    reference: &'a [[f32; 3]],
    dense_rgb: Vec<[f32; 3]>,
    size: (usize, usize),
    pinhole_seconds: f64,
    dense_seconds: f64,
}

impl Compare<'_> {
    /// The row of a mode (label, mode, k, paper-exact) from its repeats' stats and its image.
    fn row(
        &self,
        (label, mode, k, exact): (String, Mode, Option<f32>, bool),
        runs: &[RenderStats],
        film: &Film,
    ) -> Result<BenchRow, BenchError> {
        let (w, h) = self.size;
        let reference = self.reference;
        // Ray and site counts are the same in every repeat.
        let stats = &runs[0];
        let seconds = median_of(runs, |s| s.seconds);
        let rgb = film.rgb();
        let vs_ref = |space| metrics::psnr(&rgb, reference, w, h, space);
        let ssim_ref = |space| metrics::ssim(&rgb, reference, w, h, space);
        Ok(BenchRow {
            label,
            mode,
            interval_factor: k,
            paper_exact: exact,
            seconds,
            pinhole_seconds: median_of(runs, |s| s.pinhole_seconds),
            maps_seconds: median_of(runs, |s| s.maps_seconds),
            sites_seconds: median_of(runs, |s| s.sites_seconds),
            reuse_seconds: median_of(runs, |s| s.reuse_seconds),
            interpolate_seconds: median_of(runs, |s| s.interpolate_seconds),
            rays: stats.rays.total(),
            primary_rays: stats.rays.primary,
            shadow_rays: stats.rays.shadow,
            secondary_rays: stats.rays.secondary,
            mrays_per_s: stats.rays.total() as f64 / seconds / 1e6,
            sample_sites: stats.sample_sites,
            time_vs_pinhole: seconds / self.pinhole_seconds,
            speedup_vs_dense: self.dense_seconds / seconds,
            psnr_vs_dense: metrics::psnr(&rgb, &self.dense_rgb, w, h, Space::Srgb)?,
            psnr_vs_reference: vs_ref(Space::Srgb)?,
            ssim_vs_reference: ssim_ref(Space::Srgb)?,
            psnr_vs_reference_linear: vs_ref(Space::Linear)?,
            ssim_vs_reference_linear: ssim_ref(Space::Linear)?,
            max_error_vs_reference: metrics::max_abs_error(&rgb, reference, w, h, Space::Srgb)?,
        })
    }
}

impl HasKind for BenchError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Render(e) => e.kind(),
            Self::Metrics(e) => e.kind(),
            Self::Cache { .. } | Self::CacheDir { .. } => ErrorKind::Io,
            _ => ErrorKind::Usage,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_cache_round_trips_and_rejects_other_sizes() {
        let dir = tempfile::Builder::new()
            .prefix("dofray-bench-cache-")
            .tempdir()
            .unwrap();
        // In a directory that does not exist yet: writing the reference makes it.
        let path = dir.path().join("cache").join("x.ref");
        let rgb = vec![[0.25, 0.5, 1.0], [0.0, 2.0, 3.5]];
        write_reference(&path, 2, 1, &rgb, Some(41.5)).unwrap();
        assert_eq!(read_reference(&path, 2, 1), Some((rgb.clone(), Some(41.5))));
        assert_eq!(read_reference(&path, 1, 2), None);
        write_reference(&path, 2, 1, &rgb, None).unwrap();
        assert_eq!(read_reference(&path, 2, 1), Some((rgb, None)));
        std::fs::write(&path, b"DOFREF02garbage").unwrap();
        assert_eq!(read_reference(&path, 2, 1), None);
        dir.close().unwrap();
    }

    #[test]
    fn cache_dir_is_created_and_checked() {
        let scratch = tempfile::Builder::new()
            .prefix("dofray-bench-dir-")
            .tempdir()
            .unwrap();
        let base = scratch.path();
        let dir = base.join("a").join("b");
        check_cache_dir(&dir).unwrap();
        assert!(dir.is_dir());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "probe removed");
        // A directory under a regular file can never be created.
        let file = base.join("file");
        std::fs::write(&file, b"x").unwrap();
        let err = check_cache_dir(&file.join("cache")).unwrap_err();
        assert!(matches!(err, BenchError::CacheDir { .. }), "{err:?}");
        assert!(err.to_string().contains("file/cache"), "{err}");
        scratch.close().unwrap();
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(Vec::new()).is_nan());
    }
}
