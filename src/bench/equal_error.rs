//! The equal-error study (`dofray bench --equal-error`): how long dense and adaptive take to
//! reach given PSNR levels against the converged reference.
//!
//! Each method renders a ladder of sample counts (rungs). Every rung is timed (median of the
//! repeats) and its image (from the first repeat) is compared with the reference in sRGB. The
//! time a method needs for a level is interpolated between the two rungs that bracket it,
//! linearly in PSNR against log seconds; see [`time_to_reach`]. Adaptive runs with the
//! error-controlled rule at its default tolerance, so whatever that rule does, the study
//! measures it: nothing here depends on how adaptive places its sites.

use std::path::PathBuf;

use super::equal_time::{EqualTime, Picture, choose_rungs, hardest_window};
use super::{BenchError, Measure, median, reference};
use crate::camera::Camera;
use crate::metrics::{self, Space};
use crate::render::{self, Mode, Progress, RenderSettings, RenderStats, SamplingRule};
use crate::scene::{SceneDesc, World};

/// The rungs when none are given: samples per defocused site.
pub const DEFAULT_LADDER: [u32; 6] = [4, 8, 16, 32, 64, 128];
/// The PSNR levels (dB, sRGB) when none are given.
pub const DEFAULT_LEVELS: [f64; 3] = [30.0, 35.0, 40.0];
/// The edges of the blur bands each rung's error is split by ([`Rung::error_by_blur`]): the
/// depth pass's CoC diameter, pixels.
pub const BLUR_BANDS: [f32; 5] = [1.0, 4.0, 8.0, 16.0, 32.0];

/// The anti-aliasing samples (per in-focus site) of each rung.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RungAa {
    /// The same number at every rung.
    Fixed(u32),
    /// This fraction of the rung's spp, rounded, at least 1 (the defaults' 4 : 16 is 0.25),
    /// so in-focus pixels converge along with defocused ones.
    Ratio(f64),
}

impl RungAa {
    /// The aa of the rung with `spp` samples per defocused site.
    pub fn at(self, spp: u32) -> u32 {
        match self {
            Self::Fixed(n) => n,
            Self::Ratio(r) => (spp as f64 * r)
                .round()
                .clamp(1.0, RenderSettings::MAX_SAMPLES as f64)
                as u32,
        }
    }
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct EqualErrorConfig {
    /// Samples per defocused site of each rung, for both methods (sorted and deduplicated
    /// before use).
    pub ladder: Vec<u32>,
    /// PSNR levels in dB (sRGB, against the reference).
    pub levels: Vec<f64>,
    /// How each rung's anti-aliasing samples (per in-focus site) are chosen.
    pub aa: RungAa,
    /// Repeats (of each rung), reference and seed.
    pub measure: Measure,
}

impl Default for EqualErrorConfig {
    fn default() -> Self {
        Self {
            ladder: DEFAULT_LADDER.to_vec(),
            levels: DEFAULT_LEVELS.to_vec(),
            aa: RungAa::Ratio(0.25),
            measure: Measure::default(),
        }
    }
}

/// The two methods compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Dense mode: every pixel a site (Cook's distributed ray tracing).
    Dense,
    /// Adaptive mode with the error-controlled rule at its default tolerance.
    Adaptive,
}

impl Method {
    /// The method's lowercase name (`"dense"`, `"adaptive"`), as in the report's JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dense => "dense",
            Self::Adaptive => "adaptive",
        }
    }

    /// The render settings of this method at one rung: `base` with this method's mode and
    /// rule and the rung's sample counts and seed.
    pub fn settings(self, base: &RenderSettings, spp: u32, aa: u32, seed: u64) -> RenderSettings {
        RenderSettings {
            mode: match self {
                Self::Dense => Mode::Dense,
                Self::Adaptive => Mode::Adaptive,
            },
            spp,
            aa,
            rule: SamplingRule::ErrorControlled { tolerance: None },
            seed,
            record_rays: false,
            ..base.clone()
        }
    }
}

