//! Lens prescriptions: the surfaces of a real lens as lens patents and optics books list
//! them, read from the text format of pbrt's lens files (which dofray's `lenses/` use too,
//! with an optional Abbe number column). `docs/lenses.md` documents the format.
//!
//! One surface a line, front (scene side) to rear (film side), in millimetres:
//!
//! ```text
//! # D-Gauss F/2, US patent 2,673,491   <- the first comment line names the lens
//! # radius  thickness  ior    aperture  [abbe]
//! 29.475    3.76       1.67   25.2      47.2
//! 0         4.5        0      17.1          <- radius 0: the aperture stop
//! ```
//!
//! `radius` is the signed radius of curvature (positive: its centre lies towards the film;
//! `inf` for a flat surface; 0 marks the aperture stop), `thickness` the axial distance to
//! the next surface (the last line's is replaced by the film distance that focusing
//! solves), `ior` the refractive index at the d line of the medium behind the surface (0
//! or 1: air), `aperture` the clear diameter.

use std::path::{Path, PathBuf};

use crate::error_kind::{ErrorKind, HasKind};

/// The most surfaces a prescription may have (real lenses have up to about 30).
pub const MAX_SURFACES: usize = 256;
/// The largest lens file read, bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// One surface of a prescription, as the file gives it (millimetres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceSpec {
    /// Signed radius of curvature (positive: centre towards the film); infinite for a flat
    /// surface; 0 for the aperture stop.
    pub radius_mm: f64,
    /// Axial distance to the next surface towards the film.
    pub thickness_mm: f64,
    /// Refractive index at the d line (587.6 nm) of the medium behind the surface (1: air).
    pub ior: f64,
    /// Clear aperture diameter.
    pub aperture_mm: f64,
    /// Abbe number of that medium, if given (dispersion; not used yet).
    pub abbe: Option<f64>,
}

impl SurfaceSpec {
    /// Whether this is the aperture stop.
    pub fn is_stop(&self) -> bool {
        self.radius_mm == 0.0
    }
}

/// A lens prescription: its surfaces from the front (scene side) to the rear (film side).
#[derive(Debug, Clone, PartialEq)]
pub struct Prescription {
    /// The lens's name: the file's first comment line (or its file name).
    pub name: String,
    /// Its surfaces, front to rear; exactly one is the stop.
    pub surfaces: Vec<SurfaceSpec>,
}

/// Why a lens file was refused.
#[derive(Debug, thiserror::Error)]
pub enum LensFileError {
    /// The file could not be read.
    #[error("{}: cannot read lens file: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// A line (or the whole file, line 0) is not a valid prescription.
    #[error("{}:{line}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The line, from 1 (0: the file as a whole).
        line: usize,
        /// What is wrong and what was expected.
        message: String,
    },
}

impl HasKind for LensFileError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::BadInput
    }
}

impl Prescription {
    /// Reads the lens file at `path` (at most [`MAX_FILE_BYTES`], a regular file).
    pub fn load(path: &Path) -> Result<Self, LensFileError> {
        let io = |error| LensFileError::Io {
            path: path.to_path_buf(),
            error,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        let whole = |message: String| LensFileError::Invalid {
            path: path.to_path_buf(),
            line: 0,
            message,
        };
        if !meta.is_file() {
            return Err(whole("not a regular file".into()));
        }
        if meta.len() > MAX_FILE_BYTES {
            return Err(whole(format!(
                "{} bytes is more than a lens file may have ({MAX_FILE_BYTES})",
                meta.len()
            )));
        }
        let bytes = std::fs::read(path).map_err(io)?;
        let text = String::from_utf8(bytes).map_err(|e| whole(format!("not UTF-8 text ({e})")))?;
        let fallback = path
            .file_stem()
            .map_or_else(|| "lens".into(), |s| s.to_string_lossy().into_owned());
        Self::parse(&text, &fallback).map_err(|(line, message)| LensFileError::Invalid {
            path: path.to_path_buf(),
            line,
            message,
        })
    }

    /// Parses a prescription's text; `fallback_name` names it if no comment does. Errors are
    /// (line from 1, or 0 for the whole text; message).
    pub fn parse(text: &str, fallback_name: &str) -> Result<Self, (usize, String)> {
        let mut name = None;
        let mut surfaces = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let (data, comment) = raw.split_once('#').unwrap_or((raw, ""));
            let comment = comment.trim().trim_matches('"').trim();
            if name.is_none() && surfaces.is_empty() && !comment.is_empty() {
                name = Some(comment.to_string());
            }
            let fields: Vec<&str> = data.split_whitespace().collect();
            if fields.is_empty() {
                continue;
            }
            if surfaces.len() == MAX_SURFACES {
                return Err((line, format!("more than {MAX_SURFACES} surfaces")));
            }
            surfaces.push(surface(&fields).map_err(|m| (line, m))?);
        }
        check_lens(&surfaces)?;
        Ok(Self {
            name: name.unwrap_or_else(|| fallback_name.to_string()),
            surfaces,
        })
    }

    /// Index of the aperture stop in [`Prescription::surfaces`].
    pub fn stop(&self) -> usize {
        self.surfaces
            .iter()
            .position(SurfaceSpec::is_stop)
            .expect("a parsed prescription has a stop")
    }
}

const COLUMNS: &str =
    "radius, thickness, ior, aperture diameter (mm) and optionally an Abbe number";

