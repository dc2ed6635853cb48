//! The scattering function at a hit: the glTF 2.0 metallic-roughness BSDF.
//!
//! Conventions: every direction is a unit vector pointing away from the surface; `wo` towards
//! where the light goes (the viewer), `wi` towards where it comes from; `n` is the unit shading
//! normal on `wo`'s side. Values returned by [`Bsdf::eval`] include the cosine, so a light
//! sample's contribution is `eval * radiance / pdf`.

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use super::microfacet::{
    conductor_fresnel, dielectric_fresnel, ggx_d, refract, sample_visible_normal, smith_s,
};

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

/// Below this GGX alpha (perceptual roughness under about 0.032) the specular lobes are deltas:
/// their peak, `1 / (pi alpha^2)`, is then sharper than f32 directions resolve, and a mirror
/// is what such a surface looks like anyway.
const DELTA_ALPHA: f32 = 1e-3;

/// A solid surface whose relative IOR is this close to 1 bends nothing: its transmission is a
/// straight-through delta (the refraction half-vector `wo + eta wi` would vanish).
const MATCHED_ETA: f32 = 1e-3;

/// The least probability of sampling the microfacet lobes when they reflect at all, so that
/// their grazing Fresnel peaks are still found when the estimate at `wo` is small.
const MIN_MICRO: f32 = 0.02;

/// Below this `n . wo`, `wo` grazes the surface and nothing scatters (it keeps the
/// `1 / cos` factors finite).
const MIN_COS: f32 = 1e-6;

/// How transmitted light leaves the other side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Through {
    /// Refracted by a rough dielectric interface (Walter et al. 2007).
    Refract,
    /// Thin-walled: the reflection lobe mirrored to the other side, so smooth sheets pass
    /// light straight on and rough ones spread it by the same lobe.
    Mirror,
    /// An index-matched solid: straight on, a delta whatever the roughness.
    Straight,
}

/// What [`Bsdf`] needs at one `wo`, computed once per call: clamped parameters, Fresnel
/// constants and the lobe selection probability.
struct Setup {
    alpha: f32,
    a2: f32,
    /// Specular lobes are deltas (`alpha < DELTA_ALPHA`).
    delta: bool,
    eta: f32,
    f0: f32,
    /// 0 when there is no interface (eta = 1): no Fresnel reflection at all.
    grazing: f32,
    through: Through,
    metallic: f32,
    base: Vec3,
    base_mean: f32,
    /// Weights of the diffuse and transmission parts: `(1 - metallic)(1 - transmission)` and
    /// `(1 - metallic) transmission`.
    w_diffuse: f32,
    w_transmit: f32,
    cos_o: f32,
    /// [`smith_s`] at `wo`.
    s_o: f32,
    /// Probability of sampling the microfacet lobes (reflection and transmission) rather than
    /// the diffuse one.
    p_micro: f32,
}

impl Setup {
    fn new(bsdf: &Bsdf, n: Vec3, wo: Vec3) -> Option<Self> {
        let cos_o = n.dot(wo);
        if !(cos_o > MIN_COS) {
            return None;
        }
        let cos_o = cos_o.min(1.0);
        let roughness = bsdf.roughness.clamp(0.0, 1.0);
        let alpha = roughness * roughness;
        let delta = !(alpha >= DELTA_ALPHA);
        let alpha = alpha.max(DELTA_ALPHA);
        let a2 = alpha * alpha;
        let mut eta = bsdf.eta.clamp(1e-3, 1e3);
        if bsdf.thin {
            // A sheet has the same medium on both sides: only its own index matters.
            eta = eta.max(1.0 / eta);
        }
        let through = if bsdf.thin {
            Through::Mirror
        } else if (eta - 1.0).abs() < MATCHED_ETA {
            Through::Straight
        } else {
            Through::Refract
        };
        let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
        let grazing = if f0 > 0.0 { 1.0 } else { 0.0 };
        let metallic = bsdf.metallic.clamp(0.0, 1.0);
        let transmission = bsdf.transmission.clamp(0.0, 1.0);
        let base = bsdf.base_color.clamp(Vec3::ZERO, Vec3::ONE);
        let base_mean = mean(base);
        let w_diffuse = (1.0 - metallic) * (1.0 - transmission);
        let w_transmit = (1.0 - metallic) * transmission;
        let mut setup = Self {
            alpha,
            a2,
            delta,
            eta,
            f0,
            grazing,
            through,
            metallic,
            base,
            base_mean,
            w_diffuse,
            w_transmit,
            cos_o,
            s_o: smith_s(a2, cos_o),
            p_micro: 0.0,
        };
        setup.p_micro = setup.micro_probability();
        Some(setup)
    }