/// One rung of one method.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Rung {
    /// Samples per site that blur reaches (the ladder's value).
    pub spp: u32,
    /// Samples per in-focus site.
    pub aa: u32,
    /// Adaptive: the tolerance in effect (8-bit sRGB code values); dense: null.
    pub tolerance: Option<f32>,
    /// Median wall time of the repeats.
    pub seconds: f64,
    /// Median of the repeats' time lending samples between sites (sample reuse; included in
    /// `seconds`, 0 for dense): what reconstruction costs ([`RenderStats::reuse_seconds`]).
    ///
    /// [`RenderStats::reuse_seconds`]: crate::render::RenderStats::reuse_seconds
    pub reuse_seconds: f64,
    /// Rays traced per render, of every kind (the same in every repeat).
    pub rays: u64,
    /// Camera rays per render.
    pub primary_rays: u64,
    /// Pixels shaded directly (the rest were interpolated).
    pub sample_sites: u64,
    /// Samples of pixel x lens actually traced: the sum of the film's per-pixel counts.
    pub samples: u64,
    /// Light paths traced from small emitters to the lens (each one shadow ray, in `rays`).
    pub light_paths: u64,
    /// sRGB PSNR (dB) against the reference; null if identical to it.
    pub psnr_vs_reference: f64,
    /// Where its error is: the squared error against the reference by the blur of the
    /// surface each pixel's depth pass saw (bands of [`BLUR_BANDS`]).
    pub error_by_blur: Vec<metrics::BandError>,
}

/// Which side a reported time or speedup may err on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// Interpolated between two rungs that bracket the level.
    Exact,
    /// The true value is at most this.
    AtMost,
    /// The true value is at least this.
    AtLeast,
    /// Both times are upper bounds: the ratio can go either way.
    Unknown,
}

/// When one method first reaches a level.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Crossing {
    /// Seconds needed; null when no rung reaches the level.
    pub seconds: Option<f64>,
    /// The cheapest rung already reaches the level, so `seconds` (that rung's time) is an
    /// upper bound: fewer samples might do.
    pub at_first_rung: bool,
}

/// Both methods at one PSNR level.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Level {
    /// The level, in dB (sRGB, against the reference).
    pub psnr_db: f64,
    /// When dense reaches it.
    pub dense: Crossing,
    /// When adaptive reaches it.
    pub adaptive: Crossing,
    /// Dense seconds / adaptive seconds; null unless both reach the level.
    pub speedup: Option<f64>,
    /// `exact` when both times are interpolated; `at_most` / `at_least` when dense's /
    /// adaptive's time is its first rung's (an upper bound); `unknown` when both are.
    pub speedup_bound: Bound,
}

impl Level {
    fn new(psnr_db: f64, dense: &[Rung], adaptive: &[Rung]) -> Self {
        let (dense, adaptive) = (
            time_to_reach(&points(dense), psnr_db),
            time_to_reach(&points(adaptive), psnr_db),
        );
        let speedup = match (dense.seconds, adaptive.seconds) {
            (Some(d), Some(a)) if a > 0.0 => Some(d / a),
            _ => None,
        };
        let speedup_bound = match (dense.at_first_rung, adaptive.at_first_rung) {
            (false, false) => Bound::Exact,
            (true, false) => Bound::AtMost,
            (false, true) => Bound::AtLeast,
            (true, true) => Bound::Unknown,
        };
        Self {
            psnr_db,
            dense,
            adaptive,
            speedup,
            speedup_bound,
        }
    }
}

