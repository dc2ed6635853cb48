//! Geometrical optics of a placed lens prescription: exact rays traced surface by surface
//! (Snell's law at each spherical interface; a ray outside a surface's clear aperture or
//! totally reflected is lost, which is how a real lens vignettes), and the paraxial numbers
//! traced rays give: effective focal length, back focal distance, pupils, f-number, and the
//! film distance that focuses a given object distance.
//!
//! Lens space, millimetres, f64: the optical axis is z, the film is the plane z = 0 and the
//! scene lies towards +z.

use glam::{DVec2, DVec3};

use super::prescription::Prescription;

/// One surface placed on the axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// Signed radius of curvature (positive: centre towards the film); 0 or infinite: flat.
    pub radius: f64,
    /// Axial position of its vertex.
    pub z: f64,
    /// Clear semi-aperture.
    pub semi_aperture: f64,
    /// Refractive index of the medium in front of it (scene side) and behind it (film side).
    pub n_front: f64,
    /// See `n_front`.
    pub n_back: f64,
    /// Whether it is the aperture stop (flat, no refraction).
    pub stop: bool,
}

/// A lens whose surfaces are placed: the prescription at one film distance, with its stop
/// possibly closed down.
#[derive(Debug, Clone, PartialEq)]
pub struct Optics {
    /// Front (scene side) to rear (film side).
    pub surfaces: Vec<Surface>,
}

/// A ray in lens space (unit direction).
pub type LensRay = (DVec3, DVec3);

/// The paraxial numbers of a lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Paraxial {
    /// Effective focal length, mm.
    pub efl: f64,
    /// Back focal distance: rear vertex to the rear focal point, mm.
    pub bfd: f64,
    /// Axial position of the entrance pupil (the stop imaged by the surfaces in front of it).
    pub entrance_pupil_z: f64,
}

impl Optics {
    /// `p` with its last surface `film_distance` mm in front of the film and the stop's
    /// aperture scaled by `stop_scale` (<= 1 closes it down).
    pub fn new(p: &Prescription, film_distance: f64, stop_scale: f64) -> Self {
        let n = p.surfaces.len();
        let mut surfaces = Vec::with_capacity(n);
        let mut z = film_distance;
        for i in (0..n).rev() {
            let s = &p.surfaces[i];
            if i + 1 < n {
                z += s.thickness_mm;
            }
            let n_front = if i == 0 { 1.0 } else { p.surfaces[i - 1].ior };
            let scale = if s.is_stop() { stop_scale } else { 1.0 };
            surfaces.push(Surface {
                radius: if s.radius_mm.is_infinite() {
                    0.0
                } else {
                    s.radius_mm
                },
                z,
                semi_aperture: 0.5 * s.aperture_mm * scale,
                n_front,
                n_back: s.ior,
                stop: s.is_stop(),
            });
        }
        surfaces.reverse();
        Self { surfaces }
    }

    /// The rear surface's vertex position (the film distance).
    pub fn rear_z(&self) -> f64 {
        self.surfaces.last().map_or(0.0, |s| s.z)
    }

    /// The front surface's vertex position.
    pub fn front_z(&self) -> f64 {
        self.surfaces.first().map_or(0.0, |s| s.z)
    }

    /// The rear surface's clear semi-aperture.
    pub fn rear_semi_aperture(&self) -> f64 {
        self.surfaces.last().map_or(0.0, |s| s.semi_aperture)
    }

    /// Traces a ray leaving the film side (towards +z) out of the front of the lens; `None`
    /// when it is lost (outside a clear aperture, missing a surface or totally reflected).
    pub fn trace_from_film(&self, ray: LensRay) -> Option<LensRay> {
        self.surfaces
            .iter()
            .rev()
            .try_fold(ray, |r, s| cross(s, r, s.n_back, s.n_front))
    }

    /// Traces a ray entering from the scene (towards -z) out of the rear of the lens.
    pub fn trace_from_scene(&self, ray: LensRay) -> Option<LensRay> {
        self.surfaces
            .iter()
            .try_fold(ray, |r, s| cross(s, r, s.n_front, s.n_back))
    }

