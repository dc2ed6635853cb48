//! Materials, textures and lights: what a surface looks like once a ray has found it.
//! All colours are linear radiance; sRGB appears only when 8-bit images are written.

use std::sync::Arc;

use glam::{Vec2, Vec3};

/// Procedural patterns over texture coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Pattern {
    /// A checkerboard of unit cells: colour `a` and `b` alternate.
    Checker,
    /// Stripes across u: colour `b` on the first half of each period, `a` on the second.
    Stripes,
    /// Grid lines of colour `b` (a tenth of a period wide) on cells of colour `a`.
    Grid,
    /// Dots of colour `b` (radius 0.3 of a period) centred in cells of colour `a`.
    Dots,
    /// Fractal value noise.
    Noise,
    /// Veined marble: a sine wave perturbed by noise.
    Marble,
}

/// How image textures treat coordinates outside [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Wrap {
    /// Coordinates wrap around: the image tiles the plane.
    #[default]
    Repeat,
    /// Coordinates are clamped: the edge texels extend outwards.
    Clamp,
}

/// A decoded image in linear RGB, sampled bilinearly.
#[derive(Debug, Clone)]
pub struct ImageTexture {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Row-major, top row first (v = 1 is the top, as in OBJ and glTF after its flip).
    pub texels: Vec<Vec3>,
    /// The alpha channel, same layout as `texels`, when the image has one that is not 1
    /// everywhere.
    pub alpha: Option<Vec<f32>>,
    /// How coordinates outside [0, 1] are treated.
    pub wrap: Wrap,
}

impl ImageTexture {
    /// The texels a bilinear lookup at `uv` blends (indices of top-left, top-right,
    /// bottom-left, bottom-right, wrapped or clamped) and the blend fractions across and
    /// down; `None` for non-finite coordinates. v points up, so v = 0 is the bottom row.
    fn footprint(&self, uv: Vec2) -> Option<([usize; 4], f32, f32)> {
        let x = uv.x * self.width as f32 - 0.5;
        let y = (1.0 - uv.y) * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let (x0, y0) = (floor(x), floor(y));
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (w, h) = (self.width as i64, self.height as i64);
        let index = |x: i64, y: i64| {
            let (x, y) = match self.wrap {
                Wrap::Repeat => (x.rem_euclid(w), y.rem_euclid(h)),
                Wrap::Clamp => (x.clamp(0, w - 1), y.clamp(0, h - 1)),
            };
            (y * w + x) as usize
        };
        let corners = [
            index(x0, y0),
            index(x0 + 1, y0),
            index(x0, y0 + 1),
            index(x0 + 1, y0 + 1),
        ];
        Some((corners, fx, fy))
    }

    /// Bilinear lookup of the colour.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let Some(([a, b, c, d], fx, fy)) = self.footprint(uv) else {
            return Vec3::ZERO;
        };
        let t = &self.texels;
        let top = t[a].lerp(t[b], fx);
        let bottom = t[c].lerp(t[d], fx);
        top.lerp(bottom, fy)
    }

    /// Bilinear lookup of the alpha channel (1 for images without one), as [`Self::sample`].
    pub fn sample_alpha(&self, uv: Vec2) -> f32 {
        let (Some(alpha), Some(([a, b, c, d], fx, fy))) = (&self.alpha, self.footprint(uv)) else {
            return 1.0;
        };
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let top = lerp(alpha[a], alpha[b], fx);
        let bottom = lerp(alpha[c], alpha[d], fx);
        lerp(top, bottom, fy)
    }
}

/// Where a material's colour comes from.
#[derive(Debug, Clone)]
pub enum Texture {
    /// One linear RGB colour everywhere.
    Constant(Vec3),
    /// Alternates colours `a` and `b`; `scale` is the number of pattern periods per UV unit.
    Procedural {
        /// The pattern mixing `a` and `b`.
        pattern: Pattern,
        /// Linear RGB colour where the pattern's mix is 0.
        a: Vec3,
        /// Linear RGB colour where the pattern's mix is 1.
        b: Vec3,
        /// Pattern periods per UV unit.
        scale: f32,
    },
    /// An image, multiplied by `tint`.
    Image {
        /// The decoded image (shared between materials).
        image: Arc<ImageTexture>,
        /// Linear RGB factor applied to every texel.
        tint: Vec3,
    },
}

/// `x.floor()`, bit for bit (including -0.0, infinities and NaN), without the libm call that
/// `f32::floor` compiles to on baseline x86-64 (no SSE4.1 `roundss`); textures floor every
/// lookup.
#[inline]
pub fn floor(x: f32) -> f32 {
    // From 2^23 on every f32 is an integer (and NaN fails the test, so it is returned too).
    if x.abs() < 8_388_608.0 {
        // Truncation toward zero is exact here; copysign keeps floor(-0.0) = -0.0 and makes
        // truncations of (-1, 0) -0.0, which the correction below turns into -1.
        let t = ((x as i32) as f32).copysign(x);
        if t > x { t - 1.0 } else { t }
    } else {
        x
    }
}

