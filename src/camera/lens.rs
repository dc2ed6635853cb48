//! The lens as a seam: what a [`Camera`] asks of its lens ([`Lens`]), the ideal thin lens,
//! and the photographic lens's numbers (f-number, focal length, sensor) with the one
//! conversion between field of view and focal length.
//!
//! To add a lens: implement [`Lens`] for it, add a variant to [`super::CameraLens`] and a
//! line to its dispatch, and teach [`super::CameraSpec::build`] to make it (the traced lens
//! prescription, [`super::real_lens`], came this way). Renderers only see [`Camera`], which
//! forwards to its lens.

use glam::{Vec2, Vec3};

use super::aperture::{ApertureShape, LensFilter, aperture_point, aperture_points16};
use super::{
    Camera, CameraError, DEFAULT_FOCAL_LENGTH_MM, DEFAULT_SENSOR_WIDTH_MM, LensSpec, check,
    positive,
};
use crate::embree::{LANES, Ray};
use crate::limits::MAX_COORDINATE;

/// What a camera asks of its lens. Film positions are in pixels (x right, y down; pixel
/// centres at +0.5); lens sample numbers are in [0, 1)^2, and the lens maps them to its own
/// lens positions, which it later receives back to make rays and weight samples.
pub trait Lens {
    /// The lens position of lens sample numbers `u` (what [`Lens::ray`] takes).
    fn lens_point(&self, u: Vec2) -> Vec2;

    /// [`Lens::lens_point`] of 16 samples as structure of arrays, bit for bit equal to it
    /// lane by lane.
    fn lens_points16(&self, u: &[f32; LANES], v: &[f32; LANES]) -> ([f32; LANES], [f32; LANES]);

    /// The ray that leaves lens position `lens` for film position (px, py), and its weight:
    /// the irradiance it carries relative to the film's centre (1 for a thin lens; less
    /// towards a real lens's corners, 0 for a ray the lens blocks, whose ray is then any
    /// valid one).
    fn ray(&self, camera: &Camera, px: f32, py: f32, lens: Vec2) -> (Ray, f32);

    /// [`Lens::ray`] for 16 samples, each with its own film position (`px`, `py`) and lens
    /// position (`lens_x`, `lens_y`), bit for bit equal to it lane by lane; writes origins
    /// and unit directions as structure of arrays (x, y, z components), the layout of a ray
    /// packet, and the rays' weights. This is the hot path: an implementation keeps it free
    /// of calls and branches.
    fn rays16(
        &self,
        camera: &Camera,
        film: (&[f32; LANES], &[f32; LANES]),
        lens: (&[f32; LANES], &[f32; LANES]),
        origin: &mut [[f32; LANES]; 3],
        dir: &mut [[f32; LANES]; 3],
        weight: &mut [f32; LANES],
    );

    /// The ray through the centre of the lens (no depth of field): what autofocus looks along.
    fn pinhole_ray(&self, camera: &Camera, px: f32, py: f32) -> Ray;

    /// The film position (px, py) of world point `p`'s image through the middle of the lens
    /// (along [`Lens::pinhole_ray`]s: the pinhole projection for a thin lens, the chief rays'
    /// for a real one, distortion included); `None` when `p` is not in front of the lens.
    fn project(&self, camera: &Camera, p: Vec3) -> Option<Vec2>;

    /// The point that film position (px, py) images sharply: every ray of that film position
    /// passes through it (infinitely far when focused at infinity).
    fn focus_point(&self, camera: &Camera, px: f32, py: f32) -> Vec3;

    /// Where a light path enters the lens, for uniform numbers `u` in [0, 1)^2: the entry
    /// position [`Lens::entry_origin`] and [`Lens::film_point`] take. For a thin lens it is
    /// the lens position [`Lens::lens_point`] gives; a real lens's light enters through its
    /// front element.
    fn entry_point(&self, u: Vec2) -> Vec2;

    /// The world point of entry position `entry`, where light arriving there crosses into
    /// the lens.
    fn entry_origin(&self, camera: &Camera, entry: Vec2) -> Vec3;

    /// The inverse of [`Lens::ray`] for light arriving at the lens: where on the film light
    /// entering at `entry` from unit direction `dir` (pointing away from the lens, towards
    /// where the light comes from) lands, with what a light path there estimates
    /// ([`Landing`]). `None` when the lens does not pass it to the film, or the camera's own
    /// rays could not sample it. Light tracing ([`crate::render::light_trace`]) lands its
    /// paths with it.
    fn film_point(&self, camera: &Camera, entry: Vec2, dir: Vec3) -> Option<Landing>;

