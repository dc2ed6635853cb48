//! Light arriving at a real lens, for light tracing: where it enters (the front element's
//! clear aperture), where it lands on the film and what it measures there
//! ([`crate::camera::Lens::film_point`]), and what share of the paths from a point land
//! ([`crate::camera::Lens::entry_yield`]).

use glam::{DVec2, DVec3, Vec2, Vec3};

use super::RealLens;
use crate::camera::{Camera, Landing};

/// The share of light paths that land, from points at [`YIELD_ANGLES`] angles off the axis
/// (0 to 90 degrees, seen from the eye) and [`YIELD_DEPTHS`] inverse distances (infinity to
/// 5 cm in front of the front element), built once on first use: light tracing asks it for
/// every small lamp (an emissive mesh may have thousands of triangles), and the answer only
/// sets how many paths each takes, so an interpolated one serves.
#[derive(Debug, Clone, Default)]
pub(super) struct YieldTable(std::sync::OnceLock<Vec<f32>>);

impl PartialEq for YieldTable {
    /// Derived from the lens: equal lenses have equal tables.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Angle bins of the yield table.
const YIELD_ANGLES: usize = 24;
/// Inverse-distance bins of the yield table.
const YIELD_DEPTHS: usize = 6;

impl RealLens {
    /// Light entering at the front cap's point of uniform numbers `u` from unit direction
    /// `out` (lens space, pointing back towards the light): the film point (mm) it lands on,
    /// the cosine between `out` and the cap's normal there, and the camera's lens position
    /// of the same ray. `None` when the lens blocks it, or the camera's rays from that film
    /// point (aimed within its exit pupil bound) cannot take that path.
    fn land(&self, u: DVec2, out: DVec3) -> Option<(DVec2, f64, Vec2)> {
        if out.z <= 0.0 {
            return None;
        }
        let (q, normal) = self.cap.point(u);
        let cos = normal.dot(out);
        if cos <= 0.0 {
            return None;
        }
        // Start 1 mm towards the light, and only if the cap is where it enters first.
        let start = q + out;
        if !self.cap.first_hit_at(start, -out, 1.0) {
            return None;
        }
        let (o, d) = self.optics.trace_from_scene((start, -out))?;
        if d.z >= 0.0 {
            return None;
        }
        let f = (o + d * (-o.z / d.z)).truncate();
        // The camera's ray from f runs back along the light: where it crosses the rear
        // plane, in the frame of f's pupil bound (rotated onto +x).
        let rear = f - d.truncate() * (self.optics.rear_z() / -d.z);
        let r = f.length();
        let (c, s) = super::azimuth(f, r);
        let local = DVec2::new(c * rear.x + s * rear.y, -s * rear.x + c * rear.y);
        let b = self.bounds_at(r);
        let t = (local - b.lo) / (b.hi - b.lo);
        let inside = t.cmpge(DVec2::ZERO).all() && t.cmple(DVec2::ONE).all();
        (inside && f.is_finite()).then(|| (f, cos, (t * 2.0 - 1.0).as_vec2()))
    }

    /// The inverse distance (1/mm, from the eye) of the yield table's nearest points: 5 cm in
    /// front of the front element.
    fn yield_max_inv(&self) -> f64 {
        1.0 / (self.optics.front_z() + 50.0 - self.eye_z).max(1.0)
    }

    /// The share of a 16 x 16 grid of the front cap's rays from lens-space point `p` that
    /// land on the film.
    fn landing_share(&self, p: DVec3) -> f32 {
        const N: usize = 16;
        let landed = (0..N * N)
            .filter(|k| {
                let u = (DVec2::new((k % N) as f64, (k / N) as f64) + 0.5) / N as f64;
                let (q, _) = self.cap.point(u);
                (p - q)
                    .try_normalize()
                    .and_then(|out| self.land(u, out))
                    .is_some()
            })
            .count();
        landed as f32 / (N * N) as f32
    }