    /// The chance of sampling the microfacet lobes, from the albedos the Fresnel terms at `wo`
    /// suggest. Any value in (0, 1] is unbiased as long as each lobe that can carry light
    /// keeps a non-zero share; these make the common cases low-variance.
    fn micro_probability(&self) -> f32 {
        let fo = self.dielectric_fresnel(self.cos_o);
        let conductor = mean(conductor_fresnel(self.base, self.cos_o));
        let micro = self.metallic * conductor
            + (1.0 - self.metallic) * fo
            + self.w_transmit * self.base_mean * (1.0 - fo);
        // Under total internal reflection at `wo` the diffuse part still sees other halfways.
        let diffuse = self.w_diffuse * self.base_mean * (1.0 - fo).max(0.05);
        let can_micro = self.metallic > 0.0
            || self.f0 > 0.0
            || (self.w_transmit > 0.0 && self.base_mean > 0.0);
        if !can_micro {
            0.0
        } else if diffuse <= 0.0 {
            1.0
        } else {
            (micro / (micro + diffuse)).max(MIN_MICRO)
        }
    }

    fn dielectric_fresnel(&self, cos: f32) -> f32 {
        dielectric_fresnel(self.eta, self.f0, self.grazing, cos)
    }

    /// At a microfacet seen at `cos` from `wo`: the dielectric Fresnel, the reflection colour
    /// (metal and dielectric Fresnel mixed by metalness) and the probability of reflecting
    /// rather than transmitting once the facet is drawn (the two Fresnel-weighted shares).
    fn split(&self, cos: f32) -> (f32, Vec3, f32) {
        let fd = self.dielectric_fresnel(cos);
        let spec = self.metallic * conductor_fresnel(self.base, cos)
            + Vec3::splat((1.0 - self.metallic) * fd);
        let r = mean(spec);
        let t = self.w_transmit * self.base_mean * (1.0 - fd);
        let p_reflect = if r + t > 0.0 { r / (r + t) } else { 1.0 };
        (fd, spec, p_reflect)
    }

    /// `D` at the unit halfway `h`, `V` for `wi` at `cos_i` (> 0, on `wo`'s side or mirrored
    /// there), and the visible-normal density of `h` over `4 (wo . h)`: the reflection's
    /// `D V` and its sampling density before lobe selection.
    fn reflection_terms(&self, n: Vec3, h: Vec3, cos_i: f32) -> (f32, f32) {
        let d = ggx_d(self.a2, n.dot(h), n.cross(h).length_squared());
        let s_i = smith_s(self.a2, cos_i);
        let dv = d * 0.5 / (self.s_o * cos_i + s_i * self.cos_o);
        (dv, d * 0.5 / (self.cos_o + self.s_o))
    }

    /// `f |cos_i|` and the non-delta sampling density at `wi`.
    fn eval_pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        let cos_i = n.dot(wi);
        if cos_i > 0.0 {
            let h = (wo + wi).normalize_or(n);
            let (fd, spec, p_reflect) = self.split(wo.dot(h).clamp(0.0, 1.0));
            let lambert = cos_i * FRAC_1_PI;
            let mut f = self.base * (self.w_diffuse * (1.0 - fd) * lambert);
            let mut pdf = (1.0 - self.p_micro) * lambert;
            if !self.delta {
                let (dv, density) = self.reflection_terms(n, h, cos_i);
                f += spec * (dv * cos_i);
                pdf += self.p_micro * p_reflect * density;
            }
            return (f, pdf);
        }
        if !(cos_i < 0.0) || self.delta || self.w_transmit <= 0.0 {
            return (Vec3::ZERO, 0.0);
        }
        match self.through {
            Through::Mirror => {
                let h = (wo + wi - 2.0 * cos_i * n).normalize_or(n);
                let (fd, _, p_reflect) = self.split(wo.dot(h).clamp(0.0, 1.0));
                let (dv, density) = self.reflection_terms(n, h, -cos_i);
                let f = self.base * (self.w_transmit * (1.0 - fd) * dv * -cos_i);
                (f, self.p_micro * (1.0 - p_reflect) * density)
            }
            Through::Refract => self.refraction(n, wo, wi, -cos_i),
            Through::Straight => (Vec3::ZERO, 0.0),
        }
    }

    /// The rough dielectric BTDF of Walter et al. 2007 times `|cos_i|`, and its density.
    /// Radiance is not scaled by `1 / eta^2` on crossing: the factor cancels for light that
    /// leaves a closed object again, and leaving it out keeps glass white in a white furnace.
    fn refraction(&self, n: Vec3, wo: Vec3, wi: Vec3, cos_i: f32) -> (Vec3, f32) {
        let eta = self.eta;
        let m = (wo + eta * wi).normalize_or(n);
        let m = if n.dot(m) < 0.0 { -m } else { m };
        let (om, im) = (wo.dot(m), wi.dot(m));
        if !(om > 0.0 && im < 0.0) {
            return (Vec3::ZERO, 0.0);
        }
        let dn = eta * im + om;
        // d(m) / d(wi), the refraction's change of variables.
        let jacobian = eta * eta * -im / (dn * dn);
        let (fd, _, p_reflect) = self.split(om);
        let d = ggx_d(self.a2, n.dot(m), n.cross(m).length_squared());
        let s_i = smith_s(self.a2, cos_i);
        let g2_over_co = 2.0 * cos_i / (self.s_o * cos_i + s_i * self.cos_o);
        let f = self.base * (self.w_transmit * (1.0 - fd) * d * g2_over_co * om * jacobian);
        let visible = 2.0 / (self.cos_o + self.s_o) * d * om;
        (f, self.p_micro * (1.0 - p_reflect) * visible * jacobian)
    }

    /// A microfacet normal drawn from those visible from `wo` (the normal itself when smooth).
    fn facet(&self, n: Vec3, wo: Vec3, u1: f32, u2: f32) -> Vec3 {
        if self.delta {
            return n;
        }
        let (t, b) = basis(n);
        let local = Vec3::new(wo.dot(t), wo.dot(b), self.cos_o);
        let m = sample_visible_normal(local, self.alpha, u1, u2);
        (t * m.x + b * m.y + n * m.z).normalize()
    }
}

