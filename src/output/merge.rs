//! Assembling tiles (renders of regions of one image, `--region` / `--tiles`) into the image.
//!
//! A tile is a file dofray wrote for a region: its metadata names the region
//! (`dofray:region`) and the whole image's size (`dofray:width`, `dofray:height`), and an EXR
//! tile is also placed by its data window. Tiles belong together when everything else they
//! record about how they were made is the same (scene and its hash, settings, lens, dofray
//! and Embree versions), except the scene file's path, time and ray counts. They must cover
//! the image exactly once. Pixels are copied as stored (EXR samples in their own type, PNG
//! bytes), so the merged image is bit for bit the one a single render would have written.

use std::collections::HashMap;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use ::exr::prelude::*;
use std::result::Result; // not the prelude's

use super::{ImageFormat, Metadata, OutputError, Target, exr as dofray_exr, png as dofray_png};
use crate::error_kind::{ErrorKind, HasKind};
use crate::render::Region;

/// Metadata keys that may differ between tiles of one image (they describe where, when and
/// at what cost each tile was made, not what it shows).
const PER_TILE: [&str; 4] = [
    "dofray:region",
    "dofray:seconds",
    "dofray:rays",
    "dofray:scene_file",
];

/// Why tiles could not be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// The list of tiles is empty.
    #[error("no tiles given")]
    NoTiles,
    /// A tile could not be read or decoded (or is a PNG other than RGB or RGBA).
    #[error("cannot read tile {}: {message}", path.display())]
    Read {
        /// The tile.
        path: PathBuf,
        /// Why, in words.
        message: String,
    },
    /// A file lacks the metadata that places a tile (`dofray:region`, `dofray:width`,
    /// `dofray:height`), or it is invalid.
    #[error("{} is not a dofray tile: it has no valid {key} ({message})", path.display())]
    NotATile {
        /// The file.
        path: PathBuf,
        /// The metadata key that is missing or invalid.
        key: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// Two tiles are of different formats (one EXR, one PNG).
    #[error(
        "{} is a {} and {} a {}: tiles of one image share a format",
        first.display(), first_format, other.display(), other_format
    )]
    Formats {
        /// The first tile given.
        first: PathBuf,
        /// Its format, `"EXR"` or `"PNG"`.
        first_format: &'static str,
        /// The tile of the other format.
        other: PathBuf,
        /// Its format, `"EXR"` or `"PNG"`.
        other_format: &'static str,
    },
    /// The merged image's extension names another format than the tiles'.
    #[error(
        "the merged image {} must be a {} like its tiles",
        path.display(), format
    )]
    OutputFormat {
        /// The merged image's path.
        path: PathBuf,
        /// The tiles' format, `"EXR"` or `"PNG"`.
        format: &'static str,
    },
    /// Two tiles record different settings (a metadata key other than the per-tile region, time,
    /// rays and scene path differs, or only one of them has it).
    #[error(
        "{} and {} are not tiles of one render: {key} is {first_value:?} in the first and \
         {other_value:?} in the second",
        first.display(), other.display()
    )]
    Mismatch {
        /// The first tile given.
        first: PathBuf,
        /// The tile that differs from it.
        other: PathBuf,
        /// The metadata key whose values differ.
        key: String,
        /// Its value in `first` (`"(missing)"` when absent).
        first_value: String,
        /// Its value in `other` (`"(missing)"` when absent).
        other_value: String,
    },
    /// Two tiles' regions share pixels.
    #[error(
        "{} (region {first_region}) and {} (region {other_region}) overlap",
        first.display(), other.display()
    )]
    Overlap {
        /// One of the tiles.
        first: PathBuf,
        /// Its region.
        first_region: Region,
        /// The tile it overlaps.
        other: PathBuf,
        /// That tile's region.
        other_region: Region,
    },
    /// The tiles do not cover the whole image.
    #[error(
        "the tiles leave {missing} pixels of the {width}x{height} image uncovered, the first at \
         ({x}, {y}): a tile is missing"
    )]
    Gap {
        /// How many pixels no tile covers.
        missing: u64,
        /// The whole image's width in pixels.
        width: u32,
        /// The whole image's height in pixels.
        height: u32,
        /// Column of the first uncovered pixel (in row-major order).
        x: u32,
        /// Row of the first uncovered pixel.
        y: u32,
    },
    /// A tile's pixels do not match its recorded region: another size, another EXR data window
    /// position, or channels with another number of samples.
    #[error("{} holds {found} but its region {region} needs {expected}", path.display())]
    Size {
        /// The tile.
        path: PathBuf,
        /// The region its metadata records.
        region: Region,
        /// What the file holds, in words.
        found: String,
        /// What the region needs, in words.
        expected: String,
    },
    /// Checking or writing the merged image (or a tile's extension) failed.
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// A tile's pixels as stored.
enum Pixels {
    /// Every channel, in the tile's own sample types, and how the file was compressed.
    Exr {
        channels: Vec<(Text, FlatSamples)>,
        compression: Compression,
    },
    /// Rows of PNG samples and their layout.
    Png {
        data: Vec<u8>,
        bytes_per_pixel: usize,
        color: ::png::ColorType,
        depth: ::png::BitDepth,
    },
}

