//! Writing rendered films and diagnostic pictures to disk.
//!
//! Two formats, chosen by the file extension (case-insensitive):
//!
//! - `.png` ([`png`]): 8-bit (or, with [`WriteOptions::png_16bit`], 16-bit) code values of the
//!   linear colour through a display view ([`crate::view`]: sRGB by default, or AgX, Khronos PBR
//!   Neutral, with Blender's looks, exposure and gamma; [`WriteOptions::view`]), with an `sRGB` chunk and the [`Metadata`] as text chunks;
//!   with [`WriteOptions::png_alpha`], RGBA with straight (unassociated) alpha.
//! - `.exr` ([`exr`]): Blender-style multilayer channels in one part: the beauty
//!   `ViewLayer.Combined.R/G/B/A` (linear, premultiplied by the coverage alpha; 32-bit float,
//!   or half with [`WriteOptions::exr_half`]), `ViewLayer.Depth.Z` (camera-axis depth,
//!   [`exr::DEPTH_MISS`] for misses) and dofray's passes `ViewLayer.CoC.X`,
//!   `ViewLayer.Interval.X` and `ViewLayer.Samples.X` (32-bit float), compressed as
//!   [`WriteOptions::exr_compression`] says (ZIP by default); the [`Metadata`] as text header
//!   attributes. docs/outputs.md shows how compositors read it.
//!
//! Every writer is atomic: it writes a hidden temporary file next to the target and renames it
//! over the target only once everything has been written, removing the temporary file on any
//! error, so a failed or interrupted write never leaves a partial image behind; a process that
//! exits on a signal removes it with [`atomic::remove_all_for_exit`].
//!
//! Where a file goes is settled once, in a [`Target`] ([`target`]): the extension names the
//! format, symbolic links are followed to the file they name, and read-only files,
//! directories and devices are refused; [`RenderTargets`] adds a render's AOV pictures, which
//! must be distinct from its image. The writers ([`write_film_to`], [`write_png_rgb_to`],
//! [`write_aov_pictures`], [`merge::merge_into`]) take targets and do not look at the path
//! again; the path-taking functions ([`write_film`], [`write_png_rgb`], ...) make the target
//! and call them.
//!
//! The picture helpers ([`pictures`]: [`depth_picture`], [`interval_picture`],
//! [`samples_picture`], [`heat_picture`]) return *linear* RGB buffers for [`write_png_rgb`];
//! their colours are chosen in display (sRGB) space and linearised, so the PNG shows exactly
//! the intended grey ramps and palettes.
//!
//! A new format is a variant of [`ImageFormat`] (its extension in [`ImageFormat::from_path`]),
//! a writer module beside [`png`] and [`exr`] that writes through [`Target`], and its arm in
//! [`write_film_to`].

pub mod atomic;
pub mod exr;
pub mod merge;
pub mod metadata;
pub mod pictures;
pub mod png;
pub mod target;
pub mod verify;

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::error_kind::{ErrorKind, HasKind};
use crate::render::Region;
use crate::render::film::Film;
pub use crate::view::DisplayView;
pub use atomic::{TempFile, remove_all_for_exit};
pub use exr::{CompressionError, ExrCompression};
pub use metadata::Metadata;
pub use pictures::{depth_picture, heat_picture, interval_picture, samples_picture, srgb8, srgb16};
pub use target::{
    AOV_DEPTH, AOV_INTERVAL, AOV_SAMPLES, AOVS, AovTargets, ImageFormat, RenderTargets, Target,
    check_render_outputs, check_writable, resolve_target, same_file,
};

