//! The camera: where it stands and looks ([`CameraSpec`], [`Focus`]), the lens that makes its
//! rays and bounds their blur ([`lens`]), and the aperture those rays cross ([`aperture`]).
//!
//! A [`CameraSpec`] is what scenes, overrides and animation edit; [`CameraSpec::build`]
//! validates it into a [`Camera`], whose [`CameraLens`] the renderer asks for rays and for
//! the circle of confusion (CoC) of a depth. The thin lens is the only lens today; a new one
//! goes in [`lens`] (see there).

pub mod aperture;
mod camera_lens;
pub mod footprint;
pub mod lens;
pub mod optics;
pub mod prescription;
pub mod real_lens;

use glam::{Vec2, Vec3};

pub use aperture::{ApertureShape, LensFilter};
pub use camera_lens::CameraLens;
pub use footprint::BoxImage;
pub use lens::{Landing, Lens, Photographic, Reprojection, ThinLens};
pub use prescription::{LensFileError, Prescription};
pub use real_lens::{RealLens, RealLensSpec};

use crate::embree::{LANES, Ray};
use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::MAX_COORDINATE;

/// Default image width in pixels.
pub const DEFAULT_WIDTH: u32 = 640;
/// Default image height in pixels.
pub const DEFAULT_HEIGHT: u32 = 480;
/// Default vertical field of view, degrees.
pub const DEFAULT_VFOV: f32 = 40.0;
/// Focal length of a photographic lens that does not give one, millimetres.
pub const DEFAULT_FOCAL_LENGTH_MM: f32 = 50.0;
/// Sensor width of a photographic lens that does not give one, millimetres (full frame).
pub const DEFAULT_SENSOR_WIDTH_MM: f32 = 36.0;

/// Why a camera specification was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// A value out of range.
    #[error("{name} must be {expected}, got {value}")]
    Invalid {
        /// Which value (`"vfov_deg"`, `"aperture radius"`, ...).
        name: &'static str,
        /// What it must be.
        expected: &'static str,
        /// The value given, formatted.
        value: String,
    },
    /// The autofocus pixel ([`Focus::Pixel`]) is not in the image.
    #[error("autofocus pixel ({x}, {y}) is outside the {width}x{height} image")]
    FocusPixelOutside {
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
    },
    /// The autofocus pixel's pinhole ray hits nothing.
    #[error("autofocus pixel ({x}, {y}) sees no surface to focus on")]
    FocusPixelMisses {
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
    },
}

fn check(
    ok: bool,
    name: &'static str,
    expected: &'static str,
    value: impl ToString,
) -> Result<(), CameraError> {
    if ok {
        Ok(())
    } else {
        Err(CameraError::Invalid {
            name,
            expected,
            value: value.to_string(),
        })
    }
}

fn positive(name: &'static str, v: f32) -> Result<(), CameraError> {
    check(v.is_finite() && v > 0.0, name, "a finite number > 0", v)
}

/// Checks a vertical field of view in degrees: an angle strictly between 0 and 180.
pub fn check_vfov(vfov_deg: f32) -> Result<(), CameraError> {
    check(
        vfov_deg.is_finite() && vfov_deg > 0.0 && vfov_deg < 180.0,
        "vfov_deg",
        "an angle between 0 and 180 degrees",
        vfov_deg,
    )
}

/// A point whose every coordinate is within [`MAX_COORDINATE`] of the origin.
fn in_range(name: &'static str, v: Vec3) -> Result<(), CameraError> {
    check(
        v.is_finite() && v.abs().max_element() <= MAX_COORDINATE,
        name,
        "finite coordinates within 1e15 of the origin",
        format!("{v:?}"),
    )
}

