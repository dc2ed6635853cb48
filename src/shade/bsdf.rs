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
/// The widest GGX lobe [`Bsdf::glossy_share`] counts as glossy (roughness 0.3).
const GLOSSY_SHARE_ALPHA: f32 = 0.09;

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

/// What [`Bsdf`] needs at one `wo`, computed once per point and direction
/// ([`Scattering`]): clamped parameters, Fresnel constants and the lobe selection
/// probability.
#[derive(Debug, Clone, Copy)]
struct Setup {
    alpha: f32,
    a2: f32,
    /// Specular lobes are deltas (`alpha < DELTA_ALPHA`).
    delta: bool,
    eta: f32,
    f0: f32,
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
    /// What the specular layer reflects of light arriving along `wo` (its directional
    /// albedo), which the diffuse layer under it is dimmed by.
    fo: f32,
    /// Probability of sampling the microfacet lobes (reflection and transmission) rather than
    /// the diffuse one.
    p_micro: f32,
}

impl Setup {
    fn new(bsdf: &Bsdf, n: Vec3, wo: Vec3) -> Option<Self> {
        let cos_o = n.dot(wo);
        if cos_o.is_nan() || cos_o <= MIN_COS {
            return None;
        }
        let cos_o = cos_o.min(1.0);
        let roughness = clamp(bsdf.roughness, 0.0, 1.0);
        let alpha = roughness * roughness;
        let delta = alpha < DELTA_ALPHA;
        let alpha = alpha.max(DELTA_ALPHA);
        let a2 = alpha * alpha;
        let mut eta = clamp(bsdf.eta, 1e-3, 1e3);
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
        let metallic = clamp(bsdf.metallic, 0.0, 1.0);
        let transmission = clamp(bsdf.transmission, 0.0, 1.0);
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
            through,
            metallic,
            base,
            base_mean,
            w_diffuse,
            w_transmit,
            cos_o,
            s_o: smith_s(a2, cos_o),
            fo: 0.0,
            p_micro: 0.0,
        };
        setup.fo = if w_diffuse > 0.0 && f0 > 0.0 && eta >= 1.0 {
            specular_albedo(cos_o, roughness, eta)
        } else {
            setup.dielectric_fresnel(cos_o)
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
        let can_micro =
            self.metallic > 0.0 || self.f0 > 0.0 || (self.w_transmit > 0.0 && self.base_mean > 0.0);
        if !can_micro {
            0.0
        } else if diffuse <= 0.0 {
            1.0
        } else {
            (micro / (micro + diffuse)).max(MIN_MICRO)
        }
    }

    fn dielectric_fresnel(&self, cos: f32) -> f32 {
        dielectric_fresnel(self.eta, cos)
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

    /// The diffuse layer's `f |cos_i|` at `wi` (a part of [`Setup::eval_pdf`]'s).
    fn eval_diffuse(&self, n: Vec3, wi: Vec3) -> Vec3 {
        let cos_i = n.dot(wi);
        if cos_i > 0.0 {
            let lambert = cos_i * FRAC_1_PI;
            self.base * (self.w_diffuse * (1.0 - self.fo) * lambert)
        } else {
            Vec3::ZERO
        }
    }

    /// `f |cos_i|` and the non-delta sampling density at `wi`.
    fn eval_pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        let cos_i = n.dot(wi);
        if cos_i > 0.0 {
            let h = (wo + wi).normalize_or(n);
            let (fd, spec, p_reflect) = self.split(wo.dot(h).clamp(0.0, 1.0));
            let lambert = cos_i * FRAC_1_PI;
            // The diffuse layer gets what the specular layer does not reflect towards `wo`:
            // `1 - E(wo)`, its directional albedo (Cycles' albedo scaling; `F(n . wo)` when
            // smooth). glTF's `1 - F(v . h)` would let a white dielectric reflect up to 1.7
            // times the light it receives at grazing angles; `1 - F(n . wo)` would lose up to
            // 70% of a rough one's light there.
            let _ = fd;
            let mut f = self.eval_diffuse(n, wi);
            let mut pdf = (1.0 - self.p_micro) * lambert;
            if !self.delta {
                let (dv, density) = self.reflection_terms(n, h, cos_i);
                f += spec * (dv * cos_i);
                pdf += self.p_micro * p_reflect * density;
            }
            return (f, pdf);
        }
        if cos_i.is_nan() || cos_i >= 0.0 || self.delta || self.w_transmit <= 0.0 {
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

/// `x` clamped to `[lo, hi]`, NaN taken as `lo` (a bad parameter never poisons a path).
fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() { lo } else { x.clamp(lo, hi) }
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
        self.eval_pdf(n, wo, wi).0
    }

    /// The part of [`Bsdf::eval`] the diffuse layer sends (the rest, the specular
    /// reflection and transmission, is what changes quickly with the viewer: what
    /// [`Bsdf::view_alpha`] measures). The viewer's direction changes it only through the
    /// specular layer's albedo above it, slowly except at grazing angles.
    pub fn eval_diffuse(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
        self.at(n, wo).map_or(Vec3::ZERO, |s| s.eval_diffuse(wi))
    }

    /// [`Bsdf::eval_pdf`] and [`Bsdf::eval_diffuse`] at once.
    pub fn eval_pdf_diffuse(&self, n: Vec3, wo: Vec3, wi: Vec3) -> (Vec3, f32, Vec3) {
        self.at(n, wo)
            .map_or((Vec3::ZERO, 0.0, Vec3::ZERO), |s| s.eval_pdf_diffuse(wi))
    }

    /// The solid-angle density with which [`Bsdf::sample`] draws `wi` (zero for delta lobes).
    pub fn pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(n, wo, wi).1
    }