    /// The fraction of light paths from world point `from` whose entry positions (of
    /// uniform numbers) reach the film: 1 for a thin lens, less for a real lens's front
    /// element, which is larger than the beam it passes. Light tracing takes that many
    /// times more paths so the film gets as many.
    fn entry_yield(&self, camera: &Camera, from: Vec3) -> f32;

    /// Whether film images depart from the pinhole projection [`Camera::project`] (a real
    /// lens's distortion and pupil): footprints projected that way are then estimates, and
    /// nothing may be left out because of them.
    fn distorts(&self) -> bool;

    /// The weight under `filter` of a sample that crossed the lens at `lens`.
    fn weight(&self, filter: LensFilter, lens: Vec2) -> f32;

    /// An upper bound on the diameter in pixels of the blur (circle of confusion) of a point
    /// at `depth` along the view axis (infinite depth: points at infinity). The adaptive
    /// sampler trusts it to decide where a pixel needs many lens samples and where one
    /// anti-aliased sample is enough, so a lens whose blur is not a disc (aberrations,
    /// vignetting) must still return a bound of its blur's extent, never less.
    fn coc_px(&self, camera: &Camera, depth: f32) -> f32;

    /// [`Lens::coc_px`] for a point at `depth` whose image lies at film position `film`
    /// (pixels): still a bound, but of the blur near that film position only, where a lens's
    /// blur changes across the film (a real lens's field curvature and aberrations keep its
    /// corners soft where its centre is sharp). The bound over the whole film by default.
    fn coc_px_at(&self, camera: &Camera, depth: f32, film: Vec2) -> f32 {
        let _ = film;
        self.coc_px(camera, depth)
    }

    /// How the film image of a scene point moves with the lens position, when it moves
    /// rigidly over an aperture sampled uniformly (what sample reuse,
    /// [`crate::render::reuse`], needs); `None` for any other lens.
    fn reprojection(&self, camera: &Camera) -> Option<Reprojection>;

    /// Distance of the plane in focus along the view axis (may be infinite).
    fn focus_distance(&self) -> f32;

    /// Radius of the aperture (the entrance pupil) in scene units, 0 for a pinhole: what a
    /// render's metadata reports.
    fn aperture_radius(&self) -> f32;
}

/// An ideal thin lens: rays from a point of the aperture through the point on the plane in
/// focus that the film position images.
#[derive(Debug, Clone, PartialEq)]
pub struct ThinLens {
    /// Aperture radius in scene units (0 = pinhole).
    pub aperture_radius: f32,
    /// Distance of the plane in focus along the view axis (may be infinite).
    pub focus_distance: f32,
    /// 1 / `focus_distance` (0 when focused at infinity): lens rays are computed from it, so a
    /// huge focus distance behaves like infinity instead of overflowing.
    pub inv_focus_distance: f32,
    /// The aperture's outline (bokeh shape).
    pub aperture: ApertureShape,
}

impl ThinLens {
    /// A lens of `aperture_radius` focused at `focus_distance` (> 0, may be infinite).
    pub fn new(aperture_radius: f32, focus_distance: f32, aperture: ApertureShape) -> Self {
        Self {
            aperture_radius,
            focus_distance,
            inv_focus_distance: 1.0 / focus_distance,
            aperture,
        }
    }