/// How the lens aperture is specified. All four map to one thin lens of some aperture radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LensSpec {
    /// No depth of field: every ray leaves the lens centre.
    Pinhole,
    /// Aperture radius in scene units (as pbrt and Mitsuba specify it).
    Aperture {
        /// Aperture radius, scene units (>= 0; 0 is a pinhole).
        radius: f32,
    },
    /// A photographic lens: focal length and sensor width in millimetres, scene units metres.
    /// The aperture radius is `focal_length / (2 f_number)`, and the field of view follows from
    /// the focal length and sensor width (replacing the camera's `vfov_deg`); see
    /// [`Photographic`].
    Photographic {
        /// Focal length, millimetres (> 0).
        focal_length_mm: f32,
        /// f-number: focal length over aperture diameter (> 0).
        f_number: f32,
        /// Sensor width, millimetres (> 0); with the focal length it sets the field of view.
        sensor_width_mm: f32,
    },
    /// The seed's intuitive control: depths within `sharp_range` in front of and behind the
    /// focus distance stay sharp, and blur grows by `spread` pixels of CoC per `sharp_range`
    /// beyond. Using the seed's symmetric approximation of the CoC around the focus distance P,
    /// `coc_px(D) ~= 2 R k |D - P| / P^2` (k = pixels per unit at unit distance), the aperture
    /// radius is chosen so that `coc_px(P +- sharp_range) = spread`:
    /// `R = spread * P^2 / (2 k sharp_range)`.
    Seed {
        /// Depth range in front of and behind the focus distance that stays sharp, scene
        /// units (> 0).
        sharp_range: f32,
        /// CoC diameter at `sharp_range` from the focus distance, pixels (>= 0).
        spread: f32,
    },
}

impl LensSpec {
    /// The photographic lens's numbers, if it is one.
    pub fn photographic(&self) -> Option<Photographic> {
        match *self {
            Self::Photographic {
                focal_length_mm,
                f_number,
                sensor_width_mm,
            } => Some(Photographic {
                focal_length_mm,
                f_number,
                sensor_width_mm,
            }),
            _ => None,
        }
    }
}

/// Where the lens is focused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Focus {
    /// Distance along the view axis to the plane in focus, scene units (> 0; infinity focuses
    /// at infinity).
    Distance(f32),
    /// A world-space point that must be in focus.
    Point(Vec3),
    /// Autofocus: the surface seen through this pixel (x right, y down) is in focus.
    Pixel {
        /// Pixel column, from 0 at the left.
        x: u32,
        /// Pixel row, from 0 at the top.
        y: u32,
    },
}

/// Everything needed to build a [`Camera`].
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSpec {
    /// Camera position (the lens centre), world space.
    pub eye: Vec3,
    /// A point the camera looks at (must differ from `eye`).
    pub look_at: Vec3,
    /// Which way is up (any length, not parallel to the view direction).
    pub up: Vec3,
    /// Vertical field of view, degrees, in (0, 180); ignored by a photographic lens.
    pub vfov_deg: f32,
    /// Image width in pixels (>= 1).
    pub width: u32,
    /// Image height in pixels (>= 1).
    pub height: u32,
    /// The lens: how the aperture radius is given.
    pub lens: LensSpec,
    /// Where the lens is focused.
    pub focus: Focus,
    /// The aperture's outline (bokeh shape).
    pub aperture: ApertureShape,
    /// A real lens traced element by element ([`real_lens`]); when given, it replaces the
    /// thin lens: `lens`, `vfov_deg` and `aperture` are not used.
    pub real_lens: Option<RealLensSpec>,
}

/// A pinhole camera at (0, 0, 5) looking at the origin along -z (y up), 640 x 480 pixels with
/// a 40 degree vertical field of view, focused at the origin (5 units): give it a `lens` for
/// depth of field, e.g. `CameraSpec { lens: LensSpec::Aperture { radius: 0.1 }, ..Default::default() }`.
impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            eye: Vec3::new(0.0, 0.0, 5.0),
            look_at: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: DEFAULT_VFOV,
            width: DEFAULT_WIDTH,
            height: DEFAULT_HEIGHT,
            lens: LensSpec::Pinhole,
            focus: Focus::Distance(5.0),
            aperture: ApertureShape::default(),
            real_lens: None,
        }
    }
}