#[inline]
fn floor2(v: Vec2) -> Vec2 {
    Vec2::new(floor(v.x), floor(v.y))
}

/// 2D value noise in [0, 1] from a hashed integer lattice, smoothly interpolated.
fn value_noise(p: Vec2) -> f32 {
    let cell = floor2(p);
    let f = p - cell;
    let s = f * f * (Vec2::splat(3.0) - 2.0 * f);
    let corner = |dx: f32, dy: f32| {
        let x = (cell.x + dx) as i64 as u64;
        let y = (cell.y + dy) as i64 as u64;
        let h = crate::sampler::hash64(x.wrapping_mul(0x9e37_79b9) ^ y.rotate_left(32));
        (h >> 40) as f32 / (1u64 << 24) as f32
    };
    let top = corner(0.0, 0.0) + (corner(1.0, 0.0) - corner(0.0, 0.0)) * s.x;
    let bottom = corner(0.0, 1.0) + (corner(1.0, 1.0) - corner(0.0, 1.0)) * s.x;
    top + (bottom - top) * s.y
}

/// Four octaves of value noise, in [0, 1].
fn fbm(p: Vec2) -> f32 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut q = p;
    for _ in 0..4 {
        sum += amp * value_noise(q);
        q = q * 2.03 + Vec2::splat(17.1);
        amp *= 0.5;
    }
    sum / 0.9375
}

impl Pattern {
    /// The mix between colour a (0) and b (1) at `p` (UV times scale).
    pub fn mix(self, p: Vec2) -> f32 {
        let cell = floor2(p);
        let fract = p - cell;
        match self {
            Self::Checker => ((cell.x + cell.y) as i64 & 1) as f32,
            Self::Stripes => (fract.x < 0.5) as u8 as f32,
            Self::Grid => (fract.x < 0.1 || fract.y < 0.1) as u8 as f32,
            Self::Dots => ((fract - Vec2::splat(0.5)).length() < 0.3) as u8 as f32,
            Self::Noise => fbm(p * 2.0),
            Self::Marble => 0.5 + 0.5 * (p.x * 3.0 + 6.0 * fbm(p)).sin(),
        }
    }
}

impl Texture {
    /// The linear RGB colour at texture coordinates `uv` (v up; images black at non-finite `uv`).
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        match self {
            Self::Constant(c) => *c,
            Self::Procedural {
                pattern,
                a,
                b,
                scale,
            } => a.lerp(*b, pattern.mix(uv * *scale)),
            Self::Image { image, tint } => image.sample(uv) * *tint,
        }
    }
}

/// A surface: Lambertian diffuse, optional Blinn-Phong highlight, optional perfect mirror,
/// optional emission.
#[derive(Debug, Clone)]
pub struct Material {
    /// Diffuse (Lambertian) albedo, linear RGB.
    pub diffuse: Texture,
    /// Specular colour (zero for none).
    pub specular: Vec3,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Fraction of light reflected as a perfect mirror (one bounce).
    pub mirror: f32,
    /// Radiance the surface emits (linear RGB, zero for none), added wherever a camera ray or
    /// a mirror reflection sees it. It is not a light source: it lights no other surface and
    /// casts no shadows (use point or directional lights for that).
    pub emission: Vec3,
    /// An image the emission is multiplied by (glTF `emissiveTexture`), if any.
    pub emission_texture: Option<Arc<ImageTexture>>,
    /// Alpha, a metallic-roughness texture and a normal map (glTF materials); none by default.
    pub maps: MaterialMaps,
}

/// How a material's alpha makes it transparent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AlphaMode {
    /// A hole wherever alpha < cutoff (glTF `MASK`, `alphaCutoff`).
    Mask {
        /// Alpha below which the surface is a hole; at or above it, it is opaque.
        cutoff: f32,
    },
    /// Stochastic transparency (glTF `BLEND`): each ray passes with probability 1 - alpha,
    /// decided by a hash of the ray and the triangle, so renders are deterministic and the
    /// many pixel x lens samples average to the blend.
    Blend,
}

/// A material's opacity: `factor` times the texture's alpha channel.
#[derive(Debug, Clone)]
pub struct Alpha {
    /// Constant opacity (glTF `baseColorFactor`'s alpha, a scene file's `alpha`), multiplied
    /// by the texture's alpha.
    pub factor: f32,
    /// Image whose alpha channel gives per-texel opacity (only kept when it has one).
    pub texture: Option<Arc<ImageTexture>>,
    /// Whether alpha cuts holes or blends stochastically.
    pub mode: AlphaMode,
}

