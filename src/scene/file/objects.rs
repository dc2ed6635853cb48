//! Textures, materials and objects: the `[[textures]]`, `[[materials]]` and `[[objects]]`
//! tables, and the model files objects load.

use std::collections::HashMap;
use std::ops::Range;
use std::sync::Arc;

use glam::{Mat3, Vec3};
use toml::Spanned;

use super::raw::{ObjectKind, RawAlphaMode, RawMaterial, RawObject, RawTexture, v3};
use super::{Ctx, load_model};
use crate::embree::TriangleMesh;
use crate::scene::error::LoadError;
use crate::scene::model::{
    self, ModelCamera, Transform, default_material, euler_xyz_deg, short_vec,
};
use crate::scene::texture::TextureCache;
use crate::scene::{MAX_MATERIAL_VALUE, MeshMaterials, Object};
use crate::shade::{
    Alpha, AlphaMode, ImageTexture, Light, Material, MaterialMaps, Pattern, Texture,
};

/// A defined texture, before a material uses it.
pub(super) enum TextureDef {
    Image(Arc<ImageTexture>),
    Procedural {
        pattern: Pattern,
        a: Vec3,
        b: Vec3,
        scale: f32,
    },
}

/// The `[[textures]]` by name.
pub(super) fn textures(
    ctx: &Ctx,
    raw: Vec<Spanned<RawTexture>>,
    cache: &mut TextureCache,
) -> Result<HashMap<String, TextureDef>, LoadError> {
    let mut textures: HashMap<String, TextureDef> = HashMap::new();
    for (i, t) in raw.into_iter().enumerate() {
        let span = t.span();
        let t = t.into_inner();
        let key = format!("textures[{i}]");
        let name = t.name.get_ref().clone();
        if textures.contains_key(&name) {
            return Err(ctx.invalid(
                t.name.span(),
                format!("{key}.name"),
                format!("texture {name:?} is defined twice"),
            ));
        }
        let def = texture(ctx, &key, span, t, cache)?;
        textures.insert(name, def);
    }
    Ok(textures)
}

/// One texture: an image file (loaded through `cache`) or a pattern.
fn texture(
    ctx: &Ctx,
    key: &str,
    span: Range<usize>,
    t: RawTexture,
    cache: &mut TextureCache,
) -> Result<TextureDef, LoadError> {
    Ok(match (&t.image, t.pattern) {
        (Some(file), None) => {
            for (k, set) in [
                ("a", t.a.is_some()),
                ("b", t.b.is_some()),
                ("scale", t.scale.is_some()),
            ] {
                if set {
                    return Err(ctx.invalid(
                        span.clone(),
                        format!("{key}.{k}"),
                        format!(
                            "`{k}` applies to procedural textures (with `pattern`), not to images"
                        ),
                    ));
                }
            }
            let p = ctx.resolve(file.get_ref());
            let image = cache
                .file(&p, t.srgb.unwrap_or(true), t.wrap.unwrap_or_default())
                .map_err(|e| {
                    e.referenced(ctx.at_key(file.span(), format!("{key}.image")), "texture")
                })?;
            TextureDef::Image(image)
        }
        (None, Some(pattern)) => {
            for (k, set) in [("wrap", t.wrap.is_some()), ("srgb", t.srgb.is_some())] {
                if set {
                    return Err(ctx.invalid(
                        span.clone(),
                        format!("{key}.{k}"),
                        format!("`{k}` applies to image textures, not to patterns"),
                    ));
                }
            }
            TextureDef::Procedural {
                pattern,
                a: t.a.map_or(Vec3::splat(0.9), |c| c.0),
                b: t.b.map_or(Vec3::splat(0.1), |c| c.0),
                scale: t.scale.map_or(1.0, |s| s.0),
            }
        }
        (Some(_), Some(_)) => {
            return Err(ctx.invalid(
                span,
                key,
                "a texture is either an `image` or a `pattern`, not both",
            ));
        }
        (None, None) => {
            return Err(ctx.invalid(span, key, "a texture needs `image = \"file.png\"` or `pattern = \"checker\"` (or stripes, grid, dots, noise, marble)"));
        }
    })
}