/// One tile read back.
struct Tile {
    path: PathBuf,
    region: Region,
    size: (u32, u32),
    metadata: Metadata,
    pixels: Pixels,
}

impl Tile {
    fn format(&self) -> &'static str {
        match self.pixels {
            Pixels::Exr { .. } => "EXR",
            Pixels::Png { .. } => "PNG",
        }
    }
}

/// What [`merge`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged {
    /// The merged image's width in pixels.
    pub width: u32,
    /// The merged image's height in pixels.
    pub height: u32,
    /// How many tiles were merged.
    pub tiles: usize,
    /// The tiles' render times added up.
    pub seconds: f64,
    /// The tiles' rays added up (each tile traced the whole frame's depth pass).
    pub rays: u64,
}

/// Assembles `tiles` into `output` (atomically), checking that they are tiles of one render
/// that cover the image exactly once. The output's format must be the tiles'.
pub fn merge(tiles: &[PathBuf], output: &Path) -> Result<Merged, MergeError> {
    merge_into(tiles, &Target::new(output)?)
}

/// [`merge`] into a target made once ([`Target::new`]).
pub fn merge_into(tiles: &[PathBuf], output: &Target) -> Result<Merged, MergeError> {
    if tiles.is_empty() {
        return Err(MergeError::NoTiles);
    }
    let tiles: Vec<Tile> = tiles
        .iter()
        .map(|p| read_tile(p))
        .collect::<Result<_, _>>()?;
    check_one_render(&tiles, output)?;
    let first = &tiles[0];
    let (width, height) = first.size;
    check_coverage(&tiles, width, height)?;
    let (metadata, seconds, rays) = merged_metadata(&tiles);
    let size = (width as usize, height as usize);
    let written = (size, &metadata, output);
    match &first.pixels {
        Pixels::Exr {
            channels,
            compression,
        } => write_exr(&tiles, channels, *compression, written)?,
        Pixels::Png {
            bytes_per_pixel,
            color,
            depth,
            ..
        } => write_png(&tiles, *bytes_per_pixel, (*color, *depth), written)?,
    }
    Ok(Merged {
        width,
        height,
        tiles: tiles.len(),
        seconds,
        rays,
    })
}

/// The tiles share one format and one render's settings, and `output` has their format.
fn check_one_render(tiles: &[Tile], output: &Target) -> Result<(), MergeError> {
    let first = &tiles[0];
    for t in &tiles[1..] {
        if t.format() != first.format() {
            return Err(MergeError::Formats {
                first: first.path.clone(),
                first_format: first.format(),
                other: t.path.clone(),
                other_format: t.format(),
            });
        }
        check_same_render(first, t)?;
    }
    let wanted = match first.pixels {
        Pixels::Exr { .. } => ImageFormat::Exr,
        Pixels::Png { .. } => ImageFormat::Png,
    };
    if output.format() != wanted {
        return Err(MergeError::OutputFormat {
            path: output.path().to_path_buf(),
            format: first.format(),
        });
    }
    Ok(())
}

