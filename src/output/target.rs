//! Where an output really goes, and whether it may be written there: a [`Target`] is made
//! once per file, and the writers take it instead of a path.
//!
//! - The extension names the format ([`ImageFormat::from_path`]; the PNG pictures take any
//!   name, [`Target::with_format`]).
//! - A symbolic link is written *through*: the image replaces the file the link names (the
//!   link stays), and the temporary file goes next to that file, so the final rename stays on
//!   one file system. A dangling link creates the file it names.
//! - An existing target must be a regular file with at least one write permission bit: a
//!   read-only file (mode without any `w`, checked explicitly, so root is refused too), a
//!   directory or a device is never replaced. This is checked when the target is made and
//!   again (without following the links anew) just before it is written, so a file made
//!   read-only during a long render is still kept.
//! - The images one render writes (the image and its AOV pictures) must be distinct files
//!   ([`RenderTargets`]).

use std::fs::File;
use std::path::{Component, Path, PathBuf};

use super::OutputError;
use super::atomic::{TempFile, parent_dir, write_atomic};

/// Symbolic links followed at most before giving up (Linux's own limit).
const MAX_LINKS: usize = 40;

/// The file formats [`write_film`](super::write_film) writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8- or 16-bit sRGB colour, optionally with straight alpha.
    Png,
    /// Float linear colour and alpha plus depth, CoC, interval and sample-count passes.
    Exr,
}

impl ImageFormat {
    /// The format named by `path`'s extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Self, OutputError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            _ => Err(OutputError::UnknownExtension {
                path: path.to_path_buf(),
            }),
        }
    }
}

/// One output file, resolved once: the path as given (which messages name), the file it
/// names once symbolic links are followed (what is written and renamed onto) and the format
/// it is written in.
///
/// ```rust
/// use dofray::output::{ImageFormat, Target};
///
/// let path = std::env::temp_dir().join("dofray-target-example.EXR");
/// let target = Target::new(&path)?; // the extension, the links, the permissions: once
/// assert_eq!(target.format(), ImageFormat::Exr);
/// dofray::output::write_film_to(&target, &dofray::render::Film::new(4, 2), &Default::default())?;
/// assert!(Target::new("out.tif").is_err()); // no format dofray writes
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    path: PathBuf,
    resolved: PathBuf,
    format: ImageFormat,
}

impl Target {
    /// `path` as an image: the format its extension names, its links followed, and what it
    /// names checked replaceable (see the module documentation).
    pub fn new(path: impl AsRef<Path>) -> Result<Self, OutputError> {
        let path = path.as_ref();
        let format = ImageFormat::from_path(path)?;
        Self::with_format(path, format)
    }

    /// `path` written as `format` whatever its extension says (the PNG pictures and plots
    /// take any name), its links followed and what it names checked replaceable.
    pub fn with_format(path: impl AsRef<Path>, format: ImageFormat) -> Result<Self, OutputError> {
        let path = path.as_ref();
        Self::checked(path.to_path_buf(), resolve_target(path)?, format)
    }

    /// A target from `path` already resolved to `resolved`, checked replaceable.
    fn checked(path: PathBuf, resolved: PathBuf, format: ImageFormat) -> Result<Self, OutputError> {
        check_replaceable(&path, &resolved)?;
        Ok(Self {
            path,
            resolved,
            format,
        })
    }

    /// The path as given: what messages name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file written: [`Target::path`] with its symbolic links followed.
    pub fn resolved(&self) -> &Path {
        &self.resolved
    }

    /// The format the file is written in.
    pub fn format(&self) -> ImageFormat {
        self.format
    }

    /// Checks that the target's directory takes new files, by creating and removing a
    /// temporary file there, so a front end can fail before a long render rather than after.
    pub fn check_writable(&self) -> Result<(), OutputError> {
        // A probe: created, then removed again when it drops at the end of the statement.
        TempFile::create(&self.resolved).map_err(|source| OutputError::Io {
            path: self.path.clone(),
            source,
        })?;
        Ok(())
    }

