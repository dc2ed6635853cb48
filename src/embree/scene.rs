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
    ///
    /// # Panics
    /// When `id` is not a geometry of this scene (ids come from its hits or its builder).
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
                &packet.valid,
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
                &packet.valid,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::embree::{ErrorCode, LANES};

    /// A 20 x 20 quad at z = 2 (geometry 0) and a sphere behind it (geometry 1).
    fn quad_scene(device: &Device) -> Scene {
        let mut b = SceneBuilder::new(device).unwrap();
        let quad = TriangleMesh::new(
            vec![
                [-10.0, -10.0, 2.0],
                [10.0, -10.0, 2.0],
                [10.0, 10.0, 2.0],
                [-10.0, 10.0, 2.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap();
        b.add_mesh(quad).unwrap();
        b.add_spheres(Spheres::new([(Vec3::new(0.0, 0.0, 6.0), 1.0)]).unwrap())
            .unwrap();
        b.commit().unwrap()
    }

    /// Lane `lane`'s ray: from z = 0 straight at the quad, every lane at its own point.
    fn lane_ray(lane: usize) -> Ray {
        let x = (lane % 4) as f32 - 1.5;
        let y = (lane / 4) as f32 - 1.5;
        Ray::new(Vec3::new(x, y, 0.0), Vec3::new(0.05 * x, 0.05 * y, 1.0))
    }

    const INACTIVE: [usize; 5] = [1, 4, 7, 10, 15];

    /// Writes recognisable values into every hit field and `tfar` of `lane`.
    fn fill_sentinels(raw: &mut sys::RTCRayHit16, lane: usize) {
        let h = &mut raw.hit;
        h.geomID[lane] = 0xDEAD_0000 + lane as u32;
        h.primID[lane] = 0xBEEF_0000 + lane as u32;
        for level in h.instID.iter_mut() {
            level[lane] = 0xCAFE_0000 + lane as u32;
        }
        h.u[lane] = -7.25;
        h.v[lane] = -8.5;
        h.Ng_x[lane] = 1.0e30;
        h.Ng_y[lane] = -1.0e-30;
        h.Ng_z[lane] = f32::MIN_POSITIVE;
        raw.ray.tfar[lane] = 12345.5;
    }

    /// The bits of everything Embree could write in `lane`.
    fn lane_bits(raw: &sys::RTCRayHit16, lane: usize) -> Vec<u32> {
        let h = &raw.hit;
        let mut bits = vec![h.geomID[lane], h.primID[lane]];
        bits.extend(h.instID.iter().map(|level| level[lane]));
        bits.extend(
            [
                h.u[lane],
                h.v[lane],
                h.Ng_x[lane],
                h.Ng_y[lane],
                h.Ng_z[lane],
                raw.ray.tfar[lane],
            ]
            .map(f32::to_bits),
        );
        bits
    }

    #[test]
    fn intersect16_writes_no_field_of_an_inactive_lane() {
        let device = Device::new().unwrap();
        let scene = quad_scene(&device);
        for hint in [RayHint::Coherent, RayHint::Incoherent] {
            let mut packet = RayPacket16::new();
            for lane in 0..LANES {
                packet.set(lane, &lane_ray(lane));
            }
            for lane in INACTIVE {
                packet.set_inactive(lane);
                fill_sentinels(&mut packet.rayhit, lane);
                // Tracing this lane would write every field above: its ray hits the quad.
                let would = scene.intersect1(&packet.ray(lane));
                assert!(
                    would.is_some_and(|h| h.geometry == GeometryId(0) && (h.t - 2.0).abs() < 0.1),
                    "{hint:?} lane {lane}: {would:?}"
                );
            }
            let before: Vec<_> = INACTIVE
                .iter()
                .map(|&lane| lane_bits(&packet.rayhit, lane))
                .collect();

            scene.intersect16(&mut packet, hint);

            for (&lane, before) in INACTIVE.iter().zip(&before) {
                assert_eq!(
                    lane_bits(&packet.rayhit, lane),
                    *before,
                    "{hint:?}: inactive lane {lane} was written"
                );
            }
            for lane in (0..LANES).filter(|l| !INACTIVE.contains(l)) {
                let hit = packet.hit(lane);
                assert!(
                    hit.is_some_and(|h| h.geometry == GeometryId(0) && (h.t - 2.0).abs() < 0.1),
                    "{hint:?}: active lane {lane} should hit the quad: {hit:?}"
                );
            }
        }
    }

    #[test]
    fn occluded16_writes_no_field_of_an_inactive_lane() {
        let device = Device::new().unwrap();
        let scene = quad_scene(&device);
        for hint in [RayHint::Coherent, RayHint::Incoherent] {
            let mut packet = ShadowPacket16::new();
            for lane in 0..LANES {
                packet.set(lane, &lane_ray(lane));
            }
            for lane in INACTIVE {
                packet.set_inactive(lane);
                packet.rays.tfar[lane] = 12345.5;
                assert!(scene.occluded1(&packet.ray(lane)), "lane {lane} is blocked");
            }
            scene.occluded16(&mut packet, hint);
            for lane in 0..LANES {
                if INACTIVE.contains(&lane) {
                    assert_eq!(packet.rays.tfar[lane], 12345.5, "{hint:?}: lane {lane}");
                    assert!(!packet.occluded(lane));
                } else {
                    assert!(packet.occluded(lane), "{hint:?}: lane {lane}");
                }
            }
        }
    }

    #[test]
    fn embree_error_from_a_call_becomes_a_typed_error_with_embrees_message() {
        let device = Device::new().unwrap();
        let mut b = SceneBuilder::new(&device).unwrap();
        b.add_spheres(Spheres::new([(Vec3::ZERO, 1.0)]).unwrap())
            .unwrap();

        // Attaching a second geometry under the id the spheres already have is an invalid
        // operation; Embree reports it only through the error callback.
        // SAFETY: live device and scene; the new geometry is released once, and Embree refuses
        // to attach it, so the scene never references it.
        unsafe {
            let geom = sys::rtcNewGeometry(device.raw(), sys::RTC_GEOMETRY_TYPE_TRIANGLE);
            assert!(!geom.is_null());
            sys::rtcAttachGeometryByID(b.handle.0, geom, 0);
            sys::rtcReleaseGeometry(geom);
        }
        match device.check("attaching twice") {
            Err(EmbreeError::Embree { code, message }) => {
                assert_eq!(code, ErrorCode::InvalidOperation, "{message}");
                assert!(
                    message.starts_with("attaching twice: ") && message.contains("geometry ID"),
                    "Embree's own text should follow the call: {message:?}"
                );
            }
            other => panic!("expected Embree's InvalidOperation, got {other:?}"),
        }
        assert!(device.check("after").is_ok(), "the error is reported once");

        // Through the wrapper's own path: an unknown geometry type fails in rtcNewGeometry.
        let err = b
            .attach(
                Geometry::Spheres(Spheres::new([(Vec3::ONE, 1.0)]).unwrap()),
                9999,
                |_| panic!("no buffers are set when rtcNewGeometry fails"),
            )
            .unwrap_err();
        match err {
            EmbreeError::Embree { code, message } => {
                assert_eq!(code, ErrorCode::Unknown, "{message}");
                assert!(
                    message.starts_with("rtcNewGeometry: ") && message.contains("geometry type"),
                    "{message:?}"
                );
            }
            other => panic!("expected an Embree error, got {other}"),
        }
        // Neither error leaks into later calls: the builder still works.
        let scene = b.commit().unwrap();
        assert_eq!(scene.geometries().len(), 1);
        assert!(scene.occluded1(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)));
    }
}
