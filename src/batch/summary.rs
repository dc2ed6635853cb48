//! What a render and a run of jobs report, as the serde types of the `--json` summaries
//! (docs/json.md): [`JobSummary`] for one rendered image or tile, [`RunSummary`](super::RunSummary) for a run of
//! frames, tiles or shards. Serialised through [`serde_json::Value`], keys come out sorted.

use std::path::PathBuf;

use serde::Serialize;

use crate::camera::Camera;
use crate::filter::PixelFilterKind;
use crate::render::{Mode, RenderSettings, RenderStats, SamplingRule, SiteRule};

/// Which Embree ran a render and how (`embree` in a render's summary).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EmbreeSummary {
    /// Embree's version, `major.minor.patch`.
    pub version: String,
    /// The device configuration string given to Embree.
    pub config: String,
    /// The widest packet Embree traces natively here (16, 8, 4 or 1).
    pub native_packet_width: u32,
    /// The instruction-set family of that width ([`isa_family`]).
    pub isa: &'static str,
    /// Lanes per Embree call a 16-ray packet is traced with.
    pub lanes_per_call: u32,
}

impl EmbreeSummary {
    /// The device and packet tracing of `scene`.
    pub fn of(scene: &crate::embree::Scene) -> Self {
        let device = scene.device();
        Self {
            version: device.embree_version(),
            config: device.config().to_owned(),
            native_packet_width: device.native_packet_width(),
            isa: isa_family(device.native_packet_width()),
            lanes_per_call: scene.lanes_per_call(),
        }
    }
}

/// The instruction-set family behind a native packet width (Embree reports the width, not the
/// exact ISA: 8 lanes are AVX or AVX2).
pub fn isa_family(width: u32) -> &'static str {
    match width {
        16 => "AVX-512",
        8 => "AVX/AVX2",
        4 if cfg!(target_arch = "aarch64") => "NEON",
        4 => "SSE",
        _ => "scalar",
    }
}

/// An f32 as the f64 with the same shortest decimal form (0.4, not 0.4000000059604645).
fn json_f32(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::NAN)
}

/// One rendered image or tile: `dofray render --json`'s object (docs/json.md has each field).
#[derive(Debug, Clone, Serialize)]
#[allow(missing_docs)] // the fields are documented in docs/json.md, one row each
pub struct JobSummary {
    pub schema_version: u32,
    pub dofray_version: &'static str,
    pub git_commit: &'static str,
    pub scene: String,
    pub output: PathBuf,
    pub frame: Option<i64>,
    pub region: Option<String>,
    pub mode: &'static str,
    pub width: usize,
    pub height: usize,
    pub spp: u32,
    pub aa: u32,
    pub pixel_filter: PixelFilterKind,
    pub pixel_filter_width: f64,
    pub rule: SiteRule,
    pub tolerance: Option<f64>,
    pub interval_factor: Option<f64>,
    pub paper_exact: bool,
    pub transparent: bool,
    pub exposure: f64,
    pub rounds: u32,
    pub seed: u64,
    pub seconds: f64,
    pub pinhole_seconds: f64,
    pub maps_seconds: f64,
    pub sites_seconds: f64,
    pub reuse_seconds: f64,
    pub interpolate_seconds: f64,
    pub light_seconds: f64,
    pub light_paths: u64,
    pub rays: u64,
    pub primary_rays: u64,
    pub shadow_rays: u64,
    pub secondary_rays: u64,
    pub rays_by_bounce: Vec<u64>,
    pub shadow_rays_by_bounce: Vec<u64>,
    pub sample_sites: u64,
    pub defocused_sites: u64,
    pub borrowing_sites: u64,
    pub mrays_per_s: f64,
    pub aperture_radius: f64,
    pub focus_distance: f64,
    pub lens: Option<LensSummary>,
    pub threads: usize,
    pub process_threads: Option<usize>,
    pub embree: EmbreeSummary,
    pub warnings: Vec<String>,
    /// The render's statistics as measured (not in the JSON: their fields are above).
    #[serde(skip)]
    pub stats: RenderStats,
}

/// A real lens's own numbers, as focused for the render (`lens` in the JSON; null for a
/// thin lens).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LensSummary {
    /// The prescription's name (its file's first comment).
    pub name: String,
    /// Effective focal length at the focus distance, mm.
    pub focal_length_mm: f64,
    /// Working f-number (focal length over the entrance pupil's diameter).
    pub f_number: f64,
    /// Vertical field of view at the focus distance, degrees (it breathes with focus).
    pub vfov_deg: f64,
}

