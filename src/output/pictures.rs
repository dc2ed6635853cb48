//! The diagnostic pictures and the sRGB encoding every PNG uses.
//!
//! The picture helpers ([`depth_picture`], [`interval_picture`], [`samples_picture`],
//! [`heat_picture`]) return *linear* RGB buffers for [`super::write_png_rgb`]; their colours are
//! chosen in display (sRGB) space and linearised, so the PNG shows exactly the intended grey
//! ramps and palettes.

use glam::Vec3;

use crate::limits::{MemoryError, try_collect};
use crate::render::film::Film;

/// The seed's figure 2: depth as a grey picture, near = white, far = dark grey, misses black.
/// Depth is normalised by the film's finite depth range; the grey ramp is linear in display
/// (sRGB) space, from 1 at the nearest surface down to 0.15 at the farthest.
pub fn depth_picture(film: &Film) -> Result<Vec<Vec3>, MemoryError> {
    const FAR_GREY: f32 = 0.15;
    let (near, far) = film
        .depth
        .iter()
        .filter(|d| d.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &d| {
            (lo.min(d), hi.max(d))
        });
    let range = far - near;
    let picture = film.depth.iter().map(|&d| {
        if !d.is_finite() {
            return Vec3::ZERO;
        }
        let t = if range > 0.0 {
            ((d - near) / range).clamp(0.0, 1.0)
        } else {
            0.0
        };
        Vec3::splat(srgb_to_linear(1.0 - (1.0 - FAR_GREY) * t))
    });
    try_collect(picture, "the depth picture")
}

/// Display-space (sRGB) colours of the interval layers, interval 1, 2, 4, ... 128 and larger:
/// samples of the "inferno" colour map, so larger intervals are brighter and warmer.
const INTERVAL_PALETTE: [[f32; 3]; 8] = [
    [0.000, 0.000, 0.016],
    [0.160, 0.040, 0.350],
    [0.400, 0.080, 0.430],
    [0.630, 0.170, 0.360],
    [0.830, 0.290, 0.220],
    [0.960, 0.490, 0.050],
    [0.980, 0.750, 0.160],
    [0.990, 1.000, 0.640],
];

/// The seed's figure 3: the sample-interval map, one distinct colour per power-of-two layer
/// (interval 1 = black, then purple, red, orange, yellow, up to pale yellow for 128 and more).
/// An interval that is not a power of two takes its largest power-of-two layer below.
pub fn interval_picture(film: &Film) -> Result<Vec<Vec3>, MemoryError> {
    let palette = INTERVAL_PALETTE.map(|c| Vec3::from_array(c.map(srgb_to_linear)));
    let picture = film.interval.iter().map(|&i| {
        let level = i.max(1).ilog2() as usize;
        palette[level.min(palette.len() - 1)]
    });
    try_collect(picture, "the interval picture")
}

/// The samples map: samples traced per pixel as a heat map from black (0: interpolated) to
/// white (the most any pixel took), so where the renderer spent its rays shows at a glance.
pub fn samples_picture(film: &Film) -> Result<Vec<Vec3>, MemoryError> {
    let max = film.samples.iter().copied().max().unwrap_or(0) as f32;
    let values = try_collect(film.samples.iter().map(|&n| n as f32), "the samples map")?;
    heat_picture(&values, max)
}

/// Heat map of a per-pixel error in `[0, max]`: black -> red -> yellow -> white, linear in
/// display (sRGB) space. Values are clamped to the range; NaN shows as the maximum (white),
/// so broken pixels stand out. If `max` is not positive, any positive value is white.
pub fn heat_picture(values: &[f32], max: f32) -> Result<Vec<Vec3>, MemoryError> {
    let picture = values.iter().map(|&v| {
        let t = if v.is_nan() {
            1.0
        } else if max > 0.0 {
            (v / max).clamp(0.0, 1.0)
        } else if v > 0.0 {
            1.0
        } else {
            0.0
        };
        // Three equal segments: red rises, then green, then blue.
        let s = t * 3.0;
        let display = Vec3::new(
            s.clamp(0.0, 1.0),
            (s - 1.0).clamp(0.0, 1.0),
            (s - 2.0).clamp(0.0, 1.0),
        );
        Vec3::new(
            srgb_to_linear(display.x),
            srgb_to_linear(display.y),
            srgb_to_linear(display.z),
        )
    });
    try_collect(picture, "the heat map")
}

/// sRGB-encodes one linear channel, clamped to `[0, 1]` (NaN counts as 0), to 8 bits.
pub fn srgb8(v: f32) -> u8 {
    (srgb_unit(v) * 255.0).round().clamp(0.0, 255.0) as u8
}

