//! A real lens: rays traced from the film through every element of a lens prescription
//! ([`optics`]), after Kolb, Mitchell and Hanrahan (1995) and pbrt-v4's
//! `RealisticCamera`, with what the adaptive sampler needs of it.
//!
//! - **Placement.** The camera's position (`eye`) is the lens's entrance pupil at infinity
//!   focus, its centre of perspective, so a real lens frames a scene as a thin lens of the
//!   same focal length does. The film stays where it is; focusing moves the lens forward
//!   (the paraxial focus solve of [`optics::focus_film_distance`], refined to the smallest
//!   RMS spot by [`optics::best_focus`]), so the field of view breathes with focus as the
//!   lens's own does.
//! - **Sampling.** Rays from a film point are aimed at the rear element within a bound of
//!   the exit pupil that depends on the film point's distance from the axis (computed once
//!   per focus setting by tracing a grid, as pbrt does), uniformly over it; a ray the lens
//!   blocks is lost (its weight is 0: optical vignetting, cat's-eye bokeh).
//! - **Radiometry.** A ray's weight is `cos^4(theta) A / z^2` (irradiance on the film from
//!   the rear pupil bound of area `A` at distance `z`, natural vignetting included),
//!   divided by that of the film's centre: the centre of the frame is exposed as a thin
//!   lens exposes it, the corners darken as the real lens darkens them.
//! - **Blur bound** (`blur_table.rs`). A table over inverse depth and film radius of the
//!   spot a point at that depth makes there (`spot.rs`: at nine film radii, the extent of
//!   where the film point's rays cross the point's plane, searched on its pupil's rim and
//!   inside it, from rays each radius's spots share traced once; 5% wider), linear in
//!   inverse depth between knots, one of which is the focus distance's. [`Lens::coc_px`] is
//!   the largest over the radii; [`Lens::coc_px_at`], what the adaptive sampler's blur map
//!   reads per pixel, the larger of the two radii that bracket the pixel's, so a lens whose
//!   centre is sharp and whose corners are soft (field curvature, coma) is sampled as sharp
//!   in the middle.
//!
//! - **Light tracing.** Light paths enter through the front element's clear aperture,
//!   sampled uniformly by area ([`FrontCap`]), and are traced through the lens to the film
//!   ([`Lens::film_point`]); by conservation of étendue their contribution is the camera's
//!   own measure, so the two estimators meet exactly. Paths the camera's pupil bounds could
//!   not sample are dropped with them, which keeps the split between the two exact. The front
//!   element is larger than the beam any one point sends through, so light tracing takes
//!   more paths by [`Lens::entry_yield`].
//!
//! Lens positions ([`Lens::lens_point`]) are points of [-1, 1]^2, mapped onto each film
//! point's pupil bound. Sample reuse ([`Lens::reprojection`]) has no real-lens form yet:
//! the renderer leaves it out.

use std::sync::Arc;

use glam::{DVec2, DVec3, Vec2, Vec3};

use super::aperture::LensFilter;
use super::lens::{Landing, Lens, Reprojection};
use super::optics::{self, FrontCap, LensRay, Optics};
use super::prescription::Prescription;
use super::{Camera, CameraError, check};
use crate::embree::{LANES, Ray};

mod blur_table;
mod chief;
mod landing;
mod spot;

use blur_table::BlurTable;
use landing::YieldTable;

/// What a scene or program gives for a real lens.
#[derive(Debug, Clone, PartialEq)]
pub struct RealLensSpec {
    /// The lens's prescription (shared: cameras of an animation reuse it).
    pub prescription: Arc<Prescription>,
    /// Stop the lens down to this f-number (`None`: wide open). It cannot open wider than
    /// the prescription's stop allows.
    pub f_number: Option<f32>,
    /// Sensor width, millimetres; the film's height follows from the image's aspect.
    pub sensor_width_mm: f32,
}