/// Why an image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The path's extension names no format we write.
    #[error("{}: unknown image extension (expected .png or .exr)", path.display())]
    UnknownExtension {
        /// The path as given.
        path: PathBuf,
    },
    /// Creating, writing or renaming a file failed.
    #[error("cannot write {}", path.display())]
    Io {
        /// The path as given.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The encoder rejected the image, or the buffers do not match the image size.
    #[error("cannot encode {}: {message}", path.display())]
    Encode {
        /// The path as given.
        path: PathBuf,
        /// The encoder's (or the size check's) complaint.
        message: String,
    },
    /// The image has no pixels (zero width or height).
    #[error("cannot write an image with no pixels")]
    EmptyImage,
    /// A buffer of the encoded image could not be allocated.
    #[error(transparent)]
    Memory(#[from] crate::limits::MemoryError),
    /// The target exists and has no write permission bit: it is never replaced.
    #[error(
        "{} is read-only (no write permission bit{}): refusing to replace it; make it \
         writable (chmod u+w) or write elsewhere",
        path.display(),
        if path == target { String::new() } else { format!(", link to {}", target.display()) }
    )]
    ReadOnly {
        /// The path as given.
        path: PathBuf,
        /// The file it names once symbolic links are followed (`path` itself when it is no link).
        target: PathBuf,
    },
    /// The target exists but is not a regular file (a device, a socket, a FIFO).
    #[error("{} is not a regular file ({}): refusing to replace it", path.display(), target.display())]
    NotAFile {
        /// The path as given.
        path: PathBuf,
        /// What it names once symbolic links are followed (`path` itself when it is no link).
        target: PathBuf,
    },
    /// Following the target's symbolic links never ends.
    #[error("{}: too many levels of symbolic links", path.display())]
    SymlinkLoop {
        /// The path as given.
        path: PathBuf,
    },
    /// Two outputs of one run are the same file, so one would overwrite the other.
    #[error(
        "the output image {} and the AOV picture {} are the same file: one would overwrite \
         the other; choose another -o or --aov-dir",
        first.display(),
        second.display()
    )]
    Collision {
        /// The output image's path.
        first: PathBuf,
        /// The AOV picture's path (in the AOV directory).
        second: PathBuf,
    },
}

/// How [`write_film_with`] writes.
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Written as EXR header attributes and PNG text chunks.
    pub metadata: Metadata,
    /// PNG: 16 bits per channel instead of 8 (still sRGB-encoded).
    pub png_16bit: bool,
    /// PNG: RGBA instead of RGB, with straight (unassociated) alpha from [`Film::alpha`]: the
    /// colour is divided by alpha where alpha > 0 before sRGB encoding; alpha is stored
    /// linear. Meant for renders whose background is transparent (the film's colour then is
    /// premultiplied by its coverage); otherwise alpha is 1 everywhere. EXR always has alpha.
    pub png_alpha: bool,
    /// PNG: the display view (view transform, look, exposure, gamma) the colour is shown
    /// through, recorded in the PNG's text chunks; plain sRGB by default. EXR stays linear.
    pub view: DisplayView,
    /// EXR: the beauty (`ViewLayer.Combined.R/G/B/A`) as 16-bit half floats, clamped to
    /// +-65504; depth and dofray's passes stay 32-bit.
    pub exr_half: bool,
    /// EXR: how pixels are compressed (ZIP, lossless, by default).
    pub exr_compression: ExrCompression,
    /// The film is this region of an image of this size (a tile of it): EXR places it with
    /// its data window; both formats record it in the metadata (`dofray:region`, which
    /// [`merge`] reads).
    pub region: Option<(Region, (u32, u32))>,
}

/// Writes `film` to `path` in the format its extension names (see the module documentation).
pub fn write_film(path: &Path, film: &Film) -> Result<(), OutputError> {
    write_film_with(path, film, &WriteOptions::default())
}

/// [`write_film`] with metadata and format options.
///
/// ```rust
/// use dofray::output::{ExrCompression, Metadata, WriteOptions};
/// use dofray::render::Film;
///
/// let film = Film::new(8, 4); // black, opaque; a render's film in practice
/// let mut metadata = Metadata::new();
/// metadata.push("studio:shot", "sq010_sh020");
/// let options = WriteOptions {
///     metadata,
///     exr_half: true, // the beauty in half float; depth and CoC stay 32-bit
///     exr_compression: ExrCompression::Piz,
///     ..Default::default()
/// };
/// let path = std::env::temp_dir().join("dofray-write-example.exr");
/// dofray::output::write_film_with(&path, &film, &options)?; // a temporary file, then renamed
/// assert!(path.exists());
///
/// // The extension chooses the format; one dofray does not write is an error naming it.
/// assert!(dofray::output::write_film(std::path::Path::new("out.tif"), &film).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_film_with(
    path: &Path,
    film: &Film,
    options: &WriteOptions,
) -> Result<(), OutputError> {
    write_film_to(&Target::new(path)?, film, options)
}