/// The whole study.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EqualErrorReport {
    /// The scene's name.
    pub scene: String,
    /// How light was carried in every render (and the reference).
    pub integrator: crate::render::Integrator,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Timed repeats of each rung.
    pub repeat: usize,
    /// Threads of the rayon pool the renders ran on.
    pub threads: usize,
    /// Seed of every render's sample streams.
    pub seed: u64,
    /// Samples per pixel of the converged reference.
    pub reference_spp: u32,
    /// Whether the reference was read from the cache instead of rendered.
    pub reference_cached: bool,
    /// Time to render the reference (0 when it came from the cache).
    pub reference_seconds: f64,
    /// The sRGB PSNR a noise-free render would measure against the reference (from its own
    /// noise, estimated from two independent halves of its samples): levels near it measure
    /// the reference's noise as much as the renders'. Null when unknown.
    pub reference_ceiling_db: Option<f64>,
    /// How each rung's aa was chosen.
    pub aa: RungAa,
    /// Dense's rungs, in ladder order (ascending spp).
    pub dense: Vec<Rung>,
    /// Adaptive's rungs, in ladder order (ascending spp).
    pub adaptive: Vec<Rung>,
    /// The requested levels, ascending.
    pub levels: Vec<Level>,
    /// The highest PSNR both methods reach on the ladder (the lower of their best rungs), and
    /// the time each needs for it; null when a method has no finite PSNR.
    pub highest_common: Option<Level>,
    /// Where the PSNR-versus-seconds plot was written, if it was.
    pub plot: Option<PathBuf>,
    /// The equal-time pair the side-by-side picture shows ([`super::equal_time`]).
    pub equal_time: Option<EqualTime>,
}

impl EqualErrorReport {
    /// The rungs of one method.
    pub fn rungs(&self, method: Method) -> &[Rung] {
        match method {
            Method::Dense => &self.dense,
            Method::Adaptive => &self.adaptive,
        }
    }
}

/// (seconds, PSNR) of each rung, in ladder order.
fn points(rungs: &[Rung]) -> Vec<(f64, f64)> {
    rungs
        .iter()
        .map(|r| (r.seconds, r.psnr_vs_reference))
        .collect()
}

/// The time at which a method first reaches `level` dB, from its rungs' (seconds, PSNR) in
/// ladder order (ascending samples).
///
/// The first rung at or above the level and the one before it bracket the crossing; between
/// them PSNR is taken as linear in log seconds. PSNR need not rise monotonically (noise): the
/// first crossing counts, as it would for someone raising the sample count until the level is
/// met. When the first rung already reaches the level its time is reported as an upper bound
/// (`at_first_rung`); when none does, `seconds` is None. A NaN PSNR never reaches a level; an
/// infinite one (an image identical to the reference) reaches every level at its own time.
pub fn time_to_reach(points: &[(f64, f64)], level: f64) -> Crossing {
    let Some(i) = points.iter().position(|&(_, psnr)| psnr >= level) else {
        return Crossing {
            seconds: None,
            at_first_rung: false,
        };
    };
    let (s1, p1) = points[i];
    if i == 0 {
        return Crossing {
            seconds: Some(s1),
            at_first_rung: true,
        };
    }
    let (s0, p0) = points[i - 1];
    // p0 < level <= p1 here (or p0 is NaN).
    let seconds = if !p1.is_finite() || !p0.is_finite() || p1 == p0 {
        s1
    } else {
        // Log-time interpolation; a non-positive time (a clock that did not move) is taken as
        // the smallest positive one.
        let (l0, l1) = (
            s0.max(f64::MIN_POSITIVE).ln(),
            s1.max(f64::MIN_POSITIVE).ln(),
        );
        let f = (level - p0) / (p1 - p0);
        (l0 + f * (l1 - l0)).exp()
    };
    Crossing {
        seconds: Some(seconds),
        at_first_rung: false,
    }
}

/// The highest level both methods reach: the lower of their best finite PSNRs.
pub fn highest_common_level(dense: &[Rung], adaptive: &[Rung]) -> Option<f64> {
    let best = |rungs: &[Rung]| {
        rungs
            .iter()
            .map(|r| r.psnr_vs_reference)
            .filter(|p| p.is_finite())
            .reduce(f64::max)
    };
    Some(best(dense)?.min(best(adaptive)?))
}

/// Builds the level rows and the highest common level from measured rungs (ladder order).
pub fn levels(levels: &[f64], dense: &[Rung], adaptive: &[Rung]) -> (Vec<Level>, Option<Level>) {
    let rows = levels
        .iter()
        .map(|&l| Level::new(l, dense, adaptive))
        .collect();
    let common = highest_common_level(dense, adaptive).map(|l| Level::new(l, dense, adaptive));
    (rows, common)
}