/// A camera ready to generate rays: where it stands and looks, its film, and its lens.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Lens centre, world space.
    pub eye: Vec3,
    /// Unit view axis.
    pub forward: Vec3,
    /// Unit image x axis (to the right), orthogonal to `forward`.
    pub right: Vec3,
    /// Unit image y axis (up), orthogonal to `forward` and `right`.
    pub up: Vec3,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// tan(vfov / 2).
    pub tan_half_vfov: f32,
    /// The lens: makes the rays and bounds their blur.
    pub lens: CameraLens,
}

impl CameraSpec {
    /// The vertical field of view in degrees: a photographic lens's, from its focal length and
    /// sensor width at this image's aspect, else `vfov_deg`. (Not validated; `build` checks it.)
    pub fn effective_vfov_deg(&self) -> f32 {
        match self.lens.photographic() {
            Some(p) => p.vfov_deg(self.width, self.height),
            None => self.vfov_deg,
        }
    }

    /// Validates the spec and builds the camera. `depth_of` answers autofocus queries: given a
    /// pinhole ray it returns the view-axis depth of the surface it hits (None for a miss).
    pub fn build(&self, depth_of: impl FnOnce(&Ray) -> Option<f32>) -> Result<Camera, CameraError> {
        check(self.width > 0, "width", "at least 1 pixel", self.width)?;
        check(self.height > 0, "height", "at least 1 pixel", self.height)?;
        let (forward, right, up) = self.view()?;
        let size = (self.width, self.height);
        let tan_half_vfov = match &self.real_lens {
            // Only autofocus looks before the lens is focused: along the chief rays of the lens
            // at infinity focus (placing a real lens traces its pupil tables: not twice).
            Some(real) if matches!(self.focus, Focus::Pixel { .. }) => {
                RealLens::build(real, f32::INFINITY, size)?.tan_half_vfov
            }
            Some(_) => 1.0,
            None => lens::tan_half_fov(self.checked_vfov_deg()?),
        };
        let mut camera = Camera {
            eye: self.eye,
            forward,
            right,
            up,
            width: self.width,
            height: self.height,
            tan_half_vfov,
            // Autofocus looks through the lens centre, which needs no aperture or focus yet.
            lens: CameraLens::Thin(ThinLens::new(0.0, 1.0, self.aperture)),
        };
        let focus_distance = self.focus_distance(&camera, depth_of)?;
        camera.lens = match &self.real_lens {
            Some(real) => {
                let lens = RealLens::build(real, focus_distance, size)?;
                camera.tan_half_vfov = lens.tan_half_vfov;
                CameraLens::Real(Box::new(lens))
            }
            None => CameraLens::Thin(ThinLens::build(
                &self.lens,
                self.aperture,
                focus_distance,
                camera.pixels_per_unit(),
                self.eye,
            )?),
        };
        Ok(camera)
    }

    /// The thin lens's field of view, its aperture shape and film checked.
    fn checked_vfov_deg(&self) -> Result<f32, CameraError> {
        self.check_aperture_shape()?;
        if let Some(p) = self.lens.photographic() {
            p.check_film()?;
        }
        let vfov_deg = self.effective_vfov_deg();
        match self.lens.photographic() {
            // Named after what the user gave: the focal length, not a derived angle.
            Some(p) if check_vfov(vfov_deg).is_err() => check(
                false,
                "focal_length_mm",
                "a focal length whose field of view on the sensor is between 0 and 180 degrees",
                format!(
                    "{} mm on a {} mm sensor ({vfov_deg} degrees)",
                    p.focal_length_mm, p.sensor_width_mm
                ),
            )?,
            _ => check_vfov(vfov_deg)?,
        }
        Ok(vfov_deg)
    }

