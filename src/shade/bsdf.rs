//! The scattering function at a hit: the glTF 2.0 metallic-roughness BSDF.
//!
//! Conventions: every direction is a unit vector pointing away from the surface; `wo` towards
//! where the light goes (the viewer), `wi` towards where it comes from; `n` is the unit shading
//! normal on `wo`'s side. Values returned by [`Bsdf::eval`] include the cosine, so a light
//! sample's contribution is `eval * radiance / pdf`.

use glam::Vec3;

/// Which part of the BSDF a sampled direction came from (the path tracer's bounce limits and
/// ray counts are kept per kind, as in Cycles).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lobe {
    /// Lambertian reflection.
    Diffuse,
    /// Microfacet (or mirror) reflection.
    Glossy,
    /// Refraction or thin-walled transmission through the surface.
    Transmission,
}

/// A direction drawn from the BSDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Unit direction the light comes from.
    pub wi: Vec3,
    /// `eval(wi) / pdf`: what the path's throughput is multiplied by.
    pub weight: Vec3,
    /// Solid-angle density of `wi` (for a delta lobe, the probability of choosing it).
    pub pdf: f32,
    /// The lobe it was drawn from.
    pub lobe: Lobe,
    /// The lobe is a delta (a perfect mirror or smooth glass): no light sample can find it, so
    /// multiple importance sampling gives the BSDF sample the whole weight.
    pub delta: bool,
}

/// The BSDF parameters at one point (glTF metallic-roughness, plus transmission and IOR).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bsdf {
    /// Base colour (linear RGB): the diffuse albedo of dielectrics, the specular colour of
    /// metals.
    pub base_color: Vec3,
    /// Metalness, 0 to 1.
    pub metallic: f32,
    /// Perceptual roughness, 0 to 1 (the GGX alpha is its square).
    pub roughness: f32,
    /// Fraction of the dielectric's diffuse part that is transmitted instead, 0 to 1.
    pub transmission: f32,
    /// Relative index of refraction across the surface, in the direction `wo` is on
    /// (inside / outside when `wo` is outside).
    pub eta: f32,
    /// Thin-walled: transmitted light passes straight through without bending.
    pub thin: bool,
}

impl Bsdf {
    /// A Lambertian reflector of albedo `color`.
    pub fn diffuse(color: Vec3) -> Self {
        Self {
            base_color: color,
            metallic: 0.0,
            roughness: 1.0,
            transmission: 0.0,
            eta: 1.5,
            thin: false,
        }
    }

    /// `f(wo, wi) |n . wi|`.
    pub fn eval(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
        let _ = wo;
        let cos = n.dot(wi);
        if cos <= 0.0 {
            return Vec3::ZERO;
        }
        self.base_color * (cos * std::f32::consts::FRAC_1_PI)
    }

    /// The solid-angle density with which [`Bsdf::sample`] draws `wi` (zero for delta lobes).
    pub fn pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        let _ = wo;
        n.dot(wi).max(0.0) * std::f32::consts::FRAC_1_PI
    }

    /// Draws a direction from three uniform numbers; `None` when the sample carries nothing.
    pub fn sample(&self, n: Vec3, wo: Vec3, u: [f32; 3]) -> Option<BsdfSample> {
        let _ = wo;
        let wi = cosine_hemisphere(n, u[1], u[2]);
        let pdf = self.pdf(n, wo, wi);
        (pdf > 0.0).then(|| BsdfSample {
            wi,
            weight: self.base_color,
            pdf,
            lobe: Lobe::Diffuse,
            delta: false,
        })
    }
}

/// An orthonormal basis around unit `n` (Duff et al. 2017, branchless).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// A direction about `n` with density `cos / pi` (Malley: a concentric disk point lifted).
pub fn cosine_hemisphere(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    let (x, y) = (r * phi.cos(), r * phi.sin());
    let z = (1.0 - u1).max(0.0).sqrt();
    let (t, b) = basis(n);
    (t * x + b * y + n * z).normalize()
}
