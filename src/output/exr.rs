//! The EXR writer: one part of scan lines whose channels are named the way Blender names a
//! render's passes (`ViewLayer.<Pass>.<channel>`), so Blender's compositor shows them as
//! passes and OpenImageIO and Nuke as layers. docs/outputs.md describes the layout.
//!
//! | channel                  | type          | what                                         |
//! |--------------------------|---------------|----------------------------------------------|
//! | `ViewLayer.Combined.R/G/B` | f32 (or f16) | linear colour, premultiplied by alpha        |
//! | `ViewLayer.Combined.A`   | f32 (or f16)  | [`Film::alpha`] (coverage; 1 unless transparent) |
//! | `ViewLayer.Depth.Z`      | f32           | camera-axis depth, [`DEPTH_MISS`] for misses |
//! | `ViewLayer.CoC.X`        | f32           | circle of confusion diameter in pixels       |
//! | `ViewLayer.Interval.X`   | f32           | sample interval                              |
//! | `ViewLayer.Samples.X`    | f32           | lens samples traced                          |
//!
//! The channel letters follow Blender's own: `RGBA` for a colour pass, `Z` for depth, `X` for
//! any other single value (Cycles' value AOVs, sample count, object index).

use std::result::Result; // not the prelude's
use std::str::FromStr;

use ::exr::prelude::*;

use super::{Metadata, OutputError, Target};
use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::{MemoryError, try_collect};
use crate::render::Region;
use crate::render::film::Film;

/// The view layer every pass belongs to: Blender's default view layer name.
pub const LAYER: &str = "ViewLayer";
/// Beauty: linear colour, premultiplied by alpha.
pub const CHANNEL_R: &str = "ViewLayer.Combined.R";
/// Beauty green (see [`CHANNEL_R`]).
pub const CHANNEL_G: &str = "ViewLayer.Combined.G";
/// Beauty blue (see [`CHANNEL_R`]).
pub const CHANNEL_B: &str = "ViewLayer.Combined.B";
/// Coverage alpha (associated with the colour, as EXR requires).
pub const CHANNEL_A: &str = "ViewLayer.Combined.A";
/// Depth along the camera's view axis in scene units; [`DEPTH_MISS`] where the ray missed.
pub const CHANNEL_DEPTH: &str = "ViewLayer.Depth.Z";
/// Circle-of-confusion diameter in pixels.
pub const CHANNEL_COC: &str = "ViewLayer.CoC.X";
/// Sample interval (a power of two; 1 = every pixel is a sample site).
pub const CHANNEL_INTERVAL: &str = "ViewLayer.Interval.X";
/// Lens samples traced for the pixel (0 = interpolated).
pub const CHANNEL_SAMPLES: &str = "ViewLayer.Samples.X";

/// Every channel, in the order OpenEXR stores them (sorted bytewise by name).
pub const CHANNELS: [&str; 8] = [
    CHANNEL_COC,
    CHANNEL_A,
    CHANNEL_B,
    CHANNEL_G,
    CHANNEL_R,
    CHANNEL_DEPTH,
    CHANNEL_INTERVAL,
    CHANNEL_SAMPLES,
];

/// The depth written where the depth-pass ray hit nothing. Finite, like Cycles' `1e10`
/// (`film_get_pass_pixel_depth`), so that filtering, resizing or scaling the depth pass never
/// turns `inf` into `NaN` (`inf * 0`, `inf - inf`); far beyond any scene dofray accepts.
pub const DEPTH_MISS: f32 = 1e10;

/// The largest finite half float: half-float colour is clamped to `[-HALF_MAX, HALF_MAX]`
/// (as Blender does) rather than overflowing to infinity.
pub const HALF_MAX: f32 = 65504.0;

/// The header attribute Blender writes into every multilayer EXR it saves, with the same
/// value. Blender recognises a multilayer file by its layered channel names alone; the
/// attribute tells readers the channels follow Blender's layer.pass.channel scheme (Blender
/// flips the image only when the value starts with "Blender V2.43", which this does not).
pub const BLENDER_MULTICHANNEL: (&str, &str) = ("BlenderMultiChannel", "Blender V2.55.1 and newer");