    /// Effective focal length, back focal distance and entrance pupil from paraxial rays
    /// (tiny heights and angles, traced exactly). `None` for a lens that forms no image of
    /// infinity behind it (afocal or diverging).
    pub fn paraxial(&self) -> Option<Paraxial> {
        let h = 1e-4 * self.surfaces[0].semi_aperture;
        let start = DVec3::new(0.0, h, self.front_z() + 1.0);
        let (o, d) = self.trace_from_scene((start, DVec3::NEG_Z))?;
        if d.y.abs() < 1e-15 || d.y * o.y >= 0.0 {
            return None;
        }
        // Where the leaving ray crosses the axis (the rear focal point), and where it is at
        // the entering height (the rear principal plane).
        let focus = o.z + (-o.y / d.y) * d.z;
        let principal = o.z + ((h - o.y) / d.y) * d.z;
        let efl = principal - focus;
        if !(efl.is_finite() && efl > 0.0) {
            return None;
        }
        Some(Paraxial {
            efl,
            bfd: self.rear_z() - focus,
            entrance_pupil_z: self.entrance_pupil_z()?,
        })
    }

    /// Where the stop's paraxial image through the surfaces in front of it lies on the axis.
    fn entrance_pupil_z(&self) -> Option<f64> {
        let stop = self.surfaces.iter().position(|s| s.stop)?;
        let z = self.surfaces[stop].z;
        let angle = 1e-4;
        let d = DVec3::new(0.0, angle, 1.0).normalize();
        let front = Self {
            surfaces: self.surfaces[..stop].to_vec(),
        };
        let (o, d) = front.trace_from_film((DVec3::new(0.0, 0.0, z), d))?;
        if d.y.abs() < 1e-15 {
            return None;
        }
        Some(o.z - o.y / d.y * d.z)
    }

