//! How to render: [`RenderSettings`] (typed: the sampling rule carries only the values it
//! reads) and [`SettingsPatch`], what a layer (scene file, flags, keywords) gives, resolved once
//! into settings by the one function that holds the defaults and the checks.

use crate::camera::LensFilter;
use crate::error_kind::{ErrorKind, HasKind};
use crate::filter::{PixelFilter, PixelFilterKind};
use crate::params::Param;

/// Where sample sites are placed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Every pixel a site, sampled through the lens centre: no depth of field.
    Pinhole,
    /// Every pixel a site, sampled over pixel x lens (Cook's distributed ray tracing): the
    /// reference the other modes are measured against.
    Dense,
    /// Sites only where needed, spaced by the CoC; the pixels between them interpolated.
    Adaptive,
}

impl Mode {
    /// Every mode, in the order the command line lists them.
    pub const ALL: [Mode; 3] = [Mode::Pinhole, Mode::Dense, Mode::Adaptive];

    /// The mode's lowercase name, as the command line and JSON spell it (`"pinhole"`, `"dense"`,
    /// `"adaptive"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Pinhole => "pinhole",
            Self::Dense => "dense",
            Self::Adaptive => "adaptive",
        }
    }
}

/// How light is carried from the lights to the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Paths with next-event estimation and multiple importance sampling: every light kind,
    /// soft shadows, indirect light, glass. Agrees with Cycles.
    #[default]
    Path,
    /// The seed's shading, for quick previews and the seed's table: direct light from point,
    /// spot and sun lights with hard shadows, a normalised Blinn-Phong highlight, the scene's
    /// `ambient` as unshadowed ambient light, and `bounces` mirror reflections.
    Direct,
}

impl Integrator {
    /// The integrator's lowercase name (`"path"`, `"direct"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Path => "path",
            Self::Direct => "direct",
        }
    }

    /// The integrator of [`Integrator::name`] `name` (for bindings and configuration).
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Path, Self::Direct]
            .into_iter()
            .find(|i| i.name() == name)
    }
}

/// Which estimator the path tracer weighs light with: both strategies by multiple importance
/// sampling (the default), or one alone (for tests and for seeing what each contributes; the
/// image is the same in expectation, only the noise differs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Strategy {
    /// Light samples and BSDF samples, weighted by the power heuristic.
    #[default]
    Mis,
    /// Light samples only (emitters found by BSDF samples count only when no light sample
    /// could have found them).
    LightOnly,
    /// BSDF samples only (punctual lights, which no BSDF sample can find, are still sampled).
    BsdfOnly,
}

/// How long the path tracer's paths may grow (Cycles' "Light Paths" panel, with its defaults),
/// and the optional clamp on indirect light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathLimits {
    /// Most bounces of any kind (Cycles' "Total"; default 12).
    pub total: u32,
    /// Most diffuse bounces (default 4).
    pub diffuse: u32,
    /// Most glossy bounces (default 4).
    pub glossy: u32,
    /// Most transmission bounces (default 12).
    pub transmission: u32,
    /// Largest value any colour component of an indirect sample may contribute;
    /// `f32::INFINITY` (the default) clamps nothing, so the image is unbiased. Cycles' default is
    /// 10: clamping trades fireflies for energy lost where light is bright and indirect.
    pub clamp_indirect: f32,
    /// Cycles' Filter Glossy: after a bounce whose direction was unlikely (a diffuse or rough
    /// glossy one), glossy and refractive lobes are made rougher, to GGX alpha
    /// `sqrt(1 - min_pdf / filter_glossy) / 2` where `min_pdf` is the smallest solid-angle
    /// density the path's scattered directions had. Caustics (light a near-mirror reflects
    /// or glass refracts onto a rough surface, which camera paths find only by luck) come out
    /// smooth instead of as fireflies, at the cost of bias: they are blurred. 0 (the default)
    /// filters nothing, so the image is unbiased; Cycles' default is 1.
    pub filter_glossy: f32,
    /// How light samples and BSDF samples are weighed.
    pub strategy: Strategy,
    /// Whether emitters much smaller on screen than their blur (and sub-pixel ones) are seen
    /// through the lens by light tracing, from the light's side (default), instead of by the
    /// camera's rays alone: a clean bokeh disc where camera samples find the lamp by luck
    /// ([`crate::render::light_trace`]); and whether lamps' highlights (point and spot
    /// lights', emissive triangles' and spheres') on glossy surfaces out of focus are also
    /// traced from the lamp into the lens
    /// ([`crate::render::glossy_light`]). Either way the image is unbiased; only the noise
    /// differs.
    pub light_tracing: bool,
    /// Whether adaptive sites lend their lens samples to the sites around them that see the
    /// same surface points ([`crate::render::reuse`]; the error-controlled rule, a thin lens
    /// of any aperture shape and the box lens filter only): a blurred site still noisy after
    /// its samples takes its neighbours' too, which cuts noise where blurred matte or glossy
    /// surfaces carry it (1 to 4 dB at the same samples) for 20-90% more time; mirrors and
    /// glass gain nothing. On by default: at equal error it is faster on every blurred scene
    /// measured (README, "Sample reuse"); off gives the images of the sites' own samples
    /// alone. It also lets in-focus sites gather their neighbours' samples through the pixel
    /// filter (any integrator; [`crate::render::gather`]).
    pub reuse: bool,
}