    /// The thin lens that `spec` describes, focused at `focus_distance` (checked > 0) on a
    /// film of `pixels_per_unit` ([`Camera::pixels_per_unit`]), for a camera at `eye`.
    pub fn build(
        spec: &LensSpec,
        aperture: ApertureShape,
        focus_distance: f32,
        pixels_per_unit: f32,
        eye: Vec3,
    ) -> Result<Self, CameraError> {
        let aperture_radius = match *spec {
            LensSpec::Pinhole => 0.0,
            LensSpec::Aperture { radius } => {
                check(
                    radius.is_finite() && radius >= 0.0,
                    "aperture radius",
                    "a finite number >= 0",
                    radius,
                )?;
                radius
            }
            LensSpec::Photographic { .. } => {
                spec.photographic().expect("matched").aperture_radius()?
            }
            LensSpec::Seed {
                sharp_range,
                spread,
            } => {
                positive("sharp_range", sharp_range)?;
                check(
                    spread.is_finite() && spread >= 0.0,
                    "spread",
                    "a finite number >= 0",
                    spread,
                )?;
                let p = focus_distance;
                spread * p * p / (2.0 * pixels_per_unit * sharp_range)
            }
        };
        let lens = Self::new(aperture_radius, focus_distance, aperture);
        // Every lens ray starts within the aperture's extent of the eye: keep it in range
        // (a derived aperture too: a tiny f-number or sharp range gives a huge one).
        let extent = lens.aperture_extent();
        check(
            extent.is_finite() && eye.abs().max_element() + extent <= MAX_COORDINATE,
            "aperture radius",
            "finite, and small enough that the lens stays within 1e15 of the origin (check the f-number, sharp range, spread and anamorphic ratio)",
            format!(
                "{:e} ({extent:e} with the anamorphic ratio)",
                aperture_radius
            ),
        )?;
        Ok(lens)
    }

    /// The largest extent of the aperture (the CoC's largest diameter scales with it).
    fn aperture_extent(&self) -> f32 {
        self.aperture_radius * self.aperture.anamorphic.max(1.0)
    }
}

impl Lens for ThinLens {
    /// A point on the aperture's unit shape ([`aperture_point`]); rays scale it by the
    /// aperture radius.
    #[inline]
    fn lens_point(&self, u: Vec2) -> Vec2 {
        aperture_point(u, &self.aperture)
    }

    #[inline]
    fn lens_points16(&self, u: &[f32; LANES], v: &[f32; LANES]) -> ([f32; LANES], [f32; LANES]) {
        aperture_points16(u, v, &self.aperture)
    }

    /// Computed as the direction `film_dir - offset / focus_distance` (the direction to the
    /// focus point divided by the focus distance), so a lens focused at infinity gives
    /// parallel rays.
    fn ray(&self, camera: &Camera, px: f32, py: f32, lens: Vec2) -> (Ray, f32) {
        let offset = (camera.right * lens.x + camera.up * lens.y) * self.aperture_radius;
        let dir = camera.film_dir(px, py) - offset * self.inv_focus_distance;
        (Ray::new(camera.eye + offset, dir.normalize()), 1.0)
    }

    #[inline]
    fn rays16(
        &self,
        camera: &Camera,
        (px, py): (&[f32; LANES], &[f32; LANES]),
        (lens_x, lens_y): (&[f32; LANES], &[f32; LANES]),
        origin: &mut [[f32; LANES]; 3],
        dir: &mut [[f32; LANES]; 3],
        weight: &mut [f32; LANES],
    ) {
        *weight = [1.0; LANES];
        let (eye, right, up, r) = (camera.eye, camera.right, camera.up, self.aperture_radius);
        let (fwd, inv_fd) = (camera.forward, self.inv_focus_distance);
        let aspect = camera.width as f32 / camera.height as f32;
        let (w, h, tan) = (
            camera.width as f32,
            camera.height as f32,
            camera.tan_half_vfov,
        );
        for lane in 0..LANES {
            // Written out as glam evaluates film_dir, `(right * lx + up * ly) * r`,
            // `film_dir - offset * inv_fd` and `.normalize()` (v * (1 / sqrt(x*x + y*y + z*z))).
            let sx = (2.0 * px[lane] / w - 1.0) * tan * aspect;
            let sy = (1.0 - 2.0 * py[lane] / h) * tan;
            let (lx, ly) = (lens_x[lane], lens_y[lane]);
            let offx = (right.x * lx + up.x * ly) * r;
            let offy = (right.y * lx + up.y * ly) * r;
            let offz = (right.z * lx + up.z * ly) * r;
            let dx = (fwd.x + right.x * sx + up.x * sy) - offx * inv_fd;
            let dy = (fwd.y + right.y * sx + up.y * sy) - offy * inv_fd;
            let dz = (fwd.z + right.z * sx + up.z * sy) - offz * inv_fd;
            let (ox, oy, oz) = (eye.x + offx, eye.y + offy, eye.z + offz);
            let recip = 1.0 / (dx * dx + dy * dy + dz * dz).sqrt();
            origin[0][lane] = ox;
            origin[1][lane] = oy;
            origin[2][lane] = oz;
            dir[0][lane] = dx * recip;
            dir[1][lane] = dy * recip;
            dir[2][lane] = dz * recip;
        }
    }