/// [`write_film_with`] to a target made once ([`Target::new`]), in its format.
pub fn write_film_to(
    target: &Target,
    film: &Film,
    options: &WriteOptions,
) -> Result<(), OutputError> {
    check_film(target.path(), film)?;
    let mut tile_metadata;
    let options = match options.region {
        Some((region, _)) => {
            tile_metadata = options.clone();
            tile_metadata.metadata.push("dofray:region", region);
            &tile_metadata
        }
        None => options,
    };
    match target.format() {
        ImageFormat::Png => {
            let (sixteen, alpha) = (options.png_16bit, options.png_alpha);
            let data = png::film_samples(film, sixteen, alpha, &options.view)?;
            let mut metadata = options.metadata.clone();
            for (key, value) in options.view.metadata() {
                metadata.push(key, value);
            }
            let png = png::Png {
                width: film.width,
                height: film.height,
                data: &data,
                sixteen,
                alpha,
            };
            png.write(target, &metadata)
        }
        ImageFormat::Exr => {
            let exr_options = exr::ExrOptions {
                half: options.exr_half,
                compression: options.exr_compression,
                region: options.region,
            };
            exr::write_exr(target, film, &options.metadata, exr_options)
        }
    }
}

/// Writes an 8-bit sRGB PNG of any linear RGB buffer (row-major, top row first), clamping
/// each channel to `[0, 1]`. Used for the film itself, comparison pictures and heat maps.
pub fn write_png_rgb(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[Vec3],
) -> Result<(), OutputError> {
    write_png_rgb_to(
        &Target::with_format(path, ImageFormat::Png)?,
        width,
        height,
        rgb,
    )
}

/// [`write_png_rgb`] to a target made once; a PNG whatever the target's name says.
pub fn write_png_rgb_to(
    target: &Target,
    width: usize,
    height: usize,
    rgb: &[Vec3],
) -> Result<(), OutputError> {
    check_len(target.path(), width, height, rgb.len(), "colour")?;
    let bytes: Vec<u8> = rgb
        .iter()
        .flat_map(|c| [srgb8(c.x), srgb8(c.y), srgb8(c.z)])
        .collect();
    srgb8_png(width, height, &bytes).write(target, &Metadata::new())
}

/// Writes an 8-bit PNG of bytes that are already sRGB (`width x height` RGB triples, top row
/// first), atomically like every other output. Used for plots.
pub fn write_png_srgb8(
    path: &Path,
    width: usize,
    height: usize,
    bytes: &[u8],
) -> Result<(), OutputError> {
    let target = Target::with_format(path, ImageFormat::Png)?;
    srgb8_png(width, height, bytes).write(&target, &Metadata::new())
}

/// 8-bit sRGB RGB bytes as a PNG to write.
fn srgb8_png(width: usize, height: usize, bytes: &[u8]) -> png::Png<'_> {
    png::Png {
        width,
        height,
        data: bytes,
        sixteen: false,
        alpha: false,
    }
}

/// Writes the AOV pictures of `film` ([`depth_picture`], [`interval_picture`],
/// [`samples_picture`]) to their targets.
pub fn write_aov_pictures(aovs: &AovTargets, film: &Film) -> Result<(), OutputError> {
    let (w, h) = (film.width, film.height);
    write_png_rgb_to(&aovs.depth, w, h, &depth_picture(film)?)?;
    write_png_rgb_to(&aovs.interval, w, h, &interval_picture(film)?)?;
    write_png_rgb_to(&aovs.samples, w, h, &samples_picture(film)?)
}

