//! Materials: what a surface is made of, with its optional glTF maps.

use std::sync::Arc;

use glam::{Vec2, Vec3};

use super::bsdf::Bsdf;
use super::texture::{ImageTexture, Texture};

/// A surface as glTF 2.0 describes it (metallic-roughness, with KHR_materials_transmission and
/// KHR_materials_ior), plus emission. The path tracer scatters light by the [`Bsdf`] made from
/// it ([`Material::bsdf`]); the direct integrator by the simpler [`Surface`] ([`Material::surface`]).
#[derive(Debug, Clone)]
pub struct Material {
    /// Base colour (linear RGB): the diffuse albedo of a dielectric, the reflectance of a metal.
    pub base_color: Texture,
    /// Metalness, 0 (dielectric) to 1 (metal); times the blue channel of the metallic-roughness
    /// texture when there is one.
    pub metallic: f32,
    /// Perceptual roughness, 0 (smooth: a mirror or clear glass) to 1; times the green channel of
    /// the metallic-roughness texture when there is one.
    pub roughness: f32,
    /// Fraction of the dielectric's diffuse light that is transmitted instead (glass), 0 to 1.
    pub transmission: f32,
    /// Index of refraction of the inside (1.5 by default, as glTF's).
    pub ior: f32,
    /// Thin-walled: transmitted light passes through without bending (a window pane, a leaf)
    /// instead of refracting into a solid.
    pub thin: bool,
    /// Radiance the surface emits (linear RGB, zero for none): seen by every ray, and in the
    /// path tracer the surface is a light (sampled by its power).
    pub emission: Vec3,
    /// An image the emission is multiplied by (glTF `emissiveTexture`), if any.
    pub emission_texture: Option<Arc<ImageTexture>>,
    /// Emission leaves the front face only (the side the triangle winding faces), as from an
    /// area light; otherwise both faces emit, as a mesh with an emission shader does in Cycles.
    pub one_sided: bool,
    /// Alpha, a metallic-roughness texture and a normal map (glTF materials); none by default.
    pub maps: MaterialMaps,
    /// `Some` for the surface of a light object (an area light of a scene file's `[[lights]]`),
    /// which rays treat as Cycles treats its lights; `None` for every other surface.
    pub light: Option<LightObject>,
}

/// How rays treat a light object's surface, as Cycles treats a Blender light: it casts no
/// shadow (shadow rays pass through it), the back of a one-sided one lets every ray through,
/// and camera rays pass through it unless it is visible to the camera. Its front still ends
/// the paths that hit it (it absorbs what lies behind it; Cycles adds that too, usually far
/// dimmer than the light).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LightObject {
    /// Camera rays see it (Blender's Object > Visibility > Ray Visibility > Camera, off for
    /// Blender's lights by default).
    pub camera: bool,
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
    /// glTF `metallicRoughnessTexture` (blue: metallic, green: roughness; linear), multiplying
    /// the material's `metallic` and `roughness`; `None` for none.
    pub metal_rough: Option<Arc<ImageTexture>>,
    /// Tangent-space normal map; `None` for none.
    pub normal: Option<NormalMap>,
}

/// What the direct integrator (`--integrator direct`, the seed's shading) uses of a material at
/// one point: Lambertian albedo, a normalised Blinn-Phong highlight and a mirror fraction.
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

/// The direct integrator's approximation of glTF metallic-roughness: the surface of base colour
/// `base`, metalness `metallic` and perceptual roughness `roughness` (both in [0, 1]).
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
    /// A Lambertian material of linear RGB albedo `color`: index of refraction 1, so no
    /// specular reflection at all (set `ior` to 1.5 for a glTF-like dielectric with its 4%
    /// Fresnel reflection); metallic 0, roughness 1, no emission or maps.
    pub fn diffuse(color: Vec3) -> Self {
        Self {
            base_color: Texture::Constant(color),
            metallic: 0.0,
            roughness: 1.0,
            transmission: 0.0,
            ior: 1.0,
            thin: false,
            emission: Vec3::ZERO,
            emission_texture: None,
            one_sided: false,
            maps: MaterialMaps::default(),
            light: None,
        }
    }

    /// Base colour, metalness and roughness at texture coordinates `uv`.
    #[inline]
    pub fn metal_rough(&self, uv: Vec2) -> (Vec3, f32, f32) {
        let base = self.base_color.sample(uv);
        match &self.maps.metal_rough {
            None => (base, self.metallic, self.roughness),
            Some(texture) => {
                let t = texture.sample(uv);
                let metallic = (self.metallic * t.z).clamp(0.0, 1.0);
                let roughness = (self.roughness * t.y).clamp(0.0, 1.0);
                (base, metallic, roughness)
            }
        }
    }

    /// The direct integrator's surface at texture coordinates `uv`.
    #[inline]
    pub fn surface(&self, uv: Vec2) -> Surface {
        let (base, metallic, roughness) = self.metal_rough(uv);
        pbr_params(base, metallic, roughness)
    }

    /// The path tracer's BSDF at texture coordinates `uv`, seen from outside (`front`) or from
    /// inside the surface.
    #[inline]
    pub fn bsdf(&self, uv: Vec2, front: bool) -> Bsdf {
        let (base_color, metallic, roughness) = self.metal_rough(uv);
        Bsdf {
            base_color,
            metallic,
            roughness,
            transmission: self.transmission,
            // Only a solid that transmits has an inside: an opaque or thin surface seen from
            // its back is the same interface as from its front (no total internal reflection).
            eta: if front || self.thin || self.transmission <= 0.0 {
                self.ior
            } else {
                1.0 / self.ior
            },
            thin: self.thin,
        }
    }

    /// The radiance leaving the surface at texture coordinates `uv` towards a ray that met its
    /// front (`front`, the side its winding faces) or its back: zero behind a one-sided
    /// emitter.
    #[inline]
    pub fn emitted_towards(&self, uv: Vec2, front: bool) -> Vec3 {
        if self.one_sided && !front {
            Vec3::ZERO
        } else {
            self.emitted(uv)
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