    fn pinhole_ray(&self, camera: &Camera, px: f32, py: f32) -> Ray {
        Ray::new(camera.eye, camera.film_dir(px, py).normalize())
    }

    fn project(&self, camera: &Camera, p: Vec3) -> Option<Vec2> {
        camera.pinhole_project(p)
    }

    fn focus_point(&self, camera: &Camera, px: f32, py: f32) -> Vec3 {
        camera.eye + camera.film_dir(px, py) * self.focus_distance
    }

    fn entry_point(&self, u: Vec2) -> Vec2 {
        self.lens_point(u)
    }

    fn entry_origin(&self, camera: &Camera, lens: Vec2) -> Vec3 {
        camera.eye + (camera.right * lens.x + camera.up * lens.y) * self.aperture_radius
    }

    /// [`Lens::ray`]'s direction is `film_dir - offset / focus_distance` normalised, with the
    /// offset across the view axis and `film_dir`'s component along it 1: so `dir` divided by
    /// its axial component `c`, plus the offset term, is `film_dir`, which gives the film
    /// position. Film positions map to the plane at unit distance with pixels of side
    /// `s = 2 tan(vfov / 2) / height`, which a ray at angle theta to the axis sees as
    /// `s^2 cos^3 theta` steradians: `c^3 s^2`.
    fn film_point(&self, camera: &Camera, lens: Vec2, dir: Vec3) -> Option<Landing> {
        let c = dir.dot(camera.forward);
        if c.is_nan() || c <= 0.0 {
            return None;
        }
        let offset = (camera.right * lens.x + camera.up * lens.y) * self.aperture_radius;
        let film_dir = dir / c + offset * self.inv_focus_distance;
        let (w, h) = (camera.width as f32, camera.height as f32);
        let tan = camera.tan_half_vfov;
        let sx = film_dir.dot(camera.right) / (tan * (w / h));
        let sy = film_dir.dot(camera.up) / tan;
        let film = Vec2::new((sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h);
        let s = 2.0 * tan / h;
        let per_sr = 1.0 / (c * c * c * s * s);
        (film.is_finite() && per_sr.is_finite()).then_some(Landing { film, per_sr, lens })
    }

    fn entry_yield(&self, _camera: &Camera, _from: Vec3) -> f32 {
        1.0
    }

    fn distorts(&self) -> bool {
        false
    }

    /// The filter's weight at the sample's radius on the unstretched aperture.
    #[inline]
    fn weight(&self, filter: LensFilter, lens: Vec2) -> f32 {
        filter.weight(lens, self.aperture.anamorphic)
    }

    /// Exact for a thin lens, and so its own bound. For aperture diameter A focused at P, a
    /// point at depth D blurs to a disc of diameter `A |D - P| / D` on the plane in focus,
    /// which the image scales by `k / P` (k = [`Camera::pixels_per_unit`]):
    /// `coc = A k |D - P| / (D P)`. This equals the seed's `C = |Vp - Vd| F / (n Vd)` on the
    /// sensor converted to pixels (see the tests). An anamorphic aperture counts by its
    /// largest extent.
    fn coc_px(&self, camera: &Camera, depth: f32) -> f32 {
        let a = 2.0 * self.aperture_extent();
        let k = camera.pixels_per_unit();
        // |D - P| / (D P) = |1/P - 1/D|, which also holds for P or D infinite.
        let inv_d = 1.0 / depth.max(1e-6);
        a * k * (self.inv_focus_distance - inv_d).abs()
    }

    /// From [`Lens::film_point`]: a point at depth `z` seen from lens position `l` lands at
    /// `film_dir = (P - eye) / z + offset (1 / focus - 1 / z)`, so it moves by
    /// `k r (1 / focus - 1 / z)` pixels per unit of `l` (k = [`Camera::pixels_per_unit`]).
    /// Any aperture shape: `l` is the lens position as sampled on it.
    fn reprojection(&self, camera: &Camera) -> Option<Reprojection> {
        (self.aperture_radius > 0.0).then(|| Reprojection {
            scale: camera.pixels_per_unit() * self.aperture_radius,
            inv_focus_distance: self.inv_focus_distance,
            aperture: self.aperture,
        })
    }

    fn focus_distance(&self) -> f32 {
        self.focus_distance
    }

    fn aperture_radius(&self) -> f32 {
        self.aperture_radius
    }
}

/// Where light arriving at a lens lands on the film ([`Lens::film_point`]), and what a light
/// path there estimates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Landing {
    /// Film position, pixels.
    pub film: Vec2,
    /// The pixel measure per unit of the arriving light's radiance and solid angle: for a
    /// light path that entered at an entry position of uniform density and came from a
    /// direction of density `p` (per steradian), radiance `L` adds `L per_sr / p` to a pixel
    /// whose filter has unit density at `film`. For a thin lens it is the film area (square
    /// pixels) per steradian of the direction.
    pub per_sr: f32,
    /// The camera's lens position of the same ray, which the lens filter weighs.
    pub lens: Vec2,
}

