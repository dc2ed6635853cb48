//! Lights: where they are, how much they send, and how a point sees them.

use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3};

/// A light with no surface of its own: a point, a spot (which may shine from a small disc) or
/// the sun (which may have an angular size).
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
        /// Angular diameter of the sun's disc, radians (Blender's sun angle; 0: parallel light
        /// and hard shadows). Its light comes uniformly from that cone, so shadows soften.
        angle: f32,
    },
    /// A point light limited to a cone around `direction` (the way it shines, unit length):
    /// radiant intensity `intensity` near the axis, none outside the outer cone, and Blender's
    /// smooth blend between (see [`spot_falloff`]). Angles are half-angles from the axis,
    /// radians, `0 <= inner <= outer <= pi / 2`; Blender's blend is `1 - inner / outer`, as its
    /// glTF exporter writes `inner = outer (1 - blend)` (equal angles: a hard edge).
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
        /// Radius of the disc it shines from, scene units (Blender's spot radius; 0: a point
        /// and hard shadows). As Cycles' spot with Soft Falloff: a disc facing each point it
        /// lights, of radiant intensity `intensity` times the cone's falloff along each ray.
        radius: f32,
    },
}

/// Photometric to radiometric: lumens per watt (the luminous efficacy of 555 nm light, which
/// glTF and Blender's exporter use). glTF point and spot intensities (candela, lm/sr) divided
/// by it are radiant intensities (W/sr); directional ones (lux, lm/m^2) are irradiances (W/m^2).
pub const LUMENS_PER_WATT: f32 = 683.0;