/// The ladder sorted and deduplicated, after checking it.
fn checked_ladder(ladder: &[u32]) -> Result<Vec<u32>, BenchError> {
    if ladder.is_empty()
        || ladder
            .iter()
            .any(|&n| n == 0 || n > RenderSettings::MAX_SAMPLES)
    {
        return Err(BenchError::BadLadder(ladder.to_vec()));
    }
    let mut sorted = ladder.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    Ok(sorted)
}

/// The levels sorted and deduplicated, after checking them.
fn checked_levels(levels: &[f64]) -> Result<Vec<f64>, BenchError> {
    if levels.is_empty() || levels.iter().any(|l| !l.is_finite()) {
        return Err(BenchError::BadLevels(levels.to_vec()));
    }
    let mut sorted = levels.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup();
    Ok(sorted)
}

/// Runs the study. `desc` is only used for the reference cache key.
pub fn run(
    desc: &SceneDesc,
    world: &World,
    camera: &Camera,
    config: &EqualErrorConfig,
    progress: &dyn Progress,
) -> Result<EqualErrorReport, BenchError> {
    let (ladder, level_list) = checked_config(config)?;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let reference = reference(desc, world, camera, &config.measure, progress)?;

    let methods = [Method::Dense, Method::Adaptive];
    // Per method and rung: the stats of every repeat, and from the first repeat the PSNR, the
    // samples traced and the image as 8-bit sRGB (for the equal-time picture).
    let mut runs: Vec<Vec<Vec<RenderStats>>> = vec![vec![Vec::new(); ladder.len()]; 2];
    let mut quality: Vec<Vec<(f64, u64, Vec<metrics::BandError>)>> = vec![Vec::new(); 2];
    let mut pictures: Vec<Vec<Picture>> = vec![Vec::new(); 2];
    // Repeats outermost, so machine noise (these are shared machines) spreads over every rung.
    for repeat in 0..config.measure.repeat {
        for (r, &spp) in ladder.iter().enumerate() {
            for (m, method) in methods.iter().enumerate() {
                let settings = method.settings(
                    &config.measure.base,
                    spp,
                    config.aa.at(spp),
                    config.measure.seed,
                );
                let (film, stats) = render::render(world, camera, &settings, progress)?;
                if repeat == 0 {
                    let rgb = film.rgb();
                    let psnr = metrics::psnr(&rgb, &reference.rgb, w, h, Space::Srgb)?;
                    let samples = film.samples.iter().map(|&n| n as u64).sum();
                    let bands = (&film.coc[..], &BLUR_BANDS[..]);
                    let by_blur =
                        metrics::error_by_band(&rgb, &reference.rgb, (w, h), Space::Srgb, bands)?;
                    quality[m].push((psnr, samples, by_blur));
                    pictures[m].push(srgb8(film.color.iter().map(|&c| c.to_array())));
                }
                runs[m][r].push(stats);
            }
        }
    }
    let rungs = |m: usize| -> Vec<Rung> {
        ladder
            .iter()
            .enumerate()
            .map(|(r, &spp)| {
                let stats = &runs[m][r];
                let (psnr, samples, ref by_blur) = quality[m][r];
                Rung {
                    spp,
                    aa: config.aa.at(spp),
                    tolerance: (methods[m] == Method::Adaptive)
                        .then(|| RenderSettings::default_tolerance(spp)),
                    seconds: median(stats.iter().map(|s| s.seconds).collect()),
                    reuse_seconds: median(stats.iter().map(|s| s.reuse_seconds).collect()),
                    // Ray, site and sample counts are the same in every repeat.
                    rays: stats[0].rays.total(),
                    primary_rays: stats[0].rays.primary,
                    sample_sites: stats[0].sample_sites,
                    samples,
                    light_paths: stats[0].light_paths,
                    psnr_vs_reference: psnr,
                    error_by_blur: by_blur.clone(),
                }
            })
            .collect()
    };
    let (dense, adaptive) = (rungs(0), rungs(1));
    let (levels, highest_common) = levels(&level_list, &dense, &adaptive);
    let equal_time = equal_time_pair(
        &reference.rgb,
        &mut pictures,
        [&dense, &adaptive],
        highest_common.map(|l| l.psnr_db),
        (w, h),
    );
    Ok(EqualErrorReport {
        scene: desc.name.clone(),
        integrator: config.measure.base.integrator,
        width: w,
        height: h,
        repeat: config.measure.repeat,
        threads: rayon::current_num_threads(),
        seed: config.measure.seed,
        reference_spp: config.measure.reference_spp,
        reference_cached: reference.cached,
        reference_seconds: reference.seconds,
        reference_ceiling_db: reference.ceiling_db,
        aa: config.aa,
        dense,
        adaptive,
        levels,
        highest_common,
        plot: None,
        equal_time,
    })
}