/// Checks that every buffer of `film` has `width * height` entries.
fn check_film(path: &Path, film: &Film) -> Result<(), OutputError> {
    let (w, h) = (film.width, film.height);
    check_len(path, w, h, film.color.len(), "colour")?;
    check_len(path, w, h, film.alpha.len(), "alpha")?;
    check_len(path, w, h, film.depth.len(), "depth")?;
    check_len(path, w, h, film.coc.len(), "coc")?;
    check_len(path, w, h, film.interval.len(), "interval")?;
    check_len(path, w, h, film.samples.len(), "samples")
}

fn check_len(
    path: &Path,
    width: usize,
    height: usize,
    len: usize,
    what: &str,
) -> Result<(), OutputError> {
    if width == 0 || height == 0 {
        return Err(OutputError::EmptyImage);
    }
    match width.checked_mul(height) {
        Some(n) if n == len => Ok(()),
        _ => Err(OutputError::Encode {
            path: path.to_path_buf(),
            message: format!("{what} buffer has {len} pixels, expected {width}x{height}"),
        }),
    }
}

impl HasKind for OutputError {
    fn kind(&self) -> ErrorKind {
        match self {
            // The value of -o or --aov-dir is wrong, not the file system.
            Self::UnknownExtension { .. } | Self::Collision { .. } => ErrorKind::Usage,
            Self::Memory(e) => e.kind(),
            _ => ErrorKind::Io,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A unique scratch directory under the system temp dir, removed on drop.
    struct Scratch(tempfile::TempDir);

    impl Scratch {
        fn new(tag: &str) -> Self {
            let dir = tempfile::Builder::new()
                .prefix(&format!("dofray-output-{tag}-"))
                .tempdir()
                .unwrap();
            Self(dir)
        }

        fn path(&self) -> &Path {
            self.0.path()
        }

        /// Writes `film` as `name` here with the default options; checks it is the only file
        /// written (no temporary file left behind) and returns its path.
        fn write_only(&self, name: &str, film: &Film) -> PathBuf {
            let path = self.path().join(name);
            write_film(&path, film).unwrap();
            assert_eq!(self.entries(), vec![name.to_owned()]);
            path
        }

        fn entries(&self) -> Vec<String> {
            let mut names: Vec<String> = std::fs::read_dir(self.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            names
        }
    }

    fn test_film() -> Film {
        let mut film = Film::new(4, 3);
        for y in 0..3 {
            for x in 0..4 {
                let i = film.index(x, y);
                film.color[i] = Vec3::new(x as f32 / 3.0, y as f32 / 2.0, 0.25);
                film.depth[i] = if x == 3 {
                    f32::INFINITY
                } else {
                    1.0 + i as f32
                };
                film.coc[i] = 0.5 * i as f32;
                film.interval[i] = 1 << (i % 4);
                film.samples[i] = (i * 3) as u32;
            }
        }
        film.color[0] = Vec3::new(2.0, -1.0, 0.5); // out of range: clamped
        film
    }

    #[test]
    fn png_round_trip() {
        let dir = Scratch::new("png");
        let film = test_film();
        let path = dir.write_only("film.png", &film);

        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (4, 3));
        for y in 0..3 {
            for x in 0..4 {
                let c = film.color[film.index(x, y)];
                let expected = [srgb8(c.x), srgb8(c.y), srgb8(c.z)];
                assert_eq!(img.get_pixel(x as u32, y as u32).0, expected, "({x}, {y})");
            }
        }
        assert_eq!(img.get_pixel(0, 0).0, [255, 0, 188]);
        assert_eq!(img.get_pixel(3, 2).0, [255, 255, srgb8(0.25)]);
    }

    /// Every channel of an EXR, by name, as f32 (half samples widened), and whether it was
    /// stored as half.
    fn read_exr(path: &Path) -> Vec<(String, bool, Vec<f32>)> {
        use ::exr::prelude::*;
        let image = read_all_flat_layers_from_file(path).unwrap();
        assert_eq!(image.layer_data.len(), 1, "one part");
        let layer = &image.layer_data[0];
        layer
            .channel_data
            .list
            .iter()
            .map(|c| {
                let (half, values) = match &c.sample_data {
                    FlatSamples::F32(v) => (false, v.clone()),
                    FlatSamples::F16(v) => (true, v.iter().map(|h| h.to_f32()).collect()),
                    other => panic!("{}: unexpected samples {other:?}", c.name),
                };
                (c.name.to_string(), half, values)
            })
            .collect()
    }

    fn channel<'a>(channels: &'a [(String, bool, Vec<f32>)], name: &str) -> &'a [f32] {
        &channels
            .iter()
            .find(|(n, _, _)| n == name)
            .unwrap_or_else(|| panic!("{name} missing"))
            .2
    }