    /// The unit view axis, image right and image up, checked.
    fn view(&self) -> Result<(Vec3, Vec3, Vec3), CameraError> {
        in_range("eye", self.eye)?;
        in_range("look_at", self.look_at)?;
        check(
            self.up.is_finite(),
            "up",
            "finite coordinates",
            format!("{:?}", self.up),
        )?;
        let forward = (self.look_at - self.eye).normalize_or_zero();
        check(
            forward != Vec3::ZERO,
            "look_at",
            "a point different from eye",
            format!("{:?}", self.look_at),
        )?;
        let right = forward.cross(self.up).normalize_or_zero();
        check(
            right != Vec3::ZERO,
            "up",
            "a direction not parallel to the view direction",
            format!("{:?}", self.up),
        )?;
        Ok((forward, right, right.cross(forward)))
    }

    fn check_aperture_shape(&self) -> Result<(), CameraError> {
        let a = &self.aperture;
        check(
            ApertureShape::blades_ok(a.blades),
            "aperture blades",
            "0 (circular) or at least 3",
            a.blades,
        )?;
        check(
            a.rotation_deg.is_finite(),
            "aperture rotation",
            "a finite angle",
            a.rotation_deg,
        )?;
        check(
            a.anamorphic.is_finite() && a.anamorphic > 0.0 && (1e-3..=1e3).contains(&a.anamorphic),
            "anamorphic ratio",
            "a number from 0.001 to 1000",
            a.anamorphic,
        )
    }

    /// The focus distance along the view axis, checked; autofocus asks `depth_of` about the
    /// pinhole ray of `camera` (whose lens need not be set yet).
    fn focus_distance(
        &self,
        camera: &Camera,
        depth_of: impl FnOnce(&Ray) -> Option<f32>,
    ) -> Result<f32, CameraError> {
        let distance = match self.focus {
            Focus::Distance(d) => d,
            Focus::Point(p) => {
                in_range("focus point", p)?;
                (p - self.eye).dot(camera.forward)
            }
            Focus::Pixel { x, y } => {
                if x >= self.width || y >= self.height {
                    return Err(CameraError::FocusPixelOutside {
                        x,
                        y,
                        width: self.width,
                        height: self.height,
                    });
                }
                let ray = camera.pinhole_ray(x as f32 + 0.5, y as f32 + 0.5);
                depth_of(&ray).ok_or(CameraError::FocusPixelMisses { x, y })?
            }
        };
        // Infinity is a focus distance (the lens focused at infinity); so is any huge number,
        // which behaves like it (the lens rays use 1 / distance).
        check(
            distance > 0.0,
            "focus distance",
            "a number > 0 (or inf)",
            distance,
        )?;
        Ok(distance)
    }
}

impl Camera {
    /// Pixels spanned by one scene unit at unit distance along the view axis.
    pub fn pixels_per_unit(&self) -> f32 {
        self.height as f32 / (2.0 * self.tan_half_vfov)
    }

    /// Diameter in pixels of the circle of confusion of a point at `depth` along the view axis
    /// (infinite depth gives the limit for points at infinity): the lens's bound,
    /// [`Lens::coc_px`].
    pub fn coc_px(&self, depth: f32) -> f32 {
        self.lens.coc_px(self, depth)
    }

    /// [`Camera::coc_px`] for a point imaged at film position `(px, py)` (pixels): the bound
    /// of the blur near there ([`Lens::coc_px_at`]), never above the whole film's.
    pub fn coc_px_at(&self, depth: f32, px: f32, py: f32) -> f32 {
        self.lens.coc_px_at(self, depth, Vec2::new(px, py))
    }

    /// Distance of the plane in focus along the view axis (may be infinite).
    pub fn focus_distance(&self) -> f32 {
        self.lens.focus_distance()
    }

    /// How film images move with the lens position, where they move rigidly
    /// ([`Lens::reprojection`]).
    pub fn reprojection(&self) -> Option<Reprojection> {
        self.lens.reprojection(self)
    }