/// The first tile's metadata without its region, with the tiles' seconds and rays added up
/// and their count; also returns those sums.
fn merged_metadata(tiles: &[Tile]) -> (Metadata, f64, u64) {
    let seconds: f64 = tiles
        .iter()
        .filter_map(|t| t.metadata.get("dofray:seconds")?.parse::<f64>().ok())
        .sum();
    let rays: u64 = tiles
        .iter()
        .filter_map(|t| t.metadata.get("dofray:rays")?.parse::<u64>().ok())
        .sum();
    let mut metadata = Metadata::new();
    for (k, v) in tiles[0].metadata.iter() {
        match k {
            "dofray:region" => {}
            "dofray:seconds" => metadata.push(k, format!("{seconds:.3}")),
            "dofray:rays" => metadata.push(k, rays),
            _ => metadata.push(k, v),
        }
    }
    metadata.push("dofray:tiles", tiles.len());
    (metadata, seconds, rays)
}

/// Every EXR tile's channels copied into the whole image's, written with the first tile's
/// `channels` (their names and sample types) and `compression`.
fn write_exr(
    tiles: &[Tile],
    channels: &[(Text, FlatSamples)],
    compression: Compression,
    ((w, h), metadata, output): (Size, &Metadata, &Target),
) -> Result<(), MergeError> {
    let first = &tiles[0];
    let mut full: Vec<(Text, FlatSamples)> = channels
        .iter()
        .map(|(name, s)| (name.clone(), empty_like(s, w * h)))
        .collect();
    for t in tiles {
        let Pixels::Exr { channels, .. } = &t.pixels else {
            unreachable!("formats checked")
        };
        for (name, samples) in channels {
            let Some((_, dst)) = full.iter_mut().find(|(n, _)| n == name) else {
                return Err(mismatch(first, t, "channels", "", name.to_string()));
            };
            copy_rows(samples, dst, &t.region, w).map_err(|(found, expected)| {
                mismatch(first, t, &format!("channel {name}"), &expected, found)
            })?;
        }
    }
    let channels = full
        .into_iter()
        .map(|(name, s)| AnyChannel::new(name, s))
        .collect();
    let compression = dofray_exr::ExrCompression::from_exr(compression)
        .unwrap_or(dofray_exr::ExrCompression::Zip);
    let image = dofray_exr::layer_image(channels, (w, h), None, metadata, compression);
    dofray_exr::write_image(output, &image)?;
    Ok(())
}

/// Every PNG tile's pixels pasted into the whole image's, written with the first tile's
/// layout: `bpp` bytes per pixel, colour type and bit depth.
fn write_png(
    tiles: &[Tile],
    bpp: usize,
    (color, depth): (::png::ColorType, ::png::BitDepth),
    ((w, h), metadata, output): (Size, &Metadata, &Target),
) -> Result<(), MergeError> {
    let first = &tiles[0];
    let mut data = vec![0u8; w * h * bpp];
    for t in tiles {
        let Pixels::Png {
            data: src,
            bytes_per_pixel: tile_bpp,
            ..
        } = &t.pixels
        else {
            unreachable!("formats checked")
        };
        if *tile_bpp != bpp {
            return Err(mismatch(
                first,
                t,
                "PNG pixel layout",
                &format!("{bpp} bytes per pixel"),
                format!("{tile_bpp} bytes per pixel"),
            ));
        }
        let pasted = t.region.paste(src, &mut data, w, bpp);
        debug_assert!(pasted, "read_tile checked the tile's size");
    }
    let png = dofray_png::Png {
        width: w,
        height: h,
        data: &data,
        sixteen: depth == ::png::BitDepth::Sixteen,
        alpha: color == ::png::ColorType::Rgba,
    };
    png.write(output, metadata)?;
    Ok(())
}

