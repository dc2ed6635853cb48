//! Image textures: PNG and JPEG files decoded with `image`, converted to linear RGB, and shared
//! between the materials that use them.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;

use super::error::LoadError;
use super::input::{self, LoadOptions};
use crate::limits::Bytes;
use crate::shade::{ImageTexture, Wrap};

/// The sRGB transfer function, inverted: an encoded value in [0, 1] to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Memory a `width` x `height` texture of `color` needs while it is decoded and converted:
/// the decoder's buffer, an 8-bit RGB copy (or a float RGB one for 16-bit images) and the
/// linear float texels (12 bytes each); images with alpha add an RGBA copy (8-bit or float)
/// and the kept alpha channel (4 bytes a texel). Saturating, never overflowing.
pub fn texture_memory_bytes(width: u32, height: u32, color: image::ColorType) -> u64 {
    let wide = color.bytes_per_pixel() > 4;
    let conversion = if wide { 12 } else { 3 };
    let alpha = match (color.has_alpha(), wide) {
        (false, _) => 0,
        (true, false) => 4 + 4,
        (true, true) => 16 + 4,
    };
    let per_texel = color.bytes_per_pixel() as u64 + conversion + 12 + alpha;
    (width as u64)
        .saturating_mul(height as u64)
        .saturating_mul(per_texel)
}

/// Decodes a PNG or JPEG image. Colour textures are sRGB-encoded (`srgb`: converted to linear
/// here); data textures are not. Alpha (always linear) is kept when it is below 1 somewhere.
/// An image whose decoding and conversion would need more than `max_bytes`
/// ([`texture_memory_bytes`], judged from the header before anything is decoded) is refused
/// with the size it would need.
pub fn decode(
    bytes: &[u8],
    srgb: bool,
    wrap: Wrap,
    max_bytes: u64,
) -> Result<ImageTexture, String> {
    let decoder = decoder(bytes, max_bytes)?;
    let img =
        image::DynamicImage::from_decoder(decoder).map_err(|e| format!("cannot decode: {e}"))?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width == 0 || height == 0 {
        return Err(format!("the image is empty ({width}x{height})"));
    }
    let alpha = alpha_channel(&img);
    if alpha
        .as_ref()
        .is_some_and(|a| a.iter().any(|v| !v.is_finite()))
    {
        return Err("the image has non-finite alpha".into());
    }
    let texels = linear_texels(img, srgb);
    if texels.iter().any(|t| !t.is_finite()) {
        return Err("the image has non-finite texels".into());
    }
    Ok(ImageTexture {
        width,
        height,
        texels,
        alpha,
        wrap,
    })
}

/// A decoder of the image in `bytes` that has read only its header, once the image is known
/// to fit in `max_bytes`. A truncated JPEG is refused here: its decoder would not say so.
fn decoder(bytes: &[u8], max_bytes: u64) -> Result<impl image::ImageDecoder + '_, String> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    match reader.format() {
        None => return Err("not a PNG or JPEG image (unrecognised format)".into()),
        Some(image::ImageFormat::Jpeg) => check_jpeg_complete(bytes)?,
        Some(_) => {}
    }
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(max_bytes);
    reader.limits(limits);
    let decoder = reader
        .into_decoder()
        .map_err(|e| format!("cannot decode: {e}"))?;
    let (w, h) = image::ImageDecoder::dimensions(&decoder);
    let color = image::ImageDecoder::color_type(&decoder);
    let needed = texture_memory_bytes(w, h, color);
    if needed > max_bytes {
        return Err(format!(
            "a {w}x{h} texture needs about {} ({needed} bytes) to decode and convert, more \
             than the texture limit of {} (raise it with --max-texture-mib or LoadOptions::max_texture_bytes for larger \
             textures)",
            Bytes(needed),
            Bytes(max_bytes)
        ));
    }
    Ok(decoder)
}

/// The image's alpha channel in [0, 1], kept only when some texel is not opaque (an opaque
/// image needs no alpha test).
fn alpha_channel(img: &image::DynamicImage) -> Option<Vec<f32>> {
    if !img.color().has_alpha() {
        return None;
    }
    let a: Vec<f32> = match img {
        image::DynamicImage::ImageLumaA8(_) | image::DynamicImage::ImageRgba8(_) => img
            .to_rgba8()
            .pixels()
            .map(|p| p[3] as f32 / 255.0)
            .collect(),
        other => other
            .to_rgba32f()
            .pixels()
            .map(|p| p[3].clamp(0.0, 1.0))
            .collect(),
    };
    a.iter().any(|&v| v < 1.0).then_some(a)
}