/// One line's surface.
fn surface(fields: &[&str]) -> Result<SurfaceSpec, String> {
    if !(4..=5).contains(&fields.len()) {
        return Err(format!(
            "expected 4 or 5 numbers ({COLUMNS}), got {} fields",
            fields.len()
        ));
    }
    let names = ["radius", "thickness", "ior", "aperture", "abbe"];
    let mut v = [0.0f64; 5];
    for (k, f) in fields.iter().enumerate() {
        v[k] = f
            .parse::<f64>()
            .map_err(|_| format!("{}: expected a number, got {f:?}", names[k]))?;
    }
    let [radius, thickness, ior, aperture, abbe] = v;
    let expect = |ok: bool, name: &str, what: &str, value: f64| {
        if ok {
            Ok(())
        } else {
            Err(format!("{name} must be {what}, got {value}"))
        }
    };
    expect(
        !radius.is_nan() && (radius.is_infinite() || radius.abs() <= 1e6),
        "radius",
        "a curvature radius within 1e6 mm, inf (flat) or 0 (the stop)",
        radius,
    )?;
    expect(
        thickness.is_finite() && (0.0..=1e5).contains(&thickness),
        "thickness",
        "from 0 to 1e5 mm",
        thickness,
    )?;
    let stop = radius == 0.0;
    expect(
        ior == 0.0 || ior == 1.0 || (!stop && (1.0..=4.0).contains(&ior)),
        "ior",
        if stop {
            "0 or 1 at the stop (it sits in air)"
        } else {
            "0 or 1 (air) or a refractive index from 1 to 4"
        },
        ior,
    )?;
    expect(
        aperture.is_finite() && aperture > 0.0 && aperture <= 1e5,
        "aperture",
        "a diameter > 0 and at most 1e5 mm",
        aperture,
    )?;
    let abbe = (fields.len() == 5).then_some(abbe);
    if let Some(a) = abbe {
        expect(a.is_finite() && a > 0.0, "abbe", "a number > 0", a)?;
    }
    Ok(SurfaceSpec {
        radius_mm: radius,
        thickness_mm: thickness,
        ior: if ior == 0.0 { 1.0 } else { ior },
        aperture_mm: aperture,
        abbe,
    })
}

/// The checks of the lens as a whole.
fn check_lens(surfaces: &[SurfaceSpec]) -> Result<(), (usize, String)> {
    if surfaces.len() < 2 {
        return Err((
            0,
            format!(
                "a lens needs at least 2 surfaces ({COLUMNS} a line), got {}",
                surfaces.len()
            ),
        ));
    }
    let stops = surfaces.iter().filter(|s| s.is_stop()).count();
    if stops != 1 {
        return Err((
            0,
            format!("a lens needs exactly one aperture stop (a line with radius 0), got {stops}"),
        ));
    }
    if surfaces.last().is_some_and(|s| s.ior != 1.0) {
        return Err((
            0,
            "the last surface must leave the light in air (ior 0 or 1): the film is in air".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const DGAUSS: &str = "# D-Gauss test\n# radius thickness ior aperture\n29.475 3.76 1.67 25.2\n84.83 0.12 1 25.2\n0 4.5 0 17.1\n-39.73 0 1 20 55.0\n";

    #[test]
    fn a_prescription_reads_its_name_surfaces_and_stop() {
        let p = Prescription::parse(DGAUSS, "x").unwrap();
        assert_eq!(p.name, "D-Gauss test");
        assert_eq!(p.surfaces.len(), 4);
        assert_eq!(p.stop(), 2);
        assert_eq!(p.surfaces[2].ior, 1.0);
        assert_eq!(p.surfaces[3].abbe, Some(55.0));
        assert_eq!(p.surfaces[0].radius_mm, 29.475);
        let flat = Prescription::parse("inf 2 1.5 10\n0 1 0 8\n-20 0 1 10\n", "flat").unwrap();
        assert_eq!(flat.name, "flat");
        assert!(flat.surfaces[0].radius_mm.is_infinite());
    }

    #[test]
    fn bad_lines_are_refused_with_their_line_and_column() {
        let cases = [
            ("1 2 3\n", 1, "expected 4 or 5 numbers"),
            ("# x\n\n10 2 1.5 abc\n", 3, "aperture: expected a number"),
            ("10 -2 1.5 10\n0 1 0 5\n", 1, "thickness must be"),
            ("10 2 0.5 10\n0 1 0 5\n", 1, "ior must be"),
            ("10 2 1.5 10\n0 1 1.5 5\n", 2, "at the stop"),
            ("10 2 1.5 0\n", 1, "aperture must be"),
            ("nan 2 1.5 10\n", 1, "radius must be"),
            ("10 2 1.5 10\n-10 0 1 10\n", 0, "exactly one aperture stop"),
            (
                "10 2 1.5 10\n0 0 1 10\n0 0 1 10\n",
                0,
                "exactly one aperture stop",
            ),
            (
                "10 2 1.5 10\n0 0 0 10\n-10 0 1.5 10\n",
                0,
                "leave the light in air",
            ),
            ("", 0, "at least 2 surfaces"),
            ("10 2 1.5 10 -3\n", 1, "abbe must be"),
        ];
        for (text, line, want) in cases {
            let (got_line, message) = Prescription::parse(text, "x").unwrap_err();
            assert_eq!(got_line, line, "{text:?}: {message}");
            assert!(message.contains(want), "{text:?}: {message}");
        }
    }

    #[test]
    fn the_file_errors_name_the_file() {
        let scratch = tempfile::Builder::new()
            .prefix("dofray-lens-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let path = dir.join("bad.dat");
        std::fs::write(&path, "# bad\n10 2 1.5\n").unwrap();
        let e = Prescription::load(&path).unwrap_err().to_string();
        assert!(e.contains("bad.dat:2:"), "{e}");
        let e = Prescription::load(&dir.join("missing.dat"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.dat: cannot read lens file"), "{e}");
        let e = Prescription::load(dir).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
        scratch.close().unwrap();
    }
}