    /// Aperture radius in scene units (0 = pinhole).
    pub fn aperture_radius(&self) -> f32 {
        self.lens.aperture_radius()
    }

    /// Unnormalised direction from the eye through film position (px, py) in pixels
    /// (x right, y down; pixel centres at +0.5). Its component along the view axis is 1.
    fn film_dir(&self, px: f32, py: f32) -> Vec3 {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half_vfov * aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half_vfov;
        self.forward + self.right * sx + self.up * sy
    }

    /// The ray through the lens centre (no depth of field).
    pub fn pinhole_ray(&self, px: f32, py: f32) -> Ray {
        self.lens.pinhole_ray(self, px, py)
    }

    /// The ray from lens position `lens` ([`Lens::lens_point`] of the lens's sample numbers)
    /// through the point on the plane in focus that film position (px, py) images
    /// ([`Camera::focus_point`]).
    pub fn lens_ray(&self, px: f32, py: f32, lens: Vec2) -> Ray {
        self.lens.ray(self, px, py, lens).0
    }

    /// [`Camera::lens_ray`] with its weight ([`Lens::ray`]): 1 through a thin lens, the
    /// irradiance relative to the film's centre through a real one (0: blocked).
    pub fn lens_ray_weighted(&self, px: f32, py: f32, lens: Vec2) -> (Ray, f32) {
        self.lens.ray(self, px, py, lens)
    }

    /// The point on the plane in focus that film position (px, py) images: every lens ray of
    /// that pixel passes through it (infinitely far when focused at infinity).
    pub fn focus_point(&self, px: f32, py: f32) -> Vec3 {
        self.lens.focus_point(self, px, py)
    }

    /// [`Camera::lens_ray_weighted`] for 16 samples at once ([`Lens::rays16`]): origins and
    /// unit directions as structure of arrays, bit for bit equal to it lane by lane, and
    /// their weights.
    #[inline]
    pub fn lens_rays16(
        &self,
        film: (&[f32; LANES], &[f32; LANES]),
        lens: (&[f32; LANES], &[f32; LANES]),
        origin: &mut [[f32; LANES]; 3],
        dir: &mut [[f32; LANES]; 3],
        weight: &mut [f32; LANES],
    ) {
        self.lens.rays16(self, film, lens, origin, dir, weight);
    }

    /// Where light entering the lens at entry position `entry` ([`Lens::entry_point`])
    /// crosses into it (for a thin lens, where the rays of that lens position leave it).
    pub fn entry_origin(&self, entry: Vec2) -> Vec3 {
        self.lens.entry_origin(self, entry)
    }

    /// Where light entering at `entry` from unit direction `dir` lands on the film, and what
    /// a light path there estimates ([`Lens::film_point`]).
    pub fn film_point(&self, entry: Vec2, dir: Vec3) -> Option<Landing> {
        self.lens.film_point(self, entry, dir)
    }

    /// Depth along the view axis of the point at parameter `t` of `ray` (unit direction).
    pub fn depth_along_axis(&self, ray: &Ray, t: f32) -> f32 {
        (ray.at(t) - self.eye).dot(self.forward)
    }

    /// Film position (px, py) of a world point's image through the middle of the lens
    /// ([`Lens::project`]: a real lens's distortion included), if it is in front.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        self.lens.project(self, p)
    }

    /// Film position (px, py) of a world point seen from the eye through a pinhole of the
    /// camera's field of view, if in front.
    pub fn pinhole_project(&self, p: Vec3) -> Option<Vec2> {
        let v = p - self.eye;
        let z = v.dot(self.forward);
        if z <= 0.0 {
            return None;
        }
        let aspect = self.width as f32 / self.height as f32;
        let sx = v.dot(self.right) / z / (self.tan_half_vfov * aspect);
        let sy = v.dot(self.up) / z / self.tan_half_vfov;
        Some(Vec2::new(
            (sx + 1.0) * 0.5 * self.width as f32,
            (1.0 - sy) * 0.5 * self.height as f32,
        ))
    }
}