/// The image's colours as linear RGB (decoded from sRGB when `srgb`). 8-bit images go
/// through a 256-entry table; wider ones are converted per texel.
fn linear_texels(img: image::DynamicImage, srgb: bool) -> Vec<Vec3> {
    match img {
        image::DynamicImage::ImageLuma8(_)
        | image::DynamicImage::ImageLumaA8(_)
        | image::DynamicImage::ImageRgb8(_)
        | image::DynamicImage::ImageRgba8(_) => {
            let lut: [f32; 256] = std::array::from_fn(|i| {
                let v = i as f32 / 255.0;
                if srgb { srgb_to_linear(v) } else { v }
            });
            let rgb = img.into_rgb8();
            rgb.pixels()
                .map(|p| Vec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]))
                .collect()
        }
        other => {
            let rgb = other.into_rgb32f();
            rgb.pixels()
                .map(|p| {
                    let c = Vec3::new(p[0], p[1], p[2]);
                    if srgb {
                        Vec3::new(
                            srgb_to_linear(c.x),
                            srgb_to_linear(c.y),
                            srgb_to_linear(c.z),
                        )
                    } else {
                        c
                    }
                })
                .collect()
        }
    }
}

/// Checks that a JPEG runs whole from its start-of-image marker to its end-of-image marker
/// (FF D9). JPEG decoders fill the missing part of a truncated file with grey instead of
/// failing, so the marker segments and the compressed data between them are walked here.
pub fn check_jpeg_complete(b: &[u8]) -> Result<(), String> {
    let truncated = |what: String| {
        Err(format!(
            "truncated JPEG: the file ends after {} bytes, {what}, before the end-of-image \
             marker (FF D9)",
            b.len()
        ))
    };
    if !b.starts_with(&[0xFF, 0xD8]) {
        return Ok(()); // Not a JPEG stream: the decoder says what it is not.
    }
    let mut i = 2;
    loop {
        // The next marker: FF (possibly repeated as fill), then its code. Stray bytes before
        // it are skipped, as decoders do.
        let Some(ff) = b[i..].iter().position(|&x| x == 0xFF) else {
            return truncated("between two segments".into());
        };
        i += ff;
        while i < b.len() && b[i] == 0xFF {
            i += 1;
        }
        let Some(&marker) = b.get(i) else {
            return truncated("inside a marker".into());
        };
        let at = i - 1;
        i += 1;
        match marker {
            0xD9 => return Ok(()),
            // Markers without a segment: TEM, restart markers, and a stuffed 00.
            0x00 | 0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let Some(len) = b
            .get(i..i + 2)
            .map(|l| u16::from_be_bytes([l[0], l[1]]) as usize)
        else {
            return truncated(format!(
                "inside the header of segment FF {marker:02X} at byte {at}"
            ));
        };
        if i + len > b.len() {
            return truncated(format!(
                "inside segment FF {marker:02X} at byte {at}, which declares {len} bytes"
            ));
        }
        i += len.max(2);
        if marker == 0xDA {
            // A scan: compressed data up to the next marker that is not a stuffed 00 or a
            // restart marker.
            loop {
                let Some(ff) = b[i..].iter().position(|&x| x == 0xFF) else {
                    return truncated("inside the compressed image data".into());
                };
                let mut j = i + ff + 1;
                while j < b.len() && b[j] == 0xFF {
                    j += 1;
                }
                match b.get(j) {
                    None => return truncated("inside the compressed image data".into()),
                    Some(0x00 | 0xD0..=0xD7) => i = j + 1,
                    Some(_) => {
                        i = j - 1;
                        break;
                    }
                }
            }
        }
    }
}

/// Decoded textures by (file, sRGB, wrap), so a file used by many materials is decoded once.
/// It carries the [`LoadOptions`] of the load it serves, which the mesh loaders read too.
#[derive(Default)]
pub struct TextureCache {
    files: HashMap<(PathBuf, bool, bool), Arc<ImageTexture>>,
    options: LoadOptions,
}

impl TextureCache {
    /// An empty cache for a load with `options`.
    pub fn new(options: LoadOptions) -> Self {
        Self {
            files: HashMap::new(),
            options,
        }
    }

    /// The limits and path policy of this load.
    pub fn options(&self) -> &LoadOptions {
        &self.options
    }

    /// The texture in image file `path`.
    pub fn file(
        &mut self,
        path: &Path,
        srgb: bool,
        wrap: Wrap,
    ) -> Result<Arc<ImageTexture>, LoadError> {
        let key = (path.to_path_buf(), srgb, wrap == Wrap::Repeat);
        if let Some(t) = self.files.get(&key) {
            return Ok(t.clone());
        }
        let bytes = input::read(path, &self.options)?;
        let texture = Arc::new(
            decode(&bytes, srgb, wrap, self.options.max_texture_bytes).map_err(|message| {
                LoadError::Image {
                    path: path.to_path_buf(),
                    message,
                }
            })?,
        );
        self.files.insert(key, texture.clone());
        Ok(texture)
    }
}

/// An environment map (the world's equirectangular image) from image file `path`: Radiance
/// `.hdr` and OpenEXR (linear; an EXR's channels must be named R, G and B), or PNG and JPEG
/// (sRGB). Negative texels (colour-conversion noise in some HDRIs) become 0; `strength`
/// multiplies the radiance and `rotation` (radians) turns it about the up axis, as Blender's
/// Mapping node's Z rotation does.
pub fn load_environment(
    path: &Path,
    strength: f32,
    rotation: f32,
    options: &LoadOptions,
) -> Result<crate::shade::EnvironmentMap, LoadError> {
    let bad = |message: String| LoadError::Image {
        path: path.to_path_buf(),
        message,
    };
    let bytes = input::read(path, options)?;
    let linear = matches!(
        image::guess_format(&bytes),
        Ok(image::ImageFormat::Hdr | image::ImageFormat::OpenExr)
    );
    // The sampling tables take 4 more bytes a texel: leave room for them in the limit.
    let image =
        decode(&bytes, !linear, Wrap::Repeat, options.max_texture_bytes / 2).map_err(bad)?;
    let texels = image
        .texels
        .into_iter()
        .map(|t| t.max(Vec3::ZERO))
        .collect();
    crate::shade::EnvironmentMap::new(image.width, image.height, texels, strength, rotation)
        .map_err(|e| bad(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decoding_is_linearised() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214).abs() < 1e-3);
        let mut png = Vec::new();
        image::RgbImage::from_raw(2, 1, vec![255, 128, 0, 0, 0, 255])
            .unwrap()
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let t = decode(&png, true, Wrap::Clamp, 1 << 30).unwrap();
        assert_eq!((t.width, t.height), (2, 1));
        assert!((t.texels[0].y - 0.2158).abs() < 1e-3, "{:?}", t.texels[0]);
        let raw = decode(&png, false, Wrap::Clamp, 1 << 30).unwrap();
        assert!((raw.texels[0].y - 128.0 / 255.0).abs() < 1e-6);
        assert!(decode(&png[..png.len() / 2], true, Wrap::Clamp, 1 << 30).is_err());
        assert!(decode(b"not an image", true, Wrap::Clamp, 1 << 30).is_err());
    }

    #[test]
    fn every_truncation_of_a_jpeg_is_caught() {
        let img = image::RgbImage::from_fn(40, 24, |x, y| {
            image::Rgb([(x * 6) as u8, (y * 10) as u8, ((x ^ y) * 5) as u8])
        });
        let mut jpg = Vec::new();
        img.write_to(&mut Cursor::new(&mut jpg), image::ImageFormat::Jpeg)
            .unwrap();
        assert_eq!(check_jpeg_complete(&jpg), Ok(()));
        assert!(decode(&jpg, true, Wrap::Clamp, 1 << 30).is_ok());
        // Bytes after the end-of-image marker are allowed (some cameras append data).
        let mut trailing = jpg.clone();
        trailing.extend([0, 0, 0x12]);
        assert_eq!(check_jpeg_complete(&trailing), Ok(()));
        for cut in 3..jpg.len() {
            let e = decode(&jpg[..cut], true, Wrap::Clamp, 1 << 30).unwrap_err();
            assert!(e.contains("truncated JPEG"), "cut at {cut}: {e}");
            assert!(
                e.contains(&format!("after {cut} bytes")),
                "cut at {cut}: {e}"
            );
        }
    }
}