impl Alpha {
    /// The alpha of `factor` times `texture`'s alpha channel (if it has one) in `mode`, or
    /// `None` when it can never make a hole (MASK: never below the cutoff; BLEND: never below
    /// 1), so the surface needs no hit filter.
    pub fn new(factor: f32, texture: Option<Arc<ImageTexture>>, mode: AlphaMode) -> Option<Alpha> {
        let texture = texture.filter(|t| t.alpha.is_some());
        let lowest_texel = texture
            .as_ref()
            .and_then(|t| t.alpha.as_ref())
            .map_or(1.0, |a| a.iter().copied().fold(1.0f32, f32::min));
        let lowest = factor * lowest_texel;
        let holes = match mode {
            AlphaMode::Mask { cutoff } => lowest < cutoff,
            AlphaMode::Blend => lowest < 1.0,
        };
        holes.then_some(Alpha {
            factor,
            texture,
            mode,
        })
    }

    /// Opacity at texture coordinates `uv`.
    pub fn at(&self, uv: Vec2) -> f32 {
        match &self.texture {
            Some(t) => self.factor * t.sample_alpha(uv),
            None => self.factor,
        }
    }
}

/// glTF metallic-roughness, evaluated per hit: `factor`s times the texture's blue (metallic)
/// and green (roughness) channels, mapped by [`pbr_params`].
#[derive(Debug, Clone)]
pub struct MetalRough {
    /// The base colour (glTF `baseColorFactor` times `baseColorTexture`), before it is dimmed
    /// by metalness into the diffuse colour.
    pub base: Texture,
    /// Metalness factor, in [0, 1], multiplied by the texture's blue channel.
    pub metallic: f32,
    /// Perceptual roughness factor, in [0, 1], multiplied by the texture's green channel.
    pub roughness: f32,
    /// glTF `metallicRoughnessTexture` (blue: metallic, green: roughness; linear).
    pub texture: Arc<ImageTexture>,
}

/// A tangent-space normal map (glTF `normalTexture`, linear RGB, +y up as in OpenGL).
#[derive(Debug, Clone)]
pub struct NormalMap {
    /// The normal map image (linear RGB; each channel maps [0, 1] to [-1, 1]).
    pub image: Arc<ImageTexture>,
    /// Scales the map's x and y (glTF `scale`).
    pub scale: f32,
}

impl NormalMap {
    /// The shading normal at `uv` for the unit normal `n`, unit tangent `t` (orthogonal to `n`)
    /// and bitangent sign `w`.
    pub fn perturb(&self, uv: Vec2, n: Vec3, t: Vec3, w: f32) -> Vec3 {
        let c = self.image.sample(uv) * 2.0 - Vec3::ONE;
        let b = n.cross(t) * w;
        let p = (t * (c.x * self.scale) + b * (c.y * self.scale) + n * c.z).normalize_or_zero();
        if p == Vec3::ZERO { n } else { p }
    }
}

/// Optional material features (all from glTF materials).
#[derive(Debug, Clone, Default)]
pub struct MaterialMaps {
    /// Cut-outs and transparency; `None` when the material is opaque everywhere.
    pub alpha: Option<Alpha>,
    /// Per-hit metallic and roughness; `None` when they are constant (already in the
    /// material's diffuse, specular, shininess and mirror).
    pub metal_rough: Option<MetalRough>,
    /// Tangent-space normal map; `None` for none.
    pub normal: Option<NormalMap>,
}

/// What shading uses of a material at one point: diffuse albedo, Blinn-Phong specular colour
/// and exponent, and mirror fraction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// Diffuse albedo, linear RGB.
    pub albedo: Vec3,
    /// Blinn-Phong specular colour, linear RGB (zero for none).
    pub specular: Vec3,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Fraction of light reflected as a perfect mirror, in [0, 1].
    pub mirror: f32,
}

/// The mapping of glTF metallic-roughness onto dofray's material (see docs/scene-format.md):
/// the surface of base colour `base`, metalness `metallic` and perceptual roughness
/// `roughness` (both in [0, 1]).
pub fn pbr_params(base: Vec3, metallic: f32, roughness: f32) -> Surface {
    let alpha = (roughness * roughness).max(1e-3);
    Surface {
        albedo: base * (1.0 - metallic),
        specular: Vec3::splat(0.04).lerp(base, metallic) * (1.0 - roughness),
        shininess: (2.0 / (alpha * alpha) - 2.0).clamp(1.0, 10_000.0),
        mirror: metallic * (1.0 - roughness) * (1.0 - roughness),
    }
}

impl Material {
    /// A plain diffuse material of linear RGB albedo `color`: no highlight, mirror, emission
    /// or maps.
    pub fn diffuse(color: Vec3) -> Self {
        Self {
            diffuse: Texture::Constant(color),
            specular: Vec3::ZERO,
            shininess: 32.0,
            mirror: 0.0,
            emission: Vec3::ZERO,
            emission_texture: None,
            maps: MaterialMaps::default(),
        }
    }