impl RealLensSpec {
    /// The lens in the prescription file at `path`, wide open on a film of the default
    /// width ([`super::DEFAULT_SENSOR_WIDTH_MM`]); errors name the file and line.
    pub fn load(path: &std::path::Path) -> Result<Self, super::LensFileError> {
        Ok(Self {
            prescription: Arc::new(Prescription::load(path)?),
            f_number: None,
            sensor_width_mm: super::DEFAULT_SENSOR_WIDTH_MM,
        })
    }
}

/// Radial bins of the exit pupil bounds over the film's half diagonal.
const PUPIL_BINS: usize = 32;
/// Grid (per axis) over the rear element that the bounds are found with.
const PUPIL_GRID: usize = 40;
/// The blur table's spots over the traced ones: the rim's polygon is inside the rim by a
/// hair (its extremes are refined, `spot.rs`); spots between the radii and the bisection's
/// last step are covered by a few percent more.
const BLUR_MARGIN: f64 = 1.05;

/// An axis-aligned rectangle on the rear plane (lens space, mm), for a film point on +x.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bounds {
    lo: DVec2,
    hi: DVec2,
}

impl Bounds {
    fn area(&self) -> f64 {
        let e = (self.hi - self.lo).max(DVec2::ZERO);
        e.x * e.y
    }
    fn lerp(&self, u: DVec2) -> DVec2 {
        self.lo + (self.hi - self.lo) * u
    }
}

/// A lens prescription focused and ready to make rays ([`RealLensSpec`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RealLens {
    /// The lens's name (its file's first comment).
    pub name: String,
    /// The surfaces, placed for the focus distance.
    optics: Optics,
    /// The front element's clear aperture, where light paths enter.
    cap: FrontCap,
    /// Effective focal length (mm) and working f-number, the lens's own.
    pub focal_length_mm: f32,
    /// See `focal_length_mm`.
    pub f_number: f32,
    /// Entrance pupil radius, scene units (metres).
    entrance_radius: f32,
    focus_distance: f32,
    /// Lens-space z of the camera's position (the entrance pupil at infinity focus).
    eye_z: f64,
    /// Film size of a pixel, mm.
    pitch: f64,
    /// Image size in pixels.
    size: (f64, f64),
    /// Film half diagonal, mm.
    half_diagonal: f64,
    pupil: Vec<Bounds>,
    /// Weight of the film's centre (see the module documentation).
    centre_irradiance: f64,
    /// The blur bound.
    blur: BlurTable,
    /// tan of half the vertical field of view of the chief rays, at this focus.
    pub tan_half_vfov: f32,
    /// Chief rays (leaving the front of the lens) of film points at increasing radii on +x,
    /// up to the first the lens blocks: [`Lens::project`] inverts them.
    chief: Vec<(f64, LensRay)>,
    /// [`Lens::entry_yield`]'s table, made when light tracing first asks.
    yields: YieldTable,
}

