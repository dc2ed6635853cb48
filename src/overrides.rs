//! Overrides of a scene's camera, lights and render settings: what the command line's flags
//! set, as a library type, so another tool changes a loaded scene the same way `dofray render`
//! does.
//!
//! [`Overrides`] changes the scene (size, lens, focus, aperture shape, lights, ambient); the
//! render settings are a [`crate::render::SettingsPatch`] over the scene's. Every value is
//! checked when applied; an [`OverrideError`] names the [`Param`] and what was expected.

use glam::Vec3;

use crate::camera::{
    ApertureShape, CameraSpec, Focus, LensSpec, Photographic, RealLensSpec, check_vfov,
};
use crate::error_kind::{ErrorKind, HasKind};
use crate::params::Param;
use crate::scene::SceneDesc;
use crate::shade::Light;

/// Changes to a scene's camera and lights; `None` (or an empty `lights`) keeps the scene's.
///
/// ```rust
/// use dofray::glam::Vec3;
/// use dofray::{overrides::Overrides, shade::Light};
///
/// let mut scene = dofray::scene::load("paper")?; // 640 x 480
/// // `dofray render --width 320 --f-number 1.4 --focal-length 85 --light sun:-1,-2,1:3`
/// let overrides = Overrides {
///     width: Some(320),
///     f_number: Some(1.4),
///     focal_length_mm: Some(85.0),
///     lights: vec![Light::Directional {
///         direction: Vec3::new(-1.0, -2.0, 1.0).normalize(),
///         irradiance: Vec3::splat(3.0),
///         angle: 0.0,
///     }],
///     ..Default::default()
/// };
/// overrides.apply_scene(&mut scene)?;
/// assert_eq!((scene.camera.width, scene.camera.height), (320, 240)); // the aspect is kept
/// assert_eq!(scene.lights.len(), 1);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overrides {
    /// Image width in pixels; the height follows the aspect when `height` is `None`.
    pub width: Option<u32>,
    /// Image height in pixels; the width follows the aspect when `width` is `None`.
    pub height: Option<u32>,
    /// A lens of this aperture radius (scene units), replacing the scene's.
    pub aperture_radius: Option<f32>,
    /// A photographic lens of this f-number, replacing the scene's (focal length and sensor
    /// width from the fields below, else the scene's photographic lens, else 50 mm on 36 mm).
    pub f_number: Option<f32>,
    /// Focal length in mm of a photographic lens (needs `f_number` unless the scene's lens is
    /// photographic).
    pub focal_length_mm: Option<f32>,
    /// Sensor width in mm of a photographic lens (likewise).
    pub sensor_width_mm: Option<f32>,
    /// The seed's lens: (sharp range in scene units, spread in pixels), replacing the scene's.
    pub sharp_range: Option<(f32, f32)>,
    /// Focus distance along the view axis (`f32::INFINITY`: at infinity).
    pub focus_distance: Option<f32>,
    /// Autofocus on the surface seen through this pixel (wins over `focus_distance`).
    pub autofocus: Option<(u32, u32)>,
    /// Aperture blades (0: circular).
    pub blades: Option<u32>,
    /// Rotation of a polygonal aperture in degrees.
    pub blade_rotation_deg: Option<f32>,
    /// Anamorphic ratio: aperture height over width.
    pub anamorphic: Option<f32>,
    /// A real lens replacing the scene's (its `f_number` and `sensor_width_mm` are replaced
    /// by the fields above when given). With a real lens, from here or the scene, `f_number`
    /// stops it down and `sensor_width_mm` sizes its film; the thin lens's values
    /// (`aperture_radius`, `focal_length_mm`, `sharp_range`, the aperture's shape) are refused.
    pub real_lens: Option<RealLensSpec>,
    /// Lights replacing the scene's (empty: the scene's).
    pub lights: Vec<Light>,
    /// Ambient light level replacing the scene's.
    pub ambient: Option<f32>,
}