fn mean(v: Vec3) -> f32 {
    (v.x + v.y + v.z) * (1.0 / 3.0)
}

impl Bsdf {
    /// A Lambertian reflector of albedo `color` (IOR 1: no interface, so no specular at all).
    pub fn diffuse(color: Vec3) -> Self {
        Self {
            base_color: color,
            metallic: 0.0,
            roughness: 1.0,
            transmission: 0.0,
            eta: 1.0,
            thin: false,
        }
    }

    /// `f(wo, wi) |n . wi|`, without the delta lobes.
    pub fn eval(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
        Setup::new(self, n, wo).map_or(Vec3::ZERO, |s| s.eval_pdf(n, wo, wi).0)
    }

    /// The solid-angle density with which [`Bsdf::sample`] draws `wi` (zero for delta lobes).
    pub fn pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        Setup::new(self, n, wo).map_or(0.0, |s| s.eval_pdf(n, wo, wi).1)
    }

    /// Whether every lobe is a delta, so that [`Bsdf::eval`] is zero everywhere and light
    /// sampling can be skipped (a smooth metal, or smooth glass with no diffuse part).
    pub fn is_delta(&self) -> bool {
        let alpha = self.roughness * self.roughness;
        let diffuse = (1.0 - self.metallic) * (1.0 - self.transmission) * mean(self.base_color);
        alpha < DELTA_ALPHA && !(diffuse > 0.0)
    }

    /// Draws a direction from three uniform numbers; `None` when the sample carries nothing.
    /// `u[0]` picks the lobe, `u[1]` and `u[2]` the direction within it.
    pub fn sample(&self, n: Vec3, wo: Vec3, u: [f32; 3]) -> Option<BsdfSample> {
        let s = Setup::new(self, n, wo)?;
        let (wi, lobe, delta) = if u[0] >= s.p_micro {
            (cosine_hemisphere(n, u[1], u[2]), Lobe::Diffuse, None)
        } else {
            let m = s.facet(n, wo, u[1], u[2]);
            let cos = wo.dot(m);
            if !(cos > 0.0) {
                return None;
            }
            let (fd, spec, p_reflect) = s.split(cos);
            let reflected = (2.0 * cos * m - wo).normalize();
            if u[0] < s.p_micro * p_reflect {
                let delta = s.delta.then(|| (spec, s.p_micro * p_reflect));
                (reflected, Lobe::Glossy, delta)
            } else {
                let wi = match s.through {
                    Through::Mirror => reflected - 2.0 * n.dot(reflected) * n,
                    Through::Refract => refract(wo, m, s.eta)?,
                    Through::Straight => -wo,
                };
                let p = s.p_micro * (1.0 - p_reflect);
                let delta = (s.delta || s.through == Through::Straight)
                    .then(|| (s.base * (s.w_transmit * (1.0 - fd)), p));
                (wi, Lobe::Transmission, delta)
            }
        };
        // A lobe's directions stay on its side of the surface; the rest are lost (the density
        // counts only those that stay, so nothing is biased).
        let side = n.dot(wi);
        let on_side = if lobe == Lobe::Transmission { side < 0.0 } else { side > 0.0 };
        if !on_side {
            return None;
        }
        let (weight, pdf, delta) = match delta {
            Some((value, p)) => (value / p, p, true),
            None => {
                let (f, pdf) = s.eval_pdf(n, wo, wi);
                (f / pdf, pdf, false)
            }
        };
        let useful = pdf > 0.0 && weight.is_finite() && weight.max_element() > 0.0;
        useful.then_some(BsdfSample {
            wi,
            weight,
            pdf,
            lobe,
            delta,
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