impl Default for PathLimits {
    fn default() -> Self {
        Self {
            total: 12,
            diffuse: 4,
            glossy: 4,
            transmission: 12,
            clamp_indirect: f32::INFINITY,
            filter_glossy: 0.0,
            strategy: Strategy::Mis,
            light_tracing: true,
            reuse: true,
        }
    }
}

/// A name that is not a [`Mode`]'s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("mode must be \"pinhole\", \"dense\" or \"adaptive\", got {0:?}")]
pub struct UnknownMode(pub String);

/// Parses a mode's [`Mode::name`] (for bindings and configuration files).
///
/// ```rust
/// use dofray::render::Mode;
///
/// assert_eq!("dense".parse::<Mode>(), Ok(Mode::Dense));
/// assert!("fast".parse::<Mode>().unwrap_err().to_string().contains("\"fast\""));
/// ```
impl std::str::FromStr for Mode {
    type Err = UnknownMode;

    fn from_str(name: &str) -> Result<Self, UnknownMode> {
        Mode::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| UnknownMode(name.to_string()))
    }
}

/// How adaptive mode decides where sample sites go and how many samples each takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SiteRule {
    /// From an error estimate: intervals and sample counts are refined until interpolation
    /// and sampling error are within the tolerance (see [`crate::render::refine`]).
    #[default]
    Error,
    /// The seed's fixed rule: interval = max(2, k x CoC) in power-of-two layers, `spp` samples
    /// per defocused site (for reproducing the paper's table).
    Seed,
}

impl SiteRule {
    /// The rule's name as JSON and image metadata spell it (`"error"`, `"seed"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Error => "error",
            Self::Seed => "seed",
        }
    }
}

/// How adaptive mode places sample sites and sets their sample counts, with the values that
/// rule reads (and no others).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SamplingRule {
    /// From an error estimate ([`SiteRule::Error`]).
    ErrorControlled {
        /// The largest error accepted where pixels are interpolated or a site stops sampling
        /// early, in 8-bit sRGB code values (1 = one step of 255). `None`:
        /// [`RenderSettings::default_tolerance`] for `spp`.
        tolerance: Option<f32>,
    },
    /// The seed's fixed rule ([`SiteRule::Seed`]).
    Seed {
        /// The seed's k: sample interval = k x CoC in defocused regions.
        interval_factor: f32,
        /// The seed's plain per-pixel interval rule instead of the conservative one.
        paper_exact: bool,
    },
}

impl SamplingRule {
    /// Which rule it is.
    pub fn site_rule(&self) -> SiteRule {
        match self {
            Self::ErrorControlled { .. } => SiteRule::Error,
            Self::Seed { .. } => SiteRule::Seed,
        }
    }
}