    /// Checks the target again (it may have changed while the image was made), then runs
    /// `write` on a temporary file next to it and renames that over it (see
    /// [`super::atomic`]).
    pub(crate) fn write_atomic(
        &self,
        write: impl FnOnce(&mut File) -> Result<(), OutputError>,
    ) -> Result<(), OutputError> {
        check_replaceable(&self.path, &self.resolved)?;
        write_atomic(&self.path, &self.resolved, write)
    }
}

/// The file `path` names once every symbolic link is followed (`path` itself when it is not
/// a link). Relative links resolve against their own directory. The target need not exist.
pub fn resolve_target(path: &Path) -> Result<PathBuf, OutputError> {
    let mut current = path.to_path_buf();
    for _ in 0..=MAX_LINKS {
        match std::fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let link = std::fs::read_link(&current).map_err(|source| OutputError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
                current = parent_dir(&current).join(link);
            }
            _ => return Ok(current),
        }
    }
    Err(OutputError::SymlinkLoop {
        path: path.to_path_buf(),
    })
}

/// Checks that `resolved` (what `path` names) may be replaced: nothing there yet, or a
/// regular file with a write permission bit, in an existing directory. Errors name `path`.
fn check_replaceable(path: &Path, resolved: &Path) -> Result<(), OutputError> {
    let io_err = |kind, message: String| OutputError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(kind, message),
    };
    match std::fs::metadata(resolved) {
        Ok(meta) if meta.is_dir() => {
            return Err(io_err(
                std::io::ErrorKind::IsADirectory,
                "the output path is a directory".into(),
            ));
        }
        Ok(meta) if !meta.is_file() => {
            return Err(OutputError::NotAFile {
                path: path.to_path_buf(),
                target: resolved.to_path_buf(),
            });
        }
        Ok(meta) if meta.permissions().readonly() => {
            return Err(OutputError::ReadOnly {
                path: path.to_path_buf(),
                target: resolved.to_path_buf(),
            });
        }
        _ => {}
    }
    let dir = parent_dir(resolved);
    if !dir.is_dir() {
        return Err(io_err(
            std::io::ErrorKind::NotFound,
            format!("directory {} does not exist", dir.display()),
        ));
    }
    Ok(())
}

/// `resolved` (what `path` names) made absolute and its existing directories canonicalised,
/// for telling whether two output paths name the same file before either exists.
fn identity(path: &Path, resolved: &Path) -> Result<PathBuf, OutputError> {
    let absolute = if resolved.is_absolute() {
        resolved.to_path_buf()
    } else {
        let cwd = std::env::current_dir().map_err(|source| OutputError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        cwd.join(resolved)
    };
    let parts: Vec<Component> = absolute.components().collect();
    for known in (1..=parts.len()).rev() {
        let prefix: PathBuf = parts[..known].iter().collect();
        if let Ok(mut out) = std::fs::canonicalize(&prefix) {
            // The rest does not exist, so it holds no links: `..` is lexical there.
            for part in &parts[known..] {
                match part {
                    Component::ParentDir => {
                        out.pop();
                    }
                    Component::Normal(name) => out.push(name),
                    _ => {}
                }
            }
            return Ok(out);
        }
    }
    Ok(absolute)
}

/// Whether `a` and `b` are the same file: the same resolved path, or (on Unix) hard links to
/// one file.
pub fn same_file(a: &Path, b: &Path) -> Result<bool, OutputError> {
    let a_resolved = resolve_target(a)?;
    let a_identity = identity(a, &a_resolved)?;
    is_same(&a_identity, &a_resolved, b, &resolve_target(b)?)
}

/// [`same_file`] for a file whose identity is known and `b`, resolved to `b_resolved`.
fn is_same(
    a_identity: &Path,
    a_resolved: &Path,
    b: &Path,
    b_resolved: &Path,
) -> Result<bool, OutputError> {
    if a_identity == identity(b, b_resolved)? {
        return Ok(true);
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a_resolved), std::fs::metadata(b_resolved)) {
            return Ok(ma.dev() == mb.dev() && ma.ino() == mb.ino());
        }
    }
    Ok(false)
}

