//! Display views: how scene-linear colour becomes the code values of a PNG, as Blender's
//! colour management panel sets it (Render Properties > Color Management).
//!
//! A [`DisplayView`] is a view transform ([`View`]: Standard, AgX, Khronos PBR Neutral or
//! Raw), an optional [`Look`] (AgX's contrast looks), an exposure in stops applied before the
//! view and a gamma applied after it: the same order and the same formulas as Blender 4.2's
//! OpenColorIO configuration for the sRGB display, so a dofray PNG of an image and Blender's
//! PNG of the same linear image agree to the code value (checked against Blender by
//! `scripts/view-transform-check.py`). EXR output stays scene-linear; views only touch PNGs,
//! and each PNG records its view in text chunks ([`DisplayView::metadata`]).
//!
//! Filmic is not offered: Blender defines it only by LUT files (Troy Sobotka's, shipped with
//! Blender under its licence) with no published formula to bake from; AgX replaced it as
//! Blender's default in 4.0.

mod agx;
mod lut;
mod matrix;
mod pbr_neutral;

use std::fmt;
use std::str::FromStr;
use std::sync::OnceLock;

use crate::error_kind::{ErrorKind, HasKind};

/// A view transform for the sRGB display, by Blender's names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum View {
    /// The sRGB curve of the linear colour, clipped to `[0, 1]` (dofray's default, and
    /// Blender's "Standard").
    #[default]
    Standard,
    /// Troy Sobotka's AgX as Blender 4 forms it (Blender's default view since 4.0).
    AgX,
    /// The Khronos PBR Neutral tone mapper (for product shots: colours stay as authored up to
    /// 0.8, highlights roll off to white).
    KhronosPbrNeutral,
    /// No transform: linear values clipped to `[0, 1]` (Blender's "Raw", for data).
    Raw,
}

impl View {
    /// Blender's name for it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Standard => "Standard",
            Self::AgX => "AgX",
            Self::KhronosPbrNeutral => "Khronos PBR Neutral",
            Self::Raw => "Raw",
        }
    }
}

impl fmt::Display for View {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for View {
    type Err = ViewError;

    /// Blender's names or short ones, any case: `standard`, `agx`, `khronos-pbr-neutral`
    /// (`pbr-neutral`), `raw`.
    fn from_str(s: &str) -> Result<Self, ViewError> {
        match squash(s).as_str() {
            "standard" => Ok(Self::Standard),
            "agx" => Ok(Self::AgX),
            "khronospbrneutral" | "pbrneutral" => Ok(Self::KhronosPbrNeutral),
            "raw" => Ok(Self::Raw),
            "filmic" | "filmiclog" => Err(ViewError::Filmic),
            _ => Err(ViewError::UnknownView(s.to_string())),
        }
    }
}

/// An AgX look (Blender's "AgX - ..." looks), graded in AgX's log space before the view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Look {
    /// No look.
    #[default]
    None,
    /// Contrast 1.57, saturation 0.9.
    VeryHighContrast,
    /// Contrast 1.4, saturation 0.95.
    HighContrast,
    /// Contrast 1.2.
    MediumHighContrast,
    /// Contrast 1 (the base look: no change).
    BaseContrast,
    /// Contrast 0.9, saturation 1.05.
    MediumLowContrast,
    /// Contrast 0.8, saturation 1.1.
    LowContrast,
    /// Contrast 0.7, saturation 1.15.
    VeryLowContrast,
    /// Black and white by Rec.2020 luminance.
    Greyscale,
}

impl Look {
    const ALL: [Self; 9] = [
        Self::None,
        Self::VeryHighContrast,
        Self::HighContrast,
        Self::MediumHighContrast,
        Self::BaseContrast,
        Self::MediumLowContrast,
        Self::LowContrast,
        Self::VeryLowContrast,
        Self::Greyscale,
    ];