/// An override that cannot be applied. `Display` names the fields of [`Overrides`];
/// [`OverrideError::message`] names them any other way (the command line: its flags).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OverrideError {
    /// A width or height of 0 pixels.
    #[error("{}", self.message(Param::field))]
    ZeroSize(Param),
    /// Expected a finite number > 0.
    #[error("{}", self.message(Param::field))]
    NotPositive {
        /// The parameter.
        param: Param,
        /// The value given.
        value: f32,
    },
    /// Expected a finite number >= 0.
    #[error("{}", self.message(Param::field))]
    Negative {
        /// The parameter.
        param: Param,
        /// The value given.
        value: f32,
    },
    /// Expected a number > 0 or infinity.
    #[error("{}", self.message(Param::field))]
    FocusDistance(f32),
    /// Expected 0 or at least 3.
    #[error("{}", self.message(Param::field))]
    Blades(u32),
    /// Expected a finite angle.
    #[error("{}", self.message(Param::field))]
    BladeRotation(f32),
    /// A focal length or sensor width for a lens that is not photographic, without `f_number`.
    #[error("{}", self.message(Param::field))]
    NotPhotographic {
        /// The focal length or sensor width.
        param: Param,
        /// How the scene's lens is given (`"a pinhole (no aperture)"`, ...).
        lens: &'static str,
    },
    /// A thin lens's value for a camera with a real lens.
    #[error("{}", self.message(Param::field))]
    RealLens(Param),
    /// The photographic lens gives no usable field of view.
    #[error("{}", self.message(Param::field))]
    NoFieldOfView {
        /// Focal length in mm.
        focal_length_mm: f32,
        /// Sensor width in mm.
        sensor_width_mm: f32,
        /// The vertical field of view they give, in degrees.
        vfov_deg: f32,
    },
}

impl OverrideError {
    /// The message with every parameter called `name(param)`.
    pub fn message(&self, name: impl Fn(Param) -> &'static str) -> String {
        match *self {
            Self::ZeroSize(p) => format!("{} must be at least 1 pixel", name(p)),
            Self::NotPositive { param, value } => {
                format!("{} must be a finite number > 0, got {value}", name(param))
            }
            Self::Negative { param, value } => {
                format!("{} must be a finite number >= 0, got {value}", name(param))
            }
            Self::FocusDistance(d) => format!(
                "{} must be a number > 0 (or inf), got {d}",
                name(Param::FocusDistance)
            ),
            Self::Blades(b) => format!(
                "{} must be 0 (a circular aperture) or at least 3, got {b}",
                name(Param::Blades)
            ),
            Self::BladeRotation(r) => format!(
                "{} must be a finite angle in degrees, got {r}",
                name(Param::BladeRotation)
            ),
            Self::NotPhotographic { param, lens } => format!(
                "{} applies to a photographic lens, but the scene's lens is {lens}; give {} too \
                 to replace it with a photographic lens",
                name(param),
                name(Param::FNumber)
            ),
            Self::RealLens(p) => format!(
                "{} describes the thin lens, but the camera has a real lens (a lens \
                 prescription), which has its own focal length and round stop; only {} (stops \
                 it down) and {} apply to it",
                name(p),
                name(Param::FNumber),
                name(Param::SensorWidth)
            ),
            Self::NoFieldOfView {
                focal_length_mm,
                sensor_width_mm,
                vfov_deg,
            } => format!(
                "a {focal_length_mm:e} mm lens on a {sensor_width_mm} mm sensor has no usable \
                 field of view ({vfov_deg} degrees vertically); choose a longer {} or a smaller \
                 {}",
                name(Param::FocalLength),
                name(Param::SensorWidth)
            ),
        }
    }
}

fn scaled(v: u32, from: u32, to: u32) -> u32 {
    (((v as f64 + 0.5) * to as f64 / from.max(1) as f64) as u32).min(to.saturating_sub(1))
}

fn follow_aspect(given: u32, given_base: u32, other_base: u32) -> u32 {
    ((given as u64 * other_base as u64) as f64 / given_base as f64)
        .round()
        .max(1.0) as u32
}

