//! Building and committing an Embree scene, then tracing rays against it from any thread.

use glam::Vec3;

use super::device::{Device, EmbreeError, Result};
use super::geometry::{Geometry, GeometryId, Spheres, TriangleMesh};
use super::packet::{Hit, Ray, RayHint, RayPacket16, ShadowPacket16};
use super::{sys, version};

/// Embree's BVH build quality: a trade between build time and trace speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BuildQuality {
    Low,
    #[default]
    Medium,
    High,
}

impl BuildQuality {
    fn raw(self) -> sys::RTCBuildQuality {
        match self {
            Self::Low => sys::RTC_BUILD_QUALITY_LOW,
            Self::Medium => sys::RTC_BUILD_QUALITY_MEDIUM,
            Self::High => sys::RTC_BUILD_QUALITY_HIGH,
        }
    }
}

/// Owns one reference to an RTCScene.
struct SceneHandle(sys::RTCScene);

impl Drop for SceneHandle {
    fn drop(&mut self) {
        // SAFETY: the handle came from rtcNewScene and is released exactly once.
        unsafe { sys::rtcReleaseScene(self.0) }
    }
}

/// Collects geometry, then commits it into a [`Scene`].
pub struct SceneBuilder {
    // Field order is drop order: the scene handle goes before the buffers it shares.
    handle: SceneHandle,
    geometries: Vec<Geometry>,
    device: Device,
    quality: BuildQuality,
}

// SAFETY: the builder exclusively owns its scene handle and geometry buffers; Embree allows a
// scene to be built from any thread as long as one thread at a time modifies it (&mut self).
unsafe impl Send for SceneBuilder {}

impl SceneBuilder {
    pub fn new(device: &Device) -> Result<Self> {
        // SAFETY: device.raw() is a live device.
        let raw = unsafe { sys::rtcNewScene(device.raw()) };
        device.check("rtcNewScene")?;
        if raw.is_null() {
            return Err(EmbreeError::Embree {
                code: super::ErrorCode::Unknown,
                message: "rtcNewScene returned no scene".into(),
            });
        }
        Ok(Self {
            handle: SceneHandle(raw),
            geometries: Vec::new(),
            device: device.clone(),
            quality: BuildQuality::default(),
        })
    }

    pub fn build_quality(mut self, quality: BuildQuality) -> Self {
        self.quality = quality;
        self
    }

    /// Adds a triangle mesh; its buffers are shared with Embree, not copied.
    pub fn add_mesh(&mut self, mesh: TriangleMesh) -> Result<GeometryId> {
        let (vertices, vertex_count, indices, triangle_count) = mesh.raw_buffers();
        self.attach(
            Geometry::Mesh(mesh),
            sys::RTC_GEOMETRY_TYPE_TRIANGLE,
            |geom| {
                // SAFETY: both buffers are owned by the Geometry that this builder (then the Scene)
                // keeps until after the scene handle is released; each is padded by one element so
                // Embree's 16-byte loads of the last item stay in bounds; strides match the layouts.
                unsafe {
                    sys::rtcSetSharedGeometryBuffer(
                        geom,
                        sys::RTC_BUFFER_TYPE_VERTEX,
                        0,
                        sys::RTC_FORMAT_FLOAT3,
                        vertices.cast(),
                        0,
                        12,
                        vertex_count,
                    );
                    sys::rtcSetSharedGeometryBuffer(
                        geom,
                        sys::RTC_BUFFER_TYPE_INDEX,
                        0,
                        sys::RTC_FORMAT_UINT3,
                        indices.cast(),
                        0,
                        12,
                        triangle_count,
                    );
                }
            },
        )
    }

    /// Adds a set of analytic spheres (Embree's sphere point geometry).
    pub fn add_spheres(&mut self, spheres: Spheres) -> Result<GeometryId> {
        let (data, count) = spheres.raw_buffer();
        self.attach(
            Geometry::Spheres(spheres),
            sys::RTC_GEOMETRY_TYPE_SPHERE_POINT,
            |geom| {
                // SAFETY: as in add_mesh; float4 items are 16 bytes, so no padding is needed.
                unsafe {
                    sys::rtcSetSharedGeometryBuffer(
                        geom,
                        sys::RTC_BUFFER_TYPE_VERTEX,
                        0,
                        sys::RTC_FORMAT_FLOAT4,
                        data.cast(),
                        0,
                        16,
                        count,
                    );
                }
            },
        )
    }

    fn attach(
        &mut self,
        geometry: Geometry,
        kind: sys::RTCGeometryType,
        set_buffers: impl FnOnce(sys::RTCGeometry),
    ) -> Result<GeometryId> {
        let id = u32::try_from(self.geometries.len())
            .ok()
            .filter(|&id| id != sys::RTC_INVALID_GEOMETRY_ID)
            .ok_or_else(|| EmbreeError::InvalidGeometry("too many geometries".into()))?;
        // SAFETY: live device; the geometry handle is released below on every path.
        let geom = unsafe { sys::rtcNewGeometry(self.device.raw(), kind) };
        if let Err(e) = self.device.check("rtcNewGeometry") {
            if !geom.is_null() {
                // SAFETY: geom came from rtcNewGeometry and is released once.
                unsafe { sys::rtcReleaseGeometry(geom) };
            }
            return Err(e);
        }
        set_buffers(geom);
        // SAFETY: geom is live with its buffers set; the scene takes its own reference when
        // attaching, so releasing ours afterwards is correct.
        unsafe {
            sys::rtcSetGeometryBuildQuality(geom, self.quality.raw());
            sys::rtcCommitGeometry(geom);
            sys::rtcAttachGeometryByID(self.handle.0, geom, id);
            sys::rtcReleaseGeometry(geom);
        }
        // Keep the Rust-side data even on error: Embree may still reference its buffers.
        self.geometries.push(geometry);
        self.device.check("attaching geometry")?;
        Ok(GeometryId(id))
    }