/// The scene's materials: the `[[materials]]` in file order, then those the objects add.
pub(super) struct Materials {
    /// Every material, by index.
    pub(super) list: Vec<Material>,
    /// The file's materials by name.
    named: HashMap<String, usize>,
    /// The material of objects that name none: the file's "default", else one added on first
    /// use.
    default: Option<usize>,
}

impl Materials {
    /// The `[[materials]]`, whose textures come from `textures`.
    pub(super) fn read(
        ctx: &Ctx,
        raw: Vec<Spanned<RawMaterial>>,
        textures: &HashMap<String, TextureDef>,
    ) -> Result<Self, LoadError> {
        let mut list = Vec::new();
        let mut named: HashMap<String, usize> = HashMap::new();
        for (i, m) in raw.into_iter().enumerate() {
            let m = m.into_inner();
            let key = format!("materials[{i}]");
            let name = m.name.get_ref().clone();
            if named.contains_key(&name) {
                return Err(ctx.invalid(
                    m.name.span(),
                    format!("{key}.name"),
                    format!("material {name:?} is defined twice"),
                ));
            }
            let built = material(ctx, &key, &m, textures)?;
            // The ranges the renderer checks (a colour of 1e38, a pattern scale from a texture
            // of 1e38), refused here at the table that gave them.
            crate::scene::world::check_material(i, &built)
                .map_err(|e| ctx.invalid(m.name.span(), key.clone(), e.to_string()))?;
            list.push(built);
            named.insert(name, list.len() - 1);
        }
        let default = named.get("default").copied();
        Ok(Self {
            list,
            named,
            default,
        })
    }

    /// The index of the default material, adding it on first use.
    fn default_index(&mut self) -> usize {
        *self.default.get_or_insert_with(|| {
            self.list.push(default_material());
            self.list.len() - 1
        })
    }
}

/// One `[[materials]]` table.
fn material(
    ctx: &Ctx,
    key: &str,
    m: &RawMaterial,
    textures: &HashMap<String, TextureDef>,
) -> Result<Material, LoadError> {
    let diffuse = diffuse(ctx, key, m, textures)?;
    let emission = match &m.emission {
        None => Vec3::ZERO,
        Some(e) if e.get_ref().0.max_element() > MAX_MATERIAL_VALUE => {
            return Err(ctx.invalid(
                e.span(),
                format!("{key}.emission"),
                format!(
                    "emission {} is out of range: each component must be from 0 to 1e6",
                    short_vec(e.get_ref().0)
                ),
            ));
        }
        Some(e) => e.get_ref().0,
    };
    let alpha = alpha(m, &diffuse);
    let ior = match &m.ior {
        None => 1.5,
        Some(i) if (1.0..=10.0).contains(&i.get_ref().0) => i.get_ref().0,
        Some(i) => {
            return Err(ctx.invalid(
                i.span(),
                format!("{key}.ior"),
                format!(
                    "ior {} is out of range: an index of refraction from 1 to 10",
                    i.get_ref().0
                ),
            ));
        }
    };
    Ok(Material {
        base_color: diffuse,
        metallic: m.metallic.map_or(0.0, |u| u.0),
        roughness: m.roughness.map_or(1.0, |u| u.0),
        transmission: m.transmission.map_or(0.0, |u| u.0),
        ior,
        thin: m.thin.unwrap_or(false),
        emission,
        emission_texture: None,
        one_sided: false,
        maps: MaterialMaps {
            alpha,
            ..Default::default()
        },
        light: None,
    })
}

