//! Geometry data as the Rust side keeps it: validated before Embree sees it, and shared with
//! Embree (no copy) for as long as the scene lives.

use std::sync::Arc;

use glam::{Vec2, Vec3};

use super::device::{EmbreeError, Result};

/// A triangle mesh. Positions and indices are handed to Embree as shared buffers; normals and
/// UVs stay on the Rust side for shading.
///
/// The buffers are reference-counted and never change once built, so cloning a mesh (as a
/// scene description does when it builds a world) shares them instead of copying: a mesh costs
/// its own size once however many descriptions and scenes hold it.
#[derive(Debug, Clone)]
pub struct TriangleMesh {
    /// One extra, zero vertex at the end: Embree reads vertices with 16-byte loads.
    positions: Arc<Vec<[f32; 3]>>,
    /// One extra triangle at the end, for the same reason.
    indices: Arc<Vec<[u32; 3]>>,
    normals: Option<Arc<Vec<[f32; 3]>>>,
    uvs: Option<Arc<Vec<[f32; 2]>>>,
    /// Per-vertex tangents for normal maps: xyz unit, w the bitangent sign (+1 or -1).
    tangents: Option<Arc<Vec<[f32; 4]>>>,
}

fn check_finite(values: &[f32], what: &str, width: usize) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(EmbreeError::InvalidGeometry(format!(
            "{what} {} has a non-finite coordinate ({})",
            i / width,
            values[i]
        ))),
        None => Ok(()),
    }
}

impl TriangleMesh {
    /// Validates and takes ownership of the mesh: every coordinate must be finite and every
    /// index must name an existing vertex.
    pub fn new(mut positions: Vec<[f32; 3]>, mut indices: Vec<[u32; 3]>) -> Result<Self> {
        if positions.is_empty() || indices.is_empty() {
            return Err(EmbreeError::InvalidGeometry(format!(
                "a triangle mesh needs vertices and triangles (got {} vertices, {} triangles)",
                positions.len(),
                indices.len()
            )));
        }
        if positions.len() >= u32::MAX as usize || indices.len() >= u32::MAX as usize {
            return Err(EmbreeError::InvalidGeometry(
                "a triangle mesh may have at most 2^32 - 2 vertices and triangles".into(),
            ));
        }
        check_finite(positions.as_flattened(), "vertex", 3)?;
        let n = positions.len() as u32;
        if let Some((t, tri)) = indices
            .iter()
            .enumerate()
            .find(|(_, tri)| tri.iter().any(|&i| i >= n))
        {
            return Err(EmbreeError::InvalidGeometry(format!(
                "triangle {t} has index {:?} out of range for {n} vertices",
                tri
            )));
        }
        positions.push([0.0; 3]);
        indices.push([0; 3]);
        Ok(Self {
            positions: Arc::new(positions),
            indices: Arc::new(indices),
            normals: None,
            uvs: None,
            tangents: None,
        })
    }

    /// Checks that an attribute has one entry per vertex.
    fn check_per_vertex(&self, len: usize, what: &str) -> Result<()> {
        if len != self.vertex_count() {
            return Err(EmbreeError::InvalidGeometry(format!(
                "{len} {what} for {} vertices",
                self.vertex_count()
            )));
        }
        Ok(())
    }

    /// Per-vertex shading normals (one per vertex, finite; normalised here).
    pub fn with_normals(mut self, normals: Vec<[f32; 3]>) -> Result<Self> {
        self.check_per_vertex(normals.len(), "normals")?;
        check_finite(normals.as_flattened(), "normal", 3)?;
        let mut normals = normals;
        for n in &mut normals {
            *n = Vec3::from(*n).normalize_or_zero().to_array();
        }
        self.normals = Some(Arc::new(normals));
        Ok(self)
    }

    /// Per-vertex texture coordinates (one per vertex, finite).
    pub fn with_uvs(mut self, uvs: Vec<[f32; 2]>) -> Result<Self> {
        self.check_per_vertex(uvs.len(), "UVs")?;
        check_finite(uvs.as_flattened(), "UV", 2)?;
        self.uvs = Some(Arc::new(uvs));
        Ok(self)
    }

    /// Per-vertex tangents (one per vertex, finite): xyz is normalised here, w becomes the
    /// sign of the bitangent (`cross(normal, tangent) * w`).
    pub fn with_tangents(mut self, tangents: Vec<[f32; 4]>) -> Result<Self> {
        self.check_per_vertex(tangents.len(), "tangents")?;
        check_finite(tangents.as_flattened(), "tangent", 4)?;
        let mut tangents = tangents;
        for t in &mut tangents {
            let xyz = Vec3::new(t[0], t[1], t[2]).normalize_or_zero();
            let w = if t[3] < 0.0 { -1.0 } else { 1.0 };
            *t = [xyz.x, xyz.y, xyz.z, w];
        }
        self.tangents = Some(Arc::new(tangents));
        Ok(self)
    }

    /// The per-vertex tangents (xyz unit, w the bitangent sign), if the mesh has them.
    pub fn tangents(&self) -> Option<&[[f32; 4]]> {
        self.tangents.as_deref().map(Vec::as_slice)
    }

    /// Interpolated tangent (xyz, not normalised) and bitangent sign at barycentrics (u, v)
    /// of triangle `prim`, or `None` when the mesh has no tangents.
    ///
    /// # Panics
    /// When `prim` is not a triangle of this mesh.
    pub fn tangent(&self, prim: u32, u: f32, v: f32) -> Option<(Vec3, f32)> {
        let tangents = self.tangents.as_ref()?;
        let [a, b, c] = self.corners(tangents, prim);
        let xyz = |t: [f32; 4]| Vec3::new(t[0], t[1], t[2]);
        let t = xyz(a) * (1.0 - u - v) + xyz(b) * u + xyz(c) * v;
        Some((t, a[3]))
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len() - 1
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() - 1
    }