/// The merged image's width and height in pixels.
type Size = (usize, usize);

fn mismatch(first: &Tile, other: &Tile, key: &str, a: &str, b: String) -> MergeError {
    MergeError::Mismatch {
        first: first.path.clone(),
        other: other.path.clone(),
        key: key.to_string(),
        first_value: a.to_string(),
        other_value: b,
    }
}

/// Every recorded setting but the per-tile ones must agree.
fn check_same_render(first: &Tile, other: &Tile) -> Result<(), MergeError> {
    let settings = |t: &Tile| -> HashMap<String, String> {
        t.metadata
            .iter()
            .filter(|(k, _)| !PER_TILE.contains(k))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    };
    let (a, b) = (settings(first), settings(other));
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    for key in keys {
        let (va, vb) = (a.get(key), b.get(key));
        if va != vb {
            let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "(missing)".into());
            return Err(mismatch(first, other, key, &show(va), show(vb)));
        }
    }
    Ok(())
}

/// No two tiles overlap and together they cover the image.
fn check_coverage(tiles: &[Tile], width: u32, height: u32) -> Result<(), MergeError> {
    let mut sorted: Vec<&Tile> = tiles.iter().collect();
    sorted.sort_by_key(|t| (t.region.y0, t.region.x0));
    for (i, a) in sorted.iter().enumerate() {
        if let Some(b) = sorted[i + 1..]
            .iter()
            .find(|b| a.region.overlaps(&b.region))
        {
            return Err(MergeError::Overlap {
                first: a.path.clone(),
                first_region: a.region,
                other: b.path.clone(),
                other_region: b.region,
            });
        }
    }
    let area: u64 = tiles
        .iter()
        .map(|t| u64::from(t.region.width()) * u64::from(t.region.height()))
        .sum();
    let total = u64::from(width) * u64::from(height);
    if area < total {
        // Regions are disjoint and inside the image: find the first pixel none covers.
        let (x, y) = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .find(|&(x, y)| !tiles.iter().any(|t| t.region.contains(x, y)))
            .unwrap_or((0, 0));
        return Err(MergeError::Gap {
            missing: total - area,
            width,
            height,
            x,
            y,
        });
    }
    Ok(())
}

fn empty_like(s: &FlatSamples, n: usize) -> FlatSamples {
    match s {
        FlatSamples::F16(_) => FlatSamples::F16(vec![f16::ZERO; n]),
        FlatSamples::F32(_) => FlatSamples::F32(vec![0.0; n]),
        FlatSamples::U32(_) => FlatSamples::U32(vec![0; n]),
    }
}

/// Copies a region's samples into the full image's; on a type or size mismatch returns
/// (found, expected).
fn copy_rows(
    src: &FlatSamples,
    dst: &mut FlatSamples,
    r: &Region,
    width: usize,
) -> Result<(), (String, String)> {
    let kind = |s: &FlatSamples| match s {
        FlatSamples::F16(_) => "half",
        FlatSamples::F32(_) => "float",
        FlatSamples::U32(_) => "uint",
    };
    let bad = (kind(src).to_string(), kind(dst).to_string());
    match (src, dst) {
        (FlatSamples::F16(s), FlatSamples::F16(d)) => {
            r.paste(s, d, width, 1).then_some(()).ok_or_else(bad_size)
        }
        (FlatSamples::F32(s), FlatSamples::F32(d)) => {
            r.paste(s, d, width, 1).then_some(()).ok_or_else(bad_size)
        }
        (FlatSamples::U32(s), FlatSamples::U32(d)) => {
            r.paste(s, d, width, 1).then_some(()).ok_or_else(bad_size)
        }
        _ => Err(bad),
    }
}

fn bad_size() -> (String, String) {
    (
        "a different number of samples".into(),
        "one per pixel of its region".into(),
    )
}