/// How to render. Make one with [`SettingsPatch::resolve`] (which checks it), or change the
/// [`Default`] (the resolved empty patch) and [`RenderSettings::validate`] it.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    /// Where sample sites are placed.
    pub mode: Mode,
    /// Samples (of pixel x lens) per sample site that blur reaches (16 fill one packet).
    pub spp: u32,
    /// Samples per in-focus site, and per pixel in pinhole mode: the anti-aliasing samples.
    pub aa: u32,
    /// The pixel (reconstruction) filter the samples' film positions are drawn from.
    pub pixel_filter: PixelFilter,
    /// How adaptive mode places sample sites and sets their sample counts.
    pub rule: SamplingRule,
    /// Largest interval (power of two).
    pub max_interval: u32,
    /// Seed of every pixel's sample stream: renders with the same seed (and everything else the
    /// same) are bit-identical; another seed gives another, equally valid, noise pattern.
    pub seed: u64,
    /// How lens samples are weighted when a site's samples are averaged (the bokeh's profile).
    pub filter: LensFilter,
    /// How light is carried: paths (the default) or the seed's direct shading.
    pub integrator: Integrator,
    /// The path tracer's bounce limits and clamp.
    pub path: PathLimits,
    /// Mirror bounces after the first hit (the direct integrator).
    pub bounces: u32,
    /// Keep every traced packet in [`crate::render::RenderStats::ray_log`] (for intersect-only
    /// benchmarks).
    pub record_rays: bool,
    /// Leave the background out of the image (Blender's "Film > Transparent"): camera rays
    /// that miss contribute black, so [`crate::render::Film::color`] is premultiplied by
    /// [`crate::render::Film::alpha`], the coverage, and the render composites over a plate. Otherwise
    /// alpha is 1 everywhere.
    pub transparent: bool,
    /// Exposure in stops: every sample's radiance is scaled by 2^exposure before it is
    /// averaged, so the error-controlled rule's tolerance is measured in the exposed image's
    /// code values (as a camera's exposure would be). 0 leaves radiance as it is.
    pub exposure: f32,
}

/// The settings of the empty [`SettingsPatch`]: adaptive mode with the error-controlled rule,
/// 16 spp, 4 aa.
impl Default for RenderSettings {
    fn default() -> Self {
        SettingsPatch::default()
            .resolve()
            .expect("the defaults are valid")
    }
}

impl RenderSettings {
    /// The most samples per site `spp` and `aa` accept (2^16: far beyond convergence for
    /// any image, few enough that a typo cannot start a render of days).
    pub const MAX_SAMPLES: u32 = 1 << 16;
    /// The largest exposure, in stops either way.
    pub const MAX_EXPOSURE: f32 = 64.0;
    /// The most bounces any path limit allows (Cycles allows 1024).
    pub const MAX_BOUNCES: u32 = 1024;

    /// The tolerance when none is given: 4 / sqrt(spp) code values (1 at 16 spp), so the
    /// accepted error shrinks with the noise a site has at `spp` samples.
    pub fn default_tolerance(spp: u32) -> f32 {
        4.0 / (spp.max(1) as f32).sqrt()
    }

    /// The error-controlled rule's tolerance in effect; `None` under the seed's rule.
    pub fn tolerance(&self) -> Option<f32> {
        match self.rule {
            SamplingRule::ErrorControlled { tolerance } => {
                Some(tolerance.unwrap_or_else(|| Self::default_tolerance(self.spp)))
            }
            SamplingRule::Seed { .. } => None,
        }
    }

    /// Checks every setting's range, without rendering: `Err` names the first bad one (the
    /// check [`SettingsPatch::resolve`] ends with, and [`crate::render::render`] starts with).
    pub fn validate(&self) -> Result<(), SettingError> {
        let samples = |param, value| {
            if value == 0 || value > Self::MAX_SAMPLES {
                Err(SettingError::Samples { param, value })
            } else {
                Ok(())
            }
        };
        samples(Param::Spp, self.spp)?;
        samples(Param::Aa, self.aa)?;
        if !self.pixel_filter.is_valid() {
            return Err(SettingError::PixelFilterWidth(self.pixel_filter.width));
        }
        match self.rule {
            SamplingRule::Seed {
                interval_factor: k, ..
            } if !(k.is_finite() && k > 0.0) => return Err(SettingError::IntervalFactor(k)),
            SamplingRule::ErrorControlled { tolerance: Some(t) } if !(t.is_finite() && t > 0.0) => {
                return Err(SettingError::Tolerance(t));
            }
            _ => {}
        }
        if !self.max_interval.is_power_of_two() {
            return Err(SettingError::MaxInterval(self.max_interval));
        }
        if !self.exposure.is_finite() || self.exposure.abs() > Self::MAX_EXPOSURE {
            return Err(SettingError::Exposure(self.exposure));
        }
        let p = &self.path;
        for (param, value) in [
            (Param::MaxBounces, p.total),
            (Param::DiffuseBounces, p.diffuse),
            (Param::GlossyBounces, p.glossy),
            (Param::TransmissionBounces, p.transmission),
        ] {
            if value > Self::MAX_BOUNCES {
                return Err(SettingError::Bounces { param, value });
            }
        }
        if p.clamp_indirect.is_nan() || p.clamp_indirect <= 0.0 {
            return Err(SettingError::ClampIndirect(p.clamp_indirect));
        }
        if !(p.filter_glossy.is_finite() && p.filter_glossy >= 0.0) {
            return Err(SettingError::FilterGlossy(p.filter_glossy));
        }
        Ok(())
    }
}