/// How a scene point's film image moves with the lens position: seen from lens position `l`
/// (unit disc), a point at depth `z` along the view axis lands at
/// `c + shift(z) (l.x, -l.y)` pixels, `c` its image through the lens centre (film y points
/// down, lens y up). `|shift(z)|` is the radius of its circle of confusion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reprojection {
    /// Pixels per unit of `1 / focus - 1 / z`: the aperture radius times
    /// [`Camera::pixels_per_unit`].
    pub scale: f32,
    /// 1 / the focus distance (0 at infinity).
    pub inv_focus_distance: f32,
    /// The aperture the lens positions `l` are uniform over (lens units).
    pub aperture: ApertureShape,
}

impl Reprojection {
    /// The signed film motion (pixels per unit lens position) of a point at `depth` along the
    /// view axis (infinite: a point at infinity); positive beyond the focus.
    #[inline]
    pub fn shift(&self, depth: f32) -> f32 {
        self.scale * (self.inv_focus_distance - 1.0 / depth.max(1e-6))
    }

    /// How the shift changes across the film, pixels per pixel of centre, on the plane
    /// through the point `offset` from the eye with normal `normal` (world space; zero for
    /// a point at infinity, which gives zero). On a plane `1 / z` is linear in the film
    /// position, `(n.right u + n.up v + n.forward) / (n . offset)` at `(u, v) =`
    /// (centre - image centre) `/ k` with film y down, and the shift is linear in `1 / z`.
    /// Infinite for a plane seen edge-on.
    pub fn gradient(&self, camera: &Camera, offset: Vec3, normal: Vec3) -> Vec2 {
        if normal == Vec3::ZERO {
            return Vec2::ZERO;
        }
        let per_px = self.scale / (camera.pixels_per_unit() * normal.dot(offset));
        let g = Vec2::new(-normal.dot(camera.right), normal.dot(camera.up)) * per_px;
        if g.is_finite() {
            g
        } else {
            Vec2::splat(f32::INFINITY)
        }
    }

    /// Where the point that film position `film` saw from lens position `lens` at depth
    /// shift `shift` lands through the lens centre.
    #[inline]
    pub fn centre(film: Vec2, lens: Vec2, shift: f32) -> Vec2 {
        film - shift * Vec2::new(lens.x, -lens.y)
    }
}

/// A photographic lens's three numbers, scene units metres: the one place that turns them
/// into an aperture radius and a field of view, and checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photographic {
    /// Focal length, millimetres (> 0).
    pub focal_length_mm: f32,
    /// f-number: focal length over aperture diameter (> 0).
    pub f_number: f32,
    /// Sensor width, millimetres (> 0).
    pub sensor_width_mm: f32,
}

impl Photographic {
    /// A lens of f-number `f_number`; a focal length or sensor width not given is 50 mm or
    /// 36 mm (full frame).
    pub fn new(f_number: f32, focal_length_mm: Option<f32>, sensor_width_mm: Option<f32>) -> Self {
        Self {
            focal_length_mm: focal_length_mm.unwrap_or(DEFAULT_FOCAL_LENGTH_MM),
            f_number,
            sensor_width_mm: sensor_width_mm.unwrap_or(DEFAULT_SENSOR_WIDTH_MM),
        }
    }

    /// A lens of f-number `f_number` on a sensor `sensor_width_mm` wide (36 mm if not given)
    /// whose focal length is `focal_length_mm`, else the one that keeps vertical field of view
    /// `vfov_deg` on a `width` x `height` image (50 mm if that has none): a new aperture on a
    /// view that was framed without one must not reframe it.
    pub fn keeping_vfov(
        f_number: f32,
        focal_length_mm: Option<f32>,
        sensor_width_mm: Option<f32>,
        vfov_deg: f32,
        (width, height): (u32, u32),
    ) -> Self {
        let sensor = sensor_width_mm.unwrap_or(DEFAULT_SENSOR_WIDTH_MM);
        let kept = focal_length_of_vfov(vfov_deg, sensor, width, height);
        let focal = focal_length_mm.or((kept.is_finite() && kept > 0.0).then_some(kept));
        Self::new(f_number, focal, Some(sensor))
    }

