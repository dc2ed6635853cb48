//! The PNG writer: RGB or RGBA through a display view (sRGB-encoded; plain sRGB by default),
//! 8 or 16 bits per channel, with an `sRGB` chunk and the metadata as text chunks.
//!
//! PNG alpha is straight (unassociated) and linear, while the film's colour is premultiplied
//! by its alpha: an RGBA PNG stores `colour / alpha` (where alpha > 0) sRGB-encoded, and alpha
//! itself unencoded.

use std::io::{BufWriter, Write};

use super::{DisplayView, Metadata, OutputError, Target, check_len};
use crate::limits::{MemoryError, try_with_capacity};
use crate::render::film::Film;

/// The film as PNG samples: colour through `view` (straight, when `alpha`: divided by alpha
/// first, as the view applies to the colour a surface has, not to its coverage) and, when
/// `alpha`, the linear alpha; 8-bit bytes or 16-bit big-endian pairs. A [`MemoryError`] when
/// the samples' buffer cannot be allocated.
pub(super) fn film_samples(
    film: &Film,
    sixteen: bool,
    alpha: bool,
    view: &DisplayView,
) -> Result<Vec<u8>, MemoryError> {
    let channels = if alpha { 4 } else { 3 };
    let bytes = film.color.len() * channels * if sixteen { 2 } else { 1 };
    let mut out = try_with_capacity(bytes, "the PNG's samples")?;
    let mut push = |v: f32| {
        if sixteen {
            out.extend_from_slice(&linear16(v).to_be_bytes());
        } else {
            out.push(linear8(v));
        }
    };
    for (c, &a) in film.color.iter().zip(&film.alpha) {
        let straight = if alpha && a > 0.0 { *c / a } else { *c };
        for v in view.encode(straight.to_array()) {
            push(v);
        }
        if alpha {
            push(a);
        }
    }
    Ok(out)
}

/// A value in `[0, 1]` (clamped; NaN counts as 0) to 8 bits.
fn linear8(v: f32) -> u8 {
    (unit(v) * 255.0).round() as u8
}

/// A value in `[0, 1]` (clamped; NaN counts as 0) to 16 bits.
fn linear16(v: f32) -> u16 {
    (unit(v) * 65535.0).round() as u16
}

fn unit(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

/// An sRGB-encoded image ready for the PNG encoder: 8-bit bytes, or 16-bit big-endian
/// pairs; RGB, or RGBA with straight alpha.
pub(super) struct Png<'a> {
    pub width: usize,
    pub height: usize,
    pub data: &'a [u8],
    pub sixteen: bool,
    pub alpha: bool,
}

impl Png<'_> {
    /// Writes it to `target` atomically with an `sRGB` chunk (so viewers and compositors know
    /// the encoding) and one text chunk per metadata entry (`tEXt`, or `iTXt` for non-Latin-1).
    pub fn write(&self, target: &Target, metadata: &Metadata) -> Result<(), OutputError> {
        let path = target.path();
        let encode = |message: String| OutputError::Encode {
            path: path.to_path_buf(),
            message,
        };
        let pixel = if self.alpha { 4 } else { 3 } * if self.sixteen { 2 } else { 1 };
        if self.data.len() % pixel != 0 {
            return Err(encode(format!(
                "{} bytes are not whole {} pixels",
                self.data.len(),
                if self.alpha { "RGBA" } else { "RGB" }
            )));
        }
        check_len(
            path,
            self.width,
            self.height,
            self.data.len() / pixel,
            "colour",
        )?;
        let (Ok(w), Ok(h)) = (u32::try_from(self.width), u32::try_from(self.height)) else {
            return Err(encode(format!(
                "{}x{} is too large for PNG",
                self.width, self.height
            )));
        };
        target.write_atomic(|file| {
            let png_error = |e: ::png::EncodingError| match e {
                ::png::EncodingError::IoError(source) => OutputError::Io {
                    path: path.to_path_buf(),
                    source,
                },
                other => encode(other.to_string()),
            };
            let mut out = BufWriter::new(file);
            let mut encoder = ::png::Encoder::new(&mut out, w, h);
            encoder.set_color(if self.alpha {
                ::png::ColorType::Rgba
            } else {
                ::png::ColorType::Rgb
            });
            encoder.set_depth(if self.sixteen {
                ::png::BitDepth::Sixteen
            } else {
                ::png::BitDepth::Eight
            });
            encoder.set_source_srgb(::png::SrgbRenderingIntent::Perceptual);
            for (key, value) in metadata.iter() {
                let latin1 = value.chars().all(|c| u32::from(c) < 256);
                let added = if latin1 {
                    encoder.add_text_chunk(key.to_string(), value.to_string())
                } else {
                    encoder.add_itxt_chunk(key.to_string(), value.to_string())
                };
                added.map_err(png_error)?;
            }
            let mut writer = encoder.write_header().map_err(png_error)?;
            writer.write_image_data(self.data).map_err(png_error)?;
            writer.finish().map_err(png_error)?;
            out.flush().map_err(|source| OutputError::Io {
                path: path.to_path_buf(),
                source,
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::{srgb8, srgb16};
    use glam::Vec3;

    #[test]
    fn alpha_is_straight_and_linear() {
        let mut film = Film::new(3, 1);
        // Premultiplied: half-covered mid grey, fully covered white, empty.
        film.color = vec![Vec3::splat(0.25), Vec3::ONE, Vec3::ZERO];
        film.alpha = vec![0.5, 1.0, 0.0];
        let rgba = film_samples(&film, false, true, &DisplayView::default()).unwrap();
        assert_eq!(
            rgba,
            [
                srgb8(0.5),
                srgb8(0.5),
                srgb8(0.5),
                128,
                255,
                255,
                255,
                255,
                0,
                0,
                0,
                0
            ]
        );
        // Without alpha the premultiplied colour is written as it is.
        let rgb = film_samples(&film, false, false, &DisplayView::default()).unwrap();
        assert_eq!(&rgb[..3], &[srgb8(0.25); 3]);
        assert_eq!(rgb.len(), 9);
        let rgba16 = film_samples(&film, true, true, &DisplayView::default()).unwrap();
        assert_eq!(rgba16.len(), 24);
        assert_eq!(&rgba16[0..2], &srgb16(0.5).to_be_bytes());
        assert_eq!(&rgba16[6..8], &32768u16.to_be_bytes());
        assert_eq!(linear8(f32::NAN), 0);
        assert_eq!(linear16(2.0), 65535);
    }
}