/// The study's ladder and levels, sorted and checked with the rest of `config`.
fn checked_config(config: &EqualErrorConfig) -> Result<(Vec<u32>, Vec<f64>), BenchError> {
    if config.measure.repeat == 0 {
        return Err(BenchError::ZeroRepeat);
    }
    let ladder = checked_ladder(&config.ladder)?;
    let levels = checked_levels(&config.levels)?;
    let top = *ladder.last().expect("checked: not empty");
    if config.measure.reference_spp <= top {
        return Err(BenchError::ReferenceBelowLadder {
            reference_spp: config.measure.reference_spp,
            top,
        });
    }
    for &spp in &ladder {
        let m = &config.measure;
        let dense = Method::Dense.settings(&m.base, spp, config.aa.at(spp), m.seed);
        dense.validate().map_err(render::RenderError::from)?;
    }
    Ok((ladder, levels))
}

/// The pair the equal-time picture shows ([`choose_rungs`]) with its window and the
/// reference's and the pair's pictures, taken from `pictures` (per method, per rung).
fn equal_time_pair(
    reference: &[[f32; 3]],
    pictures: &mut [Vec<Picture>],
    [dense, adaptive]: [&[Rung]; 2],
    level: Option<f64>,
    (w, h): (usize, usize),
) -> Option<EqualTime> {
    let (d, a) = choose_rungs(&points(dense), &points(adaptive), level)?;
    let reference = srgb8(reference.iter().copied());
    let [dense_picture, adaptive_picture] =
        [(0, d), (1, a)].map(|(m, r)| std::mem::take(&mut pictures[m][r]));
    let crop = hardest_window(&reference, &dense_picture, &adaptive_picture, w, h);
    Some(EqualTime {
        dense_rung: d,
        adaptive_rung: a,
        crop,
        picture: None,
        pictures: Box::new([reference, dense_picture, adaptive_picture]),
    })
}