    /// Builds the BVH. The committed scene is immutable and may be traced from many threads.
    pub fn commit(self) -> Result<Scene> {
        // SAFETY: the scene handle is live and only this thread modifies it.
        unsafe {
            sys::rtcSetSceneBuildQuality(self.handle.0, self.quality.raw());
            sys::rtcCommitScene(self.handle.0);
        }
        self.device.check("rtcCommitScene")?;
        let mut bounds = sys::RTCBounds::default();
        // SAFETY: committed scene; bounds is a valid, 16-byte aligned RTCBounds.
        unsafe { sys::rtcGetSceneBounds(self.handle.0, &mut bounds) };
        self.device.check("rtcGetSceneBounds")?;
        Ok(Scene {
            handle: self.handle,
            geometries: self.geometries,
            device: self.device,
            bounds: (
                Vec3::new(bounds.lower_x, bounds.lower_y, bounds.lower_z),
                Vec3::new(bounds.upper_x, bounds.upper_y, bounds.upper_z),
            ),
        })
    }
}

/// A committed Embree scene plus the Rust-side geometry data its hits refer to.
pub struct Scene {
    // Field order is drop order: the scene handle goes before the buffers it shares.
    handle: SceneHandle,
    geometries: Vec<Geometry>,
    #[allow(dead_code)] // kept alive: the scene's error callback user pointer lives in it
    device: Device,
    bounds: (Vec3, Vec3),
}

// SAFETY: a committed RTCScene is immutable and Embree documents rtcIntersect*/rtcOccluded* on it
// as thread-safe; the Rust-side geometry is never mutated after commit (no &mut access exists),
// and the device is itself Send + Sync.
unsafe impl Send for Scene {}
// SAFETY: as above: all &Scene methods are queries on immutable data.
unsafe impl Sync for Scene {}

impl Scene {
    /// Axis-aligned bounds of everything in the scene (lower, upper).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// The Rust-side data of a geometry a hit refers to.
    pub fn geometry(&self, id: GeometryId) -> &Geometry {
        &self.geometries[id.0 as usize]
    }

    pub fn geometries(&self) -> &[Geometry] {
        &self.geometries
    }

    /// Nearest hit of one ray.
    pub fn intersect1(&self, ray: &Ray) -> Option<Hit> {
        let mut rayhit = sys::RTCRayHit {
            ray: raw_ray(ray),
            hit: sys::RTCHit {
                geomID: sys::RTC_INVALID_GEOMETRY_ID,
                primID: sys::RTC_INVALID_GEOMETRY_ID,
                instID: [sys::RTC_INVALID_GEOMETRY_ID; sys::RTC_MAX_INSTANCE_LEVEL_COUNT as usize],
                ..Default::default()
            },
        };
        // SAFETY: the scene is committed and alive for &self; rayhit is a valid RTCRayHit.
        unsafe { version::intersect1(self.handle.0, &mut rayhit, false) };
        let h = &rayhit.hit;
        (h.geomID != sys::RTC_INVALID_GEOMETRY_ID).then(|| Hit {
            t: rayhit.ray.tfar,
            geometry: GeometryId(h.geomID),
            prim: h.primID,
            u: h.u,
            v: h.v,
            ng: Vec3::new(h.Ng_x, h.Ng_y, h.Ng_z),
        })
    }

    /// True when anything blocks the ray within `[tnear, tfar]`.
    pub fn occluded1(&self, ray: &Ray) -> bool {
        let mut raw = raw_ray(ray);
        // SAFETY: the scene is committed and alive for &self; raw is a valid RTCRay.
        unsafe { version::occluded1(self.handle.0, &mut raw, false) };
        raw.tfar == f32::NEG_INFINITY
    }

    /// Traces the active lanes of a packet; inactive lanes are neither read nor written.
    pub fn intersect16(&self, packet: &mut RayPacket16, hint: RayHint) {
        // SAFETY: committed scene alive for &self; the packet's RTCRayHit16 and mask are 64-byte
        // aligned by their types, and Embree only touches active lanes.
        unsafe {
            version::intersect16(
                &packet.valid.0,
                self.handle.0,
                &mut packet.rayhit,
                hint == RayHint::Coherent,
            )
        }
    }

    /// Tests the active lanes of a shadow packet for occlusion.
    pub fn occluded16(&self, packet: &mut ShadowPacket16, hint: RayHint) {
        // SAFETY: as in intersect16.
        unsafe {
            version::occluded16(
                &packet.valid.0,
                self.handle.0,
                &mut packet.rays,
                hint == RayHint::Coherent,
            )
        }
    }
}

fn raw_ray(ray: &Ray) -> sys::RTCRay {
    sys::RTCRay {
        org_x: ray.origin.x,
        org_y: ray.origin.y,
        org_z: ray.origin.z,
        tnear: ray.tnear,
        dir_x: ray.dir.x,
        dir_y: ray.dir.y,
        dir_z: ray.dir.z,
        time: 0.0,
        tfar: ray.tfar,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}