    /// A film with partial coverage: premultiplied colour and alpha below 1 in places.
    fn transparent_film() -> Film {
        let mut film = test_film();
        for i in 0..film.alpha.len() {
            film.alpha[i] = [1.0, 0.5, 0.25, 0.0][i % 4];
            film.color[i] *= film.alpha[i];
        }
        film
    }

    #[test]
    fn exr_round_trip() {
        let dir = Scratch::new("exr");
        let film = transparent_film();
        let path = dir.write_only("film.EXR", &film);

        let channels = read_exr(&path);
        let names: Vec<&str> = channels.iter().map(|(n, _, _)| n.as_str()).collect();
        assert_eq!(names, exr::CHANNELS);
        assert!(channels.iter().all(|(_, half, _)| !half), "all f32");
        let get = |name| channel(&channels, name);
        let (r, g, a, z) = (
            get(exr::CHANNEL_R),
            get(exr::CHANNEL_G),
            get(exr::CHANNEL_A),
            get(exr::CHANNEL_DEPTH),
        );
        assert_eq!(r.len(), 12);
        for i in 0..12 {
            assert_eq!(r[i], film.color[i].x, "R[{i}]");
            assert_eq!(g[i], film.color[i].y, "G[{i}]");
            assert_eq!(get(exr::CHANNEL_B)[i], film.color[i].z, "B[{i}]");
            assert_eq!(a[i], film.alpha[i], "A[{i}]");
            assert_eq!(get(exr::CHANNEL_COC)[i], film.coc[i], "coc[{i}]");
            assert_eq!(
                get(exr::CHANNEL_INTERVAL)[i],
                film.interval[i] as f32,
                "interval[{i}]"
            );
            assert_eq!(
                get(exr::CHANNEL_SAMPLES)[i],
                film.samples[i] as f32,
                "samples[{i}]"
            );
            if film.depth[i].is_finite() {
                assert_eq!(z[i], film.depth[i], "Z[{i}]");
            } else {
                assert_eq!(z[i], exr::DEPTH_MISS, "Z[{i}]: misses are finite");
            }
        }
        // Linear values are stored unclamped.
        assert_eq!(r[0], 2.0);
        assert_eq!(g[0], -1.0);

        // The header: Blender's multilayer marker, and no view or part name.
        let meta = ::exr::meta::MetaData::read_from_file(&path, false).unwrap();
        let header = &meta.headers[0];
        assert_eq!(header.compression, ::exr::compression::Compression::ZIP16);
        let (key, value) = exr::BLENDER_MULTICHANNEL;
        assert_eq!(
            header
                .own_attributes
                .other
                .get(&::exr::prelude::Text::from(key)),
            Some(&::exr::meta::attribute::AttributeValue::Text(
                ::exr::prelude::Text::from(value)
            ))
        );
        assert!(header.own_attributes.layer_name.is_none());
    }

