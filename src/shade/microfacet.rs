//! The isotropic GGX (Trowbridge-Reitz) microfacet pieces the BSDF is built from, and the
//! Fresnel terms of the glTF 2.0 material model. `a2` is alpha squared, alpha the squared
//! perceptual roughness; cosines are taken against the shading normal.

use std::f32::consts::{FRAC_1_PI, TAU};

use glam::Vec3;

/// The GGX normal distribution `D(m)` for a microfacet normal at `cos_m` from the normal, with
/// `sin2_m` its squared sine. Taking the sine separately (from a cross product) keeps the peak
/// accurate at small alpha, where `1 - cos^2` would cancel catastrophically.
#[inline]
pub(super) fn ggx_d(a2: f32, cos_m: f32, sin2_m: f32) -> f32 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let t = sin2_m + a2 * cos_m * cos_m;
    a2 * FRAC_1_PI / (t * t)
}

/// `sqrt(a2 + (1 - a2) cos^2)`, the term of Smith's masking both `G1` and the
/// height-correlated `V` are written with: `G1(c) = 2c / (c + s)`,
/// `V = G2 / (4 co ci) = 0.5 / (so ci + si co)`.
#[inline]
pub(super) fn smith_s(a2: f32, cos: f32) -> f32 {
    (a2 + (1.0 - a2) * cos * cos).sqrt()
}

/// A microfacet normal drawn from the distribution of normals visible from `wo` (Heitz 2018),
/// by the spherical-cap construction of Dupuy and Benyoub 2023 (the same density, branchless).
/// `wo` is in the local frame (normal = +z, `wo.z >= 0`); so is the result.
#[inline]
pub(super) fn sample_visible_normal(wo: Vec3, alpha: f32, u1: f32, u2: f32) -> Vec3 {
    // Stretch to the alpha = 1 configuration, where visible normals are a spherical cap.
    let v = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize_or(Vec3::Z);
    let phi = TAU * u1;
    let z = (1.0 - u2) * (1.0 + v.z) - v.z;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let h = Vec3::new(r * phi.cos(), r * phi.sin(), z) + v;
    Vec3::new(alpha * h.x, alpha * h.y, h.z.max(0.0)).normalize_or(Vec3::Z)
}

/// Schlick's `(1 - c)^5`.
#[inline]
pub(super) fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// The glTF conductor Fresnel: `base + (1 - base)(1 - c)^5`.
#[inline]
pub(super) fn conductor_fresnel(base: Vec3, cos: f32) -> Vec3 {
    base + (Vec3::ONE - base) * schlick_weight(cos)
}

/// The dielectric Fresnel reflectance of unpolarised light meeting a facet at `cos` on the
/// side of relative index `eta` (other side / this side): the exact formula, as Cycles'
/// Principled BSDF uses (Schlick's approximation is up to 20% low between 40 and 60 degrees
/// for glass). It is the same seen from either side (`F(cos_i, eta) = F(cos_t, 1 / eta)`), 1
/// under total internal reflection and 0 where there is no interface (eta = 1).
#[inline]
pub(super) fn dielectric_fresnel(eta: f32, cos: f32) -> f32 {
    let cos = cos.clamp(0.0, 1.0);
    let cos2_t = 1.0 - (1.0 - cos * cos) / (eta * eta);
    if cos2_t <= 0.0 {
        return 1.0;
    }
    let cos_t = cos2_t.sqrt();
    let rs = (cos - eta * cos_t) / (cos + eta * cos_t);
    let rp = (eta * cos - cos_t) / (eta * cos + cos_t);
    (0.5 * (rs * rs + rp * rp)).min(1.0)
}

/// The direction refracted from `wo` through a facet of normal `m` (`wo . m > 0`) into the side
/// of relative index `eta`, or `None` under total internal reflection.
#[inline]
pub(super) fn refract(wo: Vec3, m: Vec3, eta: f32) -> Option<Vec3> {
    let cos_o = wo.dot(m);
    let cos2_t = 1.0 - (1.0 - cos_o * cos_o) / (eta * eta);
    (cos2_t > 0.0).then(|| (-wo / eta + (cos_o / eta - cos2_t.sqrt()) * m).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::hash64;

    fn unit(seed: u64) -> f32 {
        (hash64(seed) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// `D` is a distribution of projected area: the integral of `D(m) cos m` over the
    /// hemisphere is 1 for every alpha (midpoint rule in cos m, which the integrand is smooth in
    /// once the peak is resolved).
    #[test]
    fn ndf_projects_to_unit_area() {
        for alpha in [0.01f32, 0.1, 0.5, 1.0] {
            let a2 = alpha * alpha;
            let steps = 200_000;
            let mut sum = 0.0f64;
            for i in 0..steps {
                let c = (i as f64 + 0.5) / steps as f64;
                let s2 = 1.0 - c * c;
                sum += ggx_d(a2, c as f32, s2 as f32) as f64 * c;
            }
            let integral = sum / steps as f64 * std::f64::consts::TAU;
            assert!((integral - 1.0).abs() < 2e-3, "alpha {alpha}: {integral}");
        }
    }

    /// The sampled visible normals have the visible-normal density: the sample mean of
    /// `g / pdf` for `g(m) = cos m (wo . m)` is the integral of `g` over the normals facing both
    /// the normal and `wo`, `(4/3) (sin^3 t / 2 + cos t ((pi - t) / 2 + sin 2t / 4))` for `wo` at
    /// angle `t` (integrated about the line the two horizons share).
    #[test]
    fn visible_normals_have_their_density() {
        for (k, (alpha, cos_o)) in [(0.2f32, 0.9f32), (0.6, 0.3), (1.0, 0.05)]
            .into_iter()
            .enumerate()
        {
            let a2 = alpha * alpha;
            let wo = Vec3::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
            let (n, so) = (200_000, smith_s(a2, cos_o));
            let mut sum = 0.0f64;
            for i in 0..n {
                let s = (k as u64) << 40 | (i as u64) << 1;
                let m = sample_visible_normal(wo, alpha, unit(s), unit(s + 1));
                let sin2 = m.x * m.x + m.y * m.y;
                let pdf = 2.0 / (cos_o + so) * ggx_d(a2, m.z, sin2) * wo.dot(m).max(0.0);
                sum += (m.z * wo.dot(m) / pdf) as f64;
            }
            let mean = sum / n as f64;
            let t = (cos_o as f64).acos();
            let pi = std::f64::consts::PI;
            let expected = 4.0 / 3.0
                * (t.sin().powi(3) / 2.0 + t.cos() * ((pi - t) / 2.0 + (2.0 * t).sin() / 4.0));
            assert!(
                (mean - expected).abs() < 0.01 * expected,
                "alpha {alpha} cos {cos_o}: {mean} vs {expected}"
            );
        }
    }
}