/// A material's diffuse colour: its `diffuse`, or its texture tinted by it.
fn diffuse(
    ctx: &Ctx,
    key: &str,
    m: &RawMaterial,
    textures: &HashMap<String, TextureDef>,
) -> Result<Texture, LoadError> {
    let tint = m.diffuse.map(|c| c.0);
    Ok(match &m.texture {
        None => Texture::Constant(tint.unwrap_or(Vec3::splat(0.8))),
        Some(t) => match textures.get(t.get_ref()) {
            Some(TextureDef::Image(image)) => Texture::Image {
                image: image.clone(),
                tint: tint.unwrap_or(Vec3::ONE),
            },
            Some(&TextureDef::Procedural {
                pattern,
                a,
                b,
                scale,
            }) => Texture::Procedural {
                pattern,
                a: tint.map_or(a, |c| a * c),
                b: tint.map_or(b, |c| b * c),
                scale,
            },
            None => {
                return Err(ctx.invalid(
                    t.span(),
                    format!("{key}.texture"),
                    format!(
                        "no texture named {:?} (defined: {})",
                        t.get_ref(),
                        names(textures.keys())
                    ),
                ));
            }
        },
    })
}

/// A material's alpha: `alpha` times an image texture's alpha channel, as a mask (with its
/// cutoff) or blended. Without `alpha_mode`: blended when `alpha` is given, a mask when only
/// `alpha_cutoff` is, else opaque.
fn alpha(m: &RawMaterial, diffuse: &Texture) -> Option<Alpha> {
    let mode = m.alpha_mode.or(match (m.alpha, m.alpha_cutoff) {
        (Some(_), _) => Some(RawAlphaMode::Blend),
        (None, Some(_)) => Some(RawAlphaMode::Mask),
        (None, None) => None,
    });
    mode.and_then(|mode| {
        let mode = match mode {
            RawAlphaMode::Mask => AlphaMode::Mask {
                cutoff: m.alpha_cutoff.map_or(0.5, |c| c.0),
            },
            RawAlphaMode::Blend => AlphaMode::Blend,
        };
        let image = match diffuse {
            Texture::Image { image, .. } => Some(image.clone()),
            _ => None,
        };
        Alpha::new(m.alpha.map_or(1.0, |a| a.0), image, mode)
    })
}

/// A camera a model file gives: the camera, the span of the `camera = true` that asks for
/// it, and the key of its object.
pub(super) type FromModel = (ModelCamera, Range<usize>, String);

/// The `[[objects]]`, and what their model files bring.
#[derive(Default)]
pub(super) struct Objects {
    /// The objects (a mesh file gives several).
    pub(super) list: Vec<Object>,
    /// Where each object came from: its table's span and key.
    pub(super) origins: Vec<(Range<usize>, String)>,
    /// The lights of the model files (those not refused with `lights = false`).
    pub(super) lights: Vec<Light>,
    /// The camera of the model file that gives it (`camera = true`).
    pub(super) camera: Option<FromModel>,
    /// The model files' warnings.
    pub(super) warnings: Vec<String>,
}

/// The `[[objects]]`; objects without a material of their own get the default one.
pub(super) fn objects(
    ctx: &Ctx,
    raw: Vec<Spanned<RawObject>>,
    materials: &mut Materials,
    cache: &mut TextureCache,
) -> Result<Objects, LoadError> {
    let mut reader = ObjectReader {
        ctx,
        materials,
        cache,
        out: Objects::default(),
    };
    for (i, o) in raw.into_iter().enumerate() {
        let span = o.span();
        let o = o.into_inner();
        let key = format!("objects[{i}]");
        reader.object(&key, span.clone(), &o)?;
        let out = &mut reader.out;
        out.origins.resize(out.list.len(), (span, key));
    }
    if reader.out.list.is_empty() {
        return Err(LoadError::Empty {
            path: ctx.path.to_path_buf(),
        });
    }
    Ok(reader.out)
}

/// One `[[objects]]` table being read: its key and span, and what its keys common to every
/// kind give (its transform and scale, and its material).
struct Table<'a> {
    key: &'a str,
    span: Range<usize>,
    raw: &'a RawObject,
    transform: Option<(Transform, Vec3)>,
    material: Option<usize>,
}

impl Table<'_> {
    /// The value of a key an object of this kind needs (`message` says so when it is missing).
    fn needs<'v, T>(
        &self,
        ctx: &Ctx,
        value: &'v Option<T>,
        message: &str,
    ) -> Result<&'v T, LoadError> {
        value
            .as_ref()
            .ok_or_else(|| ctx.invalid(self.span.clone(), self.key, message))
    }
}

