//! The TOML scene format (documented key by key in `docs/scene-format.md`).
//!
//! Every table rejects unknown keys, so a typo is an error rather than a silently ignored
//! setting. Numbers are checked as they are read (finite; sizes and radii > 0; colours >= 0),
//! so errors carry the line, column and key of the offending value.

use std::collections::HashMap;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DVec3, Mat3, Vec3};
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Unexpected, Visitor};
use toml::Spanned;

use super::animation::{Animation, FocusTrack, Interpolation, Key, Track, Tracks, Value};
use super::error::{LoadError, Location, shown};
use super::input::{self, LoadOptions};
use super::model::{
    self, DEFAULT_HEIGHT, DEFAULT_VFOV, DEFAULT_WIDTH, ModelCamera, Transform, default_background,
    default_light, default_material, euler_xyz_deg, short_vec,
};
use super::texture::TextureCache;
use super::{Background, MAX_MATERIAL_VALUE, MeshMaterials, Object, SceneDesc};
use crate::camera::{ApertureShape, CameraSpec, Focus, LensSpec};
use crate::embree::TriangleMesh;
use crate::shade::{
    Alpha, AlphaMode, ImageTexture, Light, Material, MaterialMaps, Pattern, Texture, Wrap,
};

// ---------------------------------------------------------------------------------------------
// Checked numbers: rejected while parsing, so the error points at the value.

struct NumberVisitor {
    expected: &'static str,
    ok: fn(f32) -> bool,
    /// Accept +inf (and numbers beyond f32, which become +inf).
    allow_inf: bool,
}

impl NumberVisitor {
    fn check<E: de::Error>(&self, v: f64, unexpected: Unexpected) -> Result<f32, E> {
        let f = v as f32;
        let in_range = (v.is_finite() && f.is_finite()) || (self.allow_inf && f == f32::INFINITY);
        if in_range && (self.ok)(f) {
            Ok(f)
        } else {
            Err(E::invalid_value(unexpected, self))
        }
    }
}

impl Visitor<'_> for NumberVisitor {
    type Value = f32;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(self.expected)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f32, E> {
        self.check(v, Unexpected::Float(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f32, E> {
        self.check(v as f64, Unexpected::Signed(v))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f32, E> {
        self.check(v as f64, Unexpected::Unsigned(v))
    }
}

macro_rules! number {
    ($(#[$doc:meta])* $name:ident, $expected:expr, $ok:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        struct $name(f32);

        impl<'de> Deserialize<'de> for $name {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                d.deserialize_any(NumberVisitor {
                    expected: $expected,
                    ok: $ok,
                    allow_inf: false,
                })
                .map($name)
            }
        }
    };
}

number!(
    /// Any finite number.
    Finite,
    "a finite number",
    |_| true
);
number!(
    /// A finite number > 0 (sizes, radii, distances).
    Positive,
    "a finite number > 0",
    |v| v > 0.0
);
/// A focus distance: a number > 0, or `inf` (focused at infinity; numbers too large for f32
/// mean the same).
#[derive(Debug, Clone, Copy, PartialEq)]
struct FocusDistance(f32);

impl<'de> Deserialize<'de> for FocusDistance {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumberVisitor {
            expected: "a number > 0, or inf",
            ok: |v| v > 0.0,
            allow_inf: true,
        })
        .map(FocusDistance)
    }
}

number!(
    /// A finite number >= 0.
    NonNeg,
    "a finite number >= 0",
    |v| v >= 0.0
);
number!(
    /// A fraction in [0, 1].
    Unit,
    "a number between 0 and 1",
    |v| (0.0..=1.0).contains(&v)
);
number!(
    /// A field of view in degrees, strictly between 0 and 180.
    Fov,
    "an angle in degrees between 0 and 180 (exclusive)",
    |v| v > 0.0 && v < 180.0
);

/// A whole number with a lower bound (image sizes, sample counts, blade counts).
struct CountVisitor {
    expected: &'static str,
    min: u64,
}

impl Visitor<'_> for CountVisitor {
    type Value = u32;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(self.expected)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<u32, E> {
        if v < 0 {
            return Err(E::invalid_value(Unexpected::Signed(v), &self));
        }
        self.visit_u64(v as u64)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<u32, E> {
        if v >= self.min && v <= u32::MAX as u64 {
            Ok(v as u32)
        } else {
            Err(E::invalid_value(Unexpected::Unsigned(v), &self))
        }
    }
}

macro_rules! count {
    ($(#[$doc:meta])* $name:ident, $expected:expr, $min:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        struct $name(u32);

        impl<'de> Deserialize<'de> for $name {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                d.deserialize_any(CountVisitor {
                    expected: $expected,
                    min: $min,
                })
                .map($name)
            }
        }
    };
}

count!(
    /// An image dimension in pixels.
    Pixels,
    "a whole number of pixels >= 1",
    1
);
count!(
    /// A count of at least one.
    AtLeastOne,
    "a whole number >= 1",
    1
);
count!(
    /// A pixel coordinate or a count that may be zero.
    Whole,
    "a whole number >= 0",
    0
);

/// Three finite coordinates.
type V3 = [Finite; 3];

fn v3(v: V3) -> Vec3 {
    Vec3::new(v[0].0, v[1].0, v[2].0)
}

fn dv3(v: V3) -> DVec3 {
    v3(v).as_dvec3()
}

/// A colour: a number (grey) or `[r, g, b]`, linear, each >= 0.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Color(Vec3);

struct ColorVisitor;

impl<'de> Visitor<'de> for ColorVisitor {
    type Value = Vec3;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a colour: a number >= 0 (grey) or an array [r, g, b] of numbers >= 0")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Vec3, E> {
        if v.is_finite() && v >= 0.0 && (v as f32).is_finite() {
            Ok(Vec3::splat(v as f32))
        } else {
            Err(E::invalid_value(Unexpected::Float(v), &self))
        }
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Vec3, E> {
        if v >= 0 {
            Ok(Vec3::splat(v as f32))
        } else {
            Err(E::invalid_value(Unexpected::Signed(v), &self))
        }
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Vec3, E> {
        Ok(Vec3::splat(v as f32))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec3, A::Error> {
        let mut c = [0.0f32; 3];
        for (i, slot) in c.iter_mut().enumerate() {
            *slot = seq
                .next_element::<NonNeg>()?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?
                .0;
        }
        if seq.next_element::<de::IgnoredAny>()?.is_some() {
            return Err(de::Error::invalid_length(4, &self));
        }
        Ok(Vec3::from(c))
    }
}

impl<'de> Deserialize<'de> for Color {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ColorVisitor).map(Color)
    }
}

/// A scale: a number (uniform) or `[x, y, z]`, each > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Scale(Vec3);

struct ScaleVisitor;

impl<'de> Visitor<'de> for ScaleVisitor {
    type Value = Vec3;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a scale: a number > 0 or an array [x, y, z] of numbers > 0")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Vec3, E> {
        if v.is_finite() && v > 0.0 && (v as f32) > 0.0 && (v as f32).is_finite() {
            Ok(Vec3::splat(v as f32))
        } else {
            Err(E::invalid_value(Unexpected::Float(v), &self))
        }
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Vec3, E> {
        if v > 0 {
            Ok(Vec3::splat(v as f32))
        } else {
            Err(E::invalid_value(Unexpected::Signed(v), &self))
        }
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Vec3, E> {
        self.visit_f64(v as f64)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec3, A::Error> {
        let mut c = [0.0f32; 3];
        for (i, slot) in c.iter_mut().enumerate() {
            *slot = seq
                .next_element::<Positive>()?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?
                .0;
        }
        if seq.next_element::<de::IgnoredAny>()?.is_some() {
            return Err(de::Error::invalid_length(4, &self));
        }
        Ok(Vec3::from(c))
    }
}

impl<'de> Deserialize<'de> for Scale {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ScaleVisitor).map(Scale)
    }
}

// ---------------------------------------------------------------------------------------------
// The file's shape.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    ambient: Option<Color>,
    image: Option<RawImage>,
    render: Option<RawRender>,
    camera: Option<Spanned<RawCamera>>,
    background: Option<Spanned<RawBackground>>,
    lights: Option<Vec<Spanned<RawLight>>>,
    #[serde(default)]
    textures: Vec<Spanned<RawTexture>>,
    #[serde(default)]
    materials: Vec<Spanned<RawMaterial>>,
    #[serde(default)]
    objects: Vec<Spanned<RawObject>>,
    animation: Option<Spanned<RawAnimation>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawImage {
    width: Option<Spanned<Pixels>>,
    height: Option<Spanned<Pixels>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    spp: Option<AtLeastOne>,
    aa: Option<AtLeastOne>,
    interval_factor: Option<Positive>,
    tolerance: Option<Spanned<Positive>>,
    pixel_filter: Option<crate::filter::PixelFilterKind>,
    pixel_filter_width: Option<Spanned<Positive>>,
    transparent: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    eye: Option<Spanned<V3>>,
    look_at: Option<Spanned<V3>>,
    up: Option<Spanned<V3>>,
    vfov: Option<Spanned<Fov>>,
    aperture_radius: Option<Spanned<NonNeg>>,
    f_number: Option<Spanned<Positive>>,
    focal_length_mm: Option<Spanned<Positive>>,
    sensor_width_mm: Option<Spanned<Positive>>,
    sharp_range: Option<Spanned<Positive>>,
    spread: Option<Spanned<NonNeg>>,
    focus_distance: Option<Spanned<FocusDistance>>,
    focus_point: Option<Spanned<V3>>,
    focus_pixel: Option<Spanned<[Whole; 2]>>,
    blades: Option<Spanned<Whole>>,
    blade_rotation: Option<Finite>,
    anamorphic: Option<Positive>,
}

/// The `[animation]` table: the shot's range and rate, and its keys.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAnimation {
    fps: Option<Positive>,
    frame_start: Option<Spanned<i64>>,
    frame_end: Option<Spanned<i64>>,
    interpolation: Option<Interpolation>,
    #[serde(default)]
    key: Vec<Spanned<RawKey>>,
}