impl HasKind for CameraError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::BadInput
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(lens: LensSpec) -> CameraSpec {
        CameraSpec {
            eye: Vec3::new(0.0, 1.2, -6.0),
            look_at: Vec3::new(0.0, 0.5, 4.0),
            up: Vec3::Y,
            vfov_deg: 40.0,
            width: 640,
            height: 480,
            lens,
            focus: Focus::Distance(12.5),
            aperture: ApertureShape::default(),
            real_lens: None,
        }
    }

    fn no_autofocus(_: &Ray) -> Option<f32> {
        None
    }

    /// The seed's formula, evaluated literally with image-side distances, then converted to
    /// pixels through the sensor size.
    #[test]
    fn coc_matches_the_seeds_formula() {
        let (focal_mm, n, sensor_w_mm) = (50.0f32, 2.8f32, 36.0f32);
        let cam = spec(LensSpec::Photographic {
            focal_length_mm: focal_mm,
            f_number: n,
            sensor_width_mm: sensor_w_mm,
        })
        .build(no_autofocus)
        .unwrap();
        let f = focal_mm as f64 / 1000.0;
        let p = cam.focus_distance() as f64;
        // Image distance for an object at distance x: 1/F = 1/x + 1/V.
        let image_dist = |x: f64| f * x / (x - f);
        let vp = image_dist(p);
        // The camera's field of view is set by F and the sensor, so the sensor that covers the
        // image at image distance Vp is sensor_w * Vp / F wide, and pixels per metre follow.
        let sensor_h = (sensor_w_mm as f64 / 1000.0) * 480.0 / 640.0 * vp / f;
        let px_per_m = 480.0 / sensor_h;
        for depth in [2.0f64, 5.0, 9.0, 12.5, 14.0, 20.0, 40.0] {
            let vd = image_dist(depth);
            let c = (vp - vd).abs() * f / (n as f64 * vd);
            let expected = c * px_per_m;
            let got = cam.coc_px(depth as f32) as f64;
            assert!(
                (got - expected).abs() <= 1e-3 * expected.max(1.0),
                "depth {depth}: coc_px {got} vs seed {expected}"
            );
        }
        assert_eq!(cam.coc_px(12.5), 0.0);
    }

    #[test]
    fn paper_lens_gives_the_designed_blur() {
        let cam = spec(LensSpec::Aperture { radius: 0.2 })
            .build(no_autofocus)
            .unwrap();
        // Front sphere centre is about 5 units from the eye along the axis: CoC near 30 px.
        let front = cam.coc_px(5.05);
        assert!((25.0..35.0).contains(&front), "{front}");
        let horizon = cam.coc_px(f32::INFINITY);
        assert!((15.0..25.0).contains(&horizon), "{horizon}");
    }

    #[test]
    fn seed_lens_gives_spread_pixels_at_the_range_limits() {
        let cam = spec(LensSpec::Seed {
            sharp_range: 2.0,
            spread: 3.0,
        })
        .build(no_autofocus)
        .unwrap();
        let near = cam.coc_px(10.5);
        let far = cam.coc_px(14.5);
        // Symmetric approximation: the true CoC is larger in front than behind, around spread.
        assert!(near > far && near < 3.6 && far > 2.5, "{near} {far}");
    }

    #[test]
    fn focus_point_and_autofocus_set_the_focus_distance() {
        let mut s = spec(LensSpec::Aperture { radius: 0.1 });
        s.focus = Focus::Point(s.eye + (s.look_at - s.eye).normalize() * 7.0 + Vec3::X);
        let cam = s.build(no_autofocus).unwrap();
        assert!((cam.focus_distance() - 7.0).abs() < 1e-4);
        s.focus = Focus::Pixel { x: 320, y: 240 };
        let cam = s.build(|ray| Some(ray.dir.length() * 9.0)).unwrap();
        assert!((cam.focus_distance() - 9.0).abs() < 1e-4);
        assert!(matches!(
            s.build(no_autofocus),
            Err(CameraError::FocusPixelMisses { .. })
        ));
        s.focus = Focus::Pixel { x: 640, y: 0 };
        assert!(matches!(
            s.build(no_autofocus),
            Err(CameraError::FocusPixelOutside { .. })
        ));
    }

    #[test]
    fn lens_rays_converge_on_the_plane_in_focus() {
        let cam = spec(LensSpec::Aperture { radius: 0.3 })
            .build(no_autofocus)
            .unwrap();
        let centre = cam.pinhole_ray(100.5, 50.5);
        let t = cam.focus_distance() / centre.dir.dot(cam.forward);
        let target = centre.at(t);
        for lens in [
            Vec2::new(1.0, 0.0),
            Vec2::new(-0.3, 0.7),
            Vec2::new(0.0, -1.0),
        ] {
            let r = cam.lens_ray(100.5, 50.5, lens);
            let t = (cam.focus_distance() - cam.depth_along_axis(&r, 0.0)) / r.dir.dot(cam.forward);
            assert!((r.at(t) - target).length() < 1e-4);
        }
        let p = cam.project(target).unwrap();
        assert!((p - Vec2::new(100.5, 50.5)).length() < 1e-2, "{p}");
    }

    #[test]
    fn batched_lens_rays_equal_single_ones_bit_for_bit() {
        let cam = spec(LensSpec::Aperture { radius: 0.3 })
            .build(no_autofocus)
            .unwrap();
        let px: [f32; 16] = std::array::from_fn(|i| 100.5 + (i as f32 * 0.13).sin());
        let py: [f32; 16] = std::array::from_fn(|i| 50.5 - (i as f32 * 0.29).cos());
        let lx: [f32; 16] = std::array::from_fn(|i| (i as f32 * 0.37).sin());
        let ly: [f32; 16] = std::array::from_fn(|i| (i as f32 * 0.61).cos() * 1.3);
        let (mut origin, mut dir) = ([[0.0; 16]; 3], [[0.0; 16]; 3]);
        let mut weight = [0.0; 16];
        cam.lens_rays16((&px, &py), (&lx, &ly), &mut origin, &mut dir, &mut weight);
        assert_eq!(weight, [1.0; 16]);
        for lane in 0..16 {
            let r = cam.lens_ray(px[lane], py[lane], Vec2::new(lx[lane], ly[lane]));
            for k in 0..3 {
                assert_eq!(origin[k][lane].to_bits(), r.origin[k].to_bits());
                assert_eq!(dir[k][lane].to_bits(), r.dir[k].to_bits());
            }
        }
    }

    #[test]
    fn bad_parameters_are_rejected_by_name() {
        let mut s = spec(LensSpec::Aperture { radius: -0.1 });
        assert!(
            s.build(no_autofocus)
                .unwrap_err()
                .to_string()
                .contains("aperture radius")
        );
        s.lens = LensSpec::Aperture { radius: 0.1 };
        s.focus = Focus::Distance(0.0);
        assert!(
            s.build(no_autofocus)
                .unwrap_err()
                .to_string()
                .contains("focus distance")
        );
        s.focus = Focus::Distance(f32::NAN);
        assert!(s.build(no_autofocus).is_err());
        s.focus = Focus::Distance(5.0);
        s.width = 0;
        assert!(
            s.build(no_autofocus)
                .unwrap_err()
                .to_string()
                .contains("width")
        );
        s.width = 10;
        s.aperture.blades = 2;
        assert!(
            s.build(no_autofocus)
                .unwrap_err()
                .to_string()
                .contains("blades")
        );
        s.aperture.blades = 6;
        s.lens = LensSpec::Photographic {
            focal_length_mm: 50.0,
            f_number: 0.0,
            sensor_width_mm: 36.0,
        };
        assert!(
            s.build(no_autofocus)
                .unwrap_err()
                .to_string()
                .contains("f_number")
        );
    }
}