    /// [`YieldTable`]'s entries, angle-major.
    fn yield_table(&self) -> Vec<f32> {
        let max_inv = self.yield_max_inv();
        let mut table = Vec::with_capacity(YIELD_ANGLES * YIELD_DEPTHS);
        for i in 0..YIELD_ANGLES {
            let angle = i as f64 / (YIELD_ANGLES - 1) as f64 * std::f64::consts::FRAC_PI_2;
            for j in 0..YIELD_DEPTHS {
                let inv = j as f64 / (YIELD_DEPTHS - 1) as f64 * max_inv;
                // Infinity: far enough that the rays are parallel.
                let distance = if inv > 0.0 { 1.0 / inv } else { 1e9 };
                let p = DVec3::new(
                    distance * angle.sin(),
                    0.0,
                    self.eye_z + distance * angle.cos(),
                );
                table.push(self.landing_share(p));
            }
        }
        table
    }

    /// [`crate::camera::Lens::film_point`]: light through the front cap (area `A`) lands
    /// where the traced lens takes it. Its étendue there is `A cos(n, dir) dw` per unit of
    /// entry numbers and of solid angle, which a lossless lens carries unchanged to the
    /// film, where the camera measures `cos(theta) dw dA_film / (C0 pitch^2)` per square
    /// pixel (C0: the centre's irradiance; the camera rays' weight is that measure), so
    /// `per_sr = A cos / (C0 pitch^2)`.
    pub(super) fn landing(&self, camera: &Camera, entry: Vec2, dir: Vec3) -> Option<Landing> {
        let axes = |a: Vec3| f64::from(dir.dot(a));
        let out = DVec3::new(axes(camera.right), axes(camera.up), axes(camera.forward));
        let (f, cos, lens) = self.land(entry.as_dvec2(), out.try_normalize()?)?;
        let film = Vec2::new(
            (-f.x / self.pitch + 0.5 * self.size.0) as f32,
            (f.y / self.pitch + 0.5 * self.size.1) as f32,
        );
        let per_sr =
            (self.cap.area * cos / (self.centre_irradiance * self.pitch * self.pitch)) as f32;
        (film.is_finite() && per_sr.is_finite() && per_sr > 0.0).then_some(Landing {
            film,
            per_sr,
            lens,
        })
    }

    /// [`crate::camera::Lens::entry_yield`]: the share of a 16 x 16 grid of the front cap's
    /// rays from `from` that land, interpolated in a table over the angle off the axis and
    /// the inverse distance.
    pub(super) fn yield_from(&self, camera: &Camera, from: Vec3) -> f32 {
        let p = self.lens_point_of(camera, from);
        let (rho, z) = (p.x.hypot(p.y), p.z - self.eye_z);
        let angle = rho.atan2(z);
        let inv = 1.0 / rho.hypot(z).max(1e-9);
        let table = self.yields.0.get_or_init(|| self.yield_table());
        let max_inv = self.yield_max_inv();
        let a = (angle / std::f64::consts::FRAC_PI_2).clamp(0.0, 1.0) * (YIELD_ANGLES - 1) as f64;
        let d = (inv / max_inv).clamp(0.0, 1.0) * (YIELD_DEPTHS - 1) as f64;
        let (i, j) = (
            (a as usize).min(YIELD_ANGLES - 2),
            (d as usize).min(YIELD_DEPTHS - 2),
        );
        let (fa, fd) = ((a - i as f64) as f32, (d - j as f64) as f32);
        let at = |i: usize, j: usize| table[i * YIELD_DEPTHS + j];
        let near = at(i, j) + (at(i + 1, j) - at(i, j)) * fa;
        let far = at(i, j + 1) + (at(i + 1, j + 1) - at(i, j + 1)) * fa;
        (near + (far - near) * fd).clamp(0.0, 1.0)
    }
}