impl RealLens {
    /// Places `spec`'s lens for a `width` x `height` image focused at `focus_distance` scene
    /// units (metres) from the camera along the view axis.
    pub fn build(
        spec: &RealLensSpec,
        focus_distance: f32,
        (width, height): (u32, u32),
    ) -> Result<Self, CameraError> {
        let p = &*spec.prescription;
        check(
            spec.sensor_width_mm.is_finite() && spec.sensor_width_mm > 0.0,
            "sensor_width_mm",
            "a finite number > 0",
            spec.sensor_width_mm,
        )?;
        let not_imaging = || CameraError::Invalid {
            name: "lens",
            expected: "a prescription that forms an image of distant objects behind it",
            value: p.name.clone(),
        };
        let wide_open = Optics::new(p, 0.0, 1.0);
        let para = wide_open.paraxial().ok_or_else(not_imaging)?;
        let open_f = para.efl / (2.0 * wide_open.entrance_pupil_radius());
        let stop_scale = match spec.f_number {
            None => 1.0,
            Some(n) => {
                check(
                    n.is_finite() && f64::from(n) >= open_f * 0.999,
                    "f_number",
                    "at least the lens's widest aperture (its prescription's stop)",
                    format!("{n} ({} opens to f/{open_f:.2})", p.name),
                )?;
                stop_scale_for(p, para.efl, f64::from(n))
            }
        };
        let infinity = Optics::new(p, para.bfd, stop_scale);
        let eye_z = infinity
            .paraxial()
            .ok_or_else(not_imaging)?
            .entrance_pupil_z;
        let d_mm = f64::from(focus_distance) * 1000.0;
        let film = optics::focus_film_distance(p, stop_scale, para.bfd, eye_z, d_mm)
            .filter(|f| f.is_finite() && *f > 0.0)
            .map(|f| {
                if d_mm.is_finite() && d_mm < 1e7 {
                    optics::best_focus(p, stop_scale, f, eye_z + d_mm, para.bfd)
                } else {
                    f
                }
            });
        let film = film.ok_or_else(|| CameraError::Invalid {
            name: "focus distance",
            expected: "farther than the closest distance the lens can focus",
            value: format!("{focus_distance} ({})", p.name),
        })?;
        let optics = Optics::new(p, film, stop_scale);
        let focused = optics.paraxial().ok_or_else(not_imaging)?;
        let pitch = f64::from(spec.sensor_width_mm) / f64::from(width);
        let size = (f64::from(width), f64::from(height));
        let mut lens = Self {
            name: p.name.clone(),
            focal_length_mm: focused.efl as f32,
            f_number: (focused.efl / (2.0 * optics.entrance_pupil_radius())) as f32,
            entrance_radius: (optics.entrance_pupil_radius() * 1e-3) as f32,
            focus_distance,
            eye_z,
            pitch,
            size,
            half_diagonal: 0.5 * pitch * size.0.hypot(size.1),
            cap: FrontCap::of(&optics),
            optics,
            pupil: Vec::new(),
            centre_irradiance: 1.0,
            blur: BlurTable::default(),
            tan_half_vfov: 0.0,
            chief: Vec::new(),
            yields: YieldTable::default(),
        };
        lens.pupil = lens.pupil_bounds();
        lens.centre_irradiance = lens.centre_irradiance();
        check(
            lens.centre_irradiance > 0.0,
            "lens",
            "a prescription that passes light to the film's centre",
            p.name.clone(),
        )?;
        let top = lens.chief_ray(DVec2::new(0.0, 0.5 * size.1 * pitch));
        lens.tan_half_vfov = top.map_or(0.0, |(_, d)| (d.y.hypot(d.x) / d.z) as f32);
        check(
            lens.tan_half_vfov.is_finite() && lens.tan_half_vfov > 0.0,
            "sensor_width_mm",
            "a film the lens covers (its chief ray reaches the top edge)",
            format!("{} mm with {}", spec.sensor_width_mm, p.name),
        )?;
        lens.blur = lens.blur_table();
        lens.chief = lens.chief_rays();
        Ok(lens)
    }

    /// The surfaces as placed for the focus distance (lens space: film at z = 0, scene
    /// towards +z, millimetres).
    pub fn optics(&self) -> &Optics {
        &self.optics
    }

    /// Lens-space z of the camera's position (its entrance pupil at infinity focus).
    pub fn eye_z(&self) -> f64 {
        self.eye_z
    }

    /// The film point (lens space, mm) of film position (px, py) in pixels: the image is
    /// inverted on the film.
    fn film(&self, px: f32, py: f32) -> DVec2 {
        DVec2::new(
            -(f64::from(px) - 0.5 * self.size.0) * self.pitch,
            (f64::from(py) - 0.5 * self.size.1) * self.pitch,
        )
    }

    /// The bound of the exit pupil for film points at radius `r`.
    fn bounds_at(&self, r: f64) -> &Bounds {
        let k = (r / self.half_diagonal * PUPIL_BINS as f64) as usize;
        &self.pupil[k.min(PUPIL_BINS - 1)]
    }