/// How the EXR's pixels are compressed (OpenEXR's methods, by their usual names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExrCompression {
    /// Uncompressed.
    None,
    /// Run-length encoding, lossless.
    Rle,
    /// Deflate over blocks of 16 scan lines, lossless (OpenEXR's `ZIP_COMPRESSION`).
    #[default]
    Zip,
    /// Deflate per scan line, lossless (OpenEXR's `ZIPS_COMPRESSION`).
    Zips,
    /// Wavelet, lossless; good for noisy images.
    Piz,
    /// Lossy for 32-bit float channels (stored as 24-bit floats), lossless for half.
    Pxr24,
    /// Lossy, half channels only (32-bit channels are stored uncompressed).
    B44,
    /// B44 with flat areas stored smaller.
    B44a,
    /// Lossy DCT (DreamWorks), 32 scan lines per block, for colour channels.
    Dwaa,
    /// Lossy DCT (DreamWorks), 256 scan lines per block.
    Dwab,
}

impl ExrCompression {
    /// Every method, in the order `--help` lists them.
    pub const ALL: [Self; 10] = [
        Self::None,
        Self::Rle,
        Self::Zip,
        Self::Zips,
        Self::Piz,
        Self::Pxr24,
        Self::B44,
        Self::B44a,
        Self::Dwaa,
        Self::Dwab,
    ];

    /// The name the command line and [`FromStr`] take.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Rle => "rle",
            Self::Zip => "zip",
            Self::Zips => "zips",
            Self::Piz => "piz",
            Self::Pxr24 => "pxr24",
            Self::B44 => "b44",
            Self::B44a => "b44a",
            Self::Dwaa => "dwaa",
            Self::Dwab => "dwab",
        }
    }

    /// Whether every channel reads back bit for bit.
    pub fn is_lossless(self) -> bool {
        matches!(
            self,
            Self::None | Self::Rle | Self::Zip | Self::Zips | Self::Piz
        )
    }

    pub(crate) fn to_exr(self) -> Compression {
        match self {
            Self::None => Compression::Uncompressed,
            Self::Rle => Compression::RLE,
            Self::Zip => Compression::ZIP16,
            Self::Zips => Compression::ZIP1,
            Self::Piz => Compression::PIZ,
            Self::Pxr24 => Compression::PXR24,
            Self::B44 => Compression::B44,
            Self::B44a => Compression::B44A,
            // The default level (OpenEXR's 45).
            Self::Dwaa => Compression::DWAA(None),
            Self::Dwab => Compression::DWAB(None),
        }
    }

    /// The method a file was written with, when it is one dofray writes.
    pub(crate) fn from_exr(c: Compression) -> Option<Self> {
        Self::ALL.into_iter().find(|m| match (m.to_exr(), c) {
            (Compression::DWAA(_), Compression::DWAA(_))
            | (Compression::DWAB(_), Compression::DWAB(_)) => true,
            (a, b) => a == b,
        })
    }

    /// All names, comma-separated, for messages.
    fn names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }
}

impl std::fmt::Display for ExrCompression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not an EXR compression dofray writes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CompressionError {
    /// An OpenEXR method the EXR encoder cannot write.
    #[error(
        "EXR compression {name:?} cannot be written (the EXR encoder does not implement it); \
         choose one of: {}",
        ExrCompression::names()
    )]
    Unsupported {
        /// The name as given.
        name: String,
    },
    /// Not an OpenEXR compression at all.
    #[error(
        "unknown EXR compression {name:?}; choose one of: {}",
        ExrCompression::names()
    )]
    Unknown {
        /// The name as given.
        name: String,
    },
}

impl FromStr for ExrCompression {
    type Err = CompressionError;