/// Checks up front that `path` has a known extension, that what it names may be replaced
/// and that its directory is writable ([`Target::new`], then [`Target::check_writable`]).
pub fn check_writable(path: &Path) -> Result<ImageFormat, OutputError> {
    let target = Target::new(path)?;
    target.check_writable()?;
    Ok(target.format())
}

/// The AOV pictures `render --aov-dir DIR` writes: `DIR/depth.png` (the seed's figure 2),
/// `DIR/interval.png` (figure 3) and `DIR/samples.png` (samples traced per pixel).
pub const AOV_DEPTH: &str = "depth.png";
/// The interval picture's file name (see [`AOV_DEPTH`]).
pub const AOV_INTERVAL: &str = "interval.png";
/// The samples picture's file name (see [`AOV_DEPTH`]).
pub const AOV_SAMPLES: &str = "samples.png";
/// Every AOV picture.
pub const AOVS: [&str; 3] = [AOV_DEPTH, AOV_INTERVAL, AOV_SAMPLES];

/// Everything one render writes, each checked before it starts: the image and, with an AOV
/// directory, its pictures ([`super::write_aov_pictures`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RenderTargets {
    /// The image.
    pub image: Target,
    /// The AOV pictures, when they are asked for.
    pub aovs: Option<AovTargets>,
}

/// The AOV pictures of one render, in one directory (PNG, whatever their names say).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AovTargets {
    /// [`AOV_DEPTH`].
    pub depth: Target,
    /// [`AOV_INTERVAL`].
    pub interval: Target,
    /// [`AOV_SAMPLES`].
    pub samples: Target,
}