    /// Checks the f-number, focal length or sensor width `value` named `name`: each must be a
    /// finite number > 0.
    pub fn check_number(name: &'static str, value: f32) -> Result<(), CameraError> {
        positive(name, value)
    }

    /// Checks the focal length and sensor width (what the field of view needs).
    pub fn check_film(&self) -> Result<(), CameraError> {
        Self::check_number("focal_length_mm", self.focal_length_mm)?;
        Self::check_number("sensor_width_mm", self.sensor_width_mm)
    }

    /// The aperture radius in scene units (metres): `focal_length / (2 f_number)`, after
    /// checking the f-number.
    pub fn aperture_radius(&self) -> Result<f32, CameraError> {
        Self::check_number("f_number", self.f_number)?;
        Ok(self.focal_length_mm / 1000.0 / (2.0 * self.f_number))
    }

    /// The vertical field of view in degrees on a `width` x `height` image (not validated).
    pub fn vfov_deg(&self, width: u32, height: u32) -> f32 {
        vfov_deg_of_focal_length(self.focal_length_mm, self.sensor_width_mm, width, height)
    }

    /// The lens as a [`LensSpec`].
    pub fn spec(self) -> LensSpec {
        LensSpec::Photographic {
            focal_length_mm: self.focal_length_mm,
            f_number: self.f_number,
            sensor_width_mm: self.sensor_width_mm,
        }
    }
}

/// tan(vfov / 2) of a vertical field of view in degrees.
pub fn tan_half_fov(vfov_deg: f32) -> f32 {
    (vfov_deg.to_radians() * 0.5).tan()
}

/// The vertical field of view in degrees of a lens of focal length `focal_length_mm` on a
/// sensor `sensor_width_mm` wide, for a `width` x `height` image. Inverse of
/// [`focal_length_of_vfov`].
pub fn vfov_deg_of_focal_length(
    focal_length_mm: f32,
    sensor_width_mm: f32,
    width: u32,
    height: u32,
) -> f32 {
    let tan_half_h = sensor_width_mm / (2.0 * focal_length_mm);
    let tan_half_v = tan_half_h * height as f32 / width as f32;
    2.0 * tan_half_v.atan().to_degrees()
}