impl Overrides {
    /// Applies the size, lens, focus and aperture shape to a camera. An autofocus pixel of the
    /// camera's own moves with a new size (it names a place in the picture).
    pub fn apply_camera(&self, cam: &mut CameraSpec) -> Result<(), OverrideError> {
        for (param, v) in [(Param::Width, self.width), (Param::Height, self.height)] {
            if v == Some(0) {
                return Err(OverrideError::ZeroSize(param));
            }
        }
        let (old_w, old_h) = (cam.width, cam.height);
        match (self.width, self.height) {
            (Some(w), Some(h)) => (cam.width, cam.height) = (w, h),
            (Some(w), None) => {
                cam.height = follow_aspect(w, cam.width, cam.height);
                cam.width = w;
            }
            (None, Some(h)) => {
                cam.width = follow_aspect(h, cam.height, cam.width);
                cam.height = h;
            }
            (None, None) => {}
        }
        if let Focus::Pixel { x, y } = &mut cam.focus {
            *x = scaled(*x, old_w, cam.width);
            *y = scaled(*y, old_h, cam.height);
        }
        for (param, v) in [
            (Param::FNumber, self.f_number),
            (Param::FocalLength, self.focal_length_mm),
            (Param::SensorWidth, self.sensor_width_mm),
        ] {
            if let Some(value) = v {
                Photographic::check_number(param.field(), value)
                    .map_err(|_| OverrideError::NotPositive { param, value })?;
            }
        }
        if self.apply_real_lens(cam)? {
            return self.apply_focus(cam);
        }
        if let Some(value) = self.anamorphic
            && !(value.is_finite() && value > 0.0)
        {
            return Err(OverrideError::NotPositive {
                param: Param::Anamorphic,
                value,
            });
        }
        if let Some(r) = self.aperture_radius {
            if !(r.is_finite() && r >= 0.0) {
                return Err(OverrideError::Negative {
                    param: Param::ApertureRadius,
                    value: r,
                });
            }
            // A photographic lens set the field of view: keep the framing it gave.
            cam.vfov_deg = cam.effective_vfov_deg();
            cam.lens = LensSpec::Aperture { radius: r };
        }
        if let Some((sharp_range, spread)) = self.sharp_range {
            if !(sharp_range.is_finite() && sharp_range > 0.0) {
                return Err(OverrideError::NotPositive {
                    param: Param::SharpRange,
                    value: sharp_range,
                });
            }
            if !(spread.is_finite() && spread >= 0.0) {
                return Err(OverrideError::Negative {
                    param: Param::Spread,
                    value: spread,
                });
            }
            cam.vfov_deg = cam.effective_vfov_deg();
            cam.lens = LensSpec::Seed {
                sharp_range,
                spread,
            };
        }
        self.apply_photographic(cam)?;
        self.apply_focus(cam)?;
        if let Some(b) = self.blades {
            if !ApertureShape::blades_ok(b) {
                return Err(OverrideError::Blades(b));
            }
            cam.aperture.blades = b;
        }
        if let Some(r) = self.blade_rotation_deg {
            if !r.is_finite() {
                return Err(OverrideError::BladeRotation(r));
            }
            cam.aperture.rotation_deg = r;
        }
        if let Some(r) = self.anamorphic {
            cam.aperture.anamorphic = r;
        }
        Ok(())
    }

    /// The focus distance or autofocus pixel.
    fn apply_focus(&self, cam: &mut CameraSpec) -> Result<(), OverrideError> {
        if let Some(d) = self.focus_distance {
            if d.is_nan() || d <= 0.0 {
                return Err(OverrideError::FocusDistance(d));
            }
            cam.focus = Focus::Distance(d);
        }
        if let Some((x, y)) = self.autofocus {
            cam.focus = Focus::Pixel { x, y };
        }
        Ok(())
    }

    /// The real lens's part of [`Overrides::apply_camera`]: whether the camera has one.
    fn apply_real_lens(&self, cam: &mut CameraSpec) -> Result<bool, OverrideError> {
        if let Some(real) = &self.real_lens {
            cam.real_lens = Some(real.clone());
        }
        let Some(real) = cam.real_lens.as_mut() else {
            return Ok(false);
        };
        let thin = [
            (Param::ApertureRadius, self.aperture_radius.is_some()),
            (Param::SharpRange, self.sharp_range.is_some()),
            (Param::FocalLength, self.focal_length_mm.is_some()),
            (Param::Blades, self.blades.is_some()),
            (Param::BladeRotation, self.blade_rotation_deg.is_some()),
            (Param::Anamorphic, self.anamorphic.is_some()),
        ];
        if let Some((param, _)) = thin.into_iter().find(|(_, given)| *given) {
            return Err(OverrideError::RealLens(param));
        }
        if let Some(n) = self.f_number {
            real.f_number = Some(n);
        }
        if let Some(w) = self.sensor_width_mm {
            real.sensor_width_mm = w;
        }
        Ok(true)
    }

