//! Errors from loading scenes and models: each names the file, and the line, column and key
//! where there is one, and says what was expected.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::Bytes;

/// Where in an input file something went wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// 1-based column (in characters), when known.
    pub column: Option<usize>,
    /// The TOML key path (`objects[2].radius`), when known.
    pub key: Option<String>,
}

impl Location {
    /// The whole file.
    pub fn file(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            line: None,
            column: None,
            key: None,
        }
    }

    /// A line of a file.
    pub fn line(path: &Path, line: usize) -> Self {
        Self {
            line: Some(line),
            ..Self::file(path)
        }
    }

    /// The position of byte `offset` of `src` (the text of `path`), and the key path there.
    pub fn at_offset(path: &Path, src: &str, offset: usize) -> Self {
        let (line, column) = line_column(src, offset);
        Self {
            path: path.to_path_buf(),
            line: Some(line),
            column: Some(column),
            key: key_path(src, offset),
        }
    }

    /// The same location with an explicit key path.
    pub fn with_key(mut self, key: impl Into<String>) -> Self {
        self.key = Some(key.into());
        self
    }
}

/// A file name or URI as shown in messages: control characters (terminal escape sequences,
/// newlines, ...) are escaped (`\u{1b}`), so bytes from a file name or URI never reach the
/// user's terminal raw. Every path and URI in an error goes through this.
pub struct Shown<'a>(pub &'a str);

/// [`Shown`] for a path (non-UTF-8 bytes shown as U+FFFD).
pub fn shown(path: &Path) -> String {
    Shown(&path.to_string_lossy()).to_string()
}

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for c in self.0.chars() {
            if c.is_control() {
                write!(f, "{}", c.escape_default())?;
            } else {
                write!(f, "{c}")?;
            }
        }
        Ok(())
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", shown(&self.path))?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(column) = self.column {
                write!(f, ":{column}")?;
            }
        }
        if let Some(key) = &self.key {
            write!(f, ": `{}`", Shown(key))?;
        }
        Ok(())
    }
}