    /// Blender's name for it (`"None"`, `"AgX - High Contrast"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "None",
            Self::VeryHighContrast => "AgX - Very High Contrast",
            Self::HighContrast => "AgX - High Contrast",
            Self::MediumHighContrast => "AgX - Medium High Contrast",
            Self::BaseContrast => "AgX - Base Contrast",
            Self::MediumLowContrast => "AgX - Medium Low Contrast",
            Self::LowContrast => "AgX - Low Contrast",
            Self::VeryLowContrast => "AgX - Very Low Contrast",
            Self::Greyscale => "AgX - Greyscale",
        }
    }

    fn grade(self) -> Option<agx::Grade> {
        let primary = |contrast, saturation| {
            Some(agx::Grade::Primary {
                contrast,
                saturation,
            })
        };
        match self {
            Self::None | Self::BaseContrast => None,
            Self::VeryHighContrast => primary(1.57, 0.9),
            Self::HighContrast => primary(1.4, 0.95),
            Self::MediumHighContrast => primary(1.2, 1.0),
            Self::MediumLowContrast => primary(0.9, 1.05),
            Self::LowContrast => primary(0.8, 1.1),
            Self::VeryLowContrast => primary(0.7, 1.15),
            Self::Greyscale => Some(agx::Grade::Greyscale),
        }
    }
}

impl fmt::Display for Look {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Look {
    type Err = ViewError;