/// Reads objects into `out`, adding the materials they bring.
struct ObjectReader<'a> {
    ctx: &'a Ctx<'a>,
    materials: &'a mut Materials,
    cache: &'a mut TextureCache,
    out: Objects,
}

impl ObjectReader<'_> {
    /// One `[[objects]]` table (`key`, at `span`).
    fn object(&mut self, key: &str, span: Range<usize>, o: &RawObject) -> Result<(), LoadError> {
        let ctx = self.ctx;
        check_object_keys(ctx, key, span.clone(), o)?;
        let transform = object_transform(ctx, key, o)?;
        let named = &self.materials.named;
        let material = match &o.material {
            Some(m) => Some(*named.get(m.get_ref()).ok_or_else(|| {
                ctx.invalid(
                    m.span(),
                    format!("{key}.material"),
                    format!(
                        "no material named {:?} (defined: {})",
                        m.get_ref(),
                        names(named.keys())
                    ),
                )
            })?),
            None => None,
        };
        let table = Table {
            key,
            span,
            raw: o,
            transform,
            material,
        };
        match o.kind {
            ObjectKind::Sphere => self.sphere(table),
            ObjectKind::Quad => self.quad(table),
            ObjectKind::Mesh => self.mesh(table),
        }
    }

    fn sphere(&mut self, table: Table) -> Result<(), LoadError> {
        let (ctx, key, o) = (self.ctx, table.key, table.raw);
        let radius = table.needs(ctx, &o.radius, "a sphere needs `radius` (a number > 0)")?;
        let center = o.center.as_ref().map_or(Vec3::ZERO, |c| v3(*c.get_ref()));
        let (center, radius) = match &table.transform {
            None => (center, radius.get_ref().0),
            Some((t, scale)) => {
                if (scale.x - scale.y).abs() > 1e-6 * scale.x
                    || (scale.x - scale.z).abs() > 1e-6 * scale.x
                {
                    let s = o.scale.as_ref().map_or(table.span.clone(), |s| s.span());
                    return Err(ctx.invalid(
                        s,
                        format!("{key}.scale"),
                        "a sphere can only be scaled uniformly (give one number)",
                    ));
                }
                (
                    t.affine.transform_point3(center),
                    radius.get_ref().0 * scale.x,
                )
            }
        };
        if !(center.is_finite() && radius.is_finite() && radius > 0.0) {
            return Err(ctx.invalid(table.span, key, "the transformed sphere is not finite"));
        }
        let material = table
            .material
            .unwrap_or_else(|| self.materials.default_index());
        self.out.list.push(Object::Sphere {
            center,
            radius,
            material,
        });
        Ok(())
    }

    fn quad(&mut self, table: Table) -> Result<(), LoadError> {
        let (ctx, key, o) = (self.ctx, table.key, table.raw);
        let size = table.needs(
            ctx,
            &o.size,
            "a quad needs `size = [width, depth]` (numbers > 0)",
        )?;
        let [w, d] = *size.get_ref();
        let c = o.center.as_ref().map_or(Vec3::ZERO, |c| v3(*c.get_ref()));
        let corners = [
            [c.x - w.0 * 0.5, c.z - d.0 * 0.5],
            [c.x + w.0 * 0.5, c.z - d.0 * 0.5],
            [c.x + w.0 * 0.5, c.z + d.0 * 0.5],
            [c.x - w.0 * 0.5, c.z + d.0 * 0.5],
        ];
        // Flat, so Embree's geometric normal serves for shading (no vertex normals).
        let mut positions: Vec<[f32; 3]> = corners.iter().map(|&[x, z]| [x, c.y, z]).collect();
        let mut indices = vec![[0, 2, 1], [0, 3, 2]];
        if let Some((t, _)) = &table.transform {
            for p in &mut positions {
                *p = t.point(*p);
            }
            if t.mirrors {
                for tri in &mut indices {
                    tri.swap(1, 2);
                }
            }
        }
        let mesh = TriangleMesh::new(positions, indices)
            .and_then(|m| m.with_uvs(corners.to_vec()))
            .map_err(|e| ctx.invalid(table.span.clone(), key, format!("invalid quad: {e}")))?;
        let material = table
            .material
            .unwrap_or_else(|| self.materials.default_index());
        self.out.list.push(Object::Mesh {
            mesh,
            materials: MeshMaterials::One(material),
        });
        Ok(())
    }

    fn mesh(&mut self, table: Table) -> Result<(), LoadError> {
        let (ctx, key, o) = (self.ctx, table.key, table.raw);
        let file = table.needs(
            ctx,
            &o.file,
            "a mesh needs `file` (an .obj, .gltf or .glb file)",
        )?;
        let at = ctx.at_key(file.span(), format!("{key}.file"));
        let p = ctx.resolve(file.get_ref());
        let t = table
            .transform
            .map(|(t, _)| t)
            .unwrap_or(Transform::IDENTITY);
        let model = load_model(&p, &t, self.cache).map_err(|e| match e {
            LoadError::UnknownScene { .. } => LoadError::invalid(
                at.clone(),
                format!(
                    "unsupported mesh file {:?}: expected .obj, .gltf or .glb",
                    file.get_ref()
                ),
            ),
            e => e.referenced(at.clone(), "mesh"),
        })?;
        if o.lights != Some(false) {
            self.out.lights.extend(model.lights.iter().copied());
        }
        self.out.warnings.extend(model.warnings.iter().cloned());
        if let Some(c) = o.camera.as_ref().filter(|c| *c.get_ref()) {
            let camera = self.model_camera(key, c, file.get_ref(), &model)?;
            self.out.camera = Some((camera, c.span(), key.to_string()));
        }
        let offset = self.materials.list.len();
        let model_materials = model.materials.len();
        self.materials
            .list
            .extend(model.materials.into_iter().map(|(_, m)| m));
        for m in model.meshes {
            let index = match (table.material, m.material) {
                (Some(over), _) => over,
                (None, Some(k)) if k < model_materials => offset + k,
                (None, _) => self.materials.default_index(),
            };
            self.out.list.push(Object::Mesh {
                mesh: m.mesh,
                materials: MeshMaterials::One(index),
            });
        }
        Ok(())
    }

    /// The camera of `model` (from `file`), which `camera = true` (`flag`) asks for.
    fn model_camera(
        &self,
        key: &str,
        flag: &Spanned<bool>,
        file: &str,
        model: &model::Model,
    ) -> Result<ModelCamera, LoadError> {
        let ctx = self.ctx;
        if let Some((_, _, first)) = &self.out.camera {
            return Err(ctx.invalid(
                flag.span(),
                format!("{key}.camera"),
                format!("{first} already gives the camera; set `camera = true` on one model"),
            ));
        }
        match (model.camera, &model.orthographic_camera) {
            (Some(camera), _) => Ok(camera),
            (None, Some(ortho)) => Err(ctx.invalid(
                flag.span(),
                format!("{key}.camera"),
                format!(
                    "{file:?} has no perspective camera: its only camera, {ortho}, is \
                     orthographic, and dofray renders perspective views only"
                ),
            )),
            (None, None) => Err(ctx.invalid(
                flag.span(),
                format!("{key}.camera"),
                format!(
                    "{file:?} has no camera (`camera = true` takes the first perspective \
                     camera of a .gltf or .glb file)"
                ),
            )),
        }
    }
}