/// The focal length in millimetres that gives vertical field of view `vfov_deg` on a sensor
/// `sensor_width_mm` wide, for a `width` x `height` image. Inverse of
/// [`vfov_deg_of_focal_length`].
pub fn focal_length_of_vfov(vfov_deg: f32, sensor_width_mm: f32, width: u32, height: u32) -> f32 {
    let tan_half_h = tan_half_fov(vfov_deg) * width as f32 / height as f32;
    sensor_width_mm / (2.0 * tan_half_h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraSpec, Focus};

    /// An oblique 320 x 200 camera with a 0.2 aperture radius focused by `focus`.
    fn oblique(focus: Focus) -> CameraSpec {
        CameraSpec {
            eye: Vec3::new(0.5, 1.0, -2.0),
            look_at: Vec3::new(-1.0, 0.2, 4.0),
            width: 320,
            height: 200,
            lens: LensSpec::Aperture { radius: 0.2 },
            focus,
            ..CameraSpec::default()
        }
    }

    /// A scene point seen from any lens position lands where [`Reprojection`] says: its
    /// image through the lens centre moved by the shift at its depth times (l.x, -l.y); the
    /// shift's size times the aperture's outer radius is the CoC's radius. Through
    /// polygonal and anamorphic apertures too (lens positions as sampled on them).
    #[test]
    fn reprojection_moves_images_as_the_lens_rays_do() {
        let apertures = super::super::aperture::test_shapes();
        for (focus, aperture) in [Focus::Distance(3.0), Focus::Distance(f32::INFINITY)]
            .into_iter()
            .flat_map(|f| apertures.map(|a| (f, a)))
        {
            let spec = CameraSpec {
                aperture,
                ..oblique(focus)
            };
            let camera = spec.build(|_| None).unwrap();
            let re = camera.reprojection().unwrap();
            assert_eq!(re.aperture, aperture);
            for (px, py, t) in [
                (160.0, 100.0, 1.5),
                (30.5, 170.25, 7.0),
                (300.0, 20.0, 40.0),
            ] {
                let point = camera.pinhole_ray(px, py).at(t);
                let depth = (point - camera.eye).dot(camera.forward);
                let shift = re.shift(depth);
                assert!(
                    (2.0 * shift.abs() * aperture.outer_radius() - camera.coc_px(depth)).abs()
                        < 1e-3 * (1.0 + shift.abs())
                );
                for lens in [Vec2::new(0.6, -0.3), Vec2::new(-0.2, 1.3)] {
                    let dir = (point - camera.entry_origin(lens)).normalize();
                    let film = camera.film_point(lens, dir).unwrap().film;
                    let want = Vec2::new(px, py) + shift * Vec2::new(lens.x, -lens.y);
                    assert!((film - want).length() < 5e-3, "{focus:?}: {film} vs {want}");
                }
            }
        }
    }

    /// `film_point` inverts `ray` for any lens position, and its film area per steradian is
    /// what a small square of film around that position subtends.
    #[test]
    fn film_point_inverts_the_lens_rays_and_measures_their_solid_angle() {
        for focus in [Focus::Distance(3.0), Focus::Distance(f32::INFINITY)] {
            let camera = CameraSpec {
                aperture: ApertureShape {
                    anamorphic: 1.5,
                    ..ApertureShape::default()
                },
                ..oblique(focus)
            }
            .build(|_| None)
            .unwrap();
            for (px, py, lx, ly) in [
                (160.0, 100.0, 0.0, 0.0),
                (3.5, 7.25, 0.9, -0.3),
                (310.0, 190.0, -0.5, 1.4),
            ] {
                let lens = Vec2::new(lx, ly);
                let ray = camera.lens_ray(px, py, lens);
                assert!((ray.origin - camera.entry_origin(lens)).length() < 1e-6);
                let crate::camera::Landing { film, per_sr, .. } =
                    camera.film_point(lens, ray.dir).unwrap();
                assert!(
                    (film - Vec2::new(px, py)).length() < 2e-3,
                    "{focus:?}: {film} for ({px}, {py})"
                );
                // The solid angle of a 0.5 px square by the cross product of its edges' rays.
                let h = 0.25;
                let d = |x: f32, y: f32| camera.lens_ray(x, y, lens).dir;
                let (a, b) = (d(px + h, py) - d(px - h, py), d(px, py + h) - d(px, py - h));
                let solid = a.cross(b).length();
                let want = (2.0 * h) * (2.0 * h) / solid;
                assert!((per_sr / want - 1.0).abs() < 1e-2, "{per_sr} vs {want}");
            }
            // Nothing on the film looks backwards.
            assert!(camera.film_point(Vec2::ZERO, -camera.forward).is_none());
        }
    }

    #[test]
    fn focal_length_and_field_of_view_are_inverse() {
        for (focal, sensor, w, h) in [(50.0, 36.0, 640, 480), (85.0, 24.0, 300, 500)] {
            let vfov = vfov_deg_of_focal_length(focal, sensor, w, h);
            let back = focal_length_of_vfov(vfov, sensor, w, h);
            assert!(
                (back - focal).abs() < 1e-3 * focal,
                "{focal} -> {vfov} -> {back}"
            );
        }
        // 50 mm on full frame at 3:2 is the classic 27 degrees vertically.
        let vfov = Photographic::new(2.0, None, None).vfov_deg(1500, 1000);
        assert!((vfov - 26.99).abs() < 0.01, "{vfov}");
    }

    #[test]
    fn the_photographic_lens_checks_its_numbers_by_name() {
        let lens = Photographic::new(0.0, Some(50.0), None);
        assert!(lens.check_film().is_ok());
        let e = lens.aperture_radius().unwrap_err().to_string();
        assert_eq!(e, "f_number must be a finite number > 0, got 0");
        let e = Photographic::new(2.0, Some(f32::NAN), None).check_film();
        assert!(
            e.unwrap_err()
                .to_string()
                .starts_with("focal_length_mm must be")
        );
        let radius = Photographic::new(2.0, None, None)
            .aperture_radius()
            .unwrap();
        assert_eq!(radius, 0.05 / 4.0);
    }
}