    /// The photographic lens's part of [`Overrides::apply_camera`].
    fn apply_photographic(&self, cam: &mut CameraSpec) -> Result<(), OverrideError> {
        let (vfov_deg, size) = (cam.vfov_deg, (cam.width, cam.height));
        match (self.f_number, &mut cam.lens) {
            (
                None,
                LensSpec::Photographic {
                    focal_length_mm,
                    sensor_width_mm,
                    ..
                },
            ) => {
                *focal_length_mm = self.focal_length_mm.unwrap_or(*focal_length_mm);
                *sensor_width_mm = self.sensor_width_mm.unwrap_or(*sensor_width_mm);
            }
            (None, lens) => {
                let given = [
                    (Param::FocalLength, self.focal_length_mm.is_some()),
                    (Param::SensorWidth, self.sensor_width_mm.is_some()),
                ];
                if let Some(&(param, _)) = given.iter().find(|(_, set)| *set) {
                    let lens = match lens {
                        LensSpec::Pinhole => "a pinhole (no aperture)",
                        LensSpec::Aperture { .. } => "given by an aperture radius",
                        LensSpec::Seed { .. } => "the seed's (sharp_range and spread)",
                        LensSpec::Photographic { .. } => unreachable!("matched above"),
                    };
                    return Err(OverrideError::NotPhotographic { param, lens });
                }
            }
            (Some(n), lens) => {
                // The scene's photographic lens, else one that keeps the scene's field of
                // view, with what is given.
                let scene = lens.photographic();
                *lens = Photographic::keeping_vfov(
                    n,
                    self.focal_length_mm.or(scene.map(|p| p.focal_length_mm)),
                    self.sensor_width_mm.or(scene.map(|p| p.sensor_width_mm)),
                    vfov_deg,
                    size,
                )
                .spec();
            }
        }
        if let LensSpec::Photographic {
            focal_length_mm,
            sensor_width_mm,
            ..
        } = cam.lens
            && (self.f_number.is_some()
                || self.focal_length_mm.is_some()
                || self.sensor_width_mm.is_some())
        {
            let vfov_deg = cam.effective_vfov_deg();
            if check_vfov(vfov_deg).is_err() {
                return Err(OverrideError::NoFieldOfView {
                    focal_length_mm,
                    sensor_width_mm,
                    vfov_deg,
                });
            }
        }
        Ok(())
    }

    /// Applies the lights and ambient level, then the camera ([`Overrides::apply_camera`]).
    pub fn apply_scene(&self, desc: &mut SceneDesc) -> Result<(), OverrideError> {
        if !self.lights.is_empty() {
            desc.lights = self.lights.clone();
        }
        if let Some(v) = self.ambient {
            if !(v.is_finite() && v >= 0.0) {
                return Err(OverrideError::Negative {
                    param: Param::Ambient,
                    value: v,
                });
            }
            desc.ambient = Vec3::splat(v);
        }
        self.apply_camera(&mut desc.camera)?;
        // A lens given here replaces the one dofray guessed: its warning no longer applies.
        if self.aperture_radius.is_some() || self.f_number.is_some() || self.sharp_range.is_some() {
            if let Some(guess) = desc.lens_guessed.take() {
                desc.warnings.retain(|w| *w != guess);
            }
        }
        Ok(())
    }

    /// Whether the lens, focus or aperture shape is overridden (a camera that cannot be built
    /// is then the caller's doing, not the scene's).
    pub fn lens_given(&self) -> bool {
        self.aperture_radius.is_some()
            || self.f_number.is_some()
            || self.focal_length_mm.is_some()
            || self.sensor_width_mm.is_some()
            || self.sharp_range.is_some()
            || self.focus_distance.is_some()
            || self.autofocus.is_some()
            || self.blades.is_some()
            || self.blade_rotation_deg.is_some()
            || self.anamorphic.is_some()
    }
}

impl HasKind for OverrideError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}