/// Refuses the keys that do not apply to the object's kind.
fn check_object_keys(
    ctx: &Ctx,
    key: &str,
    span: Range<usize>,
    o: &RawObject,
) -> Result<(), LoadError> {
    let (kind_name, allowed): (&str, &[&str]) = match o.kind {
        ObjectKind::Sphere => ("sphere", &["center", "radius"]),
        ObjectKind::Quad => ("quad", &["center", "size"]),
        ObjectKind::Mesh => ("mesh", &["file", "lights", "camera"]),
    };
    for (k, set) in [
        ("center", o.center.is_some()),
        ("radius", o.radius.is_some()),
        ("size", o.size.is_some()),
        ("file", o.file.is_some()),
        ("lights", o.lights.is_some()),
        ("camera", o.camera.is_some()),
    ] {
        if set && !allowed.contains(&k) {
            return Err(ctx.invalid(
                span,
                format!("{key}.{k}"),
                format!(
                    "`{k}` does not apply to a {kind_name} (it takes {})",
                    allowed
                        .iter()
                        .map(|a| format!("`{a}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    Ok(())
}

/// A readable list of defined names.
fn names<'a>(names: impl Iterator<Item = &'a String>) -> String {
    let mut v: Vec<&str> = names.map(String::as_str).collect();
    if v.is_empty() {
        return "none".into();
    }
    v.sort_unstable();
    v.iter()
        .map(|n| format!("{n:?}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The object's transform and its scale (`None` when it has no transform keys).
fn object_transform(
    ctx: &Ctx,
    key: &str,
    o: &RawObject,
) -> Result<Option<(Transform, Vec3)>, LoadError> {
    if o.translate.is_none()
        && o.rotate.is_none()
        && o.rotate_axis.is_none()
        && o.rotate_angle.is_none()
        && o.scale.is_none()
    {
        return Ok(None);
    }
    let rotation = match (&o.rotate, &o.rotate_axis, &o.rotate_angle) {
        (None, None, None) => Mat3::IDENTITY,
        (Some(r), None, None) => euler_xyz_deg(v3(*r.get_ref())),
        (None, Some(axis), Some(angle)) => {
            let a = v3(*axis.get_ref());
            if a.length_squared() == 0.0 || !a.is_finite() {
                return Err(ctx.invalid(
                    axis.span(),
                    format!("{key}.rotate_axis"),
                    "the rotation axis must not be zero",
                ));
            }
            Mat3::from_axis_angle(a.normalize(), angle.get_ref().0.to_radians())
        }
        (Some(r), Some(_), _) | (Some(r), _, Some(_)) => {
            return Err(ctx.invalid(r.span(), format!("{key}.rotate"), "give either `rotate` (Euler angles) or `rotate_axis` with `rotate_angle`, not both"));
        }
        (None, Some(axis), None) => {
            return Err(ctx.invalid(
                axis.span(),
                format!("{key}.rotate_axis"),
                "`rotate_axis` needs `rotate_angle` (degrees)",
            ));
        }
        (None, None, Some(angle)) => {
            return Err(ctx.invalid(
                angle.span(),
                format!("{key}.rotate_angle"),
                "`rotate_angle` needs `rotate_axis`",
            ));
        }
    };
    let scale = o.scale.as_ref().map_or(Vec3::ONE, |s| s.get_ref().0);
    let translate = o
        .translate
        .as_ref()
        .map_or(Vec3::ZERO, |t| v3(*t.get_ref()));
    let span = o
        .scale
        .as_ref()
        .map(|s| s.span())
        .or(o.translate.as_ref().map(|t| t.span()))
        .unwrap_or(0..0);
    let t = Transform::from_srt(scale, rotation, translate).ok_or_else(|| {
        // Scales are finite and > 0 and rotations are orthonormal, so only the scale's
        // magnitude can make the matrix or its inverse leave the f32 range.
        let volume = scale.as_dvec3().element_product();
        let shown = if scale.x == scale.y && scale.x == scale.z {
            model::short_number(scale.x)
        } else {
            model::short_vec(scale)
        };
        let det = format!("{volume:.1e}");
        let why = if volume > f32::MAX as f64 {
            format!(
                "the scale {shown} is too large: the transform's determinant ({det}) overflows \
                 32-bit floats"
            )
        } else if volume < f32::MIN_POSITIVE as f64 {
            format!(
                "the scale {shown} is too small: the transform's determinant ({det}) underflows \
                 32-bit floats, so it cannot be inverted (for the normals)"
            )
        } else {
            format!(
                "the scale {shown} is out of range: the transform or its inverse (for the \
                 normals) overflows 32-bit floats"
            )
        };
        let key = match &o.scale {
            Some(_) => format!("{key}.scale"),
            None => key.to_string(),
        };
        ctx.invalid(span, key, why)
    })?;
    Ok(Some((t, scale)))
}