/// A render setting out of range. `Display` names the [`Param`] by its field;
/// [`SettingError::message`] names it any other way (the command line: its flag).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettingError {
    /// `spp` or `aa` is 0 or above [`RenderSettings::MAX_SAMPLES`].
    #[error("{}", self.message(Param::field))]
    Samples {
        /// [`Param::Spp`] or [`Param::Aa`].
        param: Param,
        /// The value given.
        value: u32,
    },
    /// The pixel filter's width (in pixels) is not a finite number in
    /// (0, [`PixelFilter::MAX_WIDTH`]].
    #[error("{}", self.message(Param::field))]
    PixelFilterWidth(f32),
    /// The tolerance is not a finite number > 0.
    #[error("{}", self.message(Param::field))]
    Tolerance(f32),
    /// The interval factor is not a finite number > 0.
    #[error("{}", self.message(Param::field))]
    IntervalFactor(f32),
    /// The largest interval is not a power of two.
    #[error("{}", self.message(Param::field))]
    MaxInterval(u32),
    /// The exposure is not finite or beyond +-[`RenderSettings::MAX_EXPOSURE`] stops.
    #[error("{}", self.message(Param::field))]
    Exposure(f32),
    /// A bounce limit is beyond [`RenderSettings::MAX_BOUNCES`].
    #[error("{}", self.message(Param::field))]
    Bounces {
        /// Which limit.
        param: Param,
        /// The value given.
        value: u32,
    },
    /// The indirect clamp is not a number > 0.
    #[error("{}", self.message(Param::field))]
    ClampIndirect(f32),
    /// The glossy filter is not a finite number >= 0.
    #[error("{}", self.message(Param::field))]
    FilterGlossy(f32),
}

impl SettingError {
    /// The setting at fault.
    pub fn param(&self) -> Param {
        match *self {
            Self::Samples { param, .. } => param,
            Self::PixelFilterWidth(_) => Param::PixelFilterWidth,
            Self::Tolerance(_) => Param::Tolerance,
            Self::IntervalFactor(_) => Param::IntervalFactor,
            Self::MaxInterval(_) => Param::MaxInterval,
            Self::Exposure(_) => Param::Exposure,
            Self::Bounces { param, .. } => param,
            Self::ClampIndirect(_) => Param::ClampIndirect,
            Self::FilterGlossy(_) => Param::FilterGlossy,
        }
    }

    /// The message with the setting called `name(param)`.
    pub fn message(&self, name: impl Fn(Param) -> &'static str) -> String {
        let name = name(self.param());
        match *self {
            Self::Samples { value, .. } => {
                format!(
                    "{name} must be 1 to {}, got {value}",
                    RenderSettings::MAX_SAMPLES
                )
            }
            Self::PixelFilterWidth(w) => format!(
                "{name} must be a number in (0, {}], got {w}",
                PixelFilter::MAX_WIDTH
            ),
            Self::Tolerance(t) => format!(
                "{name} must be a finite number > 0 (8-bit sRGB code values, e.g. 1), got {t}"
            ),
            Self::IntervalFactor(k) => format!("{name} must be a finite number > 0, got {k}"),
            Self::MaxInterval(n) => format!("{name} must be a power of two >= 1, got {n}"),
            Self::Exposure(e) => format!(
                "{name} must be a finite number of stops from -{max} to {max}, got {e}",
                max = RenderSettings::MAX_EXPOSURE
            ),
            Self::Bounces { value, .. } => format!(
                "{name} must be 0 to {}, got {value}",
                RenderSettings::MAX_BOUNCES
            ),
            Self::ClampIndirect(c) => {
                format!("{name} must be a number > 0 (radiance; inf for no clamp), got {c}")
            }
            Self::FilterGlossy(f) => {
                format!(
                    "{name} must be a finite number >= 0 (0: no filter; Cycles' default 1), got {f}"
                )
            }
        }
    }
}