    /// [`Bsdf::eval`] and [`Bsdf::pdf`] at once (a light sample needs both; they share the
    /// work that depends on `wo`).
    pub fn eval_pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        self.at(n, wo).map_or((Vec3::ZERO, 0.0), |s| s.eval_pdf(wi))
    }

    /// The BSDF at shading normal `n` seen from `wo`, for several evaluations and samples
    /// there; `None` where `wo` grazes the surface or lies below it (nothing scatters).
    pub fn at(&self, n: Vec3, wo: Vec3) -> Option<Scattering> {
        Setup::new(self, n, wo).map(|setup| Scattering { setup, n, wo })
    }

    /// The angle (radians) over which what the surface sends a viewer may change as the
    /// viewer moves: infinite for a Lambertian surface with no interface (it looks the same
    /// from everywhere), else its specular lobes' GGX width alpha (0 for deltas). Sample reuse
    /// ([`crate::render::reuse`]) lends a sample to other lens positions only across much
    /// less than this.
    pub fn view_alpha(&self) -> f32 {
        let interface =
            self.metallic > 0.0 || self.transmission > 0.0 || (self.eta - 1.0).abs() >= MATCHED_ETA;
        if interface {
            let r = clamp(self.roughness, 0.0, 1.0);
            r * r
        } else {
            f32::INFINITY
        }
    }

    /// Roughly what share of the light this surface reflects comes through a narrow glossy
    /// lobe (GGX alpha at most 0.09, roughness 0.3): 0 for matte and rough surfaces. Light
    /// sampling picks lamps for such a surface less by their distance
    /// ([`crate::scene::light_tree`]): what a near-mirror reflects is the lamp in its lobe,
    /// however far. A function of the material alone, so the light sample and the BSDF sample
    /// that finds the same lamp agree on it.
    pub fn glossy_share(&self) -> f32 {
        let roughness = clamp(self.roughness, 0.0, 1.0);
        if roughness * roughness > GLOSSY_SHARE_ALPHA {
            return 0.0;
        }
        let (metallic, transmission) = (
            clamp(self.metallic, 0.0, 1.0),
            clamp(self.transmission, 0.0, 1.0),
        );
        let base = mean(self.base_color.clamp(Vec3::ZERO, Vec3::ONE));
        let f0 = ((self.eta - 1.0) / (self.eta + 1.0)).powi(2);
        let f0 = if f0.is_finite() {
            f0.clamp(0.0, 1.0)
        } else {
            0.0
        };
        // Fresnel's mean over the hemisphere is near f0 + (1 - f0) / 21.
        let fresnel = f0 + (1.0 - f0) / 21.0;
        let glossy =
            metallic * base + (1.0 - metallic) * (fresnel + transmission * base * (1.0 - fresnel));
        let diffuse = (1.0 - metallic) * (1.0 - transmission) * base * (1.0 - fresnel);
        if glossy + diffuse > 0.0 {
            (glossy / (glossy + diffuse)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// Whether every lobe is a delta, so that [`Bsdf::eval`] is zero everywhere and light
    /// sampling can be skipped (a smooth metal, or smooth glass with no diffuse part).
    pub fn is_delta(&self) -> bool {
        let alpha = self.roughness * self.roughness;
        let diffuse = (1.0 - self.metallic) * (1.0 - self.transmission) * mean(self.base_color);
        alpha < DELTA_ALPHA && diffuse <= 0.0
    }

    /// Draws a direction from three uniform numbers; `None` when the sample carries nothing.
    /// `u[0]` picks the lobe, `u[1]` and `u[2]` the direction within it.
    pub fn sample(&self, n: Vec3, wo: Vec3, u: [f32; 3]) -> Option<BsdfSample> {
        self.at(n, wo)?.sample(u)
    }
}

/// A [`Bsdf`] at one point seen from one direction ([`Bsdf::at`]): what depends on the
/// normal and `wo` (Fresnel at `wo`, the specular layer's albedo, the lobes' sampling
/// probabilities) worked out once for the light sample, the BSDF sample and the evaluations a
/// path makes there.
#[derive(Debug, Clone, Copy)]
pub struct Scattering {
    setup: Setup,
    n: Vec3,
    wo: Vec3,
}

impl Scattering {
    /// [`Bsdf::eval_pdf`] at `wi`.
    pub fn eval_pdf(&self, wi: Vec3) -> (Vec3, f32) {
        self.setup.eval_pdf(self.n, self.wo, wi)
    }

    /// [`Bsdf::eval_diffuse`] at `wi`.
    pub fn eval_diffuse(&self, wi: Vec3) -> Vec3 {
        self.setup.eval_diffuse(self.n, wi)
    }

    /// [`Bsdf::eval_pdf_diffuse`] at `wi`.
    pub fn eval_pdf_diffuse(&self, wi: Vec3) -> (Vec3, f32, Vec3) {
        let (f, pdf) = self.eval_pdf(wi);
        (f, pdf, self.eval_diffuse(wi))
    }

    /// [`Bsdf::sample`]: draws a direction from three uniform numbers; `None` when the
    /// sample carries nothing. `u[0]` picks the lobe, `u[1]` and `u[2]` the direction within
    /// it.
    pub fn sample(&self, u: [f32; 3]) -> Option<BsdfSample> {
        let (s, n, wo) = (&self.setup, self.n, self.wo);
        let (wi, lobe, delta) = if u[0] >= s.p_micro {
            (cosine_hemisphere(n, u[1], u[2]), Lobe::Diffuse, None)
        } else {
            let m = s.facet(n, wo, u[1], u[2]);
            let cos = wo.dot(m);
            if cos.is_nan() || cos <= 0.0 {
                return None;
            }
            let (fd, spec, p_reflect) = s.split(cos);
            let reflected = (2.0 * cos * m - wo).normalize();
            if u[0] < s.p_micro * p_reflect {
                let delta = s.delta.then_some((spec, s.p_micro * p_reflect));
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
        let on_side = if lobe == Lobe::Transmission {
            side < 0.0
        } else {
            side > 0.0
        };
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

/// Cosines, roughnesses and indices of the specular albedo table.
const ALBEDO_COS: usize = 32;
const ALBEDO_ROUGH: usize = 24;
const ALBEDO_ETA: usize = 12;

/// The GGX dielectric specular layer's directional albedo (exact Fresnel) at `cos_o`,
/// `roughness` and relative index `eta >= 1`, as its ratio to the Fresnel reflectance at
/// `cos_o`: tabulated over `sqrt(cos_o)`, `sqrt(roughness)` and `s = (eta - 1) / (eta + 1)`
/// (the square root of the reflectance at normal incidence) by sampling the layer itself on a
/// stratified 16 x 16 grid (`tabulate_specular_albedo`, stored in `albedo_table.rs`), read
/// trilinearly, then multiplied by the exact `F(cos_o)`. The ratio is 1 for a smooth surface
/// and varies slowly elsewhere, so the interpolation keeps the albedo of any index within the
/// table's sampling error (the albedo itself is convex in the index, and interpolating it
/// would always come out low, handing the diffuse layer light the specular layer also
/// reflects).
fn specular_albedo(cos_o: f32, roughness: f32, eta: f32) -> f32 {
    let table = &super::albedo_table::SPECULAR_ALBEDO;
    let x = cos_o.clamp(0.0, 1.0).sqrt() * (ALBEDO_COS - 1) as f32;
    let y = roughness.clamp(0.0, 1.0).sqrt() * (ALBEDO_ROUGH - 1) as f32;
    let s = (eta - 1.0) / (eta + 1.0);
    let z = s.clamp(0.0, 1.0) * (ALBEDO_ETA - 1) as f32;
    let (i, j, k) = (
        (x as usize).min(ALBEDO_COS - 2),
        (y as usize).min(ALBEDO_ROUGH - 2),
        (z as usize).min(ALBEDO_ETA - 2),
    );
    let (fx, fy) = (x - i as f32, y - j as f32);
    let at = |i: usize, j: usize, k: usize| table[(k * ALBEDO_ROUGH + j) * ALBEDO_COS + i];
    let plane = |k: usize| {
        let top = at(i, j, k) + (at(i + 1, j, k) - at(i, j, k)) * fx;
        let bottom = at(i, j + 1, k) + (at(i + 1, j + 1, k) - at(i, j + 1, k)) * fx;
        top + (bottom - top) * fy
    };
    let t = ((s - albedo_node_s(k)) / (albedo_node_s(k + 1) - albedo_node_s(k))).clamp(0.0, 1.0);
    let ratio = plane(k) + (plane(k + 1) - plane(k)) * t;
    (ratio * dielectric_fresnel(eta, cos_o)).clamp(0.0, 1.0)
}

/// The node of the specular albedo table's index axis `k`, in `s = (eta - 1) / (eta + 1)`.
fn albedo_node_s(k: usize) -> f32 {
    (k as f32 / (ALBEDO_ETA - 1) as f32).clamp(0.01, 0.998)
}

/// Computes [`specular_albedo`]'s table (index, roughness, cosine; the cosine fastest) by
/// sampling the layer itself: 2.4 million samples, half a second, which every process paid
/// on its first shading when it was built at run time. It is stored in `albedo_table.rs`,
/// which a test checks against this and `DOFRAY_BLESS=1` rewrites.
#[cfg(test)]
fn tabulate_specular_albedo() -> Vec<f32> {
    let mut t = Vec::with_capacity(ALBEDO_ETA * ALBEDO_COS * ALBEDO_ROUGH);
    for k in 0..ALBEDO_ETA {
        let s = albedo_node_s(k);
        let eta = (1.0 + s) / (1.0 - s);
        for j in 0..ALBEDO_ROUGH {
            let roughness = (j as f32 / (ALBEDO_ROUGH - 1) as f32).powi(2);
            // A black, fully transmissive dielectric: only its reflection returns light, and
            // it never asks for this table (it has no diffuse layer).
            let layer = Bsdf {
                base_color: Vec3::ZERO,
                metallic: 0.0,
                roughness,
                transmission: 1.0,
                eta,
                thin: false,
            };
            for i in 0..ALBEDO_COS {
                // Nodes at squares: dense at grazing angles, where the albedo changes fast.
                let mu = (i as f32 / (ALBEDO_COS - 1) as f32).powi(2).max(0.002);
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let mut sum = 0.0f64;
                for n in 0..256u32 {
                    let u = [
                        0.5,
                        ((n % 16) as f32 + 0.5) / 16.0,
                        ((n / 16) as f32 + 0.5) / 16.0,
                    ];
                    if let Some(s) = layer.sample(Vec3::Z, wo, u)
                        && s.lobe == Lobe::Glossy
                    {
                        sum += f64::from(s.weight.x);
                    }
                }
                t.push((sum / 256.0) as f32 / dielectric_fresnel(eta, mu));
            }
        }
    }
    t
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::hash64;
    use std::f64::consts::PI;

    /// A uniform number in [0, 1) from a seed.
    fn unit(seed: u64) -> f32 {
        (hash64(seed) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn u3(seed: u64) -> [f32; 3] {
        [unit(seed * 3), unit(seed * 3 + 1), unit(seed * 3 + 2)]
    }

    /// A direction at `cos` from +z (in the xz plane).
    fn at(cos: f32) -> Vec3 {
        Vec3::new((1.0 - cos * cos).max(0.0).sqrt(), 0.0, cos)
    }

    fn material(roughness: f32, metallic: f32, transmission: f32, eta: f32) -> Bsdf {
        Bsdf {
            base_color: Vec3::ONE,
            metallic,
            roughness,
            transmission,
            eta,
            thin: false,
        }
    }

    /// Mean and standard error of a sample.
    #[derive(Default)]
    struct Stat {
        n: f64,
        sum: f64,
        sum2: f64,
    }

    impl Stat {
        fn add(&mut self, x: f64) {
            self.n += 1.0;
            self.sum += x;
            self.sum2 += x * x;
        }
        fn mean(&self) -> f64 {
            self.sum / self.n
        }
        fn error(&self) -> f64 {
            let m = self.mean();
            ((self.sum2 / self.n - m * m).max(0.0) / self.n).sqrt()
        }
    }

    /// The directional albedo by sampling: the mean weight (all lobes) per channel summed, and
    /// the fraction of draws that gave a non-delta direction.
    fn sampled(bsdf: &Bsdf, n: Vec3, wo: Vec3, count: u64, seed: u64) -> (Stat, f64) {
        let (mut albedo, mut non_delta) = (Stat::default(), 0u64);
        for i in 0..count {
            let s = bsdf.sample(n, wo, u3(seed << 32 | i));
            albedo.add(s.map_or(0.0, |s| s.weight.element_sum() as f64 / 3.0));
            non_delta += s.is_some_and(|s| !s.delta) as u64;
        }
        (albedo, non_delta as f64 / count as f64)
    }

    /// The integrals of `eval` (channels averaged) and of `pdf` over the sphere, by uniform
    /// directions stratified in (z, phi).
    fn quadrature(bsdf: &Bsdf, n: Vec3, wo: Vec3, rows: u64, seed: u64) -> (Stat, Stat) {
        let (mut f, mut p) = (Stat::default(), Stat::default());
        let (t, b) = basis(n);
        for i in 0..rows {
            for j in 0..2 * rows {
                let u = u3((seed << 32) | (i * 2 * rows + j));
                let z = 1.0 - 2.0 * (i as f32 + u[0]) / rows as f32;
                let phi = std::f32::consts::PI * (j as f32 + u[1]) / rows as f32;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let wi = t * (r * phi.cos()) + b * (r * phi.sin()) + n * z;
                let area = 4.0 * PI;
                f.add(bsdf.eval(n, wo, wi).element_sum() as f64 / 3.0 * area);
                p.add(bsdf.pdf(n, wo, wi) as f64 * area);
            }
        }
        (f, p)
    }

    fn close(a: &Stat, b: &Stat, what: &str) {
        let tolerance = 4.0 * (a.error().powi(2) + b.error().powi(2)).sqrt() + 2e-3;
        assert!(
            (a.mean() - b.mean()).abs() < tolerance,
            "{what}: {} +- {} vs {} +- {}",
            a.mean(),
            a.error(),
            b.mean(),
            b.error()
        );
    }

    /// The mean sample weight is the integral of `eval` and `pdf` integrates to the share of
    /// draws that give non-delta directions, so `sample` draws from `pdf` and MIS is unbiased.
    #[test]
    fn sampling_agrees_with_quadrature() {
        let n = Vec3::new(0.3, -0.2, 0.9).normalize();
        let (t, _) = basis(n);
        let mut seed = 0;
        for roughness in [0.35f32, 0.7, 1.0] {
            for (metallic, transmission, eta, thin) in [
                (0.0, 0.0, 1.5, false),
                (1.0, 0.0, 1.5, false),
                (0.3, 0.5, 1.5, false),
                (0.0, 1.0, 1.0 / 1.5, false),
                (0.0, 0.7, 1.33, true),
            ] {
                for cos in [0.25f32, 0.8] {
                    seed += 1;
                    let bsdf = Bsdf {
                        base_color: Vec3::new(0.9, 0.5, 0.2),
                        thin,
                        ..material(roughness, metallic, transmission, eta)
                    };
                    let wo = (n * cos + t * (1.0 - cos * cos).sqrt()).normalize();
                    let what = format!("{bsdf:?} at cos {cos}");
                    let (albedo, non_delta) = sampled(&bsdf, n, wo, 60_000, seed);
                    let (f, p) = quadrature(&bsdf, n, wo, 160, seed);
                    close(&albedo, &f, &what);
                    let mass = Stat {
                        n: 60_000.0,
                        sum: non_delta * 60_000.0,
                        sum2: non_delta * 60_000.0,
                    };
                    close(&p, &mass, &what);
                    assert!(f.error() < 0.05 * f.mean().max(0.05), "{what}: noisy");
                }
            }
        }
    }

    /// Random inputs, degenerate ones included, never give NaN, infinity or negative values,
    /// and a non-delta sample's weight is `eval / pdf` at its direction.
    #[test]
    fn outputs_are_finite_and_consistent() {
        let pick = |s: u64, values: &[f32]| values[(hash64(s) % values.len() as u64) as usize];
        let dir = |s: u64| {
            let u = u3(s);
            let z = 1.0 - 2.0 * u[0];
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * u[1];
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        };
        let mut checked = 0;
        for i in 0..40_000u64 {
            let s = i * 16;
            let bsdf = Bsdf {
                base_color: Vec3::new(pick(s, &[0.0, 1.0, 0.5]), unit(s + 1), 1.0),
                metallic: pick(s + 2, &[0.0, 1.0, 0.5, 0.03]),
                roughness: pick(s + 3, &[0.0, 1.0, 0.01, 0.04, 0.2, 0.6]),
                transmission: pick(s + 4, &[0.0, 1.0, 0.5]),
                eta: pick(s + 5, &[1.0, 1.5, 1.0 / 1.5, 1.0005, 2.4, 1.0 / 2.4]),
                thin: i % 5 == 0,
            };
            let n = dir(s + 6);
            let wo = match i % 7 {
                0 => n,
                1 => (n.cross(Vec3::X) + n * 1e-7).normalize_or(n),
                2 => -n,
                _ => dir(s + 7),
            };
            let wi = match i % 11 {
                0 => -n,
                1 => -wo,
                2 => n,
                _ => dir(s + 8),
            };
            let (f, p) = (bsdf.eval(n, wo, wi), bsdf.pdf(n, wo, wi));
            assert!(f.is_finite() && f.min_element() >= 0.0, "{bsdf:?}: {f}");
            assert!(p.is_finite() && p >= 0.0, "{bsdf:?}: {p}");
            let Some(sample) = bsdf.sample(n, wo, u3(s + 9)) else {
                continue;
            };
            let w = sample.weight;
            assert!(
                w.is_finite() && w.min_element() >= 0.0,
                "{bsdf:?}: {sample:?}"
            );
            assert!(
                sample.pdf > 0.0 && sample.pdf.is_finite(),
                "{bsdf:?}: {sample:?}"
            );
            assert!((sample.wi.length() - 1.0).abs() < 1e-4, "{sample:?}");
            if !sample.delta {
                let (f, p) = (bsdf.eval(n, wo, sample.wi), bsdf.pdf(n, wo, sample.wi));
                let expected = f / p;
                let error = (expected - w).abs().max_element();
                assert!(
                    error <= 1e-3 * w.max_element().max(1.0),
                    "{bsdf:?}: {sample:?}"
                );
                assert!((p - sample.pdf).abs() <= 1e-3 * p, "{bsdf:?}: {sample:?}");
                checked += 1;
            }
        }
        assert!(checked > 10_000, "{checked}");
    }

    /// The specular reflection is reciprocal: `f(wo, wi) = f(wi, wo)`. (The diffuse layer's
    /// albedo scaling by `1 - F(n . wo)` is not, as in Cycles: it is what keeps the layers
    /// from reflecting more than arrives.)
    #[test]
    fn reflection_is_reciprocal() {
        let n = Vec3::Z;
        for i in 0..2_000u64 {
            let bsdf = Bsdf {
                base_color: Vec3::new(0.8, 0.4, 0.1),
                ..material(0.05 + unit(i), 1.0, unit(i + 9), 1.1 + unit(i + 3))
            };
            let (a, b) = (u3(i * 5), u3(i * 5 + 1));
            let wo = Vec3::new(a[0] - 0.5, a[1] - 0.5, a[2] + 0.01).normalize();
            let wi = Vec3::new(b[0] - 0.5, b[1] - 0.5, b[2] + 0.01).normalize();
            let forward = bsdf.eval(n, wo, wi) / wi.z;
            let backward = bsdf.eval(n, wi, wo) / wo.z;
            let error = (forward - backward).abs().max_element();
            assert!(
                error <= 1e-4 * forward.max_element().max(1.0),
                "{forward} {backward}"
            );
        }
    }

    /// IOR 1 (no interface) and roughness 1: pure Lambert, every sample weighs exactly the base
    /// colour, and `eval` is `c cos / pi`.
    #[test]
    fn no_interface_is_lambert() {
        let c = Vec3::new(0.7, 0.3, 0.05);
        let bsdf = Bsdf {
            base_color: c,
            ..material(1.0, 0.0, 0.0, 1.0)
        };
        assert_eq!(bsdf, Bsdf::diffuse(c));
        for (i, cos) in [1.0f32, 0.5, 0.05].into_iter().enumerate() {
            let wo = at(cos);
            for k in 0..1_000 {
                let s = bsdf.sample(Vec3::Z, wo, u3(i as u64 * 10_000 + k)).unwrap();
                assert!((s.weight - c).abs().max_element() < 1e-5, "{s:?}");
                let f = bsdf.eval(Vec3::Z, wo, s.wi);
                let lambert = c * s.wi.z * std::f32::consts::FRAC_1_PI;
                assert!((f - lambert).abs().max_element() < 1e-6);
            }
        }
    }

    /// A white GGX conductor at alpha = 1 has `D = 1 / pi` and `V = 1 / (2 (co + ci))`, so its
    /// directional albedo is `E(mu) = 1 - mu ln(1 + 1 / mu)` exactly: 0.307 at normal
    /// incidence, 0.76 at mu = 0.1, averaging 0.41 over the hemisphere (single scattering
    /// loses about 60% at roughness 1, as Kulla and Conty 2017 show).
    #[test]
    fn white_conductor_at_roughness_one_matches_its_closed_form() {
        let bsdf = material(1.0, 1.0, 0.0, 1.5);
        for (i, mu) in [1.0f32, 0.5, 0.1].into_iter().enumerate() {
            let (albedo, _) = sampled(&bsdf, Vec3::Z, at(mu), 100_000, 100 + i as u64);
            let mu = mu as f64;
            let expected = 1.0 - mu * (1.0 + 1.0 / mu).ln();
            assert!(
                (albedo.mean() - expected).abs() < 4.0 * albedo.error() + 1e-3,
                "mu {mu}: {} +- {} vs {expected}",
                albedo.mean(),
                albedo.error()
            );
        }
    }

    /// The stored specular albedo table is the one the layer's own sampling gives today: a
    /// change to the BSDF that moves it must rewrite it (`DOFRAY_BLESS=1 cargo test
    /// albedo_table_is_current`), or diffuse layers would be dimmed by a stale albedo.
    #[test]
    fn albedo_table_is_current() {
        let fresh = tabulate_specular_albedo();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/shade/albedo_table.rs");
        if std::env::var_os("DOFRAY_BLESS").is_some() {
            let mut text = String::from(
                "//! The GGX dielectric specular layer's directional albedo over its Fresnel \
                 reflectance,\n//! [`super::bsdf`]'s `specular_albedo` table. Generated by \
                 `DOFRAY_BLESS=1 cargo test\n//! albedo_table_is_current`; do not edit.\n\n",
            );
            text += &format!(
                "pub(super) static SPECULAR_ALBEDO: [f32; {}] = [\n",
                fresh.len()
            );
            for row in fresh.chunks(ALBEDO_COS / 4) {
                let row: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
                text += &format!("    {},\n", row.join(", "));
            }
            text += "];\n";
            std::fs::write(path, text).expect("writing the albedo table");
        }
        let stored = &crate::shade::albedo_table::SPECULAR_ALBEDO;
        assert_eq!(stored.len(), fresh.len());
        for (i, (a, b)) in stored.iter().zip(&fresh).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6,
                "entry {i}: stored {a}, sampled {b}; rebless"
            );
        }
    }

    /// Directional albedos of white materials never exceed 1; printed as the table the
    /// documentation quotes (`cargo test albedo_table -- --nocapture`), the opaque white
    /// dielectric at grazing angles too (its diffuse layer is dimmed by `1 - F(n . wo)`; with
    /// glTF's `1 - F(v . h)` a smooth one returned 1.73 at cos 0.05).
    #[test]
    fn albedo_table_never_exceeds_one() {
        let cosines = [1.0f32, 0.7, 0.4, 0.2, 0.05];
        for (name, metallic, transmission, eta, conserving) in [
            ("white conductor", 1.0, 0.0, 1.5, 0.0f32),
            ("white dielectric (ior 1.5)", 0.0, 0.0, 1.5, 0.0),
            ("glass from outside (ior 1.5)", 0.0, 1.0, 1.5, 0.0),
            ("glass from inside (ior 1.5)", 0.0, 1.0, 1.0 / 1.5, 0.0),
        ] {
            println!("{name}: roughness \\ cos theta_o {cosines:?}");
            for roughness in [0.0f32, 0.1, 0.3, 0.5, 0.7, 1.0] {
                let bsdf = material(roughness, metallic, transmission, eta);
                let mut row = Vec::new();
                for (i, &mu) in cosines.iter().enumerate() {
                    let seed = (roughness * 1000.0) as u64 * 10 + i as u64;
                    let (albedo, _) = sampled(&bsdf, Vec3::Z, at(mu), 40_000, seed);
                    let a = albedo.mean();
                    let limit = 1.0 + 4.0 * albedo.error() + 2e-3;
                    assert!(mu < conserving || a <= limit, "{name} {bsdf:?} {mu}: {a}");
                    row.push(format!("{a:.3}"));
                }
                println!("  {roughness:.1}: {}", row.join(" "));
            }
        }
    }

    /// Smooth glass conserves energy exactly (reflection F and transmission 1 - F, every
    /// weight 1); from inside beyond the critical angle everything reflects; a smooth thin
    /// sheet passes light straight on; rough glass loses only what masking loses.
    #[test]
    fn glass_in_a_white_furnace() {
        for eta in [1.5f32, 1.0 / 1.5] {
            for (i, mu) in [1.0f32, 0.6, 0.3, 0.05].into_iter().enumerate() {
                let bsdf = material(0.0, 0.0, 1.0, eta);
                let (mut reflected, count) = (0, 2_000);
                for k in 0..count {
                    let s = bsdf
                        .sample(Vec3::Z, at(mu), u3(i as u64 * 7_000 + k))
                        .unwrap();
                    assert!(s.delta && (s.weight - Vec3::ONE).abs().max_element() < 1e-5);
                    reflected += (s.lobe == Lobe::Glossy) as u32;
                    if s.lobe == Lobe::Transmission {
                        // Snell's law.
                        let sin_t = (1.0 - s.wi.z * s.wi.z).sqrt();
                        assert!((sin_t * eta - (1.0 - mu * mu).sqrt()).abs() < 1e-4);
                    }
                }
                let critical = eta < 1.0 && (1.0 - mu * mu).sqrt() > eta;
                let fresnel = dielectric_fresnel(eta, mu) as f64;
                let share = reflected as f64 / count as f64;
                let noise = 4.0 * (fresnel * (1.0 - fresnel) / count as f64).sqrt() + 1e-3;
                assert!(
                    (share - fresnel).abs() < noise,
                    "{eta} {mu}: {share} vs {fresnel}"
                );
                if critical {
                    assert_eq!(reflected, count as u32, "total internal reflection");
                }
                let rough = material(0.4, 0.0, 1.0, eta);
                let (albedo, _) = sampled(&rough, Vec3::Z, at(mu), 20_000, 50 + i as u64);
                assert!(
                    albedo.mean() <= 1.0 + 1e-4 && albedo.mean() > 0.8,
                    "{eta} {mu}"
                );
            }
        }
        let sheet = Bsdf {
            thin: true,
            ..material(0.0, 0.0, 1.0, 1.5)
        };
        let wo = at(0.6);
        let through = (0..200)
            .filter_map(|k| sheet.sample(Vec3::Z, wo, u3(k)))
            .filter(|s| s.lobe == Lobe::Transmission);
        for s in through {
            assert!((s.wi + wo).length() < 1e-5, "{s:?}");
        }
    }

    /// A smooth metal is a delta: nothing for `eval` and `pdf`, and the sample carries the
    /// Schlick reflectance at `wo`.
    #[test]
    fn smooth_metal_is_a_mirror() {
        let bsdf = Bsdf {
            base_color: Vec3::new(0.9, 0.6, 0.2),
            ..material(0.0, 1.0, 0.0, 1.5)
        };
        assert!(bsdf.is_delta());
        let wo = at(0.5);
        let s = bsdf.sample(Vec3::Z, wo, [0.3, 0.2, 0.9]).unwrap();
        assert!(s.delta && s.lobe == Lobe::Glossy);
        assert!((s.wi - Vec3::new(-wo.x, 0.0, wo.z)).length() < 1e-5);
        let expected = bsdf.base_color + (Vec3::ONE - bsdf.base_color) * 0.5f32.powi(5);
        assert!((s.weight - expected).abs().max_element() < 1e-5);
        assert_eq!(bsdf.eval(Vec3::Z, wo, s.wi), Vec3::ZERO);
        assert_eq!(bsdf.pdf(Vec3::Z, wo, s.wi), 0.0);
    }
}
