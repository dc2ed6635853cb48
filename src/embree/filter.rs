//! Hit filters: safe Rust callbacks that Embree asks, for every candidate hit on a geometry,
//! whether the hit counts (alpha-masked and stochastically transparent surfaces).
//!
//! Embree 3 and 4 declare `RTCFilterFunctionNArguments` with the same fields this module
//! reads (`valid`, `geometryUserPtr`, `ray`, `hit`, `N`; only the type of `context`, which is
//! not read, differs), the same SoA layouts of `RTCRayN` / `RTCHitN`, and the same
//! `rtcSetGeometryIntersectFilterFunction` / `rtcSetGeometryOccludedFilterFunction` /
//! `rtcSetGeometryUserData`, so nothing here depends on the version. Embree 4 invokes geometry
//! filters when the query's feature mask includes them, which `RTC_FEATURE_FLAG_ALL` (see
//! `version.rs`) does.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;

use glam::Vec3;

use super::sys;

/// A hit Embree found and asks about, before it becomes the ray's hit (or blocks a shadow ray).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CandidateHit {
    /// The ray's origin, world space.
    pub origin: Vec3,
    /// The ray's direction, as traced.
    pub dir: Vec3,
    /// Triangle index in the mesh.
    pub prim: u32,
    /// Barycentric coordinates (Embree's u, v): the hit is `(1 - u - v) p0 + u p1 + v p2`.
    pub u: f32,
    /// Second barycentric coordinate (Embree's v).
    pub v: f32,
    /// True for an occlusion (shadow) query, false for a nearest-hit query.
    pub shadow: bool,
    /// True for a camera ray ([`RayPacket16::set_camera`](super::RayPacket16::set_camera)).
    pub camera: bool,
}

/// Decides whether candidate hits count. Called by Embree during traversal, from any thread
/// that traces, possibly several times for one ray and primitive: answers must depend on the
/// candidate alone (never on call order) for renders to be deterministic. A panic inside
/// `accept` is caught and counts as accepting the hit.
pub trait HitFilter: Send + Sync {
    /// Whether `hit` counts; `false` lets the ray pass through (a hole).
    fn accept(&self, hit: &CandidateHit) -> bool;
}

/// What a filtered geometry's user data pointer points at. Boxed, so its address stays put
/// while the scene (which owns the box) moves; dropped after the Embree scene is released.
pub(super) type FilterBox = Box<Arc<dyn HitFilter>>;

/// Installs `filter` on `geom` for nearest-hit and occlusion queries, and returns the box the
/// caller must keep alive for as long as Embree may trace the geometry.
///
/// # Safety
/// `geom` must be a live geometry that is not yet committed, and the returned box must outlive
/// every query on any scene the geometry is attached to.
pub(super) unsafe fn install(geom: sys::RTCGeometry, filter: Arc<dyn HitFilter>) -> FilterBox {
    let boxed: FilterBox = Box::new(filter);
    let user = (&*boxed as *const Arc<dyn HitFilter>).cast_mut().cast();
    // SAFETY: the caller guarantees a live, uncommitted geometry; `user` points into a heap box
    // the caller keeps alive for as long as the geometry is traced; the callbacks match
    // RTCFilterFunctionN's signature.
    unsafe {
        sys::rtcSetGeometryUserData(geom, user);
        sys::rtcSetGeometryIntersectFilterFunction(geom, Some(intersect_filter));
        sys::rtcSetGeometryOccludedFilterFunction(geom, Some(occluded_filter));
    }
    boxed
}

unsafe extern "C" fn intersect_filter(args: *const sys::RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments for the duration of the call.
    unsafe { run_filter(args, false) }
}

unsafe extern "C" fn occluded_filter(args: *const sys::RTCFilterFunctionNArguments) {
    // SAFETY: as above.
    unsafe { run_filter(args, true) }
}

/// Reads each valid lane's candidate hit and clears its `valid` entry when the filter rejects
/// it. Never unwinds: a panicking filter accepts the hit.
///
/// # Safety
/// `args` must be the arguments Embree passes to a filter callback of a geometry installed by
/// [`install`] (its user pointer a live `Arc<dyn HitFilter>`).
unsafe fn run_filter(args: *const sys::RTCFilterFunctionNArguments, shadow: bool) {
    if args.is_null() {
        return;
    }
    // SAFETY: non-null, and Embree keeps the arguments valid for the duration of the call.
    let args = unsafe { &*args };
    let n = args.N as usize;
    if n == 0 || args.valid.is_null() || args.geometryUserPtr.is_null() {
        return;
    }
    // SAFETY: the user pointer is the Arc boxed by `install`, which the scene keeps alive
    // while it can be traced; only shared access is taken.
    let filter = unsafe { &*(args.geometryUserPtr as *const Arc<dyn HitFilter>) };
    // SAFETY: `valid` holds N ints that the filter may write (Embree's documented contract).
    let valid = unsafe { std::slice::from_raw_parts_mut(args.valid, n) };
    let ray = args.ray as *const f32;
    let hit = args.hit as *const f32;
    // RTCRayN: org_x, org_y, org_z, tnear, dir_x, dir_y, dir_z, time, tfar, mask, id, ... each
    // N 4-byte values (SoA);
    // RTCHitN: Ng_x, Ng_y, Ng_z, u, v, primID, ... likewise (RTCRayN_* / RTCHitN_* helpers
    // of rtcore_ray.h in both Embree 3 and 4).
    if ray.is_null() || hit.is_null() {
        return;
    }
    let ray_at = |row: usize, i: usize| {
        // SAFETY: Embree's ray packets hold 11 rows of N 4-byte values (org, tnear, dir, time,
        // tfar, mask, id; i < N, row < 11); id is read as the bits of an f32.
        unsafe { *ray.add(row * n + i) }
    };
    let hit_at = |row: usize, i: usize| {
        // SAFETY: Embree's hit packets hold at least 6 rows of N 4-byte values (i < N,
        // row < 6); primID is read as the bits of an f32.
        unsafe { *hit.add(row * n + i) }
    };
    for (i, v) in valid.iter_mut().enumerate() {
        if *v == 0 {
            continue;
        }
        let candidate = CandidateHit {
            origin: Vec3::new(ray_at(0, i), ray_at(1, i), ray_at(2, i)),
            dir: Vec3::new(ray_at(4, i), ray_at(5, i), ray_at(6, i)),
            prim: hit_at(5, i).to_bits(),
            u: hit_at(3, i),
            v: hit_at(4, i),
            shadow,
            camera: ray_at(10, i).to_bits() & super::packet::CAMERA_RAY != 0,
        };
        let accept = catch_unwind(AssertUnwindSafe(|| filter.accept(&candidate))).unwrap_or(true);
        if !accept {
            *v = 0;
        }
    }
}