fn read_tile(path: &Path) -> Result<Tile, MergeError> {
    // Opening a FIFO blocks until a writer comes, and a device may never end: only regular
    // files (symbolic links followed) are read, as for every other input.
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => {}
        Ok(_) => {
            return Err(read_error(
                path,
                "not a regular file (a directory, FIFO or device); a tile is an image file".into(),
            ));
        }
        Err(e) => return Err(read_error(path, e.to_string())),
    }
    let (metadata, pixels, stored) = match ImageFormat::from_path(path)? {
        ImageFormat::Exr => read_exr_tile(path)?,
        ImageFormat::Png => read_png_tile(path)?,
    };
    let (region, size) = placed(path, &metadata, stored)?;
    Ok(Tile {
        path: path.to_path_buf(),
        region,
        size,
        metadata,
        pixels,
    })
}

/// The tile's region and the whole image's size from its metadata, once its pixels are
/// stored where the region says.
fn placed(
    path: &Path,
    metadata: &Metadata,
    (position, w, h): Stored,
) -> Result<(Region, (u32, u32)), MergeError> {
    let (region, size) = tile_place(path, metadata)?;
    let placed = position.is_none_or(|(x, y)| (x, y) == (region.x0 as i32, region.y0 as i32));
    if !placed || (w, h) != (u64::from(region.width()), u64::from(region.height())) {
        return Err(MergeError::Size {
            path: path.to_path_buf(),
            region,
            found: format!("{w}x{h} pixels at {:?}", position.unwrap_or((0, 0))),
            expected: format!(
                "{}x{} at ({}, {})",
                region.width(),
                region.height(),
                region.x0,
                region.y0
            ),
        });
    }
    Ok((region, size))
}

/// Where a tile's pixels are stored: the data window's position (EXR only) and its size.
type Stored = (Option<(i32, i32)>, u64, u64);

fn read_error(path: &Path, message: String) -> MergeError {
    MergeError::Read {
        path: path.to_path_buf(),
        message,
    }
}

/// Refuses a tile whose header asks for more pixel memory than there is, before its reader
/// allocates it: a few bytes of header can claim a data window of terabytes.
fn check_pixel_memory(path: &Path, (w, h): (u64, u64), needed: u128) -> Result<(), MergeError> {
    use crate::limits::{Bytes, MemoryBudget};
    let limit = MemoryBudget::read().binding();
    if needed > u128::from(limit.remaining()) {
        return Err(read_error(
            path,
            format!(
                "its header claims {w}x{h} pixels, which need {} of memory, but only {} \
                 {limit}: not a tile of an image that could have been rendered here",
                Bytes(needed),
                Bytes(limit.remaining())
            ),
        ));
    }
    Ok(())
}

/// An EXR tile's text attributes (sorted), channels and data window.
fn read_exr_tile(path: &Path) -> Result<(Metadata, Pixels, Stored), MergeError> {
    let headers = ::exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| read_error(path, e.to_string()))?
        .headers;
    for header in &headers {
        let (w, h) = (header.layer_size.0 as u64, header.layer_size.1 as u64);
        let pixel = header.channels.bytes_per_pixel as u128;
        check_pixel_memory(path, (w, h), u128::from(w) * u128::from(h) * pixel)?;
    }
    // The layer read is the first that is not deep: its data window must be the region its
    // attributes name before its pixels are allocated (a mangled data window can ask for
    // gigabytes the region never needed).
    if let Some(header) = headers.iter().find(|h| !h.deep) {
        let metadata = text_attributes(&header.shared_attributes, &header.own_attributes);
        let stored = exr_stored(&header.own_attributes, header.layer_size);
        placed(path, &metadata, stored)?;
    }
    let image = dofray_exr::read_first_layer(path).map_err(|e| read_error(path, e.to_string()))?;
    let layer = &image.layer_data;
    let metadata = text_attributes(&image.attributes, &layer.attributes);
    let stored = exr_stored(&layer.attributes, layer.size);
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.clone(), c.sample_data.clone()))
        .collect();
    let pixels = Pixels::Exr {
        channels,
        compression: layer.encoding.compression,
    };
    Ok((metadata, pixels, stored))
}

