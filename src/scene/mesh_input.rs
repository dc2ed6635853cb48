//! What the model loaders (OBJ, glTF) share: the file being loaded with its folder and the
//! load's limits, the path policy for the files it refers to, third-party parsers kept from
//! panicking through the loader, and meshes built from the loaders' buffers.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::error::{LoadError, Location};
use super::input::{self, Input, LoadOptions};
use super::model::Transform;
use super::texture::TextureCache;
use crate::embree::{EmbreeError, TriangleMesh};
use crate::limits::{MemoryError, try_with_capacity};
use crate::shade::{ImageTexture, Wrap};

/// A model file being loaded: its path, its folder (which the files it refers to resolve
/// from, and by default must stay inside) and the load's texture cache, which carries the
/// limits of the load.
pub(super) struct ModelFile<'a> {
    /// The model file, as given.
    pub path: &'a Path,
    /// The model's folder.
    pub folder: PathBuf,
    textures: &'a mut TextureCache,
}

impl<'a> ModelFile<'a> {
    /// The model at `path`, loaded with the texture cache (and under the options) of
    /// `textures`.
    pub fn new(path: &'a Path, textures: &'a mut TextureCache) -> Self {
        Self {
            path,
            folder: path.parent().unwrap_or(Path::new("")).to_path_buf(),
            textures,
        }
    }

    /// The load's limits and path policy.
    pub fn options(&self) -> &LoadOptions {
        self.textures.options()
    }

    /// Opens the model file for streaming, within the byte limit.
    pub fn open(&self) -> Result<Input, LoadError> {
        input::open(self.path, self.options())
    }

    /// Reads the whole model file, within the byte limit.
    pub fn read(&self) -> Result<Vec<u8>, LoadError> {
        input::read(self.path, self.options())
    }

    /// The file `name` refers to from `dir` (a folder given relative to the model's), by the
    /// path policy of [`input::reference`]; `at` is where the reference is written.
    pub fn reference(&self, dir: &Path, name: &str, at: &Location) -> Result<PathBuf, LoadError> {
        input::reference(&self.folder, dir, name, self.options(), at)
    }

    /// The image texture in the file `name` refers to from `dir`, decoded once per load;
    /// a failure is reported as the texture referenced from `at`.
    pub fn texture(
        &mut self,
        (dir, name): (&Path, &str),
        srgb: bool,
        wrap: Wrap,
        at: Location,
    ) -> Result<Arc<ImageTexture>, LoadError> {
        let file = self.reference(dir, name, &at)?;
        self.textures
            .file(&file, srgb, wrap)
            .map_err(|e| e.referenced(at, "texture"))
    }

    /// Builds one mesh from loader buffers; `what` names it in validation errors (`object
    /// "Cube"`, `mesh 0 primitive 1`).
    pub fn mesh(&self, what: &str, buffers: MeshBuffers) -> Result<TriangleMesh, LoadError> {
        let fail = |e: EmbreeError| LoadError::Geometry {
            at: Location::file(self.path),
            message: format!("{what}: {e}"),
        };
        let mut m = TriangleMesh::new(buffers.positions, buffers.triangles).map_err(fail)?;
        if let Some(n) = buffers.normals {
            m = m.with_normals(n).map_err(fail)?;
        }
        if let Some(uv) = buffers.uvs {
            m = m.with_uvs(uv).map_err(fail)?;
        }
        if let Some(t) = buffers.tangents {
            m = m.with_tangents(t).map_err(fail)?;
        }
        Ok(m)
    }
}

/// The per-vertex data and triangles a loader read for one mesh, already in world space.
pub(super) struct MeshBuffers {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Only complete per-vertex attributes are given (one per position).
    pub normals: Option<Vec<[f32; 3]>>,
    pub uvs: Option<Vec<[f32; 2]>>,
    pub tangents: Option<Vec<[f32; 4]>>,
}

/// An allocation of a load that failed, as the resource-limit error of the file `path`.
pub(super) fn memory_error(path: &Path, e: MemoryError) -> LoadError {
    LoadError::Limit {
        at: Location::file(path),
        message: e.to_string(),
    }
}

/// An empty buffer with room for exactly `n` elements (mesh data of the file `path`, sized by
/// the file), or the file's resource-limit error when the memory cannot be had.
pub(super) fn buffer<T>(path: &Path, n: usize, what: &'static str) -> Result<Vec<T>, LoadError> {
    try_with_capacity(n, what).map_err(|e| memory_error(path, e))
}

/// Reverses the winding of `triangles` when `transform` mirrors: a mirror turns every triangle
/// inside out, and the winding is what says which side a surface faces.
pub(super) fn keep_winding(triangles: &mut [[u32; 3]], transform: &Transform) {
    if transform.mirrors {
        for t in triangles {
            t.swap(1, 2);
        }
    }
}

/// Runs a third-party parser; a panic inside it becomes the error `failed` makes, instead of
/// taking the process (or a render farm job) down with a malformed file.
pub(super) fn guarded<T>(
    parse: impl FnOnce() -> T,
    failed: impl FnOnce() -> LoadError,
) -> Result<T, LoadError> {
    catch_unwind(AssertUnwindSafe(parse)).map_err(|_| failed())
}