impl LensSummary {
    /// The summary of `camera`'s lens, if it is a real one.
    pub fn of(camera: &Camera) -> Option<Self> {
        match &camera.lens {
            crate::camera::CameraLens::Real(l) => Some(Self {
                name: l.name.clone(),
                focal_length_mm: json_f32(l.focal_length_mm),
                f_number: json_f32(l.f_number),
                vfov_deg: json_f32(2.0 * l.tan_half_vfov.atan().to_degrees()),
            }),
            _ => None,
        }
    }
}

/// What a [`JobSummary`] is made of besides the render's settings, camera and stats.
#[derive(Debug, Clone)]
pub struct JobFacts {
    /// The scene's name.
    pub scene: String,
    /// The file written.
    pub output: PathBuf,
    /// The frame rendered, if one of several.
    pub frame: Option<i64>,
    /// `x0,y0,x1,y1` of a render that is not the whole image.
    pub region: Option<String>,
    /// The film's size.
    pub size: (usize, usize),
    /// Render worker threads.
    pub threads: usize,
    /// The Embree that traced it.
    pub embree: EmbreeSummary,
    /// The scene's warnings.
    pub warnings: Vec<String>,
}

impl JobSummary {
    /// The summary of a render with `settings` through `camera` that measured `stats`.
    pub fn new(
        facts: JobFacts,
        settings: &RenderSettings,
        camera: &Camera,
        stats: RenderStats,
    ) -> Self {
        let (interval_factor, paper_exact) = match settings.rule {
            SamplingRule::Seed {
                interval_factor,
                paper_exact,
            } => (Some(json_f32(interval_factor)), paper_exact),
            SamplingRule::ErrorControlled { .. } => (None, false),
        };
        Self {
            schema_version: crate::error_kind::SCHEMA_VERSION,
            dofray_version: crate::VERSION,
            git_commit: crate::GIT_COMMIT,
            scene: facts.scene,
            output: facts.output,
            frame: facts.frame,
            region: facts.region,
            mode: settings.mode.name(),
            width: facts.size.0,
            height: facts.size.1,
            spp: settings.spp,
            aa: settings.aa,
            pixel_filter: settings.pixel_filter.kind,
            pixel_filter_width: json_f32(settings.pixel_filter.width),
            rule: settings.rule.site_rule(),
            tolerance: (settings.mode == Mode::Adaptive)
                .then(|| settings.tolerance().map(json_f32))
                .flatten(),
            interval_factor,
            paper_exact,
            transparent: settings.transparent,
            exposure: json_f32(settings.exposure),
            rounds: stats.rounds,
            seed: settings.seed,
            seconds: stats.seconds,
            pinhole_seconds: stats.pinhole_seconds,
            maps_seconds: stats.maps_seconds,
            sites_seconds: stats.sites_seconds,
            reuse_seconds: stats.reuse_seconds,
            interpolate_seconds: stats.interpolate_seconds,
            light_seconds: stats.light_seconds,
            light_paths: stats.light_paths,
            rays: stats.rays.total(),
            primary_rays: stats.rays.primary,
            shadow_rays: stats.rays.shadow,
            secondary_rays: stats.rays.secondary,
            rays_by_bounce: trimmed(&stats.rays.by_bounce),
            shadow_rays_by_bounce: trimmed(&stats.rays.shadow_by_bounce),
            sample_sites: stats.sample_sites,
            defocused_sites: stats.defocused_sites,
            borrowing_sites: stats.borrowing_sites,
            mrays_per_s: stats.mrays_per_s(),
            aperture_radius: json_f32(camera.aperture_radius()),
            focus_distance: json_f32(camera.focus_distance()),
            lens: LensSummary::of(camera),
            threads: facts.threads,
            process_threads: crate::limits::process_threads(),
            embree: facts.embree,
            warnings: facts.warnings,
            stats,
        }
    }
}

/// `counts` without its trailing zeros (bounces no ray reached).
fn trimmed(counts: &[u64]) -> Vec<u64> {
    let len = counts.iter().rposition(|&c| c > 0).map_or(0, |i| i + 1);
    counts[..len].to_vec()
}