    /// The material at texture coordinates `uv`.
    #[inline]
    pub fn surface(&self, uv: Vec2) -> Surface {
        match &self.maps.metal_rough {
            None => Surface {
                albedo: self.diffuse.sample(uv),
                specular: self.specular,
                shininess: self.shininess,
                mirror: self.mirror,
            },
            Some(mr) => {
                let t = mr.texture.sample(uv);
                let metallic = (mr.metallic * t.z).clamp(0.0, 1.0);
                let roughness = (mr.roughness * t.y).clamp(0.0, 1.0);
                pbr_params(mr.base.sample(uv), metallic, roughness)
            }
        }
    }

    /// The radiance the surface emits at texture coordinates `uv` (zero for most materials).
    #[inline]
    pub fn emitted(&self, uv: Vec2) -> Vec3 {
        if self.emission == Vec3::ZERO {
            return Vec3::ZERO;
        }
        match &self.emission_texture {
            Some(image) => self.emission * image.sample(uv),
            None => self.emission,
        }
    }
}

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

/// Direct lighting from one light through an unoccluded shadow ray: diffuse + highlight.
pub fn direct(surface: &Surface, sp: &SurfacePoint, view: Vec3, light: &LightSample) -> Vec3 {
    let cos = sp.normal.dot(light.dir);
    if cos <= 0.0 {
        return Vec3::ZERO;
    }
    let mut c = surface.albedo * (1.0 - surface.mirror) * cos;
    if surface.specular != Vec3::ZERO {
        let h = (light.dir - view).normalize_or_zero();
        let cos_h = sp.normal.dot(h);
        if cos_h > 0.0 {
            c += surface.specular * cos_h.powf(surface.shininess);
        }
    }
    c * light.irradiance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_equals_libm_bit_for_bit() {
        let mut values = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            0.99999994,
            -0.99999994,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_608.0,
            16_777_217.0,
            3e9,
            -3e9,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        // Every 97th bit pattern covers all exponents and both signs.
        values.extend((0..u32::MAX / 97).map(|i| f32::from_bits(i.wrapping_mul(97))));
        for x in values {
            let (a, b) = (floor(x), x.floor());
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e} ({:#x}): {a:e} vs {b:e}",
                x.to_bits()
            );
        }
    }

    #[test]
    fn checker_alternates_per_cell() {
        let t = Texture::Procedural {
            pattern: Pattern::Checker,
            a: Vec3::ZERO,
            b: Vec3::ONE,
            scale: 1.0,
        };
        assert_eq!(t.sample(Vec2::new(0.5, 0.5)), Vec3::ZERO);
        assert_eq!(t.sample(Vec2::new(1.5, 0.5)), Vec3::ONE);
        assert_eq!(t.sample(Vec2::new(1.5, 1.5)), Vec3::ZERO);
        assert_eq!(t.sample(Vec2::new(-0.5, 0.5)), Vec3::ONE);
    }

    #[test]
    fn noise_is_bounded_and_varies() {
        let vals: Vec<f32> = (0..200)
            .map(|i| Pattern::Noise.mix(Vec2::new(i as f32 * 0.37, 1.3)))
            .collect();
        assert!(vals.iter().all(|v| (0.0..=1.0).contains(v)));
        let mean = vals.iter().sum::<f32>() / vals.len() as f32;
        assert!(vals.iter().any(|v| (v - mean).abs() > 0.1));
    }

    #[test]
    fn image_texture_is_bilinear_and_wraps() {
        let img = ImageTexture {
            width: 2,
            height: 1,
            texels: vec![Vec3::ZERO, Vec3::ONE],
            alpha: None,
            wrap: Wrap::Clamp,
        };
        assert_eq!(img.sample(Vec2::new(0.25, 0.5)), Vec3::ZERO);
        assert_eq!(img.sample(Vec2::new(0.75, 0.5)), Vec3::ONE);
        assert!((img.sample(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
        let repeat = ImageTexture {
            wrap: Wrap::Repeat,
            ..img
        };
        // Halfway between the last texel (1) and the first (0), wrapped.
        assert!((repeat.sample(Vec2::new(1.0, 0.5)).x - 0.5).abs() < 1e-6);
    }

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
        assert!((c.x - 1.0).abs() < 1e-6);
        let slanted = Light::Directional {
            direction: Vec3::new(1.0, -1.0, 0.0),
            irradiance: Vec3::ONE,
        };
        let c = direct(
            &m.surface(Vec2::ZERO),
            &sp,
            -Vec3::Y,
            &slanted.sample(sp.position),
        );
        assert!((c.x - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
    }
}