/// One `[[animation.key]]`: a frame and the values some parameters take there.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawKey {
    frame: Spanned<i64>,
    interpolation: Option<Interpolation>,
    eye: Option<Spanned<V3>>,
    look_at: Option<Spanned<V3>>,
    up: Option<Spanned<V3>>,
    vfov: Option<Spanned<Fov>>,
    focal_length_mm: Option<Spanned<Positive>>,
    f_number: Option<Spanned<Positive>>,
    aperture_radius: Option<Spanned<NonNeg>>,
    focus_distance: Option<Spanned<FocusDistance>>,
    focus_point: Option<Spanned<V3>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBackground {
    color: Option<Color>,
    horizon: Option<Color>,
    zenith: Option<Color>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum LightKind {
    Point,
    Directional,
    Spot,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLight {
    #[serde(rename = "type")]
    kind: LightKind,
    position: Option<V3>,
    intensity: Option<Color>,
    direction: Option<Spanned<V3>>,
    irradiance: Option<Color>,
    inner_angle: Option<Spanned<Finite>>,
    outer_angle: Option<Spanned<Finite>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTexture {
    name: Spanned<String>,
    image: Option<Spanned<String>>,
    wrap: Option<Wrap>,
    srgb: Option<bool>,
    pattern: Option<Pattern>,
    a: Option<Color>,
    b: Option<Color>,
    scale: Option<Positive>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    name: Spanned<String>,
    diffuse: Option<Color>,
    texture: Option<Spanned<String>>,
    specular: Option<Color>,
    shininess: Option<Positive>,
    mirror: Option<Unit>,
    emission: Option<Spanned<Color>>,
    alpha: Option<Unit>,
    alpha_mode: Option<RawAlphaMode>,
    alpha_cutoff: Option<Unit>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawAlphaMode {
    Mask,
    Blend,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum ObjectKind {
    Sphere,
    Quad,
    Mesh,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    #[serde(rename = "type")]
    kind: ObjectKind,
    material: Option<Spanned<String>>,
    center: Option<Spanned<V3>>,
    radius: Option<Spanned<Positive>>,
    size: Option<Spanned<[Positive; 2]>>,
    file: Option<Spanned<String>>,
    translate: Option<Spanned<V3>>,
    rotate: Option<Spanned<V3>>,
    rotate_axis: Option<Spanned<V3>>,
    rotate_angle: Option<Spanned<Finite>>,
    scale: Option<Spanned<Scale>>,
    lights: Option<bool>,
    camera: Option<Spanned<bool>>,
}

// ---------------------------------------------------------------------------------------------
// From the file's shape to a scene.

/// The scene file being built: its path and text, for error locations and relative paths.
struct Ctx<'a> {
    path: &'a Path,
    src: &'a str,
    dir: PathBuf,
}

impl Ctx<'_> {
    fn at(&self, span: Range<usize>) -> Location {
        Location::at_offset(self.path, self.src, span.start)
    }

    fn at_key(&self, span: Range<usize>, key: impl Into<String>) -> Location {
        self.at(span).with_key(key)
    }

    fn invalid(
        &self,
        span: Range<usize>,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> LoadError {
        LoadError::invalid(self.at_key(span, key), message)
    }

    fn resolve(&self, file: &str) -> PathBuf {
        self.dir.join(file)
    }
}

/// A defined texture, before a material uses it.
enum TextureDef {
    Image(Arc<ImageTexture>),
    Procedural {
        pattern: Pattern,
        a: Vec3,
        b: Vec3,
        scale: f32,
    },
}

/// Loads a TOML scene file.
pub fn load(path: &Path, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let bytes = input::read(path, options)?;
    let src = String::from_utf8(bytes).map_err(|e| {
        let (line, column) = super::error::line_column(
            &String::from_utf8_lossy(e.as_bytes()),
            e.utf8_error().valid_up_to(),
        );
        LoadError::Toml {
            at: Location {
                line: Some(line),
                column: Some(column),
                ..Location::file(path)
            },
            message: "invalid UTF-8 (a TOML file must be UTF-8 text)".into(),
        }
    })?;
    parse_with(&src, path, options)
}

/// Parses a TOML scene from `src`; `path` names it in errors, and relative file names in it
/// resolve against `path`'s directory.
///
/// ```rust
/// use std::path::Path;
///
/// let src = r#"
/// [image]
/// width = 320
/// height = 240
///
/// [camera]
/// eye = [0, 1, 5]
/// look_at = [0, 1, 0]
/// f_number = 2
/// focal_length_mm = 50
/// focus_point = [0, 1, 0]
///
/// [[materials]]
/// name = "red"
/// diffuse = [0.8, 0.1, 0.1]
///
/// [[objects]]
/// type = "sphere"
/// center = [0, 1, 0]
/// radius = 1
/// material = "red"
/// "#;
/// let scene = dofray::scene::file::parse(src, Path::new("memory.toml"))?;
/// assert_eq!(scene.objects.len(), 1);
///
/// // Errors give the file, line and column, and what was expected.
/// let e = dofray::scene::file::parse("[camera]\neye = 3\n", Path::new("bad.toml")).unwrap_err();
/// assert!(e.to_string().starts_with("bad.toml:2:7"), "{e}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn parse(src: &str, path: &Path) -> Result<SceneDesc, LoadError> {
    parse_with(src, path, &LoadOptions::default())
}

/// [`parse`] with explicit limits and path policy for the files the scene refers to.
pub fn parse_with(src: &str, path: &Path, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let raw: RawScene = toml::from_str(src).map_err(|e| {
        let at = match e.span() {
            Some(span) => Location::at_offset(path, src, span.start),
            None => Location::file(path),
        };
        LoadError::Toml {
            at,
            message: e.message().trim().replace('\n', "; "),
        }
    })?;
    let ctx = Ctx {
        path,
        src,
        dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
    };
    build(&ctx, raw, options)
}

fn build(ctx: &Ctx, raw: RawScene, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let mut cache = TextureCache::new(*options);

    // Textures by name.
    let mut textures: HashMap<String, TextureDef> = HashMap::new();
    for (i, t) in raw.textures.into_iter().enumerate() {
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
        let def = match (&t.image, t.pattern) {
            (Some(file), None) => {
                for (k, set) in [
                    ("a", t.a.is_some()),
                    ("b", t.b.is_some()),
                    ("scale", t.scale.is_some()),
                ] {
                    if set {
                        return Err(ctx.invalid(span.clone(), format!("{key}.{k}"), format!("`{k}` applies to procedural textures (with `pattern`), not to images")));
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
        };
        textures.insert(name, def);
    }

    // Materials by name, in file order.
    let mut materials = Vec::new();
    let mut material_index: HashMap<String, usize> = HashMap::new();
    for (i, m) in raw.materials.into_iter().enumerate() {
        let m = m.into_inner();
        let key = format!("materials[{i}]");
        let name = m.name.get_ref().clone();
        if material_index.contains_key(&name) {
            return Err(ctx.invalid(
                m.name.span(),
                format!("{key}.name"),
                format!("material {name:?} is defined twice"),
            ));
        }
        let tint = m.diffuse.map(|c| c.0);
        let diffuse = match &m.texture {
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
        };
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
        // Alpha: `alpha` times an image texture's alpha channel, as a mask (with its cutoff)
        // or blended. Without `alpha_mode`: blended when `alpha` is given, a mask when only
        // `alpha_cutoff` is, else opaque.
        let mode = m.alpha_mode.or(match (m.alpha, m.alpha_cutoff) {
            (Some(_), _) => Some(RawAlphaMode::Blend),
            (None, Some(_)) => Some(RawAlphaMode::Mask),
            (None, None) => None,
        });
        let alpha = mode.and_then(|mode| {
            let mode = match mode {
                RawAlphaMode::Mask => AlphaMode::Mask {
                    cutoff: m.alpha_cutoff.map_or(0.5, |c| c.0),
                },
                RawAlphaMode::Blend => AlphaMode::Blend,
            };
            let image = match &diffuse {
                Texture::Image { image, .. } => Some(image.clone()),
                _ => None,
            };
            Alpha::new(m.alpha.map_or(1.0, |a| a.0), image, mode)
        });
        materials.push(Material {
            diffuse,
            specular: m.specular.map_or(Vec3::ZERO, |c| c.0),
            shininess: m.shininess.map_or(32.0, |s| s.0),
            mirror: m.mirror.map_or(0.0, |u| u.0),
            emission,
            emission_texture: None,
            maps: MaterialMaps {
                alpha,
                ..Default::default()
            },
        });
        material_index.insert(name, materials.len() - 1);
    }
    let named_materials = material_index.clone();
    let mut default_index = material_index.get("default").copied();
    let mut default_material_index = |materials: &mut Vec<Material>| {
        *default_index.get_or_insert_with(|| {
            materials.push(default_material());
            materials.len() - 1
        })
    };

    // Objects, and where each came from (a mesh file gives several); the lights and camera of
    // the model files, and their warnings.
    let mut model_lights: Vec<Light> = Vec::new();
    let mut model_camera: Option<(ModelCamera, Range<usize>, String)> = None;
    let mut warnings: Vec<String> = Vec::new();
    let mut objects = Vec::new();
    let mut origins: Vec<(Range<usize>, String)> = Vec::new();
    for (i, o) in raw.objects.into_iter().enumerate() {
        let span = o.span();
        let o = o.into_inner();
        let key = format!("objects[{i}]");
        let kind = o.kind;
        let kind_name = match kind {
            ObjectKind::Sphere => "sphere",
            ObjectKind::Quad => "quad",
            ObjectKind::Mesh => "mesh",
        };
        let allowed: &[&str] = match kind {
            ObjectKind::Sphere => &["center", "radius"],
            ObjectKind::Quad => &["center", "size"],
            ObjectKind::Mesh => &["file", "lights", "camera"],
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
                    span.clone(),
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
        let transform = object_transform(ctx, &key, &o)?;
        let material = match &o.material {
            Some(m) => Some(*named_materials.get(m.get_ref()).ok_or_else(|| {
                ctx.invalid(
                    m.span(),
                    format!("{key}.material"),
                    format!(
                        "no material named {:?} (defined: {})",
                        m.get_ref(),
                        names(named_materials.keys())
                    ),
                )
            })?),
            None => None,
        };
        match kind {
            ObjectKind::Sphere => {
                let radius = o.radius.as_ref().ok_or_else(|| {
                    ctx.invalid(
                        span.clone(),
                        key.clone(),
                        "a sphere needs `radius` (a number > 0)",
                    )
                })?;
                let center = o.center.as_ref().map_or(Vec3::ZERO, |c| v3(*c.get_ref()));
                let (center, radius) = match &transform {
                    None => (center, radius.get_ref().0),
                    Some((t, scale)) => {
                        if (scale.x - scale.y).abs() > 1e-6 * scale.x
                            || (scale.x - scale.z).abs() > 1e-6 * scale.x
                        {
                            let s = o.scale.as_ref().map_or(span.clone(), |s| s.span());
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
                    return Err(ctx.invalid(span, key, "the transformed sphere is not finite"));
                }
                let material = material.unwrap_or_else(|| default_material_index(&mut materials));
                objects.push(Object::Sphere {
                    center,
                    radius,
                    material,
                });
            }
            ObjectKind::Quad => {
                let size = o.size.as_ref().ok_or_else(|| {
                    ctx.invalid(
                        span.clone(),
                        key.clone(),
                        "a quad needs `size = [width, depth]` (numbers > 0)",
                    )
                })?;
                let [w, d] = *size.get_ref();
                let c = o.center.as_ref().map_or(Vec3::ZERO, |c| v3(*c.get_ref()));
                let corners = [
                    [c.x - w.0 * 0.5, c.z - d.0 * 0.5],
                    [c.x + w.0 * 0.5, c.z - d.0 * 0.5],
                    [c.x + w.0 * 0.5, c.z + d.0 * 0.5],
                    [c.x - w.0 * 0.5, c.z + d.0 * 0.5],
                ];
                // Flat, so Embree's geometric normal serves for shading (no vertex normals).
                let mut positions: Vec<[f32; 3]> =
                    corners.iter().map(|&[x, z]| [x, c.y, z]).collect();
                let mut indices = vec![[0, 2, 1], [0, 3, 2]];
                if let Some((t, _)) = &transform {
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
                    .map_err(|e| {
                        ctx.invalid(span.clone(), key.clone(), format!("invalid quad: {e}"))
                    })?;
                let material = material.unwrap_or_else(|| default_material_index(&mut materials));
                objects.push(Object::Mesh {
                    mesh,
                    materials: MeshMaterials::One(material),
                });
            }
            ObjectKind::Mesh => {
                let file = o.file.as_ref().ok_or_else(|| {
                    ctx.invalid(
                        span.clone(),
                        key.clone(),
                        "a mesh needs `file` (an .obj, .gltf or .glb file)",
                    )
                })?;
                let at = ctx.at_key(file.span(), format!("{key}.file"));
                let p = ctx.resolve(file.get_ref());
                let t = transform.map(|(t, _)| t).unwrap_or(Transform::IDENTITY);
                let model = load_model(&p, &t, &mut cache).map_err(|e| match e {
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
                    model_lights.extend(model.lights.iter().copied());
                }
                warnings.extend(model.warnings.iter().cloned());
                if let Some(c) = o.camera.as_ref().filter(|c| *c.get_ref()) {
                    if let Some((_, _, first)) = &model_camera {
                        return Err(ctx.invalid(
                            c.span(),
                            format!("{key}.camera"),
                            format!(
                                "{first} already gives the camera; set `camera = true` on one model"
                            ),
                        ));
                    }
                    let camera = match (model.camera, &model.orthographic_camera) {
                        (Some(camera), _) => camera,
                        (None, Some(ortho)) => {
                            return Err(ctx.invalid(
                                c.span(),
                                format!("{key}.camera"),
                                format!(
                                    "{:?} has no perspective camera: its only camera, {ortho}, \
                                     is orthographic, and dofray renders perspective views only",
                                    file.get_ref()
                                ),
                            ));
                        }
                        (None, None) => {
                            return Err(ctx.invalid(
                                c.span(),
                                format!("{key}.camera"),
                                format!(
                                    "{:?} has no camera (`camera = true` takes the first \
                                     perspective camera of a .gltf or .glb file)",
                                    file.get_ref()
                                ),
                            ));
                        }
                    };
                    model_camera = Some((camera, c.span(), key.clone()));
                }
                let offset = materials.len();
                let model_materials = model.materials.len();
                materials.extend(model.materials.into_iter().map(|(_, m)| m));
                for m in model.meshes {
                    let index = match (material, m.material) {
                        (Some(over), _) => over,
                        (None, Some(k)) if k < model_materials => offset + k,
                        (None, _) => default_material_index(&mut materials),
                    };
                    objects.push(Object::Mesh {
                        mesh: m.mesh,
                        materials: MeshMaterials::One(index),
                    });
                }
            }
        }
        origins.resize(objects.len(), (span, key));
    }
    if objects.is_empty() {
        return Err(LoadError::Empty {
            path: ctx.path.to_path_buf(),
        });
    }

    // Image, camera and lens.
    let image = raw.image.as_ref();
    let width = image
        .and_then(|i| i.width.as_ref())
        .map_or(DEFAULT_WIDTH, |p| p.get_ref().0);
    // A model camera's aspect ratio sets the height when the file gives none.
    let aspect = model_camera
        .as_ref()
        .and_then(|(c, _, _)| c.aspect)
        .filter(|a| a.is_finite() && *a > 0.05 && *a < 20.0);
    let height = image.and_then(|i| i.height.as_ref()).map_or_else(
        || {
            aspect.map_or(DEFAULT_HEIGHT, |a| {
                ((width as f32 / a).round() as u32).max(1)
            })
        },
        |p| p.get_ref().0,
    );
    // An image whose render buffers cannot fit is refused here, naming the key that asks for
    // it (the larger side's; the command line's --width/--height cannot rescue such a file).
    if let Err(e) = crate::limits::check_image_memory(width, height) {
        let (key, span) = match image.map(|i| (&i.width, &i.height)) {
            Some((Some(w), h)) if h.as_ref().is_none_or(|h| w.get_ref().0 >= h.get_ref().0) => {
                ("image.width", w.span())
            }
            Some((_, Some(h))) => ("image.height", h.span()),
            _ => ("image", 0..0),
        };
        return Err(ctx.invalid(span, key, e.to_string()));
    }
    // Without a focus key, the focus is on look_at, and follows it when it is animated.
    let focus_on_look_at = !raw.camera.as_ref().is_some_and(|c| {
        let c = c.get_ref();
        c.focus_distance.is_some() || c.focus_point.is_some() || c.focus_pixel.is_some()
    });
    let camera = camera(
        ctx,
        raw.camera,
        width,
        height,
        &objects,
        &origins,
        model_camera.as_ref(),
    )?;
    let animation = raw
        .animation
        .map(|a| animation(ctx, a, &camera, focus_on_look_at))
        .transpose()?;

    // Lights and environment: the file's, else the default key light unless a model brings
    // lights; plus the models' lights.
    let mut lights: Vec<Light> = match raw.lights {
        None if model_lights.is_empty() => vec![default_light(
            (camera.look_at - camera.eye).normalize_or(Vec3::Z),
        )],
        None => Vec::new(),
        Some(lights) => lights
            .into_iter()
            .enumerate()
            .map(|(i, l)| light(ctx, i, l))
            .collect::<Result<_, _>>()?,
    };
    lights.extend(model_lights);
    let background = match raw.background {
        None => default_background(),
        Some(b) => {
            let span = b.span();
            let b = b.into_inner();
            match (b.color, b.horizon, b.zenith) {
                (Some(c), None, None) => Background::uniform(c.0),
                (None, h, z) => {
                    let d = default_background();
                    Background {
                        horizon: h.map_or(d.horizon, |c| c.0),
                        zenith: z.map_or(d.zenith, |c| c.0),
                    }
                }
                _ => return Err(ctx.invalid(span, "background", "give either `color` (a uniform background) or `horizon` and `zenith`, not both")),
            }
        }
    };
    let render = raw.render.unwrap_or(RawRender {
        spp: None,
        aa: None,
        interval_factor: None,
        tolerance: None,
        pixel_filter: None,
        pixel_filter_width: None,
        transparent: None,
    });
    let tolerance = match (&render.tolerance, render.interval_factor) {
        (Some(t), Some(_)) => {
            return Err(ctx.invalid(
                t.span(),
                "render.tolerance",
                "either `tolerance` (the error-controlled rule) or `interval_factor` (the \
                 seed's fixed rule), not both",
            ));
        }
        (t, _) => t.as_ref().map(|t| t.get_ref().0),
    };
    let name = raw.name.unwrap_or_else(|| {
        ctx.path
            .file_stem()
            .map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned())
    });
    Ok(SceneDesc {
        name,
        camera,
        materials,
        objects,
        lights,
        ambient: raw.ambient.map_or(Vec3::splat(0.1), |c| c.0),
        background,
        spp: render.spp.map(|s| s.0),
        aa: render.aa.map(|s| s.0),
        pixel_filter: match (render.pixel_filter, &render.pixel_filter_width) {
            (None, None) => None,
            (kind, width) => {
                let mut filter = crate::filter::PixelFilter::new(kind.unwrap_or_default());
                if let Some(w) = width {
                    filter.width = w.get_ref().0;
                    if !filter.is_valid() {
                        return Err(ctx.invalid(
                            w.span(),
                            "render.pixel_filter_width",
                            "a width in pixels up to 16",
                        ));
                    }
                }
                Some(filter)
            }
        },
        interval_factor: render.interval_factor.map(|k| k.0),
        tolerance,
        transparent: render.transparent.unwrap_or(false),
        warnings,
        animation,
    })
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

fn camera(
    ctx: &Ctx,
    raw: Option<Spanned<RawCamera>>,
    width: u32,
    height: u32,
    objects: &[Object],
    origins: &[(Range<usize>, String)],
    from_model: Option<&(ModelCamera, Range<usize>, String)>,
) -> Result<CameraSpec, LoadError> {
    let table_span = raw.as_ref().map_or(0..0, |r| r.span());
    if let (Some((_, _, key)), Some(raw)) = (from_model, &raw) {
        let raw = raw.get_ref();
        for (k, span) in [
            ("eye", raw.eye.as_ref().map(|s| s.span())),
            ("look_at", raw.look_at.as_ref().map(|s| s.span())),
            ("up", raw.up.as_ref().map(|s| s.span())),
            ("vfov", raw.vfov.as_ref().map(|s| s.span())),
        ] {
            if let Some(span) = span {
                return Err(ctx.invalid(
                    span,
                    format!("camera.{k}"),
                    format!(
                        "the camera's view comes from the model of {key} (`camera = true`); \
                         remove `{k}` (lens and focus keys still apply)"
                    ),
                ));
            }
        }
    }
    let raw = raw.map(Spanned::into_inner).unwrap_or(RawCamera {
        eye: None,
        look_at: None,
        up: None,
        vfov: None,
        aperture_radius: None,
        f_number: None,
        focal_length_mm: None,
        sensor_width_mm: None,
        sharp_range: None,
        spread: None,
        focus_distance: None,
        focus_point: None,
        focus_pixel: None,
        blades: None,
        blade_rotation: None,
        anamorphic: None,
    });
    let vfov_deg = match from_model {
        Some((c, _, _)) => c.vfov_deg,
        None => raw.vfov.as_ref().map_or(DEFAULT_VFOV, |v| v.get_ref().0),
    };
    let mut up = raw.up.as_ref().map_or(Vec3::Y, |u| v3(*u.get_ref()));
    let spanned = |v: &Spanned<V3>| v3(*v.get_ref());
    let (eye, look_at) = match (&raw.eye, &raw.look_at) {
        _ if from_model.is_some() => {
            // The model's camera, looking as far as the objects' centre lies along its view
            // (the default focus).
            let (c, _, _) = from_model.expect("checked");
            let center =
                model::bounds(objects).map_or(c.eye + c.forward, |(lo, hi)| (lo + hi) * 0.5);
            let along = (center - c.eye).dot(c.forward);
            let along = if along.is_finite() {
                along.max(1e-3)
            } else {
                1.0
            };
            if c.up.cross(c.forward).length_squared() > 1e-6 {
                up = c.up;
            }
            (c.eye, c.eye + c.forward * along)
        }
        (Some(e), Some(l)) => (spanned(e), spanned(l)),
        (e, l) => {
            let (lo, hi) = model::bounds(objects).unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
            let aspect = width as f32 / height as f32;
            let (fe, fl) = model::frame(lo, hi, vfov_deg, aspect);
            let framed = match e {
                None => model::frame_checked(lo, hi, vfov_deg, aspect).map(|_| ()),
                Some(_) if !fl.is_finite() => Err(format!(
                    "the scene bounds are too large to aim at: they span {} to {}, and their \
                     centre is beyond the range of 32-bit floats",
                    model::short_vec(lo),
                    model::short_vec(hi)
                )),
                Some(_) => Ok(()),
            };
            if let Err(message) = framed {
                // Point at the object reaching farthest from the origin.
                let reach = |o: &Object| {
                    let (lo, hi) = model::object_bounds(o);
                    lo.abs().max(hi.abs()).max_element()
                };
                let far = (0..objects.len())
                    .max_by(|&a, &b| reach(&objects[a]).total_cmp(&reach(&objects[b])))
                    .unwrap_or(0);
                let (span, key) = origins.get(far).cloned().unwrap_or((0..0, "camera".into()));
                return Err(ctx.invalid(
                    span,
                    key,
                    format!(
                        "{message}; give `eye` and `look_at` in [camera], or make the objects \
                         smaller"
                    ),
                ));
            }
            (
                e.as_ref().map_or(fe, spanned),
                l.as_ref().map_or(fl, spanned),
            )
        }
    };
    let camera_span = || {
        [
            raw.up.as_ref().map(|u| u.span()),
            raw.vfov.as_ref().map(|v| v.span()),
        ]
        .into_iter()
        .flatten()
        .next()
        .unwrap_or(table_span.clone())
    };
    match view_problem(eye, look_at, up) {
        None => {}
        Some(("up", message)) => {
            let span = raw.up.as_ref().map_or(camera_span(), |u| u.span());
            return Err(ctx.invalid(span, "camera.up", message));
        }
        Some((_, message)) => {
            let (span, key) = match (&raw.look_at, &raw.eye) {
                (Some(l), _) => (l.span(), "camera.look_at"),
                (None, Some(e)) => (e.span(), "camera.eye"),
                (None, None) => (camera_span(), "camera.look_at"),
            };
            return Err(ctx.invalid(span, key, message));
        }
    }

    // Lens: at most one parameterisation.
    let lenses: Vec<(&str, Range<usize>)> = [
        (
            "aperture_radius",
            raw.aperture_radius.as_ref().map(|s| s.span()),
        ),
        ("f_number", raw.f_number.as_ref().map(|s| s.span())),
        ("sharp_range", raw.sharp_range.as_ref().map(|s| s.span())),
    ]
    .into_iter()
    .filter_map(|(k, s)| s.map(|s| (k, s)))
    .collect();
    if lenses.len() > 1 {
        return Err(ctx.invalid(lenses[1].1.clone(), format!("camera.{}", lenses[1].0), format!("`{}` and `{}` both set the lens; give one of aperture_radius, f_number (photographic) or sharp_range + spread (the seed's)", lenses[0].0, lenses[1].0)));
    }
    if raw.f_number.is_none() {
        for (k, s) in [
            ("focal_length_mm", &raw.focal_length_mm),
            ("sensor_width_mm", &raw.sensor_width_mm),
        ] {
            if let Some(s) = s {
                return Err(ctx.invalid(
                    s.span(),
                    format!("camera.{k}"),
                    format!("`{k}` describes a photographic lens and needs `f_number`"),
                ));
            }
        }
    } else if let Some(v) = &raw.vfov {
        return Err(ctx.invalid(v.span(), "camera.vfov", "a photographic lens (`f_number`) sets the field of view from focal_length_mm and sensor_width_mm; remove `vfov`"));
    }
    if raw.sharp_range.is_some() != raw.spread.is_some() {
        let (k, s) = match (&raw.sharp_range, &raw.spread) {
            (Some(s), _) => ("sharp_range", s.span()),
            (_, Some(s)) => ("spread", s.span()),
            _ => unreachable!(),
        };
        return Err(ctx.invalid(
            s,
            format!("camera.{k}"),
            "the seed's lens needs both `sharp_range` (scene units) and `spread` (pixels)",
        ));
    }
    let lens = if let Some(r) = &raw.aperture_radius {
        if r.get_ref().0 == 0.0 {
            LensSpec::Pinhole
        } else {
            LensSpec::Aperture {
                radius: r.get_ref().0,
            }
        }
    } else if let Some(n) = &raw.f_number {
        let sensor_width_mm = raw
            .sensor_width_mm
            .as_ref()
            .map_or(model::DEFAULT_SENSOR_WIDTH_MM, |s| s.get_ref().0);
        // With a model's camera, the focal length that keeps its field of view on this sensor.
        let keep_fov = from_model.map(|_| {
            let tan_half_h = (vfov_deg.to_radians() * 0.5).tan() * width as f32 / height as f32;
            sensor_width_mm / (2.0 * tan_half_h)
        });
        LensSpec::Photographic {
            focal_length_mm: raw
                .focal_length_mm
                .as_ref()
                .map_or(keep_fov.unwrap_or(model::DEFAULT_FOCAL_LENGTH_MM), |f| {
                    f.get_ref().0
                }),
            f_number: n.get_ref().0,
            sensor_width_mm,
        }
    } else if let (Some(r), Some(s)) = (&raw.sharp_range, &raw.spread) {
        LensSpec::Seed {
            sharp_range: r.get_ref().0,
            spread: s.get_ref().0,
        }
    } else {
        LensSpec::Pinhole
    };

    // Focus: at most one way.
    let focuses: Vec<(&str, Range<usize>)> = [
        (
            "focus_distance",
            raw.focus_distance.as_ref().map(|s| s.span()),
        ),
        ("focus_point", raw.focus_point.as_ref().map(|s| s.span())),
        ("focus_pixel", raw.focus_pixel.as_ref().map(|s| s.span())),
    ]
    .into_iter()
    .filter_map(|(k, s)| s.map(|s| (k, s)))
    .collect();
    if focuses.len() > 1 {
        return Err(ctx.invalid(
            focuses[1].1.clone(),
            format!("camera.{}", focuses[1].0),
            format!(
                "`{}` and `{}` both set the focus; give one",
                focuses[0].0, focuses[1].0
            ),
        ));
    }
    let focus = if let Some(d) = &raw.focus_distance {
        Focus::Distance(d.get_ref().0)
    } else if let Some(p) = &raw.focus_point {
        let p = v3(*p.get_ref());
        Focus::Point(p)
    } else if let Some(px) = &raw.focus_pixel {
        let [x, y] = *px.get_ref();
        if x.0 >= width || y.0 >= height {
            return Err(ctx.invalid(px.span(), "camera.focus_pixel", format!("pixel ({}, {}) is outside the {width}x{height} image (x < width, y < height, counted from the top left)", x.0, y.0)));
        }
        Focus::Pixel { x: x.0, y: y.0 }
    } else {
        Focus::Point(look_at)
    };
    if let Focus::Point(p) = focus {
        if !in_front(eye, look_at, p) {
            let span = raw.focus_point.as_ref().map_or(camera_span(), |s| s.span());
            return Err(ctx.invalid(span, "camera.focus_point", BEHIND));
        }
    }
    let blades = raw.blades.as_ref().map_or(0, |b| b.get_ref().0);
    if blades == 1 || blades == 2 {
        return Err(ctx.invalid(
            raw.blades.as_ref().map(|b| b.span()).unwrap_or(0..0),
            "camera.blades",
            "`blades` must be 0 (a circular aperture) or at least 3",
        ));
    }
    Ok(CameraSpec {
        eye,
        look_at,
        up,
        vfov_deg,
        width,
        height,
        lens,
        focus,
        aperture: ApertureShape {
            blades,
            rotation_deg: raw.blade_rotation.map_or(0.0, |r| r.0),
            anamorphic: raw.anamorphic.map_or(1.0, |a| a.0),
        },
    })
}

/// What is wrong with a view, if anything: the key to blame (`look_at` or `up`) and why.
fn view_problem(eye: Vec3, look_at: Vec3, up: Vec3) -> Option<(&'static str, &'static str)> {
    let view = (look_at - eye).length_squared();
    if view == 0.0 {
        Some(("look_at", "`look_at` must differ from `eye`"))
    } else if !view.is_finite() {
        Some((
            "look_at",
            "`eye` and `look_at` are too far apart: the distance between them is beyond the \
             range of 32-bit floats",
        ))
    } else if (look_at - eye).cross(up).length_squared() <= 1e-12 * view * up.length_squared() {
        Some((
            "up",
            "`up` must not be zero or parallel to the view direction (eye to look_at)",
        ))
    } else {
        None
    }
}

/// Whether the point `p` is in front of a camera at `eye` looking at `look_at`.
fn in_front(eye: Vec3, look_at: Vec3, p: Vec3) -> bool {
    (p - eye).dot(look_at - eye) > 0.0
}

const BEHIND: &str = "the point in focus must be in front of the camera";

/// The largest frame number (either sign) a scene may give.
const MAX_FRAME: i64 = 1_000_000_000;
/// The most frames a shot may have (every one is checked when the file is loaded).
const MAX_SHOT_FRAMES: i64 = 1_000_000;

/// Where one parameter's key is written: its frame, its `[[animation.key]]` index and the span
/// of its value.
struct Place {
    frame: i64,
    index: usize,
    span: Range<usize>,
}

/// The keys of one parameter and where they are written (in frame order).
type Places = Vec<(&'static str, Vec<Place>)>;

/// The keys' positions (`[x, y, z]`) by name.
const POINTS: [&str; 4] = ["eye", "look_at", "up", "focus_point"];
/// The keys' numbers by name.
const SCALARS: [&str; 5] = [
    "vfov",
    "focal_length_mm",
    "f_number",
    "aperture_radius",
    "focus_distance",
];

impl RawKey {
    /// Where position `name` is written in this key, and its value, if the key sets it.
    fn point(&self, name: &str) -> Option<(Range<usize>, DVec3)> {
        let v = match name {
            "eye" => &self.eye,
            "look_at" => &self.look_at,
            "up" => &self.up,
            "focus_point" => &self.focus_point,
            _ => return None,
        }
        .as_ref()?;
        Some((v.span(), dv3(*v.get_ref())))
    }

    /// Where number `name` is written in this key, and its value, if the key sets it.
    fn scalar(&self, name: &str) -> Option<(Range<usize>, f64)> {
        fn read<T>(v: &Option<Spanned<T>>, f: fn(&T) -> f32) -> Option<(Range<usize>, f64)> {
            v.as_ref().map(|v| (v.span(), f(v.get_ref()) as f64))
        }
        match name {
            "vfov" => read(&self.vfov, |v| v.0),
            "focal_length_mm" => read(&self.focal_length_mm, |v| v.0),
            "f_number" => read(&self.f_number, |v| v.0),
            "aperture_radius" => read(&self.aperture_radius, |v| v.0),
            "focus_distance" => read(&self.focus_distance, |v| v.0),
            _ => None,
        }
    }
}

/// Reads tracks from the keys, recording where each parameter's keys are.
struct TrackReader<'a> {
    ctx: &'a Ctx<'a>,
    keys: &'a [Spanned<RawKey>],
    /// The table's interpolation (for keys that give none).
    default: Interpolation,
    places: Places,
}

impl TrackReader<'_> {
    /// The track of position `name`, or None when no key sets it.
    fn point(&mut self, name: &'static str) -> Result<Option<Track<DVec3>>, LoadError> {
        self.track(name, |k| k.point(name))
    }

    /// The track of number `name`, interpolated as `space` of it, or None when no key sets it.
    fn scalar(
        &mut self,
        name: &'static str,
        space: fn(f64) -> f64,
    ) -> Result<Option<Track<f64>>, LoadError> {
        self.track(name, |k| k.scalar(name).map(|(span, v)| (span, space(v))))
    }

    /// The track of parameter `name` from the keys that set it (`value` reads it from a key,
    /// in the space it is interpolated in), or None when no key does.
    fn track<T: Value>(
        &mut self,
        name: &'static str,
        value: impl Fn(&RawKey) -> Option<(Range<usize>, T)>,
    ) -> Result<Option<Track<T>>, LoadError> {
        let (mut found, mut spots) = (Vec::new(), Vec::<Place>::new());
        for (index, k) in self.keys.iter().enumerate() {
            let k = k.get_ref();
            let Some((span, value)) = value(k) else {
                continue;
            };
            let frame = *k.frame.get_ref();
            if let Some(first) = spots.iter().find(|p| p.frame == frame) {
                return Err(self.ctx.invalid(
                    span,
                    format!("animation.key[{index}].{name}"),
                    format!(
                        "`{name}` is keyed twice at frame {frame} (animation.key[{}] keys it \
                         there too); a parameter has at most one key per frame",
                        first.index
                    ),
                ));
            }
            found.push(Key {
                frame,
                value,
                interpolation: k.interpolation.unwrap_or(self.default),
            });
            spots.push(Place { frame, index, span });
        }
        if !spots.is_empty() {
            spots.sort_by_key(|p| p.frame);
            self.places.push((name, spots));
        }
        // Frames are unique, so this fails only without keys.
        Ok(Track::new(found).ok())
    }
}

/// The keys of `name`, if it is animated.
fn keys_of<'a>(places: &'a Places, name: &str) -> Option<&'a [Place]> {
    places
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, p)| p.as_slice())
}

/// The `[animation]` table: its tracks, checked against the camera's lens, and every frame of
/// the shot checked for a valid view. `focus_on_look_at`: the camera's focus is its `look_at`
/// by default (no focus key in `[camera]`), so without focus keys it follows an animated
/// `look_at`.
fn animation(
    ctx: &Ctx,
    raw: Spanned<RawAnimation>,
    camera: &CameraSpec,
    focus_on_look_at: bool,
) -> Result<Animation, LoadError> {
    let table = raw.span();
    let raw = raw.into_inner();
    let frame_ok = |v: &Spanned<i64>, key: String| {
        if v.get_ref().abs() <= MAX_FRAME {
            Ok(*v.get_ref())
        } else {
            Err(ctx.invalid(
                v.span(),
                key,
                "a frame number from -1000000000 to 1000000000",
            ))
        }
    };
    for (i, k) in raw.key.iter().enumerate() {
        let key = k.get_ref();
        frame_ok(&key.frame, format!("animation.key[{i}].frame"))?;
        let sets = POINTS.iter().any(|n| key.point(n).is_some())
            || SCALARS.iter().any(|n| key.scalar(n).is_some());
        if !sets {
            return Err(ctx.invalid(
                k.span(),
                format!("animation.key[{i}]"),
                "a key sets no parameter: give at least one of eye, look_at, up, vfov, \
                 focal_length_mm, f_number, aperture_radius, focus_distance, focus_point",
            ));
        }
    }
    let key_frames = || raw.key.iter().map(|k| *k.get_ref().frame.get_ref());
    let range_end = |v: &Option<Spanned<i64>>, key: &str, default: Option<i64>| match v {
        Some(v) => frame_ok(v, format!("animation.{key}")),
        None => default.ok_or_else(|| {
            ctx.invalid(
                table.clone(),
                format!("animation.{key}"),
                "an animation without keys needs `frame_start` and `frame_end`",
            )
        }),
    };
    let frame_start = range_end(&raw.frame_start, "frame_start", key_frames().min())?;
    let frame_end = range_end(&raw.frame_end, "frame_end", key_frames().max())?;
    let frames = frame_end - frame_start + 1;
    if !(1..=MAX_SHOT_FRAMES).contains(&frames) {
        let span = raw
            .frame_end
            .as_ref()
            .or(raw.frame_start.as_ref())
            .map_or(table.clone(), |s| s.span());
        let message = if frames < 1 {
            format!("`frame_end` ({frame_end}) must be at least `frame_start` ({frame_start})")
        } else {
            format!(
                "the shot from frame {frame_start} to {frame_end} has {frames} frames; a shot \
                 has at most {MAX_SHOT_FRAMES}"
            )
        };
        return Err(ctx.invalid(span, "animation.frame_end", message));
    }

    let mut read = TrackReader {
        ctx,
        keys: &raw.key,
        default: raw.interpolation.unwrap_or_default(),
        places: Places::new(),
    };
    let same = |v: f64| v;
    let tracks = Tracks {
        eye: read.point("eye")?,
        look_at: read.point("look_at")?,
        up: read.point("up")?,
        vfov: read.scalar("vfov", same)?,
        focal_length_mm: read.scalar("focal_length_mm", same)?,
        ln_f_number: read.scalar("f_number", f64::ln)?,
        aperture_radius: read.scalar("aperture_radius", same)?,
        focus: None,
    };
    // Focus distances in dioptres (inf is 0).
    let dioptres = read.scalar("focus_distance", |d| 1.0 / d)?;
    let focus_point = read.point("focus_point")?;
    let places = read.places;
    let first_key = |name: &str| {
        let spots = keys_of(&places, name)?;
        spots.iter().min_by_key(|p| p.index)
    };
    let lens_conflict = |name: &str, message: String| match first_key(name) {
        Some(p) => Err(ctx.invalid(
            p.span.clone(),
            format!("animation.key[{}].{name}", p.index),
            message,
        )),
        None => Ok(()),
    };
    let lens = match camera.lens {
        LensSpec::Pinhole => "a pinhole (no lens key, or `aperture_radius = 0`)",
        LensSpec::Aperture { .. } => "an aperture radius (`aperture_radius`)",
        LensSpec::Photographic { .. } => "photographic (`f_number`)",
        LensSpec::Seed { .. } => "the seed's (`sharp_range` and `spread`)",
    };
    if !matches!(camera.lens, LensSpec::Photographic { .. }) {
        for name in ["f_number", "focal_length_mm"] {
            lens_conflict(
                name,
                format!(
                    "`{name}` animates a photographic lens, but the [camera] lens is {lens}; \
                     give `f_number` in [camera]{}",
                    if matches!(camera.lens, LensSpec::Seed { .. }) {
                        ""
                    } else {
                        " or animate `aperture_radius`"
                    }
                ),
            )?;
        }
    } else {
        lens_conflict(
            "vfov",
            "a photographic lens (`f_number` in [camera]) sets the field of view from \
             focal_length_mm and sensor_width_mm; animate `focal_length_mm` instead of `vfov`"
                .into(),
        )?;
    }
    if !matches!(camera.lens, LensSpec::Aperture { .. } | LensSpec::Pinhole) {
        lens_conflict(
            "aperture_radius",
            format!(
                "`aperture_radius` animates an aperture-radius lens (or a pinhole), but the \
                 [camera] lens is {lens}{}",
                if matches!(camera.lens, LensSpec::Photographic { .. }) {
                    "; animate `f_number` instead"
                } else {
                    ""
                }
            ),
        )?;
    }
    if let (Some(d), Some(p)) = (first_key("focus_distance"), first_key("focus_point")) {
        let ((later, name), other) = if d.index > p.index {
            ((d, "focus_distance"), p)
        } else {
            ((p, "focus_point"), d)
        };
        return Err(ctx.invalid(
            later.span.clone(),
            format!("animation.key[{}].{name}", later.index),
            format!(
                "`focus_distance` and `focus_point` are both keyed (animation.key[{}] keys the \
                 other); animate one of them",
                other.index
            ),
        ));
    }
    let focus = match (dioptres, focus_point) {
        (Some(d), _) => Some(FocusTrack::Dioptres(d)),
        (None, Some(p)) => Some(FocusTrack::Point(p)),
        (None, None) if focus_on_look_at => tracks.look_at.clone().map(FocusTrack::Point),
        (None, None) => None,
    };
    let animation = Animation {
        fps: raw.fps.map_or(24.0, |f| f.0),
        frame_start,
        frame_end,
        tracks: Tracks { focus, ..tracks },
    };
    check_frames(ctx, &animation, camera, &places, table)?;
    Ok(animation)
}

/// Checks the camera of every frame of the shot: a valid view, the point in focus in front,
/// and whatever [`CameraSpec::build`] checks; the first bad frame is reported at the key of
/// the parameter most likely to blame that is animated (the last of its keys at or before the
/// frame, else its first), else at the `[animation]` table.
fn check_frames(
    ctx: &Ctx,
    animation: &Animation,
    camera: &CameraSpec,
    places: &Places,
    table: Range<usize>,
) -> Result<(), LoadError> {
    for frame in animation.frames() {
        let mut c = camera.clone();
        animation.apply(&mut c, frame as f64);
        let (suspects, message): (&[&str], String) =
            if let Some((key, message)) = view_problem(c.eye, c.look_at, c.up) {
                let suspects: &[&str] = if key == "up" {
                    &["up", "eye", "look_at"]
                } else {
                    &["look_at", "eye"]
                };
                let shown = format!(
                    "{message} (eye {}, look_at {}, up {})",
                    short_vec(c.eye),
                    short_vec(c.look_at),
                    short_vec(c.up)
                );
                (suspects, shown)
            } else if matches!(c.focus, Focus::Point(p) if !in_front(c.eye, c.look_at, p)) {
                (&["focus_point", "eye", "look_at"], BEHIND.into())
            } else {
                match c.build(|_| Some(1.0)) {
                    Ok(_) => continue,
                    Err(e) => {
                        let suspects: &[&str] = match &e {
                            crate::camera::CameraError::Invalid { name, .. } => match *name {
                                "vfov_deg" => &["vfov", "focal_length_mm"],
                                "focal_length_mm" => &["focal_length_mm"],
                                "f_number" => &["f_number"],
                                "aperture radius" => {
                                    &["aperture_radius", "f_number", "focal_length_mm", "eye"]
                                }
                                "focus distance" => &["focus_distance", "focus_point"],
                                _ => &["eye", "look_at", "up"],
                            },
                            _ => &[],
                        };
                        (suspects, e.to_string())
                    }
                }
            };
        let (span, key) = suspects
            .iter()
            .find_map(|&name| {
                let spots = keys_of(places, name)?;
                let p = spots
                    .iter()
                    .rev()
                    .find(|p| p.frame <= frame)
                    .unwrap_or(&spots[0]);
                Some((p.span.clone(), format!("animation.key[{}].{name}", p.index)))
            })
            .unwrap_or((table, "animation".into()));
        return Err(ctx.invalid(span, key, format!("at frame {frame}: {message}")));
    }
    Ok(())
}

fn light(ctx: &Ctx, i: usize, l: Spanned<RawLight>) -> Result<Light, LoadError> {
    let span = l.span();
    let l = l.into_inner();
    let key = format!("lights[{i}]");
    let cone = |k: &str, set: bool| -> Result<(), LoadError> {
        if set {
            Err(ctx.invalid(
                span.clone(),
                format!("{key}.{k}"),
                format!("`{k}` belongs to spot lights"),
            ))
        } else {
            Ok(())
        }
    };
    if l.kind != LightKind::Spot {
        cone("inner_angle", l.inner_angle.is_some())?;
        cone("outer_angle", l.outer_angle.is_some())?;
    }
    match l.kind {
        LightKind::Spot => {
            if l.irradiance.is_some() {
                return Err(ctx.invalid(span, format!("{key}.irradiance"), "`irradiance` belongs to directional lights; a spot light takes `position`, `direction`, `intensity`, `inner_angle` and `outer_angle`"));
            }
            let position = l.position.ok_or_else(|| {
                ctx.invalid(span.clone(), key.clone(), "a spot light needs `position`")
            })?;
            let direction = l.direction.ok_or_else(|| {
                ctx.invalid(
                    span.clone(),
                    key.clone(),
                    "a spot light needs `direction` (the way it shines)",
                )
            })?;
            let d = v3(*direction.get_ref());
            if d.length_squared() == 0.0 || !d.normalize().is_finite() {
                return Err(ctx.invalid(
                    direction.span(),
                    format!("{key}.direction"),
                    "the direction must not be zero",
                ));
            }
            let angle = |a: &Option<Spanned<Finite>>, default: f32| {
                a.as_ref()
                    .map_or((default, span.clone()), |a| (a.get_ref().0, a.span()))
            };
            let (outer, outer_span) = angle(&l.outer_angle, 45.0);
            let (inner, inner_span) = angle(&l.inner_angle, 0.0);
            if !(outer > 0.0 && outer <= 90.0) {
                return Err(ctx.invalid(
                    outer_span,
                    format!("{key}.outer_angle"),
                    "the outer cone angle (degrees from the axis) must be > 0 and at most 90",
                ));
            }
            if !(inner >= 0.0 && inner <= outer) {
                return Err(ctx.invalid(
                    inner_span,
                    format!("{key}.inner_angle"),
                    format!(
                        "the inner cone angle (degrees from the axis) must be from 0 to \
                         outer_angle ({outer})"
                    ),
                ));
            }
            Ok(Light::Spot {
                position: v3(position),
                direction: d.normalize(),
                intensity: l.intensity.map_or(Vec3::splat(100.0), |c| c.0),
                inner_angle: inner.to_radians(),
                outer_angle: outer.to_radians(),
            })
        }
        LightKind::Point => {
            for (k, set) in [
                ("direction", l.direction.is_some()),
                ("irradiance", l.irradiance.is_some()),
            ] {
                if set {
                    return Err(ctx.invalid(span, format!("{key}.{k}"), format!("`{k}` belongs to directional lights; a point light takes `position` and `intensity`")));
                }
            }
            let position = l
                .position
                .ok_or_else(|| ctx.invalid(span, key, "a point light needs `position`"))?;
            Ok(Light::Point {
                position: v3(position),
                intensity: l.intensity.map_or(Vec3::splat(100.0), |c| c.0),
            })
        }
        LightKind::Directional => {
            for (k, set) in [
                ("position", l.position.is_some()),
                ("intensity", l.intensity.is_some()),
            ] {
                if set {
                    return Err(ctx.invalid(span, format!("{key}.{k}"), format!("`{k}` belongs to point lights; a directional light takes `direction` and `irradiance`")));
                }
            }
            let direction = l.direction.ok_or_else(|| {
                ctx.invalid(
                    span.clone(),
                    key.clone(),
                    "a directional light needs `direction`",
                )
            })?;
            let d = v3(*direction.get_ref());
            if d.length_squared() == 0.0 {
                return Err(ctx.invalid(
                    direction.span(),
                    format!("{key}.direction"),
                    "the direction must not be zero",
                ));
            }
            Ok(Light::Directional {
                direction: d,
                irradiance: l.irradiance.map_or(Vec3::ONE, |c| c.0),
            })
        }
    }
}

/// Loads a mesh file by its extension (`UnknownScene` when the extension is not a mesh's).
pub fn load_model(
    path: &Path,
    transform: &Transform,
    textures: &mut TextureCache,
) -> Result<model::Model, LoadError> {
    match extension(path).as_deref() {
        Some("obj") => super::obj::load(path, transform, textures),
        Some("gltf" | "glb") => super::gltf::load(path, transform, textures),
        _ => Err(LoadError::UnknownScene {
            name: shown(path),
            builtins: String::new(),
        }),
    }
}

/// A path's extension, lower-cased.
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}