    #[test]
    fn exr_half_beauty_keeps_the_passes_f32() {
        let dir = Scratch::new("exr-half");
        let path = dir.path().join("half.exr");
        let mut film = transparent_film();
        film.color[1] = Vec3::new(1e6, -1e6, 0.1); // beyond half's range: clamped
        film.depth[2] = 1234.567; // needs f32
        let options = WriteOptions {
            exr_half: true,
            ..WriteOptions::default()
        };
        write_film_with(&path, &film, &options).unwrap();
        let channels = read_exr(&path);
        for (name, half, _) in &channels {
            let beauty = name.starts_with("ViewLayer.Combined.");
            assert_eq!(*half, beauty, "{name}: half only for the beauty");
        }
        let (r, a) = (
            channel(&channels, exr::CHANNEL_R),
            channel(&channels, exr::CHANNEL_A),
        );
        for i in [0, 3, 5, 6, 9, 11] {
            let c = film.color[i].x;
            // Half has an 11-bit significand: relative error at most 2^-11.
            assert!(
                (r[i] - c).abs() <= c.abs() / 2048.0,
                "R[{i}] {} vs {c}",
                r[i]
            );
            assert_eq!(a[i], film.alpha[i], "A[{i}]: 1, 0.5, 0.25 and 0 are exact");
        }
        assert_eq!(r[1], exr::HALF_MAX);
        assert_eq!(channel(&channels, exr::CHANNEL_G)[1], -exr::HALF_MAX);
        assert_eq!(channel(&channels, exr::CHANNEL_DEPTH)[2], 1234.567);
    }

    #[test]
    fn every_exr_compression_writes_a_readable_file() {
        let dir = Scratch::new("exr-compression");
        let film = transparent_film();
        for compression in ExrCompression::ALL {
            for half in [false, true] {
                let path = dir.path().join(format!("{compression}-{half}.exr"));
                let options = WriteOptions {
                    exr_half: half,
                    exr_compression: compression,
                    ..WriteOptions::default()
                };
                write_film_with(&path, &film, &options)
                    .unwrap_or_else(|e| panic!("{compression} half={half}: {e}"));
                let channels = read_exr(&path);
                assert_eq!(channels.len(), 8, "{compression}");
                let meta = ::exr::meta::MetaData::read_from_file(&path, false).unwrap();
                assert_eq!(
                    meta.headers[0].compression,
                    compression.to_exr(),
                    "{compression}"
                );
                let samples = channel(&channels, exr::CHANNEL_SAMPLES);
                let a = channel(&channels, exr::CHANNEL_A);
                for i in 0..12 {
                    if compression.is_lossless() {
                        assert_eq!(samples[i], film.samples[i] as f32, "{compression}");
                        assert_eq!(a[i], film.alpha[i], "{compression}");
                    } else {
                        // Lossy methods stay close on these small values.
                        let s = film.samples[i] as f32;
                        assert!((samples[i] - s).abs() <= 0.01 * s.max(1.0), "{compression}");
                    }
                }
            }
        }
    }

    #[test]
    fn png_rgba_has_straight_alpha_in_8_and_16_bits() {
        let dir = Scratch::new("png-rgba");
        let film = transparent_film();
        for sixteen in [false, true] {
            let path = dir.path().join(format!("rgba-{sixteen}.png"));
            let options = WriteOptions {
                png_alpha: true,
                png_16bit: sixteen,
                ..WriteOptions::default()
            };
            write_film_with(&path, &film, &options).unwrap();
            let decoded = image::open(&path).unwrap();
            assert!(decoded.color().has_alpha());
            let img = decoded.to_rgba16();
            for i in 0..12 {
                let (x, y) = ((i % 4) as u32, (i / 4) as u32);
                let px = img.get_pixel(x, y).0;
                let a = film.alpha[i];
                let straight = if a > 0.0 {
                    film.color[i] / a
                } else {
                    film.color[i]
                };
                let expected: [u16; 4] = if sixteen {
                    [
                        srgb16(straight.x),
                        srgb16(straight.y),
                        srgb16(straight.z),
                        (a * 65535.0).round() as u16,
                    ]
                } else {
                    // 8-bit samples widen to 16 bits as v * 257.
                    [
                        u16::from(srgb8(straight.x)) * 257,
                        u16::from(srgb8(straight.y)) * 257,
                        u16::from(srgb8(straight.z)) * 257,
                        u16::from((a * 255.0).round() as u8) * 257,
                    ]
                };
                assert_eq!(px, expected, "sixteen={sixteen} pixel {i}");
                // Straight alpha: the colour of a half-covered pixel is the full colour.
                if a > 0.0 {
                    let original = test_film().color[i];
                    assert_eq!(px[0], expected[0]);
                    assert!((straight.x - original.x).abs() < 1e-6);
                }
            }
        }
    }