/// The sampling rule a [`SettingsPatch`] asks for, with the values it gives (`None`: the
/// lower layer's, else the default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RulePatch {
    /// The error-controlled rule ([`SamplingRule::ErrorControlled`]).
    ErrorControlled {
        /// The tolerance, 8-bit sRGB code values.
        tolerance: Option<f32>,
    },
    /// The seed's fixed rule ([`SamplingRule::Seed`]).
    Seed {
        /// The interval factor k (default 0.4, the paper's).
        interval_factor: Option<f32>,
        /// Per pixel as the paper has it.
        paper_exact: bool,
    },
}

/// Render settings as a layer gives them (a scene file, the command line's flags, a binding's
/// keywords): `None` (or `false`) leaves a value to the layer below ([`SettingsPatch::over`]),
/// else the default. [`SettingsPatch::resolve`] is the one place that holds the defaults and
/// checks the values.
///
/// ```rust
/// use dofray::render::{Mode, RulePatch, SamplingRule, SettingsPatch};
///
/// let scene = dofray::scene::load("paper")?;
/// let flags = SettingsPatch { spp: Some(64), ..Default::default() };
/// let settings = flags.over(&scene.settings).resolve()?;
/// assert_eq!((settings.mode, settings.spp), (Mode::Adaptive, 64));
/// assert_eq!(settings.rule, SamplingRule::ErrorControlled { tolerance: None });
/// // The seed paper's fixed rule, k = 0.4 (`dofray render -k 0.4`).
/// let seed = SettingsPatch {
///     rule: Some(RulePatch::Seed { interval_factor: Some(0.4), paper_exact: false }),
///     ..Default::default()
/// };
/// assert_eq!(
///     seed.resolve()?.rule,
///     SamplingRule::Seed { interval_factor: 0.4, paper_exact: false }
/// );
/// // Values are checked: 0 samples is an error naming them.
/// let zero = SettingsPatch { spp: Some(0), ..Default::default() };
/// assert!(zero.resolve().unwrap_err().to_string().contains("spp"));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SettingsPatch {
    /// Where sample sites are placed. Default: adaptive.
    pub mode: Option<Mode>,
    /// Samples per sample site that blur reaches (traced in packets of 16). Default: 16.
    pub spp: Option<u32>,
    /// Samples per in-focus sample site (anti-aliasing). Default: 4.
    pub aa: Option<u32>,
    /// The pixel filter's shape (at its default width unless `pixel_filter_width` is given).
    /// Default: Blackman-Harris.
    pub pixel_filter: Option<PixelFilterKind>,
    /// The pixel filter's width in pixels.
    pub pixel_filter_width: Option<f32>,
    /// The sampling rule. Default: error-controlled, at the default tolerance.
    pub rule: Option<RulePatch>,
    /// The background contributes nothing; alpha is coverage (when any layer says so).
    pub transparent: bool,
    /// Exposure in stops. Default: 0.
    pub exposure: Option<f32>,
    /// The random seed. Default: 0.
    pub seed: Option<u64>,
    /// The weighting of lens samples. Default: box.
    pub lens_filter: Option<LensFilter>,
    /// How light is carried. Default: path.
    pub integrator: Option<Integrator>,
    /// Most bounces of any kind. Default: 12.
    pub max_bounces: Option<u32>,
    /// Most diffuse bounces. Default: 4.
    pub diffuse_bounces: Option<u32>,
    /// Most glossy bounces. Default: 4.
    pub glossy_bounces: Option<u32>,
    /// Most transmission bounces. Default: 12.
    pub transmission_bounces: Option<u32>,
    /// Clamp on indirect samples. Default: none.
    pub clamp_indirect: Option<f32>,
    /// Glossy filter ([`PathLimits::filter_glossy`]). Default: 0, none.
    pub filter_glossy: Option<f32>,
    /// Light tracing of small emitters ([`PathLimits::light_tracing`]). Default: on.
    pub light_tracing: Option<bool>,
    /// Sample reuse across sites ([`PathLimits::reuse`]). Default: on.
    pub reuse: Option<bool>,
}

