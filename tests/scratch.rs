//! Scratch directories for the tests: each a new directory under the system temp dir
//! (`$TMPDIR`, else `/tmp`) with a unique name, removed with everything in it when the
//! [`Scratch`] is dropped, at the end of the test whether it passed or panicked. A test keeps
//! its `Scratch` alive for as long as it, or a `dofray` process it started, uses the directory.

use std::ffi::OsStr;
use std::ops::Deref;
use std::path::{Path, PathBuf};

use tempfile::TempDir;

/// A directory removed on drop; derefs to its path. Bind it to a name: a temporary one
/// (`scratch("x").join("scene.toml")`) is removed at the end of its statement.
pub struct Scratch(TempDir);

impl Scratch {
    /// A new, empty directory named `dofray-{name}-` and a random suffix.
    pub fn new(name: &str) -> Self {
        let dir = tempfile::Builder::new()
            .prefix(&format!("dofray-{name}-"))
            .tempdir()
            .unwrap_or_else(|e| panic!("cannot make a scratch directory for {name}: {e}"));
        Self(dir)
    }

    /// Removes the directory now, and says whether that failed (a drop ignores errors).
    pub fn close(self) -> std::io::Result<()> {
        self.0.close()
    }
}

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<OsStr> for Scratch {
    fn as_ref(&self) -> &OsStr {
        self.0.path().as_os_str()
    }
}

/// A file in a [`Scratch`] directory that it keeps: the directory lives as long as the
/// file's path is in use. Derefs to the path.
pub struct ScratchFile {
    path: PathBuf,
    _dir: Scratch,
}

impl ScratchFile {
    /// `path`, in `dir`.
    pub fn new(dir: Scratch, path: PathBuf) -> Self {
        debug_assert!(path.starts_with(&*dir));
        Self { path, _dir: dir }
    }
}

impl Deref for ScratchFile {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}