    /// Blender's names (`"AgX - High Contrast"`) or short ones (`high-contrast`), any case.
    fn from_str(s: &str) -> Result<Self, ViewError> {
        let key = squash(s);
        let key = key.strip_prefix("agx").unwrap_or(&key);
        if key == "punchy" {
            return Err(ViewError::Punchy);
        }
        Self::ALL
            .into_iter()
            .find(|l| squash(l.name()).trim_start_matches("agx") == key)
            .ok_or_else(|| ViewError::UnknownLook(s.to_string()))
    }
}

/// Lower case without spaces, dashes and underscores: `"AgX - High Contrast"` and
/// `high-contrast` compare equal after the `agx` prefix.
fn squash(s: &str) -> String {
    s.chars()
        .filter(|c| !matches!(c, ' ' | '-' | '_'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// How a PNG shows scene-linear colour: Blender's view transform, look, exposure and gamma
/// for the sRGB display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisplayView {
    /// The view transform.
    pub view: View,
    /// The look (AgX looks need [`View::AgX`]).
    pub look: Look,
    /// Stops applied to the linear colour before the look and view (Blender's view
    /// exposure; the render's own `--exposure` scales the EXR too, this only the PNG).
    pub exposure: f32,
    /// Applied to display values after the view: `v^(1/gamma)` (Blender's view gamma).
    pub gamma: f32,
}

impl Default for DisplayView {
    fn default() -> Self {
        Self {
            view: View::Standard,
            look: Look::None,
            exposure: 0.0,
            gamma: 1.0,
        }
    }
}

impl DisplayView {
    /// The largest view exposure, in stops either way (Blender's slider: +-32).
    pub const MAX_EXPOSURE: f32 = 32.0;
    /// Blender's gamma range.
    pub const GAMMA_RANGE: (f32, f32) = (0.0, 5.0);

    /// Checks the combination: an AgX look needs the AgX view; exposure and gamma in
    /// Blender's ranges (gamma above 0).
    pub fn validate(&self) -> Result<(), ViewError> {
        if self.look != Look::None && self.view != View::AgX {
            return Err(ViewError::LookNeedsAgX {
                look: self.look,
                view: self.view,
            });
        }
        if !self.exposure.is_finite() || self.exposure.abs() > Self::MAX_EXPOSURE {
            return Err(ViewError::Exposure(self.exposure));
        }
        let (lo, hi) = Self::GAMMA_RANGE;
        if !(self.gamma > lo && self.gamma <= hi) {
            return Err(ViewError::Gamma(self.gamma));
        }
        Ok(())
    }

    /// Whether this is plain sRGB of the linear colour (no view work needed).
    pub fn is_standard(&self) -> bool {
        *self == Self::default()
    }

    /// One scene-linear Rec.709 colour to display code values in `[0, 1]` (sRGB-encoded;
    /// linear for [`View::Raw`]). NaN and negative channels count as 0.
    pub fn encode(&self, linear: [f32; 3]) -> [f32; 3] {
        let scale = self.exposure.exp2();
        let mut c = linear.map(|v| {
            if v.is_nan() {
                0.0
            } else {
                (v * scale).max(0.0)
            }
        });
        if let Some(grade) = self.look.grade() {
            c = agx::apply_look(grade, c);
        }
        let display = match self.view {
            View::Standard => c.map(srgb_curve),
            View::Raw => c.map(|v| v.clamp(0.0, 1.0)),
            View::AgX => agx_view().apply(c).map(srgb_curve),
            View::KhronosPbrNeutral => pbr_neutral_view().apply(c).map(srgb_curve),
        };
        if self.gamma == 1.0 {
            display
        } else {
            display.map(|v| v.powf(1.0 / self.gamma))
        }
    }

    /// The PNG text entries that record it: `dofray:view`, `dofray:look`,
    /// `dofray:view_exposure`, `dofray:view_gamma` (Blender's names and values).
    pub fn metadata(&self) -> [(&'static str, String); 4] {
        [
            ("dofray:view", self.view.name().to_string()),
            ("dofray:look", self.look.name().to_string()),
            ("dofray:view_exposure", self.exposure.to_string()),
            ("dofray:view_gamma", self.gamma.to_string()),
        ]
    }
}

/// The sRGB curve of a linear value clamped to `[0, 1]`.
fn srgb_curve(v: f32) -> f32 {
    crate::metrics::srgb_curve(v.clamp(0.0, 1.0))
}

/// AgX's LUT, baked once per process on first use.
fn agx_view() -> &'static agx::AgX {
    static VIEW: OnceLock<agx::AgX> = OnceLock::new();
    VIEW.get_or_init(agx::AgX::new)
}

fn pbr_neutral_view() -> &'static pbr_neutral::PbrNeutral {
    static VIEW: OnceLock<pbr_neutral::PbrNeutral> = OnceLock::new();
    VIEW.get_or_init(pbr_neutral::PbrNeutral::new)
}

/// A view, look, exposure or gamma dofray cannot apply.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewError {
    /// Not a view dofray knows.
    #[error("unknown view transform {0:?}: expected Standard, AgX, \"Khronos PBR Neutral\" or Raw")]
    UnknownView(String),
    /// Filmic (see the module documentation).
    #[error(
        "the Filmic view is not available: Blender defines it only by its LUT files, with no \
         formula to reproduce; use AgX (Blender's default since 4.0) or Standard"
    )]
    Filmic,
    /// Not a look dofray knows.
    #[error(
        "unknown look {0:?}: expected None, Greyscale, or a contrast: Very High, High, Medium \
         High, Base, Medium Low, Low, Very Low (\"AgX - High Contrast\" or high-contrast)"
    )]
    UnknownLook(String),
    /// AgX's Punchy look (an OpenColorIO tone grading dofray does not reproduce).
    #[error(
        "the look \"AgX - Punchy\" is not available (OpenColorIO's GradingTone, which dofray \
         does not reproduce); try \"AgX - Medium High Contrast\""
    )]
    Punchy,
    /// A look with a view other than AgX.
    #[error("the look {look:?} needs the AgX view, not {view}", look = look.name())]
    LookNeedsAgX {
        /// The look.
        look: Look,
        /// The view it was given with.
        view: View,
    },
    /// View exposure out of range.
    #[error("view exposure {0} is not a number of stops within +-32")]
    Exposure(f32),
    /// View gamma out of range.
    #[error("view gamma {0} is not in (0, 5]")]
    Gamma(f32),
}