    /// The ray from film point `f` through pupil position `u` in [0, 1]^2 of its bound, and
    /// the irradiance weight before normalisation; `None` when the lens blocks it.
    fn trace(&self, f: DVec2, u: DVec2) -> Option<(LensRay, f64)> {
        self.trace_in(self.bounds_at(f.length()), f, u)
    }

    /// [`RealLens::trace`] through pupil bound `b`, whatever `f`'s own.
    fn trace_in(&self, b: &Bounds, f: DVec2, u: DVec2) -> Option<(LensRay, f64)> {
        let r = f.length();
        let area = b.area();
        if area <= 0.0 {
            return None;
        }
        let q = b.lerp(u);
        let (c, s) = azimuth(f, r);
        let q = DVec2::new(c * q.x - s * q.y, s * q.x + c * q.y);
        let z = self.optics.rear_z();
        let d = (DVec3::new(q.x - f.x, q.y - f.y, z)).normalize();
        let out = self.optics.trace_from_film((f.extend(0.0), d))?;
        let cos2 = d.z * d.z;
        Some((out, cos2 * cos2 * area / (z * z)))
    }

    /// The ray through the middle of film point `f`'s pupil bound (its chief ray), if the
    /// lens passes it.
    fn chief_ray(&self, f: DVec2) -> Option<LensRay> {
        self.trace(f, DVec2::splat(0.5)).map(|(r, _)| r)
    }

    /// Exit pupil bounds per radial bin: the rear-plane points through which rays from film
    /// points of the bin pass the lens, grown by a grid cell.
    fn pupil_bounds(&self) -> Vec<Bounds> {
        let reach = 1.5 * self.optics.rear_semi_aperture();
        let step = 2.0 * reach / PUPIL_GRID as f64;
        let z = self.optics.rear_z();
        (0..PUPIL_BINS)
            .map(|k| {
                let mut b = Bounds {
                    lo: DVec2::splat(f64::INFINITY),
                    hi: DVec2::splat(f64::NEG_INFINITY),
                };
                for j in 0..4 {
                    let r = (k as f64 + j as f64 / 3.0) / PUPIL_BINS as f64 * self.half_diagonal;
                    for gy in 0..=PUPIL_GRID {
                        for gx in 0..=PUPIL_GRID {
                            let q =
                                DVec2::new(-reach + gx as f64 * step, -reach + gy as f64 * step);
                            let d = DVec3::new(q.x - r, q.y, z).normalize();
                            let ray = (DVec3::new(r, 0.0, 0.0), d);
                            if self.optics.trace_from_film(ray).is_some() {
                                b.lo = b.lo.min(q);
                                b.hi = b.hi.max(q);
                            }
                        }
                    }
                }
                if b.lo.x > b.hi.x {
                    return Bounds {
                        lo: DVec2::ZERO,
                        hi: DVec2::ZERO,
                    };
                }
                Bounds {
                    lo: b.lo - DVec2::splat(step),
                    hi: b.hi + DVec2::splat(step),
                }
            })
            .collect()
    }

    /// The mean unnormalised weight at the film's centre.
    fn centre_irradiance(&self) -> f64 {
        self.mean_weight(DVec2::ZERO)
    }

