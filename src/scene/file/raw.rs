//! The raw shape of a scene file: the TOML tables as serde reads them, and the checked numbers,
//! counts, colours and scales their values are, rejected while parsing so an error points at
//! the value.

use std::fmt;

use glam::{DVec3, Vec3};
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Unexpected, Visitor};
use toml::Spanned;

use crate::scene::animation::Interpolation;
use crate::shade::{Pattern, Wrap};

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
        pub(super) struct $name(pub(super) f32);

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
pub(super) struct FocusDistance(pub(super) f32);

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
        pub(super) struct $name(pub(super) u32);

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
pub(super) type V3 = [Finite; 3];

pub(super) fn v3(v: V3) -> Vec3 {
    Vec3::new(v[0].0, v[1].0, v[2].0)
}

pub(super) fn dv3(v: V3) -> DVec3 {
    v3(v).as_dvec3()
}

/// A colour: a number (grey) or `[r, g, b]`, linear, each >= 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Color(pub(super) Vec3);

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
pub(super) struct Scale(pub(super) Vec3);

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
pub(super) struct RawScene {
    pub(super) name: Option<String>,
    pub(super) ambient: Option<Color>,
    pub(super) image: Option<RawImage>,
    pub(super) render: Option<RawRender>,
    pub(super) camera: Option<Spanned<RawCamera>>,
    pub(super) background: Option<Spanned<RawBackground>>,
    pub(super) world: Option<Spanned<RawWorld>>,
    pub(super) lights: Option<Vec<Spanned<RawLight>>>,
    #[serde(default)]
    pub(super) textures: Vec<Spanned<RawTexture>>,
    #[serde(default)]
    pub(super) materials: Vec<Spanned<RawMaterial>>,
    #[serde(default)]
    pub(super) objects: Vec<Spanned<RawObject>>,
    pub(super) animation: Option<Spanned<RawAnimation>>,
    pub(super) view: Option<RawView>,
}