impl SettingsPatch {
    /// Samples per defocused site when no layer gives them.
    pub const DEFAULT_SPP: u32 = 16;
    /// Samples per in-focus site when no layer gives them.
    pub const DEFAULT_AA: u32 = 4;
    /// The seed rule's k when no layer gives it (the paper's).
    pub const DEFAULT_INTERVAL_FACTOR: f32 = 0.4;

    /// This patch over `lower`: each value from here, else from `lower`. A pixel filter
    /// shape given here drops `lower`'s width (it was for another shape); a rule given here
    /// replaces `lower`'s, except that values of the same rule not given here come from it.
    pub fn over(&self, lower: &SettingsPatch) -> SettingsPatch {
        let pixel_filter_width = match self.pixel_filter {
            Some(_) => self.pixel_filter_width,
            None => self.pixel_filter_width.or(lower.pixel_filter_width),
        };
        use RulePatch::{ErrorControlled, Seed};
        let rule = match (self.rule, lower.rule) {
            (None, lower) => lower,
            (Some(ErrorControlled { tolerance }), Some(ErrorControlled { tolerance: below })) => {
                Some(ErrorControlled {
                    tolerance: tolerance.or(below),
                })
            }
            (
                Some(Seed {
                    interval_factor,
                    paper_exact,
                }),
                Some(Seed {
                    interval_factor: k,
                    paper_exact: exact,
                }),
            ) => Some(Seed {
                interval_factor: interval_factor.or(k),
                paper_exact: paper_exact || exact,
            }),
            (upper, _) => upper,
        };
        SettingsPatch {
            mode: self.mode.or(lower.mode),
            spp: self.spp.or(lower.spp),
            aa: self.aa.or(lower.aa),
            pixel_filter: self.pixel_filter.or(lower.pixel_filter),
            pixel_filter_width,
            rule,
            transparent: self.transparent || lower.transparent,
            exposure: self.exposure.or(lower.exposure),
            seed: self.seed.or(lower.seed),
            lens_filter: self.lens_filter.or(lower.lens_filter),
            integrator: self.integrator.or(lower.integrator),
            max_bounces: self.max_bounces.or(lower.max_bounces),
            diffuse_bounces: self.diffuse_bounces.or(lower.diffuse_bounces),
            glossy_bounces: self.glossy_bounces.or(lower.glossy_bounces),
            transmission_bounces: self.transmission_bounces.or(lower.transmission_bounces),
            clamp_indirect: self.clamp_indirect.or(lower.clamp_indirect),
            filter_glossy: self.filter_glossy.or(lower.filter_glossy),
            light_tracing: self.light_tracing.or(lower.light_tracing),
            reuse: self.reuse.or(lower.reuse),
        }
    }

    /// The settings: each value given, else its default; checked
    /// ([`RenderSettings::validate`]).
    pub fn resolve(&self) -> Result<RenderSettings, SettingError> {
        let mut pixel_filter = PixelFilter::new(self.pixel_filter.unwrap_or_default());
        if let Some(width) = self.pixel_filter_width {
            pixel_filter.width = width;
        }
        let rule = match self.rule {
            None => SamplingRule::ErrorControlled { tolerance: None },
            Some(RulePatch::ErrorControlled { tolerance }) => {
                SamplingRule::ErrorControlled { tolerance }
            }
            Some(RulePatch::Seed {
                interval_factor,
                paper_exact,
            }) => SamplingRule::Seed {
                interval_factor: interval_factor.unwrap_or(Self::DEFAULT_INTERVAL_FACTOR),
                paper_exact,
            },
        };
        let d = PathLimits::default();
        let integrator = self.integrator.unwrap_or_default();
        let spp = self.spp.unwrap_or(Self::DEFAULT_SPP);
        let settings = RenderSettings {
            mode: self.mode.unwrap_or(Mode::Adaptive),
            spp,
            // Paths are as noisy in focus as in the blur: in-focus sites take as many samples
            // unless asked otherwise. The direct integrator's in-focus pixels only need
            // anti-aliasing.
            aa: self.aa.unwrap_or(match integrator {
                Integrator::Path => spp,
                Integrator::Direct => Self::DEFAULT_AA,
            }),
            pixel_filter,
            rule,
            max_interval: 64,
            seed: self.seed.unwrap_or(0),
            filter: self.lens_filter.unwrap_or(LensFilter::Box),
            integrator,
            path: PathLimits {
                total: self.max_bounces.unwrap_or(d.total),
                diffuse: self.diffuse_bounces.unwrap_or(d.diffuse),
                glossy: self.glossy_bounces.unwrap_or(d.glossy),
                transmission: self.transmission_bounces.unwrap_or(d.transmission),
                clamp_indirect: self.clamp_indirect.unwrap_or(d.clamp_indirect),
                filter_glossy: self.filter_glossy.unwrap_or(d.filter_glossy),
                strategy: d.strategy,
                light_tracing: self.light_tracing.unwrap_or(d.light_tracing),
                reuse: self.reuse.unwrap_or(d.reuse),
            },
            bounces: 1,
            record_rays: false,
            transparent: self.transparent,
            exposure: self.exposure.unwrap_or(0.0),
        };
        settings.validate()?;
        Ok(settings)
    }
}