    /// The mean unnormalised weight of film point `f`'s rays (its irradiance), over a 64 x 64
    /// grid of its pupil bound.
    fn mean_weight(&self, f: DVec2) -> f64 {
        let n = 64;
        let mut sum = 0.0;
        for j in 0..n {
            for i in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                sum += self.trace(f, u).map_or(0.0, |(_, w)| w);
            }
        }
        sum / (n * n) as f64
    }

    /// The blur diameter in pixels of a point `depth` scene units (metres) in front of the
    /// camera along the view axis, imaged `film_radius_mm` from the film's centre, as traced
    /// through the rim of the pupil (the blur table's entries, before their margin).
    pub fn blur_px(&self, film_radius_mm: f32, depth: f32) -> f32 {
        let z_plane = self.eye_z + f64::from(depth) * 1000.0;
        let f = DVec2::new(f64::from(film_radius_mm), 0.0);
        self.spot_rays(f).spot_px(z_plane, 1.0)
    }

    /// The fraction of the film's centre's irradiance that reaches film point
    /// `(x, y)` (mm from the centre): natural and optical vignetting.
    pub fn relative_illumination(&self, x: f32, y: f32) -> f32 {
        let f = DVec2::new(f64::from(x), f64::from(y));
        (self.mean_weight(f) / self.centre_irradiance) as f32
    }

    /// The blur table: for inverse depths from 0 (infinity) to that of a point 5 cm in
    /// front of the front element, the spot at each of its film radii, each radius's
    /// depth-independent rays traced once.
    fn blur_table(&self) -> BlurTable {
        self.blur_table_of(|f| {
            let rays = self.spot_rays(f);
            move |z_plane| rays.spot_px(z_plane, BLUR_MARGIN)
        })
    }

    /// The blur table of `spot`: `spot(f)`, made once per film radius, is film point `f`'s
    /// evaluator, which gives the spot (px) of a point at lens-space depth `z_plane` (mm).
    fn blur_table_of<E>(&self, spot: impl Fn(DVec2) -> E + Sync) -> BlurTable
    where
        E: Fn(f64) -> f32 + Send + Sync,
    {
        let nearest_mm = (self.optics.front_z() - self.eye_z).max(0.0) + 50.0;
        let inv_focus = 1.0 / f64::from(self.focus_distance);
        BlurTable::new(1000.0 / nearest_mm, inv_focus, |r| {
            let at = spot(DVec2::new(r * self.half_diagonal, 0.0));
            move |inv: f64| {
                // A plane far enough to stand for infinity when inv is 0.
                let depth_mm = if inv > 0.0 { 1000.0 / inv } else { 1e9 };
                at(self.eye_z + depth_mm)
            }
        })
    }

    /// The world ray of lens ray `(o, d)` (lens space, mm) for `camera`.
    fn world_ray(&self, camera: &Camera, (o, d): LensRay) -> Ray {
        let axes = |v: DVec3| {
            camera.right * v.x as f32 + camera.up * v.y as f32 + camera.forward * v.z as f32
        };
        let origin = camera.eye + axes(DVec3::new(o.x, o.y, o.z - self.eye_z) * 1e-3);
        Ray::new(origin, axes(d).normalize())
    }

    /// Lens space (mm) of world point `p` for `camera`: [`RealLens::world_ray`]'s inverse.
    fn lens_point_of(&self, camera: &Camera, p: Vec3) -> DVec3 {
        let v = p - camera.eye;
        let along = |a: Vec3| f64::from(v.dot(a)) * 1e3;
        DVec3::new(
            along(camera.right),
            along(camera.up),
            along(camera.forward) + self.eye_z,
        )
    }

    /// The ray of film position (px, py) and lens position `lens` with its weight (0: lost).
    fn weighted_ray(&self, camera: &Camera, px: f32, py: f32, lens: Vec2) -> (Ray, f32) {
        let u = (lens.as_dvec2() * 0.5 + 0.5).clamp(DVec2::ZERO, DVec2::ONE);
        match self.trace(self.film(px, py), u) {
            Some((ray, w)) => (
                self.world_ray(camera, ray),
                (w / self.centre_irradiance) as f32,
            ),
            None => (Ray::new(camera.eye, camera.forward), 0.0),
        }
    }
}

/// cos and sin of film point `f`'s angle about the axis (`r` its length; +x at the centre):
/// the rotation from the frame the pupil bounds are found in (film points on +x) to `f`'s.
fn azimuth(f: DVec2, r: f64) -> (f64, f64) {
    if r > 0.0 {
        (f.x / r, f.y / r)
    } else {
        (1.0, 0.0)
    }
}

