//! Rays, hits and 16-wide structure-of-arrays ray packets in Embree's own layout.

use glam::Vec3;

use super::geometry::GeometryId;
use super::sys;

/// Number of rays in a packet.
pub const LANES: usize = 16;

/// A ray segment `origin + t * dir` for `t` in `[tnear, tfar]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tnear: f32,
    pub tfar: f32,
}

impl Ray {
    /// A ray from `origin` along `dir` with no far limit.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            tnear: 0.0,
            tfar: f32::INFINITY,
        }
    }

    /// A ray limited to `t` in `[tnear, tfar]`.
    pub fn segment(origin: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> Self {
        Self {
            origin,
            dir,
            tnear,
            tfar,
        }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The nearest hit of a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (a distance when `dir` is unit length).
    pub t: f32,
    pub geometry: GeometryId,
    /// Triangle index in a mesh, sphere index in a sphere set.
    pub prim: u32,
    /// Barycentric coordinates for triangles (Embree's u, v); unspecified for spheres.
    pub u: f32,
    pub v: f32,
    /// Unnormalised geometric normal as Embree reports it.
    pub ng: Vec3,
}

/// Whether a packet's rays are coherent (primary rays, lens samples of one pixel) or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayHint {
    Coherent,
    Incoherent,
}

/// Embree's lane mask: -1 is active, 0 inactive. 64-byte aligned as rtcIntersect16 requires.
#[repr(C, align(64))]
#[derive(Clone, Copy)]
pub(super) struct Mask16(pub(super) [i32; LANES]);

// rtcIntersect16 / rtcOccluded16 require the mask and the packets to be 64-byte aligned (the
// bindgen types carry the header's alignment). Checked at compile time, so an Embree header or
// bindgen change that lost it cannot turn into unaligned AVX-512 loads.
const _: () = assert!(
    std::mem::align_of::<Mask16>() == 64
        && std::mem::size_of::<Mask16>() == 64
        && std::mem::align_of::<sys::RTCRayHit16>() == 64
        && std::mem::align_of::<sys::RTCRay16>() == 64
        && std::mem::align_of::<sys::RTCHit16>() == 64
);

fn init_ray(raw: &mut sys::RTCRay16, lane: usize, ray: &Ray) {
    raw.org_x[lane] = ray.origin.x;
    raw.org_y[lane] = ray.origin.y;
    raw.org_z[lane] = ray.origin.z;
    raw.dir_x[lane] = ray.dir.x;
    raw.dir_y[lane] = ray.dir.y;
    raw.dir_z[lane] = ray.dir.z;
    raw.tnear[lane] = ray.tnear;
    raw.tfar[lane] = ray.tfar;
    raw.time[lane] = 0.0;
    raw.mask[lane] = u32::MAX;
    raw.id[lane] = lane as u32;
    raw.flags[lane] = 0;
}

/// Gives every inactive lane of a bulk-filled packet a harmless finite ray (origin 0,
/// direction +z, an empty segment), whatever the caller's arrays held there. Without AVX-512,
/// Embree runs 16-wide queries as 8- or 4-wide pieces whose input checks assert on non-finite
/// rays in inactive lanes too (callers fill all lanes, and unused ones may hold NaN).
fn idle_inactive_lanes(raw: &mut sys::RTCRay16, valid: &Mask16) {
    let idle = valid.0.map(|v| v == 0);
    let keep = |x: &mut [f32; LANES], idle_value: f32| {
        for (x, &idle) in x.iter_mut().zip(&idle) {
            *x = if idle { idle_value } else { *x };
        }
    };
    keep(&mut raw.org_x, 0.0);
    keep(&mut raw.org_y, 0.0);
    keep(&mut raw.org_z, 0.0);
    keep(&mut raw.dir_x, 0.0);
    keep(&mut raw.dir_y, 0.0);
    keep(&mut raw.dir_z, 1.0);
    keep(&mut raw.tfar, 0.0);
}

fn read_ray(raw: &sys::RTCRay16, lane: usize) -> Ray {
    Ray {
        origin: Vec3::new(raw.org_x[lane], raw.org_y[lane], raw.org_z[lane]),
        dir: Vec3::new(raw.dir_x[lane], raw.dir_y[lane], raw.dir_z[lane]),
        tnear: raw.tnear[lane],
        tfar: raw.tfar[lane],
    }
}