    /// Case-insensitive; `zip16`/`zip1` and `uncompressed` are accepted as aliases.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        if let Some(&c) = Self::ALL.iter().find(|c| c.name() == name) {
            return Ok(c);
        }
        match name.as_str() {
            "uncompressed" => Ok(Self::None),
            "zip16" => Ok(Self::Zip),
            "zip1" => Ok(Self::Zips),
            "htj2k" | "htj2k32" | "htj2k256" => Err(CompressionError::Unsupported {
                name: s.to_string(),
            }),
            _ => Err(CompressionError::Unknown {
                name: s.to_string(),
            }),
        }
    }
}

/// How an EXR is encoded: set from [`WriteOptions`](super::WriteOptions) by
/// [`write_film_with`](super::write_film_with).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExrOptions {
    /// The beauty (`ViewLayer.Combined.R/G/B/A`) as 16-bit half floats; depth and dofray's
    /// passes stay 32-bit.
    pub half: bool,
    /// The compression of every channel.
    pub compression: ExrCompression,
    /// The film is this region of a larger image of this size (a tile): the file's data
    /// window is the region and its display window the whole image, as OpenEXR places tiles
    /// and crops.
    pub region: Option<(Region, (u32, u32))>,
}

/// Writes `film` as an EXR (see the module documentation) to `target`, atomically. The film's
/// buffers must already have been checked against its size.
/// The first flat layer of an EXR with all its channels and attributes, every chunk read and
/// decompressed: what the tile merge and `--skip-existing`'s check read.
pub(super) fn read_first_layer(
    path: &std::path::Path,
) -> ::exr::error::Result<Image<Layer<AnyChannels<FlatSamples>>>> {
    read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
}

pub(super) fn write_exr(
    target: &Target,
    film: &Film,
    metadata: &Metadata,
    options: ExrOptions,
) -> Result<(), OutputError> {
    // Every channel's buffer is allocated fallibly: a MemoryError, not an abort.
    let f32s = |name: &str, data: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(data));
    let floats =
        |values: &mut dyn ExactSizeIterator<Item = f32>| try_collect(values, "an EXR channel");
    let beauty = |name: &str, values: &mut dyn ExactSizeIterator<Item = f32>| {
        Ok::<_, MemoryError>(if options.half {
            let halves = values.map(|v| f16::from_f32(v.clamp(-HALF_MAX, HALF_MAX)));
            AnyChannel::new(
                name,
                FlatSamples::F16(try_collect(halves, "an EXR channel")?),
            )
        } else {
            f32s(name, floats(values)?)
        })
    };
    let depth = |&d: &f32| if d.is_finite() { d } else { DEPTH_MISS };
    let channels = SmallVec::from_vec(vec![
        beauty(CHANNEL_R, &mut film.color.iter().map(|c| c.x))?,
        beauty(CHANNEL_G, &mut film.color.iter().map(|c| c.y))?,
        beauty(CHANNEL_B, &mut film.color.iter().map(|c| c.z))?,
        beauty(CHANNEL_A, &mut film.alpha.iter().copied())?,
        f32s(CHANNEL_DEPTH, floats(&mut film.depth.iter().map(depth))?),
        f32s(CHANNEL_COC, floats(&mut film.coc.iter().copied())?),
        f32s(
            CHANNEL_INTERVAL,
            floats(&mut film.interval.iter().map(|&i| i as f32))?,
        ),
        f32s(
            CHANNEL_SAMPLES,
            floats(&mut film.samples.iter().map(|&s| s as f32))?,
        ),
    ]);
    let size = (film.width, film.height);
    let image = layer_image(
        channels,
        size,
        options.region,
        metadata,
        options.compression,
    );
    write_image(target, &image)
}