impl HasKind for ViewError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_as_blender_spells_them_and_short() {
        assert_eq!("AgX".parse::<View>(), Ok(View::AgX));
        assert_eq!(
            "khronos-pbr-neutral".parse::<View>(),
            Ok(View::KhronosPbrNeutral)
        );
        assert_eq!(
            "Khronos PBR Neutral".parse::<View>(),
            Ok(View::KhronosPbrNeutral)
        );
        assert_eq!("Filmic".parse::<View>(), Err(ViewError::Filmic));
        assert!(matches!(
            "ACES".parse::<View>(),
            Err(ViewError::UnknownView(_))
        ));
        assert_eq!(
            "AgX - High Contrast".parse::<Look>(),
            Ok(Look::HighContrast)
        );
        assert_eq!(
            "very-low-contrast".parse::<Look>(),
            Ok(Look::VeryLowContrast)
        );
        assert_eq!("greyscale".parse::<Look>(), Ok(Look::Greyscale));
        assert_eq!("None".parse::<Look>(), Ok(Look::None));
        assert_eq!("AgX - Punchy".parse::<Look>(), Err(ViewError::Punchy));
        for look in Look::ALL {
            assert_eq!(look.name().parse::<Look>(), Ok(look));
        }
    }

    #[test]
    fn standard_is_the_srgb_curve() {
        let v = DisplayView::default();
        assert!(v.is_standard());
        let out = v.encode([0.0, 0.18, 2.0]);
        assert_eq!(out[0], 0.0);
        assert!((out[1] - crate::metrics::srgb_curve(0.18)).abs() < 1e-7);
        assert!((out[2] - 1.0).abs() < 1e-6);
        assert_eq!(v.encode([f32::NAN, -1.0, 0.0]), [0.0; 3]);
    }

    #[test]
    fn exposure_and_gamma_apply_as_blender_orders_them() {
        let base = DisplayView::default();
        let brighter = DisplayView {
            exposure: 1.0,
            ..base
        };
        assert_eq!(brighter.encode([0.1; 3]), base.encode([0.2; 3]));
        let gamma = DisplayView { gamma: 2.0, ..base };
        let want = base.encode([0.2; 3])[0].sqrt();
        assert!((gamma.encode([0.2; 3])[0] - want).abs() < 1e-6);
    }

    #[test]
    fn agx_compresses_highlights_where_standard_clips() {
        let agx = DisplayView {
            view: View::AgX,
            ..Default::default()
        };
        let a = agx.encode([4.0; 3])[0];
        let b = agx.encode([16.0; 3])[0];
        assert!(a < b && b < 1.0, "{a} {b}");
        // A saturated red keeps its hue but loses purity as it brightens.
        let dim = agx.encode([0.2, 0.0, 0.0]);
        let hot = agx.encode([50.0, 0.0, 0.0]);
        assert!(dim[0] > dim[1] && hot[0] >= hot[1] && hot[1] > dim[1]);
    }

    #[test]
    fn looks_need_agx_and_ranges_are_checked() {
        let bad = DisplayView {
            look: Look::HighContrast,
            ..Default::default()
        };
        assert!(matches!(
            bad.validate(),
            Err(ViewError::LookNeedsAgX { .. })
        ));
        for (exposure, gamma) in [(f32::NAN, 1.0), (40.0, 1.0), (0.0, 0.0), (0.0, 6.0)] {
            let v = DisplayView {
                exposure,
                gamma,
                ..Default::default()
            };
            assert!(v.validate().is_err(), "{exposure} {gamma}");
        }
        let ok = DisplayView {
            view: View::AgX,
            look: Look::Greyscale,
            exposure: -2.0,
            gamma: 2.2,
        };
        assert_eq!(ok.validate(), Ok(()));
        let grey = ok.encode([0.8, 0.1, 0.3]);
        assert!(
            (grey[0] - grey[1]).abs() < 2e-3 && (grey[1] - grey[2]).abs() < 2e-3,
            "{grey:?}"
        );
    }
}
