//! Where a real lens images a point: its chief rays, tabulated once per focus and inverted
//! at the point's depth ([`crate::camera::Lens::project`]), distortion included.

use glam::{DVec2, Vec2, Vec3};

use super::RealLens;
use crate::camera::Camera;
use crate::camera::optics::LensRay;

/// Chief rays tabulated for [`crate::camera::Lens::project`].
const CHIEF_RAYS: usize = 64;

impl RealLens {
    /// The chief rays of film points at [`CHIEF_RAYS`] radii from the centre to a quarter
    /// beyond the film's corner, up to the first the lens blocks or that leaves sideways.
    pub(super) fn chief_rays(&self) -> Vec<(f64, LensRay)> {
        (0..CHIEF_RAYS)
            .map(|k| k as f64 / (CHIEF_RAYS - 1) as f64 * 1.25 * self.half_diagonal)
            .map_while(|r| self.chief_ray(DVec2::new(r, 0.0)).map(|ray| (r, ray)))
            // A fisheye's corners look sideways or back: depths no longer order them.
            .take_while(|(_, (_, d))| d.z > 1e-3)
            .collect()
    }

    /// The film radius (mm) whose chief ray passes the axis distance `rho` at lens-space
    /// depth `z` (interpolated between the tabulated chief rays, extrapolated beyond them).
    fn film_radius_towards(&self, rho: f64, z: f64) -> Option<f64> {
        // Where chief ray k is at depth z, measured on the side it leaves towards (the image
        // is inverted: film points on +x look towards -x).
        let at = |k: usize| {
            let (_, (o, d)) = self.chief[k];
            -(o.x + d.x * (z - o.z) / d.z)
        };
        let n = self.chief.len();
        if n < 2 {
            return None;
        }
        // The first tabulated ray past rho (the rays fan out monotonically), by bisection.
        let (mut lo, mut hi) = (0, n - 1);
        if at(hi) > rho {
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if at(mid) > rho { hi = mid } else { lo = mid }
            }
        } else {
            lo = n - 2;
        }
        let (a, b) = (at(lo), at(lo + 1));
        let (ra, rb) = (self.chief[lo].0, self.chief[lo + 1].0);
        let t = if b != a { (rho - a) / (b - a) } else { 0.0 };
        let r = ra + (rb - ra) * t;
        r.is_finite().then_some(r.max(0.0))
    }

    /// [`crate::camera::Lens::project`]: the film radius whose chief ray reaches the
    /// point's distance from the axis at its depth, on the opposite side of the film (the
    /// image is inverted).
    pub(super) fn image_of(&self, camera: &Camera, p: Vec3) -> Option<Vec2> {
        let q = self.lens_point_of(camera, p);
        if q.z.is_nan() || q.z <= self.optics.front_z() {
            return None;
        }
        let rho = q.x.hypot(q.y);
        let r = self.film_radius_towards(rho, q.z)?;
        let (c, s) = if rho > 0.0 {
            (q.x / rho, q.y / rho)
        } else {
            (1.0, 0.0)
        };
        let film = Vec2::new(
            (r * c / self.pitch + 0.5 * self.size.0) as f32,
            (-r * s / self.pitch + 0.5 * self.size.1) as f32,
        );
        film.is_finite().then_some(film)
    }
}