/// One layer of `channels` (any order) of `size` pixels with dofray's attributes, placed as
/// `region` says (else at the origin of an image of its own size).
pub(super) fn layer_image(
    channels: SmallVec<[AnyChannel<FlatSamples>; 4]>,
    size: (usize, usize),
    region: Option<(Region, (u32, u32))>,
    metadata: &Metadata,
    compression: ExrCompression,
) -> Image<Layer<AnyChannels<FlatSamples>>> {
    let mut attributes = LayerAttributes {
        software_name: Some(Text::from(
            format!("dofray {}", env!("CARGO_PKG_VERSION")).as_str(),
        )),
        ..LayerAttributes::default()
    };
    let (key, value) = BLENDER_MULTICHANNEL;
    attributes
        .other
        .insert(Text::from(key), AttributeValue::Text(Text::from(value)));
    for (key, value) in metadata.iter().filter(|(k, _)| *k != "Software") {
        // EXR text is Latin-1: other characters become '?'.
        let latin1: String = value
            .chars()
            .map(|c| if u32::from(c) < 256 { c } else { '?' })
            .collect();
        if let (Some(k), Some(v)) = (Text::new_or_none(key), Text::new_or_none(latin1)) {
            attributes.other.insert(k, AttributeValue::Text(v));
        }
    }
    if let Some((r, _)) = region {
        attributes.layer_position = Vec2(r.x0 as i32, r.y0 as i32);
    }
    let encoding = Encoding {
        compression: compression.to_exr(),
        ..Encoding::SMALL_LOSSLESS
    };
    let layer = Layer::new(
        size,
        attributes,
        encoding,
        // EXR requires channels sorted by name; `sort` does that (bytewise, see CHANNELS).
        AnyChannels::sort(channels),
    );
    let (w, h) = match region {
        Some((_, (w, h))) => (w as usize, h as usize),
        None => size,
    };
    let mut attributes = ImageAttributes::new(IntegerBounds::from_dimensions((w, h)));
    // The colour is linear Rec.709 / sRGB primaries with a D65 white: say so, as Blender and
    // Nuke read it.
    attributes.chromaticities = Some(REC709_D65);
    Image {
        attributes,
        layer_data: layer,
    }
}

/// Rec.709 (sRGB) primaries and the D65 white point, CIE xy.
const REC709_D65: exr::meta::attribute::Chromaticities = exr::meta::attribute::Chromaticities {
    red: Vec2(0.64, 0.33),
    green: Vec2(0.30, 0.60),
    blue: Vec2(0.15, 0.06),
    white: Vec2(0.3127, 0.3290),
};

/// Writes an EXR image to `target` atomically.
pub(super) fn write_image(
    target: &Target,
    image: &Image<Layer<AnyChannels<FlatSamples>>>,
) -> Result<(), OutputError> {
    let path = target.path();
    target.write_atomic(|file| {
        image
            .write()
            .to_unbuffered(&mut *file)
            .map_err(|e| match e {
                Error::Io(source) => OutputError::Io {
                    path: path.to_path_buf(),
                    source,
                },
                other => OutputError::Encode {
                    path: path.to_path_buf(),
                    message: other.to_string(),
                },
            })
    })
}

impl HasKind for CompressionError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_are_listed_in_file_order() {
        let mut sorted = CHANNELS;
        sorted.sort_unstable();
        assert_eq!(sorted, CHANNELS);
    }

    #[test]
    fn compression_names_parse_and_unknown_ones_list_the_choices() {
        for c in ExrCompression::ALL {
            assert_eq!(c.name().parse::<ExrCompression>(), Ok(c));
            assert_eq!(c.name().to_uppercase().parse::<ExrCompression>(), Ok(c));
            assert_eq!(c.to_string(), c.name());
        }
        assert_eq!(ExrCompression::default(), ExrCompression::Zip);
        assert_eq!("zip16".parse(), Ok(ExrCompression::Zip));
        assert_eq!("uncompressed".parse(), Ok(ExrCompression::None));
        let err = "lzma".parse::<ExrCompression>().unwrap_err();
        assert!(matches!(err, CompressionError::Unknown { .. }));
        let text = err.to_string();
        assert!(text.contains("\"lzma\""), "{text}");
        assert!(
            text.contains("none, rle, zip, zips, piz, pxr24, b44, b44a, dwaa, dwab"),
            "{text}"
        );
        let err = "HTJ2K".parse::<ExrCompression>().unwrap_err();
        assert!(matches!(err, CompressionError::Unsupported { .. }));
        assert!(err.to_string().contains("cannot be written"), "{err}");
    }
}