/// 16 rays and their hits, structure-of-arrays, 64-byte aligned, with a valid mask.
/// Build one per thread and reuse it: `set` overwrites a lane, `clear` deactivates all lanes.
#[derive(Clone)]
pub struct RayPacket16 {
    pub(super) rayhit: sys::RTCRayHit16,
    pub(super) valid: Mask16,
}

impl Default for RayPacket16 {
    fn default() -> Self {
        Self::new()
    }
}

impl RayPacket16 {
    /// A packet with every lane inactive.
    pub fn new() -> Self {
        Self {
            rayhit: sys::RTCRayHit16::default(),
            valid: Mask16([0; LANES]),
        }
    }

    /// Deactivates every lane (their data is left as it was).
    pub fn clear(&mut self) {
        self.valid.0 = [0; LANES];
    }

    /// Activates `lane` with `ray` and no hit.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set(&mut self, lane: usize, ray: &Ray) {
        init_ray(&mut self.rayhit.ray, lane, ray);
        let hit = &mut self.rayhit.hit;
        hit.geomID[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        hit.primID[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        for level in hit.instID.iter_mut() {
            level[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        }
        self.valid.0[lane] = -1;
    }

    /// Fills every lane from structure-of-arrays origins and directions (x, y, z components)
    /// with `tnear` 0, no far limit and no hit, and activates lanes `0..active` (the others
    /// are inactive and get an idle finite ray, whatever `origin` and `dir` hold there). Equal
    /// to `clear` then `set` of each active lane.
    /// An `active` above 16 activates every lane.
    pub fn set_lanes(
        &mut self,
        active: usize,
        origin: &[[f32; LANES]; 3],
        dir: &[[f32; LANES]; 3],
    ) {
        let raw = &mut self.rayhit.ray;
        raw.org_x = origin[0];
        raw.org_y = origin[1];
        raw.org_z = origin[2];
        raw.dir_x = dir[0];
        raw.dir_y = dir[1];
        raw.dir_z = dir[2];
        raw.tnear = [0.0; LANES];
        raw.tfar = [f32::INFINITY; LANES];
        raw.time = [0.0; LANES];
        raw.mask = [u32::MAX; LANES];
        raw.id = std::array::from_fn(|lane| lane as u32);
        raw.flags = [0; LANES];
        let hit = &mut self.rayhit.hit;
        hit.geomID = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        hit.primID = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        for level in hit.instID.iter_mut() {
            *level = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        }
        self.valid.0 = std::array::from_fn(|lane| if lane < active { -1 } else { 0 });
        idle_inactive_lanes(raw, &self.valid);
    }

    /// Ray origins of all lanes as structure of arrays (x, y, z).
    pub fn origins(&self) -> [&[f32; LANES]; 3] {
        let r = &self.rayhit.ray;
        [&r.org_x, &r.org_y, &r.org_z]
    }

    /// Ray directions of all lanes as structure of arrays (x, y, z).
    pub fn dirs(&self) -> [&[f32; LANES]; 3] {
        let r = &self.rayhit.ray;
        [&r.dir_x, &r.dir_y, &r.dir_z]
    }

    /// `tfar` of all lanes (after tracing: the hit distance of lanes that hit).
    pub fn tfars(&self) -> &[f32; LANES] {
        &self.rayhit.ray.tfar
    }

    /// Unnormalised geometric normals of all lanes as structure of arrays (x, y, z); only
    /// meaningful in lanes that hit.
    pub fn geometric_normals(&self) -> [&[f32; LANES]; 3] {
        let h = &self.rayhit.hit;
        [&h.Ng_x, &h.Ng_y, &h.Ng_z]
    }

    /// Bit `i` set: lane `i` is active and its ray hit something.
    pub fn hit_mask(&self) -> u32 {
        let h = &self.rayhit.hit;
        let mut mask = 0;
        for lane in 0..LANES {
            if self.valid.0[lane] != 0 && h.geomID[lane] != sys::RTC_INVALID_GEOMETRY_ID {
                mask |= 1 << lane;
            }
        }
        mask
    }

    /// Deactivates one lane; Embree will neither read nor write it.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set_inactive(&mut self, lane: usize) {
        self.valid.0[lane] = 0;
    }

    /// Whether `lane` will be traced.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn is_active(&self, lane: usize) -> bool {
        self.valid.0[lane] != 0
    }