/// [`srgb8`] to 16 bits.
pub fn srgb16(v: f32) -> u16 {
    (srgb_unit(v) * 65535.0).round().clamp(0.0, 65535.0) as u16
}

/// The sRGB encoding of one linear channel in `[0, 1]` (clamped; NaN counts as 0).
fn srgb_unit(v: f32) -> f32 {
    crate::metrics::srgb_curve(if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) })
}

/// The inverse of the sRGB transfer function: display value in `[0, 1]` to linear.
fn srgb_to_linear(e: f32) -> f32 {
    let e = e.clamp(0.0, 1.0);
    if e <= 0.040_45 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb8_known_values() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(0.5), 188);
        assert_eq!(srgb8(-3.0), 0);
        assert_eq!(srgb8(7.0), 255);
        assert_eq!(srgb8(f32::NAN), 0);
        // The linear segment near black.
        assert_eq!(srgb8(0.001), (0.001f32 * 12.92 * 255.0).round() as u8);
        // Inverse transfer round-trips every 8-bit level.
        for b in 0..=255u8 {
            assert_eq!(srgb8(srgb_to_linear(b as f32 / 255.0)), b);
        }
    }

    #[test]
    fn depth_picture_near_white_far_dark_miss_black() {
        let mut film = Film::new(4, 1);
        film.depth = vec![2.0, 4.0, 6.0, f32::INFINITY];
        let pic = depth_picture(&film).unwrap();
        let bytes: Vec<u8> = pic.iter().map(|c| srgb8(c.x)).collect();
        assert_eq!(bytes[0], 255);
        assert_eq!(bytes[3], 0);
        assert!(
            bytes[0] > bytes[1] && bytes[1] > bytes[2] && bytes[2] > 0,
            "{bytes:?}"
        );
        assert_eq!(bytes[1], ((1.0 - 0.85 * 0.5) * 255.0f32).round() as u8);
        assert!(pic.iter().all(|c| c.x == c.y && c.y == c.z));
        // A single finite depth is white; no finite depth at all is black.
        film.depth = vec![3.0, 3.0, f32::INFINITY, f32::INFINITY];
        let pic = depth_picture(&film).unwrap();
        assert_eq!(pic[0], Vec3::ONE);
        assert_eq!(pic[2], Vec3::ZERO);
        film.depth = vec![f32::INFINITY; 4];
        assert!(
            depth_picture(&film)
                .unwrap()
                .iter()
                .all(|&c| c == Vec3::ZERO)
        );
    }

    #[test]
    fn interval_picture_distinct_and_brightening() {
        let mut film = Film::new(9, 1);
        film.interval = (0..9).map(|k| 1u32 << k).collect();
        let pic = interval_picture(&film).unwrap();
        let luma = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
        assert!(luma(pic[0]) < 0.01, "interval 1 is dark");
        for k in 1..8 {
            assert_ne!(pic[k], pic[k - 1]);
            assert!(luma(pic[k]) > luma(pic[k - 1]), "layer {k} brighter");
        }
        assert_eq!(pic[8], pic[7], "256 shares the last colour");
        // Non-powers of two take the layer below; 0 counts as 1.
        film.interval = vec![3, 2, 0, 1, 5, 4, 1, 1, 1];
        let pic2 = interval_picture(&film).unwrap();
        assert_eq!(pic2[0], pic2[1]);
        assert_eq!(pic2[2], pic2[3]);
        assert_eq!(pic2[4], pic2[5]);
    }

    #[test]
    fn heat_picture_ramp() {
        let pic = heat_picture(&[0.0, 1.0, 2.0, 3.0, 10.0, -1.0, f32::NAN], 3.0).unwrap();
        let bytes: Vec<[u8; 3]> = pic
            .iter()
            .map(|c| [srgb8(c.x), srgb8(c.y), srgb8(c.z)])
            .collect();
        assert_eq!(bytes[0], [0, 0, 0]);
        assert_eq!(bytes[1], [255, 0, 0]);
        assert_eq!(bytes[2], [255, 255, 0]);
        assert_eq!(bytes[3], [255, 255, 255]);
        assert_eq!(bytes[4], [255, 255, 255]);
        assert_eq!(bytes[5], [0, 0, 0]);
        assert_eq!(bytes[6], [255, 255, 255]);
        assert_eq!(heat_picture(&[0.5], 3.0).unwrap()[0].y, 0.0);
        assert_eq!(
            heat_picture(&[0.0, 1.0], 0.0).unwrap(),
            vec![Vec3::ZERO, Vec3::ONE]
        );
    }
}