/// `[view]`: Blender's colour management for PNG outputs.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawView {
    pub(super) transform: Option<Spanned<String>>,
    pub(super) look: Option<Spanned<String>>,
    pub(super) exposure: Option<Spanned<f32>>,
    pub(super) gamma: Option<Spanned<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawImage {
    pub(super) width: Option<Spanned<Pixels>>,
    pub(super) height: Option<Spanned<Pixels>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRender {
    pub(super) spp: Option<Spanned<AtLeastOne>>,
    pub(super) aa: Option<Spanned<AtLeastOne>>,
    pub(super) interval_factor: Option<Spanned<Positive>>,
    pub(super) tolerance: Option<Spanned<Positive>>,
    pub(super) pixel_filter: Option<crate::filter::PixelFilterKind>,
    pub(super) pixel_filter_width: Option<Spanned<Positive>>,
    pub(super) transparent: Option<bool>,
    pub(super) integrator: Option<crate::settings::Integrator>,
    pub(super) max_bounces: Option<Spanned<u32>>,
    pub(super) diffuse_bounces: Option<Spanned<u32>>,
    pub(super) glossy_bounces: Option<Spanned<u32>>,
    pub(super) transmission_bounces: Option<Spanned<u32>>,
    pub(super) clamp_indirect: Option<Spanned<Positive>>,
    pub(super) filter_glossy: Option<Spanned<f32>>,
    pub(super) light_tracing: Option<bool>,
    pub(super) reuse: Option<bool>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCamera {
    pub(super) eye: Option<Spanned<V3>>,
    pub(super) look_at: Option<Spanned<V3>>,
    pub(super) up: Option<Spanned<V3>>,
    pub(super) vfov: Option<Spanned<Fov>>,
    pub(super) aperture_radius: Option<Spanned<NonNeg>>,
    pub(super) f_number: Option<Spanned<Positive>>,
    pub(super) focal_length_mm: Option<Spanned<Positive>>,
    pub(super) sensor_width_mm: Option<Spanned<Positive>>,
    pub(super) sharp_range: Option<Spanned<Positive>>,
    pub(super) spread: Option<Spanned<NonNeg>>,
    pub(super) focus_distance: Option<Spanned<FocusDistance>>,
    pub(super) focus_point: Option<Spanned<V3>>,
    pub(super) focus_pixel: Option<Spanned<[Whole; 2]>>,
    pub(super) blades: Option<Spanned<Whole>>,
    pub(super) blade_rotation: Option<Spanned<Finite>>,
    pub(super) anamorphic: Option<Spanned<Positive>>,
    /// A lens prescription file (relative to the scene file).
    pub(super) lens: Option<Spanned<String>>,
}

/// The `[animation]` table: the shot's range and rate, and its keys.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAnimation {
    pub(super) fps: Option<Positive>,
    pub(super) frame_start: Option<Spanned<i64>>,
    pub(super) frame_end: Option<Spanned<i64>>,
    pub(super) interpolation: Option<Interpolation>,
    #[serde(default)]
    pub(super) key: Vec<Spanned<RawKey>>,
}

/// One `[[animation.key]]`: a frame and the values some parameters take there.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawKey {
    pub(super) frame: Spanned<i64>,
    pub(super) interpolation: Option<Interpolation>,
    pub(super) eye: Option<Spanned<V3>>,
    pub(super) look_at: Option<Spanned<V3>>,
    pub(super) up: Option<Spanned<V3>>,
    pub(super) vfov: Option<Spanned<Fov>>,
    pub(super) focal_length_mm: Option<Spanned<Positive>>,
    pub(super) f_number: Option<Spanned<Positive>>,
    pub(super) aperture_radius: Option<Spanned<NonNeg>>,
    pub(super) focus_distance: Option<Spanned<FocusDistance>>,
    pub(super) focus_point: Option<Spanned<V3>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawWorld {
    pub(super) color: Option<Color>,
    pub(super) strength: Option<NonNeg>,
    pub(super) map: Option<Spanned<String>>,
    pub(super) rotation: Option<Finite>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBackground {
    pub(super) color: Option<Color>,
    pub(super) horizon: Option<Color>,
    pub(super) zenith: Option<Color>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum LightKind {
    Point,
    Directional,
    Spot,
    Rect,
    Disk,
    Sphere,
}

/// A rectangle light's size: one number (a square) or `[width, height]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
pub(super) enum RawSize {
    Square(Positive),
    Sides([Positive; 2]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLight {
    #[serde(rename = "type")]
    pub(super) kind: LightKind,
    pub(super) position: Option<V3>,
    pub(super) intensity: Option<Color>,
    pub(super) direction: Option<Spanned<V3>>,
    pub(super) irradiance: Option<Color>,
    pub(super) inner_angle: Option<Spanned<Finite>>,
    pub(super) outer_angle: Option<Spanned<Finite>>,
    pub(super) size: Option<RawSize>,
    pub(super) radius: Option<Positive>,
    pub(super) power: Option<Spanned<NonNeg>>,
    pub(super) color: Option<Color>,
    pub(super) up: Option<V3>,
    pub(super) visible_to_camera: Option<bool>,
    pub(super) angle: Option<Spanned<Finite>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTexture {
    pub(super) name: Spanned<String>,
    pub(super) image: Option<Spanned<String>>,
    pub(super) wrap: Option<Wrap>,
    pub(super) srgb: Option<bool>,
    pub(super) pattern: Option<Pattern>,
    pub(super) a: Option<Color>,
    pub(super) b: Option<Color>,
    pub(super) scale: Option<Positive>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMaterial {
    pub(super) name: Spanned<String>,
    pub(super) diffuse: Option<Color>,
    pub(super) texture: Option<Spanned<String>>,
    pub(super) metallic: Option<Unit>,
    pub(super) roughness: Option<Unit>,
    pub(super) transmission: Option<Unit>,
    pub(super) ior: Option<Spanned<Finite>>,
    pub(super) thin: Option<bool>,
    pub(super) emission: Option<Spanned<Color>>,
    pub(super) alpha: Option<Unit>,
    pub(super) alpha_mode: Option<RawAlphaMode>,
    pub(super) alpha_cutoff: Option<Unit>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum RawAlphaMode {
    Mask,
    Blend,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum ObjectKind {
    Sphere,
    Quad,
    Mesh,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawObject {
    #[serde(rename = "type")]
    pub(super) kind: ObjectKind,
    pub(super) material: Option<Spanned<String>>,
    pub(super) center: Option<Spanned<V3>>,
    pub(super) radius: Option<Spanned<Positive>>,
    pub(super) size: Option<Spanned<[Positive; 2]>>,
    pub(super) file: Option<Spanned<String>>,
    pub(super) translate: Option<Spanned<V3>>,
    pub(super) rotate: Option<Spanned<V3>>,
    pub(super) rotate_axis: Option<Spanned<V3>>,
    pub(super) rotate_angle: Option<Spanned<Finite>>,
    pub(super) scale: Option<Spanned<Scale>>,
    pub(super) lights: Option<bool>,
    pub(super) camera: Option<Spanned<bool>>,
}