    /// Number of active lanes.
    pub fn active_count(&self) -> usize {
        self.valid.0.iter().filter(|&&v| v != 0).count()
    }

    /// The ray in `lane` (after tracing, `tfar` is the hit distance when it hit).
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn ray(&self, lane: usize) -> Ray {
        read_ray(&self.rayhit.ray, lane)
    }

    /// The hit in `lane`, or `None` when the lane is inactive or its ray missed.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn hit(&self, lane: usize) -> Option<Hit> {
        let h = &self.rayhit.hit;
        if !self.is_active(lane) || h.geomID[lane] == sys::RTC_INVALID_GEOMETRY_ID {
            return None;
        }
        Some(Hit {
            t: self.rayhit.ray.tfar[lane],
            geometry: GeometryId(h.geomID[lane]),
            prim: h.primID[lane],
            u: h.u[lane],
            v: h.v[lane],
            ng: Vec3::new(h.Ng_x[lane], h.Ng_y[lane], h.Ng_z[lane]),
        })
    }
}

/// 16 shadow (occlusion) rays, structure-of-arrays, 64-byte aligned, with a valid mask.
#[derive(Clone)]
pub struct ShadowPacket16 {
    pub(super) rays: sys::RTCRay16,
    pub(super) valid: Mask16,
}

impl Default for ShadowPacket16 {
    fn default() -> Self {
        Self::new()
    }
}

impl ShadowPacket16 {
    /// A packet with every lane inactive.
    pub fn new() -> Self {
        Self {
            rays: sys::RTCRay16::default(),
            valid: Mask16([0; LANES]),
        }
    }

    /// Deactivates every lane (their data is left as it was).
    pub fn clear(&mut self) {
        self.valid.0 = [0; LANES];
    }

    /// Activates `lane` with the shadow ray `ray`.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set(&mut self, lane: usize, ray: &Ray) {
        init_ray(&mut self.rays, lane, ray);
        self.valid.0[lane] = -1;
    }

    /// Fills every lane with the segment from `origin` along `dir` for `t` in `[0, tfar]`
    /// (structure of arrays) and activates the lanes whose bit is set in `active`; the others
    /// get an idle finite ray, whatever the arrays hold there (NaN included). Equal to `clear`
    /// then `set` of each active lane.
    pub fn set_segments(
        &mut self,
        active: u32,
        origin: &[[f32; LANES]; 3],
        dir: &[[f32; LANES]; 3],
        tfar: &[f32; LANES],
    ) {
        let raw = &mut self.rays;
        raw.org_x = origin[0];
        raw.org_y = origin[1];
        raw.org_z = origin[2];
        raw.dir_x = dir[0];
        raw.dir_y = dir[1];
        raw.dir_z = dir[2];
        raw.tnear = [0.0; LANES];
        raw.tfar = *tfar;
        raw.time = [0.0; LANES];
        raw.mask = [u32::MAX; LANES];
        raw.id = std::array::from_fn(|lane| lane as u32);
        raw.flags = [0; LANES];
        self.valid.0 = std::array::from_fn(|lane| -(((active >> lane) & 1) as i32));
        idle_inactive_lanes(raw, &self.valid);
    }

    /// Deactivates one lane; Embree will neither read nor write it.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set_inactive(&mut self, lane: usize) {
        self.valid.0[lane] = 0;
    }

    /// Whether `lane` will be traced.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn is_active(&self, lane: usize) -> bool {
        self.valid.0[lane] != 0
    }

    /// Number of active lanes.
    pub fn active_count(&self) -> usize {
        self.valid.0.iter().filter(|&&v| v != 0).count()
    }

    /// The shadow ray in `lane` (after tracing, `tfar` is -inf when it was blocked).
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn ray(&self, lane: usize) -> Ray {
        read_ray(&self.rays, lane)
    }

    /// True when the active ray in `lane` is blocked (Embree sets its `tfar` to -inf).
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn occluded(&self, lane: usize) -> bool {
        self.is_active(lane) && self.rays.tfar[lane] == f32::NEG_INFINITY
    }
}