/// The scale of `p`'s stop that makes its f-number (`efl` over the entrance pupil's
/// diameter) `n`, by bisection: the pupil is the stop's image, unless another element
/// limits the beam first.
fn stop_scale_for(p: &Prescription, efl: f64, n: f64) -> f64 {
    let f_number = |scale: f64| efl / (2.0 * Optics::new(p, 0.0, scale).entrance_pupil_radius());
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if f_number(mid) > n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

impl Lens for RealLens {
    fn lens_point(&self, u: Vec2) -> Vec2 {
        u * 2.0 - 1.0
    }

    fn lens_points16(&self, u: &[f32; LANES], v: &[f32; LANES]) -> ([f32; LANES], [f32; LANES]) {
        (u.map(|x| x * 2.0 - 1.0), v.map(|y| y * 2.0 - 1.0))
    }

    fn ray(&self, camera: &Camera, px: f32, py: f32, lens: Vec2) -> (Ray, f32) {
        self.weighted_ray(camera, px, py, lens)
    }

    fn rays16(
        &self,
        camera: &Camera,
        (px, py): (&[f32; LANES], &[f32; LANES]),
        (lens_x, lens_y): (&[f32; LANES], &[f32; LANES]),
        origin: &mut [[f32; LANES]; 3],
        dir: &mut [[f32; LANES]; 3],
        weight: &mut [f32; LANES],
    ) {
        for lane in 0..LANES {
            let lens = Vec2::new(lens_x[lane], lens_y[lane]);
            let (ray, w) = self.weighted_ray(camera, px[lane], py[lane], lens);
            for axis in 0..3 {
                origin[axis][lane] = ray.origin[axis];
                dir[axis][lane] = ray.dir[axis];
            }
            weight[lane] = w;
        }
    }

    /// The chief ray (through the middle of the pupil bound); the thin-lens direction from
    /// the eye where the lens passes none.
    fn pinhole_ray(&self, camera: &Camera, px: f32, py: f32) -> Ray {
        match self.chief_ray(self.film(px, py)) {
            Some(ray) => self.world_ray(camera, ray),
            None => Ray::new(camera.eye, camera.film_dir(px, py).normalize()),
        }
    }

    fn project(&self, camera: &Camera, p: Vec3) -> Option<Vec2> {
        self.image_of(camera, p)
    }

    fn focus_point(&self, camera: &Camera, px: f32, py: f32) -> Vec3 {
        let ray = self.pinhole_ray(camera, px, py);
        let along = ray.dir.dot(camera.forward).max(1e-6);
        let depth = self.focus_distance - (ray.origin - camera.eye).dot(camera.forward);
        ray.origin + ray.dir * (depth / along)
    }

    /// Uniform numbers of the front cap (by area).
    fn entry_point(&self, u: Vec2) -> Vec2 {
        u.clamp(Vec2::ZERO, Vec2::ONE)
    }

    fn entry_origin(&self, camera: &Camera, entry: Vec2) -> Vec3 {
        let (q, _) = self.cap.point(entry.as_dvec2());
        self.world_ray(camera, (q, DVec3::Z)).origin
    }

    fn film_point(&self, camera: &Camera, entry: Vec2, dir: Vec3) -> Option<Landing> {
        self.landing(camera, entry, dir)
    }

    fn entry_yield(&self, camera: &Camera, from: Vec3) -> f32 {
        self.yield_from(camera, from)
    }

    fn distorts(&self) -> bool {
        true
    }

    fn weight(&self, filter: LensFilter, lens: Vec2) -> f32 {
        filter.weight(lens, 1.0)
    }

    fn coc_px(&self, _camera: &Camera, depth: f32) -> f32 {
        self.blur.whole(depth)
    }

    fn coc_px_at(&self, _camera: &Camera, depth: f32, film: Vec2) -> f32 {
        let r = self.film(film.x, film.y).length() / self.half_diagonal;
        self.blur.near(depth, r)
    }

    fn reprojection(&self, _camera: &Camera) -> Option<Reprojection> {
        None
    }

    fn focus_distance(&self) -> f32 {
        self.focus_distance
    }

    fn aperture_radius(&self) -> f32 {
        self.entrance_radius
    }
}
