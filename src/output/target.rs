//! Where an output really goes, and whether it may be written there.
//!
//! - A symbolic link is written *through*: the image replaces the file the link names (the
//!   link stays), and the temporary file goes next to that file, so the final rename stays on
//!   one file system. A dangling link creates the file it names.
//! - An existing target must be a regular file with at least one write permission bit: a
//!   read-only file (mode without any `w`, checked explicitly, so root is refused too), a
//!   directory or a device is never replaced.
//! - The images one render writes (the image and its AOV pictures) must be distinct files.

use std::path::{Component, Path, PathBuf};

use super::atomic::parent_dir;
use super::{ImageFormat, OutputError};

/// Symbolic links followed at most before giving up (Linux's own limit).
const MAX_LINKS: usize = 40;

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

/// Resolves `path` (see [`resolve_target`]) and checks that what it names may be replaced:
/// nothing there yet, or a regular file with a write permission bit, in an existing directory.
pub(crate) fn check_target(path: &Path) -> Result<PathBuf, OutputError> {
    let target = resolve_target(path)?;
    let io_err = |kind, message: String| OutputError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(kind, message),
    };
    match std::fs::metadata(&target) {
        Ok(meta) if meta.is_dir() => {
            return Err(io_err(
                std::io::ErrorKind::IsADirectory,
                "the output path is a directory".into(),
            ));
        }
        Ok(meta) if !meta.is_file() => {
            return Err(OutputError::NotAFile {
                path: path.to_path_buf(),
                target,
            });
        }
        Ok(meta) if meta.permissions().readonly() => {
            return Err(OutputError::ReadOnly {
                path: path.to_path_buf(),
                target,
            });
        }
        _ => {}
    }
    let dir = parent_dir(&target);
    if !dir.is_dir() {
        return Err(io_err(
            std::io::ErrorKind::NotFound,
            format!("directory {} does not exist", dir.display()),
        ));
    }
    Ok(target)
}

/// `path` made absolute, its links followed and its existing directories canonicalised, for
/// telling whether two output paths name the same file before either exists.
fn identity(path: &Path) -> Result<PathBuf, OutputError> {
    let io_err = |source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    };
    let target = resolve_target(path)?;
    let absolute = if target.is_absolute() {
        target
    } else {
        std::env::current_dir().map_err(io_err)?.join(target)
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
    if identity(a)? == identity(b)? {
        return Ok(true);
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return Ok(ma.dev() == mb.dev() && ma.ino() == mb.ino());
        }
    }
    Ok(false)
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

/// Checks everything one render will write before it starts: the image at `output` (see
/// [`super::check_writable`]) and, with `aov_dir`, the directory (created if missing) and its
/// pictures, which must each be replaceable and distinct from the image.
pub fn check_render_outputs(
    output: &Path,
    aov_dir: Option<&Path>,
) -> Result<ImageFormat, OutputError> {
    let Some(dir) = aov_dir else {
        return super::check_writable(output);
    };
    ImageFormat::from_path(output)?;
    for name in AOVS {
        let aov = dir.join(name);
        if same_file(output, &aov)? {
            return Err(OutputError::Collision {
                first: output.to_path_buf(),
                second: aov,
            });
        }
    }
    std::fs::create_dir_all(dir).map_err(|source| OutputError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    // After creating the directory, which may be the image's too.
    let format = super::check_writable(output)?;
    for name in AOVS {
        super::check_writable(&dir.join(name))?;
    }
    Ok(format)
}
