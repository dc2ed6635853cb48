//! Building and committing an Embree scene, then tracing rays against it from any thread.

use std::sync::Arc;

use glam::Vec3;

use super::device::{Device, EmbreeError, Result};
use super::filter::{self, FilterBox, HitFilter};
use super::geometry::{Geometry, GeometryId, Spheres, TriangleMesh};
use super::packet::{Hit, Ray, RayHint, RayPacket16, ShadowPacket16};
use super::{sys, version};

/// Embree's BVH build quality: a trade between build time and trace speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BuildQuality {
    /// `RTC_BUILD_QUALITY_LOW`: the fastest build, slower tracing.
    Low,
    /// `RTC_BUILD_QUALITY_MEDIUM`: Embree's default balance.
    #[default]
    Medium,
    /// `RTC_BUILD_QUALITY_HIGH`: a slower build for faster tracing.
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

/// How a 16-ray packet is handed to Embree.
///
/// Embree traces 16-wide packets natively only with AVX-512. Elsewhere `rtcIntersect16`
/// goes through its ray-stream fallback; `X8` and `X4` instead split the packet into
/// native 8- or 4-wide calls (pieces without an active lane are skipped). Every width traces
/// the same rays and finds the same hits; only the speed differs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PacketWidth {
    /// The fastest measured on the device's ISA. That is one 16-wide call everywhere: with
    /// AVX2 the ray-stream fallback traced the paper scene's coherent lens rays as fast as two
    /// native 8-wide calls and its shadow rays faster (`cargo bench --bench packets`, README).
    #[default]
    Auto,
    /// One 16-wide call (`rtcIntersect16` / `rtcOccluded16`).
    X16,
    /// 8-wide calls (`rtcIntersect8` / `rtcOccluded8`), one per half with an active lane.
    X8,
    /// 4-wide calls (`rtcIntersect4` / `rtcOccluded4`), one per quarter with an active lane.
    X4,
}