impl RenderTargets {
    /// The image at `output` (see [`Target::new`], [`Target::check_writable`]) and, with
    /// `aov_dir`, the directory (created if missing) and its pictures, which must each be
    /// replaceable, writable and distinct from the image ([`OutputError::Collision`]).
    pub fn new(output: &Path, aov_dir: Option<&Path>) -> Result<Self, OutputError> {
        let format = ImageFormat::from_path(output)?;
        let resolved = resolve_target(output)?;
        let Some(dir) = aov_dir else {
            let image = Target::checked(output.to_path_buf(), resolved, format)?;
            image.check_writable()?;
            return Ok(Self { image, aovs: None });
        };
        let image_identity = identity(output, &resolved)?;
        // Before the directory is made, so a collision creates nothing.
        let distinct = |name: &str| -> Result<(PathBuf, PathBuf), OutputError> {
            let aov = dir.join(name);
            let aov_resolved = resolve_target(&aov)?;
            if is_same(&image_identity, &resolved, &aov, &aov_resolved)? {
                return Err(OutputError::Collision {
                    first: output.to_path_buf(),
                    second: aov,
                });
            }
            Ok((aov, aov_resolved))
        };
        let (depth, interval, samples) = (
            distinct(AOV_DEPTH)?,
            distinct(AOV_INTERVAL)?,
            distinct(AOV_SAMPLES)?,
        );
        std::fs::create_dir_all(dir).map_err(|source| OutputError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        // After making the directory, which may be the image's too.
        let writable = |(path, resolved), format| -> Result<Target, OutputError> {
            let target = Target::checked(path, resolved, format)?;
            target.check_writable()?;
            Ok(target)
        };
        let image = writable((output.to_path_buf(), resolved), format)?;
        let aovs = AovTargets {
            depth: writable(depth, ImageFormat::Png)?,
            interval: writable(interval, ImageFormat::Png)?,
            samples: writable(samples, ImageFormat::Png)?,
        };
        Ok(Self {
            image,
            aovs: Some(aovs),
        })
    }
}

/// Checks everything one render will write before it starts ([`RenderTargets::new`]) and
/// returns the image's format.
pub fn check_render_outputs(
    output: &Path,
    aov_dir: Option<&Path>,
) -> Result<ImageFormat, OutputError> {
    Ok(RenderTargets::new(output, aov_dir)?.image.format())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_extension() {
        assert_eq!(
            ImageFormat::from_path(Path::new("a/b.png")).unwrap(),
            ImageFormat::Png
        );
        assert_eq!(
            ImageFormat::from_path(Path::new("B.PNG")).unwrap(),
            ImageFormat::Png
        );
        assert_eq!(
            ImageFormat::from_path(Path::new("x.ExR")).unwrap(),
            ImageFormat::Exr
        );
        for bad in ["x.jpg", "x.txt", "x", "png", ".png.bak"] {
            let err = ImageFormat::from_path(Path::new(bad)).unwrap_err();
            assert!(
                matches!(&err, OutputError::UnknownExtension { path } if path == Path::new(bad)),
                "{bad}: {err:?}"
            );
            assert!(err.to_string().contains(".png or .exr"), "{err}");
        }
    }

    /// A fresh directory under the system temp dir, removed on drop.
    struct Scratch(tempfile::TempDir);

    impl Scratch {
        fn new(tag: &str) -> Self {
            let dir = tempfile::Builder::new()
                .prefix(&format!("dofray-target-{tag}-"))
                .tempdir()
                .unwrap();
            Self(dir)
        }

        fn path(&self) -> &Path {
            self.0.path()
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_target_keeps_the_given_path_and_writes_what_its_links_name() {
        use std::os::unix::fs::{PermissionsExt, symlink};
        let dir = Scratch::new("links");
        let real = dir.path().join("real.png");
        let link = dir.path().join("link.PNG");
        symlink("real.png", &link).unwrap();
        let target = Target::new(&link).unwrap();
        assert_eq!(target.path(), link);
        assert_eq!(target.resolved(), real);
        assert_eq!(target.format(), ImageFormat::Png);
        target.check_writable().unwrap();
        let with = Target::with_format(dir.path().join("plot.svg"), ImageFormat::Png).unwrap();
        assert_eq!(with.format(), ImageFormat::Png);

        // Made read-only after the target was made: still refused when it is written.
        std::fs::write(&real, b"old").unwrap();
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o444)).unwrap();
        let err = target.write_atomic(|_| Ok(())).unwrap_err();
        assert!(matches!(err, OutputError::ReadOnly { .. }), "{err:?}");
        assert_eq!(std::fs::read(&real).unwrap(), b"old");
    }

    #[test]
    fn render_targets_refuse_collisions_and_name_the_pictures() {
        let dir = Scratch::new("render");
        let aov = dir.path().join("aov");
        let err = RenderTargets::new(&aov.join(AOV_SAMPLES), Some(&aov)).unwrap_err();
        assert!(matches!(err, OutputError::Collision { .. }), "{err:?}");
        assert!(!aov.exists(), "nothing made");

        let image = dir.path().join("image.exr");
        let targets = RenderTargets::new(&image, Some(&aov)).unwrap();
        assert_eq!(targets.image.format(), ImageFormat::Exr);
        let aovs = targets.aovs.unwrap();
        assert_eq!(aovs.depth.path(), aov.join(AOV_DEPTH));
        assert_eq!(aovs.interval.path(), aov.join(AOV_INTERVAL));
        assert_eq!(aovs.samples.path(), aov.join(AOV_SAMPLES));
        assert!(same_file(&aov.join("x/../depth.png"), aovs.depth.path()).unwrap());
        assert!(!same_file(&image, aovs.depth.path()).unwrap());
        assert!(RenderTargets::new(&image, None).unwrap().aovs.is_none());
    }
}