/// An EXR file's and layer's text attributes, sorted.
fn text_attributes(image: &ImageAttributes, layer: &LayerAttributes) -> Metadata {
    let mut attributes: Vec<(String, String)> = image
        .other
        .iter()
        .chain(&layer.other)
        .filter_map(|(k, v)| match v {
            AttributeValue::Text(t) => Some((k.to_string(), t.to_string())),
            _ => None,
        })
        .collect();
    attributes.sort();
    let mut metadata = Metadata::new();
    for (k, v) in attributes {
        metadata.push(k, v);
    }
    metadata
}

/// Where an EXR layer's pixels are: its data window.
fn exr_stored(layer: &LayerAttributes, size: Vec2<usize>) -> Stored {
    let position = layer.layer_position;
    (Some((position.0, position.1)), size.0 as u64, size.1 as u64)
}

/// A PNG tile's text chunks, bytes (as stored: 8 or 16 bits, RGB or RGBA) and size.
fn read_png_tile(path: &Path) -> Result<(Metadata, Pixels, Stored), MergeError> {
    let read_error = |message: String| read_error(path, message);
    let file = std::fs::File::open(path).map_err(|e| read_error(e.to_string()))?;
    let mut decoder = ::png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(::png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(|e| read_error(e.to_string()))?;
    let size = reader.info().size();
    let bytes = reader
        .output_buffer_size()
        .ok_or_else(|| read_error("too large".into()))?;
    check_pixel_memory(path, (size.0.into(), size.1.into()), bytes as u128)?;
    let mut data = vec![0; bytes];
    let frame = reader
        .next_frame(&mut data)
        .map_err(|e| read_error(e.to_string()))?;
    data.truncate(frame.buffer_size());
    let info = reader.info();
    let mut metadata = Metadata::new();
    for t in &info.uncompressed_latin1_text {
        metadata.push(t.keyword.clone(), t.text.clone());
    }
    for t in &info.utf8_text {
        if let Ok(text) = t.get_text() {
            metadata.push(t.keyword.clone(), text);
        }
    }
    let channels = match frame.color_type {
        ::png::ColorType::Rgb => 3,
        ::png::ColorType::Rgba => 4,
        other => {
            return Err(read_error(format!(
                "{other:?} PNG; dofray writes RGB or RGBA"
            )));
        }
    };
    let bytes = if frame.bit_depth == ::png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    let stored = (None, u64::from(frame.width), u64::from(frame.height));
    let pixels = Pixels::Png {
        data,
        bytes_per_pixel: channels * bytes,
        color: frame.color_type,
        depth: frame.bit_depth,
    };
    Ok((metadata, pixels, stored))
}

/// The tile's region and the whole image's size, from its metadata.
fn tile_place(path: &Path, metadata: &Metadata) -> Result<(Region, (u32, u32)), MergeError> {
    let not_a_tile = |key: &'static str, message: String| MergeError::NotATile {
        path: path.to_path_buf(),
        key,
        message,
    };
    let number = |key: &'static str| -> Result<u32, MergeError> {
        let v = metadata
            .get(key)
            .ok_or_else(|| not_a_tile(key, "missing".into()))?;
        v.parse()
            .map_err(|_| not_a_tile(key, format!("{v:?} is not a whole number")))
    };
    let region: Region = metadata
        .get("dofray:region")
        .ok_or_else(|| {
            not_a_tile(
                "dofray:region",
                "missing: render tiles with --region or --tiles".into(),
            )
        })?
        .parse()
        .map_err(|e: crate::render::RegionError| not_a_tile("dofray:region", e.to_string()))?;
    let size = (number("dofray:width")?, number("dofray:height")?);
    region
        .check(size.0, size.1)
        .map_err(|e| not_a_tile("dofray:region", e.to_string()))?;
    Ok((region, size))
}

impl HasKind for MergeError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Output(e) => e.kind(),
            Self::NoTiles | Self::OutputFormat { .. } => ErrorKind::Usage,
            _ => ErrorKind::BadInput,
        }
    }
}