impl PacketWidth {
    /// The lanes per Embree call.
    pub fn lanes(self) -> u32 {
        match self {
            Self::Auto | Self::X16 => 16,
            Self::X8 => 8,
            Self::X4 => 4,
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
    /// The hit filters Embree's geometries point at (see `filter.rs`).
    filters: Vec<FilterBox>,
    device: Device,
    quality: BuildQuality,
}

// SAFETY: the builder exclusively owns its scene handle and geometry buffers; Embree allows a
// scene to be built from any thread as long as one thread at a time modifies it (&mut self).
unsafe impl Send for SceneBuilder {}

impl SceneBuilder {
    /// An empty scene on `device` (build quality [`BuildQuality::Medium`]).
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
            filters: Vec::new(),
            device: device.clone(),
            quality: BuildQuality::default(),
        })
    }

    /// Sets the BVH build quality of the geometries added after this call and of the commit.
    pub fn build_quality(mut self, quality: BuildQuality) -> Self {
        self.quality = quality;
        self
    }

    /// Adds a triangle mesh; its buffers are shared with Embree, not copied.
    pub fn add_mesh(&mut self, mesh: TriangleMesh) -> Result<GeometryId> {
        self.add_mesh_with(mesh, None)
    }

    /// Adds a triangle mesh whose candidate hits `filter` accepts or rejects, for nearest-hit
    /// and occlusion queries alike (holes in alpha-masked surfaces). Embree calls the filter
    /// during traversal; a mesh without one costs nothing extra.
    pub fn add_mesh_filtered(
        &mut self,
        mesh: TriangleMesh,
        filter: Arc<dyn HitFilter>,
    ) -> Result<GeometryId> {
        self.add_mesh_with(mesh, Some(filter))
    }

    fn add_mesh_with(
        &mut self,
        mesh: TriangleMesh,
        filter: Option<Arc<dyn HitFilter>>,
    ) -> Result<GeometryId> {
        let (vertices, vertex_count, indices, triangle_count) = mesh.raw_buffers();
        // Each buffer is padded by one element so Embree's 16-byte loads of the last item stay
        // in bounds.
        let buffers = [
            SharedBuffer {
                kind: sys::RTC_BUFFER_TYPE_VERTEX,
                format: sys::RTC_FORMAT_FLOAT3,
                data: vertices.cast(),
                stride: 12,
                count: vertex_count,
            },
            SharedBuffer {
                kind: sys::RTC_BUFFER_TYPE_INDEX,
                format: sys::RTC_FORMAT_UINT3,
                data: indices.cast(),
                stride: 12,
                count: triangle_count,
            },
        ];
        let kind = sys::RTC_GEOMETRY_TYPE_TRIANGLE;
        self.attach(Geometry::Mesh(mesh), kind, filter, &buffers)
    }

    /// Adds a set of analytic spheres (Embree's sphere point geometry).
    pub fn add_spheres(&mut self, spheres: Spheres) -> Result<GeometryId> {
        self.add_spheres_with(spheres, None)
    }

    /// Adds a set of analytic spheres whose candidate hits `filter` accepts or rejects, as
    /// [`SceneBuilder::add_mesh_filtered`] does for a mesh.
    pub fn add_spheres_filtered(
        &mut self,
        spheres: Spheres,
        filter: Arc<dyn HitFilter>,
    ) -> Result<GeometryId> {
        self.add_spheres_with(spheres, Some(filter))
    }

    fn add_spheres_with(
        &mut self,
        spheres: Spheres,
        filter: Option<Arc<dyn HitFilter>>,
    ) -> Result<GeometryId> {
        let (data, count) = spheres.raw_buffer();
        // float4 items are 16 bytes: Embree's loads stay in bounds without padding.
        let buffer = SharedBuffer {
            kind: sys::RTC_BUFFER_TYPE_VERTEX,
            format: sys::RTC_FORMAT_FLOAT4,
            data: data.cast(),
            stride: 16,
            count,
        };
        let kind = sys::RTC_GEOMETRY_TYPE_SPHERE_POINT;
        self.attach(Geometry::Spheres(spheres), kind, filter, &[buffer])
    }

    /// Creates a geometry of `kind`, shares `buffers` (which point into `geometry`) with
    /// Embree, installs `filter` (if any) for its candidate hits, and attaches it to the scene.
    fn attach(
        &mut self,
        geometry: Geometry,
        kind: sys::RTCGeometryType,
        filter: Option<Arc<dyn HitFilter>>,
        buffers: &[SharedBuffer],
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
        for b in buffers {
            // SAFETY: every buffer points into `geometry`, which this builder (then the Scene)
            // keeps until after the scene handle is released; its callers size and pad each
            // for Embree's loads; strides match the layouts.
            unsafe {
                sys::rtcSetSharedGeometryBuffer(
                    geom, b.kind, 0, b.format, b.data, 0, b.stride, b.count,
                );
            }
        }
        if let Some(filter) = filter {
            // SAFETY: geom is live and not yet committed; the box is kept in the builder, then
            // the Scene, whose field order drops it after the scene handle is released.
            self.filters.push(unsafe { filter::install(geom, filter) });
        }
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
        if let Err(e) = self.device.check("rtcCommitScene") {
            // A build that failed (out of memory: a worker thread or buffer refused) leaves
            // a TBB task group that was never waited on; releasing the scene destroys it, and
            // TBB answers with `missing_wait` thrown from a destructor: std::terminate, the
            // process aborts (seen under `ulimit -v 400000`). So the failed scene is leaked,
            // with everything it may still point at (its buffers, filters and device), and
            // the error returned: once per failed build, on the way to exiting.
            std::mem::forget(self);
            return Err(e);
        }
        let mut bounds = sys::RTCBounds::default();
        // SAFETY: committed scene; bounds is a valid, 16-byte aligned RTCBounds.
        unsafe { sys::rtcGetSceneBounds(self.handle.0, &mut bounds) };
        self.device.check("rtcGetSceneBounds")?;
        Ok(Scene {
            lanes_per_call: PacketWidth::Auto.lanes(),
            handle: self.handle,
            geometries: self.geometries,
            _filters: self.filters,
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
    /// Kept alive: filtered geometries' user data points into them.
    _filters: Vec<FilterBox>,
    /// Kept alive: the scene's error callback user pointer lives in it.
    device: Device,
    bounds: (Vec3, Vec3),
    /// 16, 8 or 4: the lanes per Embree call a 16-ray packet is traced with.
    lanes_per_call: u32,
}

// SAFETY: a committed RTCScene is immutable and Embree documents rtcIntersect*/rtcOccluded* on it
// as thread-safe; the Rust-side geometry is never mutated after commit (no &mut access exists),
// and the device is itself Send + Sync.
unsafe impl Send for Scene {}
// SAFETY: as above: all &Scene methods are queries on immutable data.
unsafe impl Sync for Scene {}

/// A buffer a geometry shares with Embree (slot 0 of its kind): `count` items of `stride`
/// bytes in `format` at `data`.
struct SharedBuffer {
    kind: sys::RTCBufferType,
    format: sys::RTCFormat,
    data: *const std::ffi::c_void,
    stride: usize,
    count: usize,
}

/// Hands a 16-ray packet to Embree in calls of the scene's width: the `version` function
/// `$f16` on the whole packet (its `$rays` field), else `$f8` or `$f4` on each part with an
/// active lane.
macro_rules! by_packet_width {
    ($scene:ident, $packet:ident, $hint:ident, $rays:ident, $f16:ident, $f8:ident, $f4:ident) => {{
        let (scene, coherent) = ($scene.handle.0, $hint == RayHint::Coherent);
        match $scene.lanes_per_call {
            16 => {
                // SAFETY: the scene is committed and alive for &self; the mask and packet are
                // 64-byte aligned by their types.
                unsafe { version::$f16(&$packet.valid, scene, &mut $packet.$rays, coherent) }
            }
            8 => $packet.for_each_part8(|valid, part| {
                // SAFETY: as above, with 32-byte aligned 8-wide types.
                unsafe { version::$f8(valid, scene, part, coherent) }
            }),
            _ => $packet.for_each_part4(|valid, part| {
                // SAFETY: as above, with 16-byte aligned 4-wide types.
                unsafe { version::$f4(valid, scene, part, coherent) }
            }),
        }
    }};
}

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

    /// The Rust-side data of every geometry, indexed by [`GeometryId`].
    pub fn geometries(&self) -> &[Geometry] {
        &self.geometries
    }

    /// Nearest hit of one ray (`None` too for a ray Embree cannot trace: see
    /// [`Ray::is_traceable`]).
    pub fn intersect1(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_traceable() {
            return None;
        }
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

    /// True when anything blocks the ray within `[tnear, tfar]` (false for a ray Embree cannot
    /// trace).
    pub fn occluded1(&self, ray: &Ray) -> bool {
        if !ray.is_traceable() {
            return false;
        }
        let mut raw = raw_ray(ray);
        // SAFETY: the scene is committed and alive for &self; raw is a valid RTCRay.
        unsafe { version::occluded1(self.handle.0, &mut raw, false) };
        raw.tfar == f32::NEG_INFINITY
    }

    /// The device the scene was built on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The lanes per Embree call (16, 8 or 4) this scene traces its 16-ray packets with.
    pub fn lanes_per_call(&self) -> u32 {
        self.lanes_per_call
    }

    /// Chooses how 16-ray packets are handed to Embree (a new scene uses
    /// [`PacketWidth::Auto`], the device's native width). Images do not depend on it.
    pub fn set_packet_width(&mut self, width: PacketWidth) {
        self.lanes_per_call = width.lanes();
    }

    /// Traces the active lanes of a packet; the hits of inactive lanes are not written.
    pub fn intersect16(&self, packet: &mut RayPacket16, hint: RayHint) {
        by_packet_width!(
            self,
            packet,
            hint,
            rayhit,
            intersect16,
            intersect8,
            intersect4
        );
    }

    /// Tests the active lanes of a shadow packet for occlusion.
    pub fn occluded16(&self, packet: &mut ShadowPacket16, hint: RayHint) {
        by_packet_width!(self, packet, hint, rays, occluded16, occluded8, occluded4);
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

    /// A native device and one limited to each narrower ISA this CPU has, each scene traced
    /// with every packet width: every kernel path Embree can take on this machine.
    fn every_path() -> Vec<(String, Scene)> {
        let mut devices = vec![("native".to_string(), Device::with_config("").unwrap())];
        for isa in crate::embree::limited_isas() {
            devices.push((
                isa.into(),
                Device::with_config(&format!("isa={isa}")).unwrap(),
            ));
        }
        let mut paths = Vec::new();
        for (isa, device) in devices {
            for width in [PacketWidth::X16, PacketWidth::X8, PacketWidth::X4] {
                let mut scene = quad_scene(&device);
                scene.set_packet_width(width);
                paths.push((format!("isa {isa}, {width:?}"), scene));
            }
        }
        paths
    }

    /// Writes recognisable values into every hit field of `lane`.
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

    /// A caller fills every lane with a ray that hits, then deactivates some. On every path
    /// (Embree's ray-stream fallback for 16-wide calls without AVX-512 ignores the valid mask
    /// and traces any lane with tnear <= tfar) the deactivated lanes must not be written.
    #[test]
    fn intersect16_writes_no_field_of_an_inactive_lane() {
        for (path, scene) in every_path() {
            for hint in [RayHint::Coherent, RayHint::Incoherent] {
                let mut packet = RayPacket16::new();
                for lane in 0..LANES {
                    packet.set(lane, &lane_ray(lane));
                    // Tracing this lane would write every field: its ray hits the quad.
                    let would = scene.intersect1(&lane_ray(lane));
                    assert!(
                        would.is_some_and(|h| h.geometry == GeometryId(0)),
                        "{path}, {hint:?} lane {lane}: {would:?}"
                    );
                }
                for lane in INACTIVE {
                    fill_sentinels(&mut packet.rayhit, lane);
                    packet.set_inactive(lane);
                    let idle = packet.ray(lane);
                    assert!(
                        idle.tnear > idle.tfar && idle.origin.is_finite() && idle.dir.is_finite(),
                        "{idle:?}"
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
                        "{path}, {hint:?}: inactive lane {lane} was written"
                    );
                    assert_eq!(packet.hit(lane), None);
                }
                for lane in (0..LANES).filter(|l| !INACTIVE.contains(l)) {
                    // (The triangle may differ: some rays hit the quad's diagonal.)
                    let (wide, single) = (packet.hit(lane), scene.intersect1(&lane_ray(lane)));
                    assert!(
                        matches!((wide, single), (Some(w), Some(s))
                            if w.geometry == s.geometry && (w.t - s.t).abs() < 1e-5),
                        "{path}, {hint:?}: active lane {lane}: {wide:?} vs {single:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn occluded16_writes_no_field_of_an_inactive_lane() {
        for (path, scene) in every_path() {
            for hint in [RayHint::Coherent, RayHint::Incoherent] {
                let mut packet = ShadowPacket16::new();
                for lane in 0..LANES {
                    packet.set(lane, &lane_ray(lane));
                    assert!(scene.occluded1(&lane_ray(lane)), "lane {lane} is blocked");
                }
                for lane in INACTIVE {
                    packet.set_inactive(lane);
                }
                let idle: Vec<_> = INACTIVE.iter().map(|&lane| packet.ray(lane)).collect();
                scene.occluded16(&mut packet, hint);
                for lane in 0..LANES {
                    if let Some(i) = INACTIVE.iter().position(|&l| l == lane) {
                        assert_eq!(packet.ray(lane), idle[i], "{path}, {hint:?}: lane {lane}");
                        assert!(!packet.occluded(lane));
                    } else {
                        assert!(packet.occluded(lane), "{path}, {hint:?}: lane {lane}");
                    }
                }
            }
        }
    }

    /// Lanes that are never activated (a fresh packet, `clear`, bulk fills) are idle too.
    #[test]
    fn every_way_of_deactivating_a_lane_leaves_an_empty_finite_segment() {
        let empty = |ray: Ray| {
            ray.tnear > ray.tfar
                && ray.origin.is_finite()
                && ray.dir.is_finite()
                && ray.tnear.is_finite()
        };
        let mut packet = RayPacket16::new();
        assert!((0..LANES).all(|l| empty(packet.ray(l))));
        packet.set(3, &lane_ray(3));
        packet.clear();
        assert!((0..LANES).all(|l| empty(packet.ray(l))));
        let nan = [[f32::NAN; LANES]; 3];
        packet.set_lanes(5, &nan, &nan);
        assert!((5..LANES).all(|l| empty(packet.ray(l))));
        let mut shadow = ShadowPacket16::new();
        assert!((0..LANES).all(|l| empty(shadow.ray(l))));
        shadow.set_segments(0b101, &nan, &nan, &[f32::NAN; LANES]);
        assert!(
            (0..LANES)
                .filter(|l| ![0, 2].contains(l))
                .all(|l| empty(shadow.ray(l)))
        );
        shadow.clear();
        assert!((0..LANES).all(|l| empty(shadow.ray(l))));
    }

    /// Rejects every hit on triangle `reject`; panics on `panic_on`.
    struct TestFilter {
        reject: u32,
        panic_on: u32,
    }

    impl HitFilter for TestFilter {
        fn accept(&self, hit: &crate::embree::CandidateHit) -> bool {
            assert!(hit.prim != self.panic_on, "a panicking filter");
            hit.prim != self.reject
        }
    }

    /// The quad of `quad_scene` with a filter, and a second quad behind it at z = 4.
    fn filtered_scene(device: &Device, filter: TestFilter) -> Scene {
        let quad = |z: f32| {
            TriangleMesh::new(
                vec![
                    [-10.0, -10.0, z],
                    [10.0, -10.0, z],
                    [10.0, 10.0, z],
                    [-10.0, 10.0, z],
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            )
            .unwrap()
        };
        let mut b = SceneBuilder::new(device).unwrap();
        b.add_mesh_filtered(quad(2.0), Arc::new(filter)).unwrap();
        b.add_mesh(quad(4.0)).unwrap();
        b.commit().unwrap()
    }

    /// Hit filters run on every kernel path and packet width, for nearest-hit and occlusion
    /// queries: a rejected triangle lets rays through to what is behind it; a filter that
    /// panics accepts the hit (and the panic does not cross into Embree).
    #[test]
    fn hit_filters_reject_hits_and_survive_panics() {
        let mut devices = vec![Device::with_config("").unwrap()];
        for isa in crate::embree::limited_isas() {
            devices.push(Device::with_config(&format!("isa={isa}")).unwrap());
        }
        for device in &devices {
            for width in [PacketWidth::X16, PacketWidth::X8, PacketWidth::X4] {
                // Triangle 0 ([0, 1, 2]) covers x > y; triangle 1 panics.
                let filter = TestFilter {
                    reject: 0,
                    panic_on: 1,
                };
                let mut scene = filtered_scene(device, filter);
                scene.set_packet_width(width);
                let mut packet = RayPacket16::new();
                let mut shadow = ShadowPacket16::new();
                let mut expected = [0.0f32; LANES];
                for (lane, e) in expected.iter_mut().enumerate() {
                    let ray = lane_ray(lane);
                    packet.set(lane, &ray);
                    let p = ray.at(2.0 / ray.dir.z);
                    // Through the rejected triangle to the quad behind, else the first quad.
                    let through = p.x > p.y + 1e-3;
                    *e = if through { 4.0 } else { 2.0 };
                    if (p.x - p.y).abs() < 1e-3 {
                        *e = f32::NAN; // on the diagonal: either
                    }
                    // A shadow segment ending before the back quad: blocked unless through.
                    shadow.set(
                        lane,
                        &Ray::segment(ray.origin, ray.dir, 0.0, 3.0 / ray.dir.z),
                    );
                }
                scene.intersect16(&mut packet, RayHint::Coherent);
                scene.occluded16(&mut shadow, RayHint::Coherent);
                for (lane, &e) in expected.iter().enumerate() {
                    if e.is_nan() {
                        continue;
                    }
                    let hit = packet.hit(lane).expect("every lane hits a quad");
                    let z = lane_ray(lane).at(hit.t).z;
                    assert!(
                        (z - e).abs() < 1e-3,
                        "{width:?} lane {lane}: z {z}, not {e}"
                    );
                    assert_eq!(shadow.occluded(lane), e == 2.0, "{width:?} lane {lane}");
                    let single = scene.intersect1(&lane_ray(lane)).unwrap();
                    assert!((lane_ray(lane).at(single.t).z - e).abs() < 1e-3);
                }
            }
        }
    }

    /// Rejects camera rays only (a surface hidden from the camera).
    struct CameraFilter;

    impl HitFilter for CameraFilter {
        fn accept(&self, hit: &crate::embree::CandidateHit) -> bool {
            !hit.camera
        }
    }

    /// Filters see which rays are camera rays on every kernel path and packet width: a packet
    /// marked as camera rays passes through a surface that hides from the camera, the same
    /// rays unmarked (and single rays) hit it.
    #[test]
    fn hit_filters_see_camera_rays() {
        let mut devices = vec![Device::with_config("").unwrap()];
        for isa in crate::embree::limited_isas() {
            devices.push(Device::with_config(&format!("isa={isa}")).unwrap());
        }
        let quad = |z: f32| {
            TriangleMesh::new(
                vec![
                    [-10.0, -10.0, z],
                    [10.0, -10.0, z],
                    [10.0, 10.0, z],
                    [-10.0, 10.0, z],
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            )
            .unwrap()
        };
        for device in &devices {
            let mut b = SceneBuilder::new(device).unwrap();
            b.add_mesh_filtered(quad(2.0), Arc::new(CameraFilter))
                .unwrap();
            b.add_mesh(quad(4.0)).unwrap();
            let mut scene = b.commit().unwrap();
            for width in [PacketWidth::X16, PacketWidth::X8, PacketWidth::X4] {
                scene.set_packet_width(width);
                for camera in [true, false] {
                    let mut packet = RayPacket16::new();
                    for lane in 0..LANES {
                        packet.set(lane, &lane_ray(lane));
                    }
                    packet.set_camera(camera);
                    scene.intersect16(&mut packet, RayHint::Coherent);
                    let expected = if camera { 4.0 } else { 2.0 };
                    for lane in 0..LANES {
                        let hit = packet.hit(lane).expect("every lane hits a quad");
                        let z = lane_ray(lane).at(hit.t).z;
                        assert!((z - expected).abs() < 1e-3, "{width:?} {camera}: z {z}");
                    }
                }
                let single = scene.intersect1(&lane_ray(0)).unwrap();
                assert!((lane_ray(0).at(single.t).z - 2.0).abs() < 1e-3);
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
                None,
                &[],
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