/// Linear RGB pixels as 8-bit sRGB bytes.
fn srgb8(pixels: impl Iterator<Item = [f32; 3]>) -> Picture {
    pixels.flat_map(|c| c.map(crate::output::srgb8)).collect()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    #[test]
    fn a_bracketed_level_is_interpolated_in_log_time() {
        // 30 dB at 1 s, 40 dB at 100 s: 35 dB is halfway in log time, 10 s.
        let pts = [(1.0, 30.0), (100.0, 40.0)];
        let c = time_to_reach(&pts, 35.0);
        assert!(close(c.seconds.unwrap(), 10.0), "{c:?}");
        assert!(!c.at_first_rung);
        // A quarter of the way up in PSNR is a quarter of the decades.
        let c = time_to_reach(&pts, 32.5);
        assert!(close(c.seconds.unwrap(), 10f64.powf(0.5)), "{c:?}");
    }

    #[test]
    fn exact_hits_take_the_rungs_time() {
        let pts = [(0.5, 28.0), (1.0, 31.0), (2.0, 35.0)];
        let c = time_to_reach(&pts, 31.0);
        assert!(close(c.seconds.unwrap(), 1.0), "{c:?}");
        assert!(!c.at_first_rung);
        let c = time_to_reach(&pts, 35.0);
        assert!(close(c.seconds.unwrap(), 2.0), "{c:?}");
    }

    #[test]
    fn levels_beyond_the_ladder_are_not_reached_and_below_it_are_bounds() {
        let pts = [(0.5, 28.0), (1.0, 31.0), (2.0, 35.0)];
        let c = time_to_reach(&pts, 35.01);
        assert_eq!(c.seconds, None);
        assert!(!c.at_first_rung);
        // Reached by the cheapest rung: its time, flagged as an upper bound.
        let c = time_to_reach(&pts, 25.0);
        assert_eq!(c.seconds, Some(0.5));
        assert!(c.at_first_rung);
        let c = time_to_reach(&pts, 28.0);
        assert_eq!(c.seconds, Some(0.5));
        assert!(c.at_first_rung);
        assert_eq!(time_to_reach(&[], 30.0).seconds, None);
    }

    #[test]
    fn non_monotone_psnr_counts_the_first_crossing() {
        // Noise: 32 dB at 2 s, then a dip to 31 at 4 s, then 36 at 8 s.
        let pts = [(1.0, 28.0), (2.0, 32.0), (4.0, 31.0), (8.0, 36.0)];
        // 30 dB: crossed between rung 0 and 1 (28 -> 32, halfway in PSNR: sqrt 2 seconds).
        let c = time_to_reach(&pts, 30.0);
        assert!(close(c.seconds.unwrap(), 2f64.sqrt()), "{c:?}");
        // 33.5 dB: first reached between the dip (31 at 4 s) and 36 at 8 s, halfway.
        let c = time_to_reach(&pts, 33.5);
        assert!(close(c.seconds.unwrap(), 32f64.sqrt()), "{c:?}");
        // 31.5 dB: the first rung at or above it is rung 1 (32 dB), bracketed by rung 0.
        let c = time_to_reach(&pts, 31.5);
        let expected = (2f64.ln() * 3.5 / 4.0).exp();
        assert!(close(c.seconds.unwrap(), expected), "{c:?}");
    }

    #[test]
    fn nan_never_reaches_and_infinity_reaches_at_its_rung() {
        let pts = [(1.0, f64::NAN), (2.0, 33.0)];
        let c = time_to_reach(&pts, 30.0);
        assert_eq!(c.seconds, Some(2.0));
        let pts = [(1.0, 29.0), (2.0, f64::INFINITY)];
        assert_eq!(time_to_reach(&pts, 60.0).seconds, Some(2.0));
    }

    /// A rung of made-up figures.
    pub(in crate::bench) fn rung(spp: u32, seconds: f64, psnr: f64) -> Rung {
        Rung {
            spp,
            aa: 1,
            tolerance: None,
            seconds,
            reuse_seconds: 0.0,
            rays: 0,
            primary_rays: 0,
            sample_sites: 0,
            samples: 0,
            light_paths: 0,
            psnr_vs_reference: psnr,
            error_by_blur: Vec::new(),
        }
    }

    #[test]
    fn levels_report_speedups_bounds_and_the_highest_common_level() {
        let dense = [rung(4, 1.0, 28.0), rung(8, 2.0, 31.0), rung(16, 4.0, 34.0)];
        let adaptive = [rung(4, 0.1, 31.0), rung(8, 0.2, 33.0), rung(16, 0.4, 36.0)];
        let (rows, common) = levels(&[30.0, 33.0, 35.0], &dense, &adaptive);
        // 30 dB: dense interpolated, adaptive at its first rung (an upper bound): the speedup
        // is at least the ratio.
        assert_eq!(rows[0].speedup_bound, Bound::AtLeast);
        assert!(rows[0].adaptive.at_first_rung);
        let d30 = (2f64.ln() * 2.0 / 3.0).exp();
        assert!(close(rows[0].dense.seconds.unwrap(), d30));
        assert!(close(rows[0].speedup.unwrap(), d30 / 0.1));
        // 33 dB: both interpolated (adaptive exactly at its 8-spp rung).
        assert_eq!(rows[1].speedup_bound, Bound::Exact);
        assert!(close(rows[1].adaptive.seconds.unwrap(), 0.2));
        // 35 dB: dense never gets there.
        assert_eq!(rows[2].dense.seconds, None);
        assert_eq!(rows[2].speedup, None);
        // Both reach 34 dB (dense's best): dense at its top rung.
        let common = common.unwrap();
        assert_eq!(common.psnr_db, 34.0);
        assert!(close(common.dense.seconds.unwrap(), 4.0));
        let a34 = (0.2f64.ln() + (0.4f64.ln() - 0.2f64.ln()) / 3.0).exp();
        assert!(close(common.adaptive.seconds.unwrap(), a34));
        assert!(close(common.speedup.unwrap(), 4.0 / a34));
        assert_eq!(highest_common_level(&dense, &[]), None);
    }

    /// A 64x48 study of made-up rungs at the PSNR `levels`.
    pub(in crate::bench) fn report(
        dense: Vec<Rung>,
        adaptive: Vec<Rung>,
        levels: &[f64],
    ) -> EqualErrorReport {
        let (levels, highest_common) = super::levels(levels, &dense, &adaptive);
        EqualErrorReport {
            scene: "hand-made".into(),
            integrator: crate::render::Integrator::Path,
            width: 64,
            height: 48,
            repeat: 1,
            threads: 1,
            seed: 0,
            reference_spp: 64,
            reference_cached: false,
            reference_seconds: 0.0,
            reference_ceiling_db: None,
            aa: RungAa::Ratio(0.25),
            dense,
            adaptive,
            levels,
            highest_common,
            plot: None,
            equal_time: None,
        }
    }

    #[test]
    fn the_json_has_the_documented_shape() {
        let dense = vec![rung(4, 1.0, 28.0), rung(8, 2.0, 31.0)];
        let adaptive = vec![rung(4, 0.1, 31.0), rung(8, 0.2, 33.0)];
        let report = report(dense, adaptive, &[30.0, 40.0]);
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["aa"], serde_json::json!({"ratio": 0.25}));
        assert_eq!(json["dense"][1]["spp"], 8);
        for key in [
            "spp",
            "aa",
            "tolerance",
            "seconds",
            "rays",
            "primary_rays",
            "sample_sites",
            "samples",
            "light_paths",
            "psnr_vs_reference",
            "error_by_blur",
        ] {
            assert!(json["adaptive"][0].get(key).is_some(), "{key} missing");
        }
        let level = &json["levels"][0];
        assert_eq!(level["psnr_db"], 30.0);
        assert_eq!(level["adaptive"]["at_first_rung"], true);
        assert_eq!(level["speedup_bound"], "at_least");
        // 40 dB is beyond both ladders: nulls.
        assert!(json["levels"][1]["dense"]["seconds"].is_null());
        assert!(json["levels"][1]["speedup"].is_null());
        assert_eq!(json["highest_common"]["psnr_db"], 31.0);
        assert!(json["plot"].is_null());
    }

    #[test]
    fn ladders_and_levels_are_checked_sorted_and_deduplicated() {
        assert_eq!(checked_ladder(&[16, 4, 8, 4]).unwrap(), [4, 8, 16]);
        assert!(checked_ladder(&[]).is_err());
        assert!(checked_ladder(&[0, 4]).is_err());
        assert!(checked_ladder(&[RenderSettings::MAX_SAMPLES + 1]).is_err());
        assert_eq!(checked_levels(&[40.0, 30.0]).unwrap(), [30.0, 40.0]);
        assert!(checked_levels(&[f64::NAN]).is_err());
        assert!(checked_levels(&[]).is_err());
    }

    #[test]
    fn rung_aa_scales_or_stays_fixed() {
        assert_eq!(RungAa::Ratio(0.25).at(16), 4);
        assert_eq!(RungAa::Ratio(0.25).at(2), 1);
        assert_eq!(RungAa::Ratio(0.25).at(6), 2);
        assert_eq!(RungAa::Fixed(4).at(128), 4);
    }
}
