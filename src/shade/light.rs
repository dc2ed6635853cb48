//! Lights: where they are, how much they send, and how a point sees them.

use glam::Vec3;

/// A light that casts hard shadows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Radiant intensity `intensity` at `position`, falling off as 1 / distance^2.
    Point {
        /// Light position, scene units.
        position: Vec3,
        /// Radiant intensity (linear RGB, W/sr).
        intensity: Vec3,
    },
    /// Parallel light arriving along `direction` (pointing from the light into the scene).
    Directional {
        /// Direction the light travels in (from the light into the scene; need not be unit).
        direction: Vec3,
        /// Irradiance on a surface facing the light (linear RGB, W/m^2).
        irradiance: Vec3,
    },
    /// A point light limited to a cone around `direction` (the way it shines, unit length):
    /// radiant intensity `intensity` inside the inner cone, none outside the outer cone, and
    /// glTF's smooth falloff between (see [`spot_falloff`]). Angles are half-angles from the
    /// axis, radians, `0 <= inner <= outer <= pi / 2` (equal: a hard edge).
    Spot {
        /// Light position, scene units.
        position: Vec3,
        /// Direction the spot shines in (unit length).
        direction: Vec3,
        /// Radiant intensity inside the inner cone (linear RGB, W/sr).
        intensity: Vec3,
        /// Half-angle of the fully lit inner cone, radians.
        inner_angle: f32,
        /// Half-angle of the outer cone, beyond which there is no light, radians.
        outer_angle: f32,
    },
}

/// Photometric to radiometric: lumens per watt (the luminous efficacy of 555 nm light, which
/// glTF and Blender's exporter use). glTF point and spot intensities (candela, lm/sr) divided
/// by it are radiant intensities (W/sr); directional ones (lux, lm/m^2) are irradiances (W/m^2).
pub const LUMENS_PER_WATT: f32 = 683.0;

/// The fraction of a spot light's intensity sent along a direction whose cosine with the
/// spot's axis is `cos_angle`: 1 inside the inner cone, 0 outside the outer cone, and between
/// them the falloff of the glTF KHR_lights_punctual reference,
/// `t = clamp((cos - cos(outer)) / max(0.001, cos(inner) - cos(outer)), 0, 1)`, squared.
#[inline]
pub fn spot_falloff(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    let scale = 1.0 / (cos_inner - cos_outer).max(1e-3);
    let t = ((cos_angle - cos_outer) * scale).clamp(0.0, 1.0);
    t * t
}

/// A spot light's cone as its falloff uses it.
#[derive(Debug, Clone, Copy)]
pub struct Cone {
    /// Unit direction the spot points in.
    pub axis: Vec3,
    /// Cosine of the inner cone's half-angle.
    pub cos_inner: f32,
    /// Cosine of the outer cone's half-angle.
    pub cos_outer: f32,
}

impl Cone {
    /// [`spot_falloff`] at a point that sees the light in unit direction `to_light`.
    #[inline]
    pub fn falloff(&self, to_light: Vec3) -> f32 {
        spot_falloff(-to_light.dot(self.axis), self.cos_inner, self.cos_outer)
    }
}

/// A light at a position: its position, its intensity, and for a spot its cone.
#[derive(Debug, Clone, Copy)]
pub struct Positional {
    /// Light position, scene units.
    pub position: Vec3,
    /// Radiant intensity (linear RGB, W/sr), falling off as 1 / distance^2.
    pub intensity: Vec3,
    /// The spot's cone; `None` for a point light (shines in every direction).
    pub cone: Option<Cone>,
}

impl Positional {
    /// The irradiance (before the cosine term) at squared distance `dist2`, seen in unit
    /// direction `to_light`.
    #[inline]
    pub fn irradiance(&self, to_light: Vec3, dist2: f32) -> Vec3 {
        match self.cone {
            None => self.intensity / dist2,
            Some(cone) => self.intensity * (cone.falloff(to_light) / dist2),
        }
    }
}

/// What a shadow ray needs to know about a light as seen from a point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the point towards the light.
    pub dir: Vec3,
    /// Distance to the light (infinite for directional lights).
    pub distance: f32,
    /// Irradiance arriving at the point (before the cosine term).
    pub irradiance: Vec3,
}

impl Light {
    /// Position, intensity and cone of a point or spot light; None for a directional light.
    pub fn positional(&self) -> Option<Positional> {
        match *self {
            Self::Point {
                position,
                intensity,
            } => Some(Positional {
                position,
                intensity,
                cone: None,
            }),
            Self::Spot {
                position,
                direction,
                intensity,
                inner_angle,
                outer_angle,
            } => Some(Positional {
                position,
                intensity,
                cone: Some(Cone {
                    axis: direction.normalize_or_zero(),
                    cos_inner: inner_angle.cos(),
                    cos_outer: outer_angle.cos(),
                }),
            }),
            Self::Directional { .. } => None,
        }
    }

    /// Direction, distance and irradiance of this light as seen from point `p`.
    pub fn sample(&self, p: Vec3) -> LightSample {
        if let Some(light) = self.positional() {
            let d = light.position - p;
            let dist2 = d.length_squared().max(1e-12);
            let distance = dist2.sqrt();
            let dir = d / distance;
            return LightSample {
                dir,
                distance,
                irradiance: light.irradiance(dir, dist2),
            };
        }
        let Self::Directional {
            direction,
            irradiance,
        } = *self
        else {
            unreachable!("every light but a directional one has a position")
        };
        LightSample {
            dir: -direction.normalize(),
            distance: f32::INFINITY,
            irradiance,
        }
    }
}