/// Why a scene or model could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// Neither a built-in scene nor a file of a known type.
    #[error(
        "unknown scene {name:?}: expected a built-in scene ({builtins}), a .toml scene file, \
         or a .obj, .gltf or .glb model"
    )]
    UnknownScene {
        /// The name given.
        name: String,
        /// The built-in scenes' names, comma-separated.
        builtins: String,
    },
    /// A file could not be opened or read.
    #[error("{}: cannot read: {error}", shown(path))]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// The TOML scene is malformed: a syntax error, an unknown key, a wrong type or an
    /// invalid value (NaN, infinity, a size or radius <= 0, ...).
    #[error("{at}: {message}")]
    Toml {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// The scene is well-formed TOML but inconsistent (a material that does not exist, two
    /// lenses at once, a key that does not apply to an object's type, ...).
    #[error("{at}: {message}")]
    Invalid {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A file the scene (or a model) refers to failed to load.
    #[error("{at}: {what}: {cause}")]
    Referenced {
        /// Where the reference is.
        at: Location,
        /// What the file was to be (`"texture"`, `"mesh"`, `"material library"`, ...).
        what: &'static str,
        /// The referenced file's own error (its message is part of this one's).
        cause: Box<LoadError>,
    },
    /// A malformed Wavefront OBJ or MTL file.
    #[error("{at}: {message}")]
    Obj {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A malformed glTF 2.0 file (.gltf or .glb).
    #[error("{at}: {message}")]
    Gltf {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A lens prescription file that cannot be read or is invalid.
    #[error(transparent)]
    Lens(#[from] crate::camera::LensFileError),
    /// An image that could not be decoded.
    #[error("{}: {message}", shown(path))]
    Image {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// Mesh data that cannot be traced (non-finite coordinates, face indices out of range, ...).
    #[error("{at}: {message}")]
    Geometry {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A scene without anything to see.
    #[error(
        "{}: the scene has no objects (expected at least one [[objects]] entry or a mesh with triangles)",
        shown(path)
    )]
    Empty {
        /// The scene file (or model).
        path: PathBuf,
    },
    /// An input that is not a regular file (a device, FIFO, socket or directory).
    #[error("{}: cannot read: it is {kind}, expected a regular file", shown(path))]
    NotAFile {
        /// The file.
        path: PathBuf,
        /// What it is instead (`"a directory"`, `"a named pipe (FIFO)"`, ...).
        kind: &'static str,
    },
    /// An input file longer than `LoadOptions::max_input_bytes`.
    #[error(
        "{}: the file is larger than the input limit of {} ({limit} bytes; raise \
         it with --max-input-mib or LoadOptions::max_input_bytes for larger files)",
        shown(path), Bytes(*limit)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        limit: u64,
    },
    /// A model refers to a file outside its folder (absolute, or `..` leading out of it).
    #[error(
        "{at}: `{}` is outside the model's folder (absolute paths and `..` leading out of \
         the folder are refused; allow them with --allow-outside-paths or \
         LoadOptions::allow_outside_paths)",
        Shown(name)
    )]
    OutsidePath {
        /// Where the reference is.
        at: Location,
        /// The file name as the model gives it.
        name: String,
    },
    /// A resource limit: an expansion or an allocation larger than `LoadOptions` allow.
    #[error("{at}: {message}")]
    Limit {
        /// Where in which file.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
}

impl LoadError {
    pub(crate) fn io(path: &Path, error: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            error,
        }
    }

    pub(crate) fn invalid(at: Location, message: impl Into<String>) -> Self {
        Self::Invalid {
            at,
            message: message.into(),
        }
    }

    /// Wraps the failure of a file referenced from `at`.
    pub(crate) fn referenced(self, at: Location, what: &'static str) -> Self {
        Self::Referenced {
            at,
            what,
            cause: Box::new(self),
        }
    }

    /// The innermost error (the one a referenced file reported).
    pub fn root(&self) -> &LoadError {
        match self {
            Self::Referenced { cause, .. } => cause.root(),
            other => other,
        }
    }
}

/// 1-based line and column (in characters) of byte `offset` in `src`.
pub fn line_column(src: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(src.len());
    while !src.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &src[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = src[line_start..offset].chars().count() + 1;
    (line, column)
}

fn is_key_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' || c == '"' || c == '\''
}

/// A table header line (`[name]` or `[[name]]`): its name and whether it is an array of tables.
fn header(line: &str) -> Option<(&str, bool)> {
    let line = line.split('#').next().unwrap_or("").trim();
    let (inner, array) = if let Some(rest) = line.strip_prefix("[[") {
        (rest.strip_suffix("]]")?, true)
    } else {
        (line.strip_prefix('[')?.strip_suffix(']')?, false)
    };
    let inner = inner.trim();
    (!inner.is_empty() && inner.chars().all(|c| is_key_char(c) || c == ' '))
        .then_some((inner, array))
}

/// The key before the last `=` of `text`, if any.
fn key_before_eq(text: &str) -> Option<&str> {
    let eq = text.rfind('=')?;
    let before = text[..eq].trim_end();
    let start = before
        .char_indices()
        .rev()
        .find(|&(_, c)| !is_key_char(c))
        .map_or(0, |(i, c)| i + c.len_utf8());
    let key = &before[start..];
    (!key.is_empty()).then_some(key)
}

/// Best-effort TOML key path of the value or key at byte `offset` of `src`:
/// the enclosing table (`objects[2]` for the third `[[objects]]`) and the key on that line.
pub fn key_path(src: &str, offset: usize) -> Option<String> {
    let mut offset = offset.min(src.len());
    while !src.is_char_boundary(offset) {
        offset -= 1;
    }
    let line_start = src[..offset].rfind('\n').map_or(0, |i| i + 1);
    let line_end = src[offset..].find('\n').map_or(src.len(), |i| offset + i);
    let line = &src[line_start..line_end];
    let col = offset - line_start;

    // The enclosing table, counting earlier headers of the same array of tables.
    let mut table: Option<(String, bool, usize)> = None;
    let mut counts: std::collections::HashMap<String, usize> = Default::default();
    // Name -> (is an array of tables, headers seen).
    let mut arrays: std::collections::HashMap<String, (bool, usize)> = Default::default();
    for l in src[..line_start].lines() {
        if let Some((name, array)) = header(l) {
            let n = counts.entry(name.to_string()).or_default();
            table = Some((name.to_string(), array, *n));
            *n += 1;
            arrays.insert(name.to_string(), (array, *n));
        }
    }
    if header(line).is_some() {
        // The error is about a table itself; point at the table being opened.
        let (name, array) = header(line)?;
        let n = counts.get(name).copied().unwrap_or(0);
        return Some(if array {
            format!("{name}[{n}]")
        } else {
            name.to_string()
        });
    }

    // The key: before the last `=` left of the offset, else the key starting at the offset
    // (an unknown key), else the key of the nearest earlier line (a multi-line value).
    let here = &line[col.min(line.len())..];
    let token_len = here.find(|c: char| !is_key_char(c)).unwrap_or(here.len());
    let token = &here[..token_len];
    let after_token = here[token_len..].trim_start();
    let key = if let Some(k) = key_before_eq(&line[..col.min(line.len())]) {
        Some(k.to_string())
    } else if !token.is_empty() && after_token.starts_with('=') {
        Some(token.to_string())
    } else {
        src[..line_start]
            .lines()
            .rev()
            .take_while(|l| header(l).is_none())
            .find_map(key_before_eq)
            .map(str::to_string)
    };
    let table = table.map(|(name, array, n)| {
        if array {
            return format!("{name}[{n}]");
        }
        // `[objects.extra]` after `[[objects]]` is a sub-table of the latest array element.
        if let Some((first, rest)) = name.split_once('.')
            && let Some(&(true, count)) = arrays.get(first)
        {
            return format!("{first}[{}].{rest}", count - 1);
        }
        name
    });
    match (table, key) {
        (Some(t), Some(k)) => Some(format!("{t}.{k}")),
        (None, Some(k)) => Some(k),
        (Some(t), None) => Some(t),
        (None, None) => None,
    }
}

impl HasKind for LoadError {
    /// A limit is a resource limit, wherever the loader met it; anything else is bad input.
    fn kind(&self) -> ErrorKind {
        match self.root() {
            Self::TooLarge { .. } | Self::Limit { .. } => ErrorKind::ResourceLimit,
            _ => ErrorKind::BadInput,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_in_names_are_escaped() {
        let e = LoadError::io(Path::new("a\x1b[31mred\n.obj"), std::io::Error::other("x"));
        let m = e.to_string();
        assert!(!m.contains('\x1b') && !m.contains('\n'), "{m}");
        assert!(m.contains("a\\u{1b}[31mred\\n.obj"), "{m}");
    }

    #[test]
    fn offsets_become_lines_columns_and_keys() {
        let src = "name = \"x\"\n[camera]\neye = [0, nan, 1]\n\n[[objects]]\ntype = \"sphere\"\n\n[[objects]]\nradius = -1\nradis = 2\n";
        let off = src.find("nan").unwrap();
        assert_eq!(line_column(src, off), (3, 11));
        assert_eq!(key_path(src, off).as_deref(), Some("camera.eye"));
        let off = src.find("-1").unwrap();
        assert_eq!(key_path(src, off).as_deref(), Some("objects[1].radius"));
        let off = src.find("radis").unwrap();
        assert_eq!(key_path(src, off).as_deref(), Some("objects[1].radis"));
        assert_eq!(key_path(src, 0).as_deref(), Some("name"));
        let src = "[camera]\neye = [\n  0,\n  inf, 1]\n";
        let off = src.find("inf").unwrap();
        assert_eq!(key_path(src, off).as_deref(), Some("camera.eye"));
        let src = "[[objects]]\n[[objects]]\n[objects.extra]\nx = 1\n";
        let off = src.find("x =").unwrap();
        assert_eq!(key_path(src, off).as_deref(), Some("objects[1].extra.x"));
    }
}