    #[test]
    fn missing_directory_is_an_io_error_and_creates_nothing() {
        let dir = Scratch::new("missing");
        let missing = dir.path().join("no-such-dir");
        for name in ["out.png", "out.exr"] {
            let path = missing.join(name);
            let err = write_film(&path, &test_film()).unwrap_err();
            assert!(
                matches!(&err, OutputError::Io { path: p, .. } if *p == path),
                "{err:?}"
            );
            assert!(err.to_string().contains(name), "{err}");
            let err = check_writable(&path).unwrap_err();
            assert!(matches!(err, OutputError::Io { .. }), "{err:?}");
            let err = write_png_rgb(&path, 1, 1, &[Vec3::ONE]).unwrap_err();
            assert!(matches!(err, OutputError::Io { .. }), "{err:?}");
        }
        assert!(!missing.exists());
        assert!(dir.entries().is_empty());
    }

    #[test]
    fn check_writable_accepts_a_writable_directory_and_leaves_it_clean() {
        let dir = Scratch::new("check");
        assert_eq!(
            check_writable(&dir.path().join("a.png")).unwrap(),
            ImageFormat::Png
        );
        assert_eq!(
            check_writable(&dir.path().join("a.exr")).unwrap(),
            ImageFormat::Exr
        );
        assert!(matches!(
            check_writable(&dir.path().join("a.jpg")),
            Err(OutputError::UnknownExtension { .. })
        ));
        // A directory named like an image is not a writable output path.
        std::fs::create_dir(dir.path().join("d.png")).unwrap();
        assert!(matches!(
            check_writable(&dir.path().join("d.png")),
            Err(OutputError::Io { .. })
        ));
        assert_eq!(dir.entries(), vec!["d.png".to_owned()]);
    }

    #[test]
    fn failed_writes_leave_no_files_and_keep_the_old_target() {
        let dir = Scratch::new("fail");
        // Unknown extension: nothing is created.
        assert!(matches!(
            write_film(&dir.path().join("x.jpg"), &test_film()),
            Err(OutputError::UnknownExtension { .. })
        ));
        // Empty images.
        assert!(matches!(
            write_film(&dir.path().join("e.png"), &Film::new(0, 3)),
            Err(OutputError::EmptyImage)
        ));
        assert!(matches!(
            write_png_rgb(&dir.path().join("e.png"), 3, 0, &[]),
            Err(OutputError::EmptyImage)
        ));
        // Mismatched buffers.
        let mut bad = test_film();
        bad.depth.pop();
        assert!(matches!(
            write_film(&dir.path().join("b.exr"), &bad),
            Err(OutputError::Encode { .. })
        ));
        assert!(matches!(
            write_png_rgb(&dir.path().join("b.png"), 2, 2, &[Vec3::ONE; 3]),
            Err(OutputError::Encode { .. })
        ));
        assert!(dir.entries().is_empty(), "{:?}", dir.entries());

        // A failure inside the writer removes the temp file and keeps the previous target.
        let target = dir.path().join("keep.png");
        std::fs::write(&target, b"old").unwrap();
        let err = Target::new(&target)
            .unwrap()
            .write_atomic(|file| {
                file.write_all(b"partial").unwrap();
                Err(OutputError::Encode {
                    path: target.clone(),
                    message: "boom".into(),
                })
            })
            .unwrap_err();
        assert!(matches!(err, OutputError::Encode { .. }));
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(dir.entries(), vec!["keep.png".to_owned()]);

        // A successful write replaces it, again without leftovers.
        write_film(&target, &test_film()).unwrap();
        assert_eq!(image::open(&target).unwrap().to_rgb8().dimensions(), (4, 3));
        assert_eq!(dir.entries(), vec!["keep.png".to_owned()]);
    }
}