/// The fraction of a spot light's intensity sent along a direction whose cosine with the
/// spot's axis is `cos_angle`, as Blender (Cycles and EEVEE) computes it: 0 outside the cone of
/// half-angle `outer` (cosine `cos_outer`), and inside it the smoothstep `3x^2 - 2x^3` of
/// `x = clamp((cos_angle - cos_outer) / ((1 - cos_outer) blend), 0, 1)`; `blend` 0 is a hard
/// edge. (glTF's reference falloff, a square in place of the smoothstep between an inner and the
/// outer cone, sends up to 1.4 times less light over a soft spot's disc than Blender, which
/// rendered the artist's image.)
#[inline]
pub fn spot_falloff(cos_angle: f32, cos_outer: f32, blend: f32) -> f32 {
    if cos_angle <= cos_outer {
        return 0.0;
    }
    let smooth = (1.0 - cos_outer) * blend;
    if smooth <= 0.0 {
        return 1.0;
    }
    let x = ((cos_angle - cos_outer) / smooth).min(1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Blender's spot blend for a cone of half-angles `inner` and `outer`: `1 - inner / outer`.
#[inline]
pub fn spot_blend(inner: f32, outer: f32) -> f32 {
    if outer > 0.0 {
        (1.0 - inner / outer).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// A spot light's cone as its falloff uses it.
#[derive(Debug, Clone, Copy)]
pub struct Cone {
    /// Unit direction the spot points in.
    pub axis: Vec3,
    /// Cosine of the outer cone's half-angle.
    pub cos_outer: f32,
    /// Blender's spot blend ([`spot_blend`]).
    pub blend: f32,
}

impl Cone {
    /// [`spot_falloff`] at a point that sees the light in unit direction `to_light`.
    #[inline]
    pub fn falloff(&self, to_light: Vec3) -> f32 {
        spot_falloff(-to_light.dot(self.axis), self.cos_outer, self.blend)
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

/// The disc of a sun with an angular size, as rays that leave the scene see it: uniform
/// radiance over a cone of directions around `axis` (Cycles' sun: a distant light that glossy
/// and refracted rays can hit).
#[derive(Debug, Clone, Copy)]
pub struct SunDisc {
    /// Unit direction towards the sun's centre.
    pub axis: Vec3,
    /// Cosine of the disc's angular radius.
    pub cos_max: f32,
    /// Radiance of every direction in the disc: a surface facing the sun receives its
    /// irradiance E, so L = E / (pi sin^2), as Cycles normalises it.
    pub radiance: Vec3,
    /// Solid-angle density of a direction drawn uniformly over the disc: 1 / (2 pi (1 - cos)).
    pub pdf: f32,
}

impl SunDisc {
    /// Whether unit direction `dir` sees the disc.
    #[inline]
    pub fn contains(&self, dir: Vec3) -> bool {
        dir.dot(self.axis) >= self.cos_max
    }

    /// A direction drawn with `u` uniformly over the disc (density [`SunDisc::pdf`]).
    pub fn sample(&self, u: Vec2) -> Vec3 {
        // 1 - cos is 1 / (2 pi pdf), without cancellation.
        let cos_t = 1.0 - u.x / (TAU * self.pdf);
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let (t, b) = crate::shade::basis(self.axis);
        let phi = TAU * u.y;
        (self.axis * cos_t + (t * phi.cos() + b * phi.sin()) * sin_t).normalize()
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
    /// The light with its intensity (or a sun's irradiance) multiplied by `color`.
    pub fn tinted(mut self, color: Vec3) -> Self {
        match &mut self {
            Self::Point { intensity, .. } | Self::Spot { intensity, .. } => *intensity *= color,
            Self::Directional { irradiance, .. } => *irradiance *= color,
        }
        self
    }

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
                ..
            } => Some(Positional {
                position,
                intensity,
                cone: Some(Cone {
                    axis: direction.normalize_or_zero(),
                    cos_outer: outer_angle.cos(),
                    blend: spot_blend(inner_angle, outer_angle),
                }),
            }),
            Self::Directional { .. } => None,
        }
    }

    /// Whether its light comes from more than one point or direction (a spot with a radius, a
    /// sun with an angle): [`Light::sample_area`] then needs random numbers, and its shadows
    /// are soft.
    pub fn is_extended(&self) -> bool {
        match *self {
            Self::Point { .. } => false,
            Self::Spot { radius, .. } => radius > 0.0,
            Self::Directional { angle, .. } => angle > 0.0,
        }
    }

    /// The disc of a sun with an angle, which rays leaving the scene may find; `None` for
    /// every other light (a point, a spot, a parallel sun: no ray finds them).
    pub fn sun_disc(&self) -> Option<SunDisc> {
        let Self::Directional {
            direction,
            irradiance,
            angle,
        } = *self
        else {
            return None;
        };
        if angle <= 0.0 {
            return None; // a parallel sun (a NaN angle gives no finite disc below)
        }
        // `angle` is at most pi (World::build checks it). The solid angle is written with
        // sin^2 / (1 + cos) instead of 1 - cos: no cancellation for a sun of half a degree.
        let half = 0.5 * angle;
        let (sin, cos_max) = half.sin_cos();
        let sin2 = sin * sin;
        let radiance = irradiance / (PI * sin2);
        let pdf = (1.0 + cos_max) / (TAU * sin2);
        // An angle so small that the disc's radiance overflows is a parallel sun.
        (pdf.is_finite() && radiance.is_finite()).then(|| SunDisc {
            axis: -direction.normalize(),
            cos_max,
            radiance,
            pdf,
        })
    }

    /// Direction, distance and irradiance of this light as seen from point `p`, drawn with
    /// `u` over the spot's disc or the sun's cone: on average over `u`, what the light sends
    /// `p` (the cosine term is the caller's). A light that is not extended gives
    /// [`Light::sample`].
    pub fn sample_area(&self, p: Vec3, u: Vec2) -> LightSample {
        if let Some(disc) = self.sun_disc() {
            // Its radiance over its density, so a surface facing the sun receives its
            // irradiance (the cone's mean cosine is (1 + cos) / 2).
            return LightSample {
                dir: disc.sample(u),
                distance: f32::INFINITY,
                irradiance: disc.radiance / disc.pdf,
            };
        }
        match *self {
            Self::Spot { radius, .. } if radius > 0.0 => {
                let Some(light) = self.positional() else {
                    return self.sample(p);
                };
                // A disc facing p: its normal points from the light's centre towards p.
                let to_centre = light.position - p;
                let centre_distance = to_centre.length_squared().max(1e-12).sqrt();
                let n = -(to_centre / centre_distance);
                let (t, b) = crate::shade::basis(n);
                let (r, phi) = (radius * u.x.sqrt(), TAU * u.y);
                let q = (p - n * centre_distance) + (t * phi.cos() + b * phi.sin()) * r;
                let d = q - p;
                let dist2 = d.length_squared().max(1e-12);
                let distance = dist2.sqrt();
                let dir = d / distance;
                // A Lambertian disc (the cosine at it over the squared distance) of the spot's
                // intensity times its falloff along this ray, as Cycles evaluates it: the disc
                // blurs the cone's edge too.
                let cos_light = n.dot(-dir).max(0.0);
                LightSample {
                    dir,
                    distance,
                    irradiance: light.irradiance(dir, dist2) * cos_light,
                }
            }
            _ => self.sample(p),
        }
    }

    /// Direction, distance and irradiance of this light's centre as seen from point `p` (for
    /// an extended light, the point light or parallel sun it shrinks to).
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
            ..
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sun(angle: f32) -> Light {
        Light::Directional {
            direction: Vec3::new(0.0, -2.0, 0.0),
            irradiance: Vec3::splat(3.0),
            angle,
        }
    }

    #[test]
    fn a_suns_disc_gives_a_facing_surface_its_irradiance() {
        for degrees in [0.5f32, 10.0, 90.0, 180.0] {
            let disc = sun(degrees.to_radians()).sun_disc().unwrap();
            // Irradiance on a surface facing the sun: L pi sin^2 of the angular radius.
            let sin = (0.5 * degrees.to_radians()).sin();
            let e = disc.radiance.x * PI * sin * sin;
            assert!((e - 3.0).abs() < 3e-3 * 3.0, "{degrees} degrees: {e}");
            // The density is uniform over the cone's solid angle 2 pi (1 - cos).
            let solid = TAU * (1.0 - disc.cos_max);
            assert!((disc.pdf * solid - 1.0).abs() < 0.02, "{degrees} degrees");
            assert!(disc.contains(Vec3::Y), "{degrees} degrees: the centre");
            let low = Vec3::new(1.0, 0.01, 0.0).normalize();
            let what = format!("{degrees} degrees: near the horizon");
            assert_eq!(disc.contains(low), degrees == 180.0, "{what}");
            assert!(
                !disc.contains(-Vec3::Y),
                "{degrees} degrees: away from the sun"
            );
        }
    }

    #[test]
    fn a_sun_too_small_for_its_radiance_is_a_parallel_sun() {
        // sin^2 of the angular radius is a subnormal 2.5e-41: E / (pi sin^2) overflows.
        let light = sun(1e-20);
        assert!(light.sun_disc().is_none());
        let s = light.sample_area(Vec3::ZERO, Vec2::new(0.3, 0.7));
        assert_eq!(s.dir, Vec3::Y);
        assert_eq!(s.irradiance, Vec3::splat(3.0));
        assert!(sun(0.0).sun_disc().is_none());
    }
}