impl HasKind for UnknownMode {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

impl HasKind for SettingError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seed(k: Option<f32>, paper_exact: bool) -> Option<RulePatch> {
        Some(RulePatch::Seed {
            interval_factor: k,
            paper_exact,
        })
    }

    fn error(tolerance: Option<f32>) -> Option<RulePatch> {
        Some(RulePatch::ErrorControlled { tolerance })
    }

    #[test]
    fn the_upper_rule_wins_and_fills_in_from_the_same_rule_below() {
        let rule = |upper, lower| {
            let patch = |rule| SettingsPatch {
                rule,
                ..Default::default()
            };
            patch(upper).over(&patch(lower)).resolve().unwrap().rule
        };
        let seed_rule = |k, paper_exact| SamplingRule::Seed {
            interval_factor: k,
            paper_exact,
        };
        let error_rule = |tolerance| SamplingRule::ErrorControlled { tolerance };
        assert_eq!(rule(None, None), error_rule(None));
        assert_eq!(rule(None, seed(Some(0.25), false)), seed_rule(0.25, false));
        assert_eq!(
            rule(error(Some(0.5)), seed(Some(0.25), false)),
            error_rule(Some(0.5))
        );
        assert_eq!(rule(error(None), error(Some(2.0))), error_rule(Some(2.0)));
        assert_eq!(
            rule(seed(None, true), seed(Some(0.25), false)),
            seed_rule(0.25, true)
        );
        assert_eq!(
            rule(seed(None, true), error(Some(2.0))),
            seed_rule(0.4, true)
        );
    }

    #[test]
    fn a_pixel_filter_shape_above_drops_the_width_below() {
        let below = SettingsPatch {
            pixel_filter: Some(PixelFilterKind::Gaussian),
            pixel_filter_width: Some(2.0),
            ..Default::default()
        };
        let shape = SettingsPatch {
            pixel_filter: Some(PixelFilterKind::Box),
            ..Default::default()
        };
        let f = shape.over(&below).resolve().unwrap().pixel_filter;
        assert_eq!(f, PixelFilter::new(PixelFilterKind::Box));
        let f = SettingsPatch::default()
            .over(&below)
            .resolve()
            .unwrap()
            .pixel_filter;
        assert_eq!((f.kind, f.width), (PixelFilterKind::Gaussian, 2.0));
    }

    #[test]
    fn the_default_settings_are_the_empty_patch_resolved() {
        let d = RenderSettings::default();
        // The path tracer's in-focus sites take as many samples as blurred ones.
        assert_eq!((d.mode, d.spp, d.aa), (Mode::Adaptive, 16, 16));
        assert_eq!(d.tolerance(), Some(1.0));
        let direct = SettingsPatch {
            integrator: Some(Integrator::Direct),
            spp: Some(64),
            ..Default::default()
        };
        assert_eq!(direct.resolve().unwrap().aa, 4);
        let path = SettingsPatch {
            spp: Some(64),
            ..Default::default()
        };
        assert_eq!(path.resolve().unwrap().aa, 64);
    }
}