    /// The radius of the widest beam parallel to the axis that the lens passes (the
    /// entrance pupil's, at infinity focus), by bisection.
    pub fn entrance_pupil_radius(&self) -> f64 {
        let passes = |h: f64| {
            let start = DVec3::new(0.0, h, self.front_z() + 1.0);
            self.trace_from_scene((start, DVec3::NEG_Z)).is_some()
        };
        let (mut lo, mut hi) = (0.0, self.surfaces[0].semi_aperture);
        if passes(hi) {
            return hi;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if passes(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// Where the paraxial image of the axial point at `z_object` falls (on the axis, lens
    /// space), `None` if it forms none behind the lens.
    pub fn image_z(&self, z_object: f64) -> Option<f64> {
        let front = self.front_z();
        let h = 1e-4 * self.surfaces[0].semi_aperture;
        let d = (DVec3::new(0.0, h, front) - DVec3::new(0.0, 0.0, z_object)).normalize();
        let (o, d) =
            self.trace_from_scene(near_front(self, (DVec3::new(0.0, 0.0, z_object), d)))?;
        if d.y * o.y >= 0.0 {
            return None;
        }
        Some(o.z - o.y / d.y * d.z)
    }
}

/// The front surface's clear aperture as a surface light enters through: the part of its
/// sphere (or plane) within its semi-aperture, on the vertex's side of the centre, which
/// [`Optics::trace_from_scene`] accepts. Light tracing samples it uniformly by area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrontCap {
    surface: Surface,
    /// cos of the cap's half angle seen from the sphere's centre (1 for a plane).
    cos_alpha: f64,
    /// Area, mm^2.
    pub area: f64,
}

impl FrontCap {
    /// The cap of `optics`' front surface.
    pub fn of(optics: &Optics) -> Self {
        let surface = optics.surfaces[0];
        let (a, r) = (surface.semi_aperture, surface.radius.abs());
        if surface.radius == 0.0 {
            let area = std::f64::consts::PI * a * a;
            return Self {
                surface,
                cos_alpha: 1.0,
                area,
            };
        }
        // A semi-aperture beyond the radius leaves the whole hemisphere.
        let sin = (a / r).min(1.0);
        let cos_alpha = (1.0 - sin * sin).sqrt();
        Self {
            surface,
            cos_alpha,
            area: std::f64::consts::TAU * r * r * (1.0 - cos_alpha),
        }
    }

    /// The point of uniform numbers `u` in [0, 1]^2 (uniform by area: on a sphere the axial
    /// coordinate is uniform, Archimedes' hat-box theorem) and the unit normal there facing
    /// the scene (+z).
    pub fn point(&self, u: DVec2) -> (DVec3, DVec3) {
        let s = &self.surface;
        let azimuth = std::f64::consts::TAU * u.y;
        if s.radius == 0.0 {
            let rho = s.semi_aperture * u.x.sqrt();
            let p = DVec3::new(rho * azimuth.cos(), rho * azimuth.sin(), s.z);
            return (p, DVec3::Z);
        }
        let cos = 1.0 - u.x * (1.0 - self.cos_alpha);
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let r = s.radius.abs();
        // Convex towards the scene (radius > 0): the cap bulges to +z around a centre behind
        // the vertex; concave: it dips to -z around a centre in front.
        let sign = s.radius.signum();
        let centre_z = s.z - s.radius;
        let n = DVec3::new(sin * azimuth.cos(), sin * azimuth.sin(), sign * cos);
        let p = DVec3::new(r * n.x, r * n.y, centre_z + r * n.z);
        let facing = if sign > 0.0 { n } else { -n };
        (p, facing)
    }

    /// Whether a ray arriving along `d` (towards the lens) from `start` first meets the
    /// front surface `distance` along it, at the cap point it was aimed at (rays can graze a
    /// curved cap and meet it earlier elsewhere).
    pub fn first_hit_at(&self, start: DVec3, d: DVec3, distance: f64) -> bool {
        intersect(&self.surface, start, d)
            .is_some_and(|(t, _)| (t - distance).abs() < 1e-6 * distance.max(1.0))
    }
}

/// The film distance at which `p` (its stop scaled by `stop_scale`) images the axial point
/// `distance` mm in front of `origin_z`, where `origin_z` is measured in the lens at film
/// distance `start` (the lens moves, the film and the origin stay): solved by the secant
/// method on the paraxial image position. `None` if it cannot be focused there.
pub fn focus_film_distance(
    p: &Prescription,
    stop_scale: f64,
    start: f64,
    origin_z: f64,
    distance: f64,
) -> Option<f64> {
    if distance.is_infinite() {
        return Some(start);
    }
    let z_object = origin_z + distance;
    let miss = |film: f64| {
        let optics = Optics::new(p, film, stop_scale);
        if optics.front_z() >= z_object {
            return None;
        }
        optics.image_z(z_object)
    };
    let (mut a, mut b) = (start, start + 1e-3 * start.max(1.0));
    let (mut fa, mut fb) = (miss(a)?, miss(b)?);
    for _ in 0..60 {
        if fb.abs() < 1e-9 || (fb - fa).abs() < 1e-15 {
            break;
        }
        let c = b - fb * (b - a) / (fb - fa);
        if !c.is_finite() || c <= 0.0 {
            return None;
        }
        (a, fa) = (b, fb);
        b = c;
        fb = miss(b)?;
    }
    let (best, miss) = if fa.abs() < fb.abs() {
        (a, fa)
    } else {
        (b, fb)
    };
    (miss.abs() < 1e-6).then_some(best)
}

/// The RMS radius on the film (z = 0) of the rays from the axial point at `z_object` that
/// pass the lens, over a 21 x 21 grid of its front aperture; `None` if none pass.
pub fn rms_spot(optics: &Optics, z_object: f64) -> Option<f64> {
    let front = optics.surfaces[0];
    let from = DVec3::new(0.0, 0.0, z_object);
    let (mut sum, mut n) = (0.0, 0usize);
    for j in 0..21 {
        for i in 0..21 {
            let x = (i as f64 / 10.0 - 1.0) * front.semi_aperture;
            let y = (j as f64 / 10.0 - 1.0) * front.semi_aperture;
            let dir = (DVec3::new(x, y, front.z) - from).normalize();
            if let Some((o, d)) = optics.trace_from_scene(near_front(optics, (from, dir))) {
                let p = o + d * (-o.z / d.z);
                sum += p.x * p.x + p.y * p.y;
                n += 1;
            }
        }
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// The film distance near `paraxial` (the paraxial focus of the axial point at `z_object`,
/// in the lens space of film distance `start`) that makes that point's spot smallest (RMS):
/// best focus, which spherical aberration moves away from the paraxial one, as a camera's
/// contrast autofocus finds it. Golden-section search over +-2% of the film distance.
pub fn best_focus(
    p: &Prescription,
    stop_scale: f64,
    paraxial: f64,
    z_object: f64,
    start: f64,
) -> f64 {
    // The object stays put in the film's frame: lens space moves with the film distance only
    // through the surfaces, so z_object (measured from the film) is fixed.
    let _ = start;
    let spot = |film: f64| {
        let optics = Optics::new(p, film, stop_scale);
        if optics.front_z() >= z_object {
            return f64::INFINITY;
        }
        rms_spot(&optics, z_object).unwrap_or(f64::INFINITY)
    };
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (paraxial * 0.98, paraxial * 1.02);
    for _ in 0..48 {
        let (x1, x2) = (b - g * (b - a), a + g * (b - a));
        if spot(x1) < spot(x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    let best = 0.5 * (a + b);
    if spot(best) <= spot(paraxial) {
        best
    } else {
        paraxial
    }
}

/// `ray` (from the scene, towards the lens) moved along itself to 1 mm in front of the
/// front vertex: intersections computed from a distant origin lose their precision.
fn near_front(optics: &Optics, (o, d): LensRay) -> LensRay {
    let z = optics.front_z() + 1.0;
    if o.z <= z || d.z >= 0.0 {
        return (o, d);
    }
    (o + d * ((z - o.z) / d.z), d)
}

/// `ray` across surface `s` from the medium of index `n_in` into `n_out`.
fn cross(s: &Surface, (o, d): LensRay, n_in: f64, n_out: f64) -> Option<LensRay> {
    let (t, normal) = intersect(s, o, d)?;
    let p = o + d * t;
    if p.x * p.x + p.y * p.y > s.semi_aperture * s.semi_aperture {
        return None;
    }
    if s.stop || n_in == n_out {
        return Some((p, d));
    }
    Some((p, refract(d, normal, n_in / n_out)?))
}

/// The first intersection of ray (o, d) with the surface's cap around its vertex, and the
/// unit normal there (either orientation).
fn intersect(s: &Surface, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
    if s.radius == 0.0 {
        if d.z.abs() < 1e-300 {
            return None;
        }
        let t = (s.z - o.z) / d.z;
        return (t > 0.0).then_some((t, DVec3::Z));
    }
    let centre = DVec3::new(0.0, 0.0, s.z - s.radius);
    let oc = o - centre;
    let b = oc.dot(d);
    let c = oc.length_squared() - s.radius * s.radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    // The cap around the vertex lies on the vertex's side of the centre.
    [-b - root, -b + root]
        .into_iter()
        .find(|&t| t > 1e-9 && ((o.z + t * d.z) - centre.z) * s.radius > 0.0)
        .map(|t| (t, (o + d * t - centre) / s.radius))
}

/// Unit direction `d` refracted at unit `normal` with relative index `eta` = n_in / n_out;
/// `None` on total internal reflection.
fn refract(d: DVec3, normal: DVec3, eta: f64) -> Option<DVec3> {
    let n = if normal.dot(d) > 0.0 { -normal } else { normal };
    let cos_i = -n.dot(d);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((d * eta + n * (eta * cos_i - cos_t)).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A thin-ish biconvex singlet: the lensmaker's equation gives its focal length.
    #[test]
    fn a_singlet_focuses_where_the_lensmakers_equation_says() {
        let (r, n, t) = (100.0, 1.5, 0.01);
        let text = format!("{r} {t} {n} 20\n{} 1 1 20\n0 0 0 18\n", -r);
        let p = Prescription::parse(&text, "singlet").unwrap();
        let optics = Optics::new(&p, 80.0, 1.0);
        let para = optics.paraxial().unwrap();
        // 1/f = (n - 1) (2/R - (n - 1) t / (n R^2)).
        let want = 1.0 / ((n - 1.0) * (2.0 / r - (n - 1.0) * t / (n * r * r)));
        assert!(
            (para.efl / want - 1.0).abs() < 1e-6,
            "{} vs {want}",
            para.efl
        );
        // Snell at a flat surface from glass to air bends away from the normal.
        let bent = refract(DVec3::new(0.6, 0.0, -0.8), DVec3::Z, 1.5).unwrap();
        assert!((bent.x - 0.9).abs() < 1e-12);
        assert!(refract(DVec3::new(0.8, 0.0, -0.6), DVec3::Z, 1.5).is_none());
    }
}
