//! The one way input files are opened and read: every scene, OBJ, MTL, glTF/GLB, external
//! buffer and texture goes through here.
//!
//! - Only regular files are read. The path is checked with `metadata` (symlinks followed)
//!   *before* it is opened, so a FIFO is never opened (opening one blocks) and a device such as
//!   `/dev/zero` is never read; directories and sockets are refused too.
//! - At most [`LoadOptions::max_input_bytes`] are read from any one file.
//! - Files a model refers to (MTL libraries, textures, external buffers) must stay inside the
//!   model's folder unless [`LoadOptions::allow_outside_paths`] is set ([`reference()`]).

use std::fs::File;
use std::io::{BufReader, Read, Take};
use std::path::{Component, Path, PathBuf};

use super::error::{LoadError, Location};

/// Limits and policies of scene loading. Every limit can be raised for real huge scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadOptions {
    /// Bytes read from any one input file at most (default 4 GiB).
    pub max_input_bytes: u64,
    /// Memory one decoded image texture may need at most, counting the decoder's buffer, the
    /// conversion to RGB and the float texels (default 1 GiB; an 8192 x 8192 RGB PNG fits).
    pub max_texture_bytes: u64,
    /// Triangles a glTF file may instance at most, summed over its expanded node tree
    /// (default 50 million).
    pub max_instanced_triangles: u64,
    /// Node instances a glTF file may expand to at most (default 1,048,576).
    pub max_node_instances: u64,
    /// Allow MTL libraries, textures and buffers a model refers to by absolute paths or by
    /// `..` paths leading out of the model's folder (default false).
    pub allow_outside_paths: bool,
}

impl LoadOptions {
    /// Default of [`LoadOptions::max_input_bytes`]: 4 GiB.
    pub const DEFAULT_MAX_INPUT_BYTES: u64 = 4 << 30;
    /// Default of [`LoadOptions::max_texture_bytes`]: 1 GiB.
    pub const DEFAULT_MAX_TEXTURE_BYTES: u64 = 1 << 30;
    /// Default of [`LoadOptions::max_instanced_triangles`]: 50 million.
    pub const DEFAULT_MAX_INSTANCED_TRIANGLES: u64 = 50_000_000;
    /// Default of [`LoadOptions::max_node_instances`]: 2^20 (1,048,576).
    pub const DEFAULT_MAX_NODE_INSTANCES: u64 = 1 << 20;
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            max_input_bytes: Self::DEFAULT_MAX_INPUT_BYTES,
            max_texture_bytes: Self::DEFAULT_MAX_TEXTURE_BYTES,
            max_instanced_triangles: Self::DEFAULT_MAX_INSTANCED_TRIANGLES,
            max_node_instances: Self::DEFAULT_MAX_NODE_INSTANCES,
            allow_outside_paths: false,
        }
    }
}

/// What a non-regular file is, for messages.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a named pipe (FIFO)"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Refuses anything but a regular file (symlinks followed), without opening it.
fn check_regular(path: &Path) -> Result<(), LoadError> {
    let meta = std::fs::metadata(path).map_err(|e| LoadError::io(path, e))?;
    if meta.is_file() {
        Ok(())
    } else {
        Err(LoadError::NotAFile {
            path: path.to_path_buf(),
            kind: kind(&meta),
        })
    }
}

/// A reader of an input file that stops one byte past the limit; see [`Input::finish`].
pub struct Input {
    reader: Take<BufReader<File>>,
    path: PathBuf,
    limit: u64,
    /// The file's size when it was opened.
    size: u64,
}

impl Input {
    /// The file's size when it was opened, bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The reader (at most the limit plus one byte).
    pub fn reader(&mut self) -> &mut Take<BufReader<File>> {
        &mut self.reader
    }

    /// An error if the file was longer than the limit (the reader hit the extra byte).
    pub fn finish(&self) -> Result<(), LoadError> {
        if self.reader.limit() == 0 {
            Err(too_large(&self.path, self.limit))
        } else {
            Ok(())
        }
    }
}

fn too_large(path: &Path, limit: u64) -> LoadError {
    LoadError::TooLarge {
        path: path.to_path_buf(),
        limit,
    }
}

/// Opens a regular file for streaming, capped at `options.max_input_bytes`.
pub fn open(path: &Path, options: &LoadOptions) -> Result<Input, LoadError> {
    check_regular(path)?;
    let file = File::open(path).map_err(|e| LoadError::io(path, e))?;
    // The path may have been swapped since the check: look at what was opened.
    let meta = file.metadata().map_err(|e| LoadError::io(path, e))?;
    if !meta.is_file() {
        return Err(LoadError::NotAFile {
            path: path.to_path_buf(),
            kind: kind(&meta),
        });
    }
    let limit = options.max_input_bytes;
    Ok(Input {
        reader: BufReader::with_capacity(1 << 16, file).take(limit.saturating_add(1)),
        path: path.to_path_buf(),
        limit,
        size: meta.len(),
    })
}

/// Reads a whole regular file, refusing more than `options.max_input_bytes`. Its buffer is
/// allocated at once for the file's size, so memory that cannot be had is a resource-limit
/// error naming the file, not an abort halfway through.
pub fn read(path: &Path, options: &LoadOptions) -> Result<Vec<u8>, LoadError> {
    let mut input = open(path, options)?;
    if input.size > input.limit {
        return Err(too_large(path, input.limit));
    }
    let size = input.size;
    let mut bytes =
        crate::limits::try_with_capacity(size as usize, "the file's bytes").map_err(|e| {
            LoadError::Limit {
                at: Location::file(path),
                message: e.to_string(),
            }
        })?;
    input
        .reader()
        .read_to_end(&mut bytes)
        .map_err(|e| LoadError::io(path, e))?;
    input.finish()?;
    Ok(bytes)
}

/// The file `name` refers to from `dir` (a folder inside the model's folder `root`, given
/// relative to it), by the path policy: a relative path that stays inside `root` (`..` may
/// climb back only as far as `root`); absolute paths and escapes only with
/// `options.allow_outside_paths`. `at` is where the reference is written, for the error.
pub fn reference(
    root: &Path,
    dir: &Path,
    name: &str,
    options: &LoadOptions,
    at: &Location,
) -> Result<PathBuf, LoadError> {
    let relative = dir.join(name);
    if options.allow_outside_paths {
        return Ok(root.join(relative));
    }
    let mut depth = 0usize;
    let mut inside = true;
    for c in relative.components() {
        match c {
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
            Component::ParentDir if depth > 0 => depth -= 1,
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => inside = false,
        }
    }
    if inside {
        Ok(root.join(relative))
    } else {
        Err(LoadError::OutsidePath {
            at: at.clone(),
            name: name.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_stay_inside_the_model_folder() {
        let o = LoadOptions::default();
        let at = Location::file(Path::new("m.obj"));
        let root = Path::new("/models/a");
        let ok = |dir: &str, name: &str| reference(root, Path::new(dir), name, &o, &at);
        assert_eq!(ok("", "t.png").unwrap(), Path::new("/models/a/t.png"));
        assert!(ok("sub", "../t.png").is_ok());
        assert!(ok("", "sub/../t.png").is_ok());
        assert!(ok("", "../t.png").is_err());
        assert!(ok("sub", "../../t.png").is_err());
        assert!(ok("", "/etc/passwd").is_err());
        let allow = LoadOptions {
            allow_outside_paths: true,
            ..o
        };
        assert!(reference(root, Path::new(""), "../t.png", &allow, &at).is_ok());
    }
}
