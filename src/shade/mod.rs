//! Materials, textures and lights: what a surface looks like once a ray has found it.
//! All colours are linear radiance; sRGB appears only when 8-bit images are written.

mod albedo_table;
mod bsdf;
mod environment;
mod light;
mod material;
mod microfacet;
mod texture;

pub use bsdf::{Bsdf, BsdfSample, Lobe, Scattering, basis, cosine_hemisphere};
pub use environment::{EnvSample, EnvironmentError, EnvironmentMap, uniform_sphere};
pub use light::*;
pub use material::*;
pub use texture::*;

use glam::{Vec2, Vec3};

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// Local shading frame of a hit: everything shading needs, independent of geometry type.
#[derive(Debug, Clone, Copy)]
pub struct SurfacePoint {
    /// Hit position, world space.
    pub position: Vec3,
    /// Unit shading normal facing the incoming ray.
    pub normal: Vec3,
    /// Texture coordinates (v up).
    pub uv: Vec2,
}

/// The [`SurfacePoint`]s of a 16-ray packet, positions and normals as structure of arrays
/// (x, y, z components) so per-lane arithmetic over them vectorises.
#[derive(Debug, Clone)]
pub struct SurfacePoints16 {
    /// Hit positions: x, y and z rows of 16 lanes, world space.
    pub position: [[f32; 16]; 3],
    /// Unit shading normals facing the incoming rays: x, y and z rows of 16 lanes.
    pub normal: [[f32; 16]; 3],
    /// Texture coordinates per lane.
    pub uv: [Vec2; 16],
}

impl Default for SurfacePoints16 {
    fn default() -> Self {
        Self {
            position: [[0.0; 16]; 3],
            normal: [[0.0; 16]; 3],
            uv: [Vec2::ZERO; 16],
        }
    }
}

impl SurfacePoints16 {
    /// The surface point of lane `lane` (0..16).
    pub fn get(&self, lane: usize) -> SurfacePoint {
        let (p, n) = (&self.position, &self.normal);
        SurfacePoint {
            position: Vec3::new(p[0][lane], p[1][lane], p[2][lane]),
            normal: Vec3::new(n[0][lane], n[1][lane], n[2][lane]),
            uv: self.uv[lane],
        }
    }
}

/// Direct lighting from one light through an unoccluded shadow ray (the direct integrator):
/// Lambertian `albedo / pi` plus the energy-normalised Blinn-Phong lobe
/// `specular (s + 8) / (8 pi) cos_h^s`, times the cosine and the light's irradiance.
pub fn direct(surface: &Surface, sp: &SurfacePoint, view: Vec3, light: &LightSample) -> Vec3 {
    let cos = sp.normal.dot(light.dir);
    if cos <= 0.0 {
        return Vec3::ZERO;
    }
    let mut f = surface.albedo * ((1.0 - surface.mirror) * std::f32::consts::FRAC_1_PI);
    if surface.specular != Vec3::ZERO {
        let h = (light.dir - view).normalize_or_zero();
        let cos_h = sp.normal.dot(h);
        if cos_h > 0.0 {
            let norm = (surface.shininess + 8.0) / (8.0 * std::f32::consts::PI);
            f += surface.specular * (norm * cos_h.powf(surface.shininess));
        }
    }
    f * cos * light.irradiance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambert_follows_the_cosine_and_inverse_square() {
        let m = Material::diffuse(Vec3::ONE);
        let sp = SurfacePoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            uv: Vec2::ZERO,
        };
        let light = Light::Point {
            position: Vec3::new(0.0, 2.0, 0.0),
            intensity: Vec3::splat(4.0),
        };
        let c = direct(
            &m.surface(Vec2::ZERO),
            &sp,
            -Vec3::Y,
            &light.sample(sp.position),
        );
        assert!((c.x - std::f32::consts::FRAC_1_PI).abs() < 1e-6);
        let slanted = Light::Directional {
            direction: Vec3::new(1.0, -1.0, 0.0),
            irradiance: Vec3::ONE,
            angle: 0.0,
        };
        let c = direct(
            &m.surface(Vec2::ZERO),
            &sp,
            -Vec3::Y,
            &slanted.sample(sp.position),
        );
        assert!((c.x - std::f32::consts::FRAC_1_SQRT_2 / std::f32::consts::PI).abs() < 1e-6);
    }
}