    /// Vertex positions (without Embree's padding vertex).
    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions[..self.vertex_count()]
    }

    /// Each triangle's three vertex indices (without Embree's padding triangle).
    pub fn indices(&self) -> &[[u32; 3]] {
        &self.indices[..self.triangle_count()]
    }

    /// The per-vertex unit shading normals, if the mesh has them.
    pub fn normals(&self) -> Option<&[[f32; 3]]> {
        self.normals.as_deref().map(Vec::as_slice)
    }

    /// The per-vertex texture coordinates, if the mesh has them.
    pub fn uvs(&self) -> Option<&[[f32; 2]]> {
        self.uvs.as_deref().map(Vec::as_slice)
    }

    /// Bytes held by the mesh's buffers (what a 1M-triangle mesh costs in memory; clones share
    /// them).
    pub fn heap_bytes(&self) -> usize {
        self.positions.capacity() * 12
            + self.indices.capacity() * 12
            + self.normals.as_ref().map_or(0, |n| n.capacity() * 12)
            + self.uvs.as_ref().map_or(0, |u| u.capacity() * 8)
            + self.tangents.as_ref().map_or(0, |t| t.capacity() * 16)
    }

    /// The buffers Embree shares: (vertex pointer, vertex count, index pointer, triangle count).
    /// They are never modified after construction, so the pointers stay valid for as long as
    /// this mesh or any clone of it lives.
    pub(super) fn raw_buffers(&self) -> (*const [f32; 3], usize, *const [u32; 3], usize) {
        (
            self.positions.as_ptr(),
            self.vertex_count(),
            self.indices.as_ptr(),
            self.triangle_count(),
        )
    }

    fn corners<T: Copy>(&self, data: &[T], prim: u32) -> [T; 3] {
        let [a, b, c] = self.indices[prim as usize];
        [data[a as usize], data[b as usize], data[c as usize]]
    }

    /// Interpolated, normalised shading normal at barycentrics (u, v) of triangle `prim`,
    /// or `None` when the mesh has no normals.
    ///
    /// # Panics
    /// When `prim` is not a triangle of this mesh.
    pub fn shading_normal(&self, prim: u32, u: f32, v: f32) -> Option<Vec3> {
        let normals = self.normals.as_ref()?;
        let [a, b, c] = self.corners(normals, prim).map(Vec3::from);
        Some((a * (1.0 - u - v) + b * u + c * v).normalize_or_zero())
    }

    /// Interpolated texture coordinate, or `None` when the mesh has no UVs.
    ///
    /// # Panics
    /// When `prim` is not a triangle of this mesh.
    pub fn uv(&self, prim: u32, u: f32, v: f32) -> Option<Vec2> {
        let uvs = self.uvs.as_ref()?;
        let [a, b, c] = self.corners(uvs, prim).map(Vec2::from);
        Some(a * (1.0 - u - v) + b * u + c * v)
    }

    /// The geometric normal of triangle `prim` (unnormalised winding order a, b, c).
    ///
    /// # Panics
    /// When `prim` is not a triangle of this mesh.
    pub fn face_normal(&self, prim: u32) -> Vec3 {
        let [a, b, c] = self.corners(&self.positions, prim).map(Vec3::from);
        (b - a).cross(c - a)
    }
}

/// A set of analytic spheres in one Embree geometry; the primitive id is the sphere's index.
#[derive(Debug, Clone)]
pub struct Spheres {
    /// x, y, z, radius: the layout of Embree's `RTC_FORMAT_FLOAT4` sphere buffer.
    data: Vec<[f32; 4]>,
}

impl Spheres {
    /// Validates centres (finite) and radii (finite, > 0).
    pub fn new(spheres: impl IntoIterator<Item = (Vec3, f32)>) -> Result<Self> {
        let data: Vec<[f32; 4]> = spheres
            .into_iter()
            .map(|(c, r)| [c.x, c.y, c.z, r])
            .collect();
        if data.is_empty() {
            return Err(EmbreeError::InvalidGeometry(
                "a sphere set needs at least one sphere".into(),
            ));
        }
        check_finite(data.as_flattened(), "sphere", 4)?;
        if let Some((i, s)) = data.iter().enumerate().find(|(_, s)| s[3] <= 0.0) {
            return Err(EmbreeError::InvalidGeometry(format!(
                "sphere {i} has radius {} (must be > 0)",
                s[3]
            )));
        }
        Ok(Self { data })
    }

    /// Number of spheres.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Whether the set has no spheres.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Centre of sphere `prim`.
    ///
    /// # Panics
    /// When `prim` is not a sphere of this set.
    pub fn center(&self, prim: u32) -> Vec3 {
        let [x, y, z, _] = self.data[prim as usize];
        Vec3::new(x, y, z)
    }

    /// Radius of sphere `prim`.
    ///
    /// # Panics
    /// When `prim` is not a sphere of this set.
    pub fn radius(&self, prim: u32) -> f32 {
        self.data[prim as usize][3]
    }

    pub(super) fn raw_buffer(&self) -> (*const [f32; 4], usize) {
        (self.data.as_ptr(), self.data.len())
    }
}

/// A geometry attached to a scene, as the Rust side keeps it for shading.
#[derive(Debug, Clone)]
pub enum Geometry {
    /// A triangle mesh; primitives are its triangles.
    Mesh(TriangleMesh),
    /// A set of spheres; primitives are its spheres.
    Spheres(Spheres),
}

/// The id Embree gave a geometry (`geomID` in a hit); indexes `Scene::geometry`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct GeometryId(pub u32);
