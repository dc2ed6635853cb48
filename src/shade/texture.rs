//! Where a material's colour comes from: constants, procedural patterns and images.

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
}
