//! Rays, hits and 16-wide structure-of-arrays ray packets in Embree's own layout.

use glam::Vec3;

use super::geometry::GeometryId;
use super::sys;

/// Number of rays in a packet.
pub const LANES: usize = 16;

/// A ray segment `origin + t * dir` for `t` in `[tnear, tfar]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point, world space.
    pub origin: Vec3,
    /// Direction (not necessarily unit length; `t` is measured in multiples of it).
    pub dir: Vec3,
    /// Smallest ray parameter that counts as a hit.
    pub tnear: f32,
    /// Largest ray parameter that counts as a hit (infinity for none).
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

    /// The point at ray parameter `t`: `origin + t * dir`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The nearest hit of a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (a distance when `dir` is unit length).
    pub t: f32,
    /// The geometry hit.
    pub geometry: GeometryId,
    /// Triangle index in a mesh, sphere index in a sphere set.
    pub prim: u32,
    /// Barycentric coordinates for triangles (Embree's u, v); unspecified for spheres.
    pub u: f32,
    /// Second barycentric coordinate (Embree's v), as `u`.
    pub v: f32,
    /// Unnormalised geometric normal as Embree reports it.
    pub ng: Vec3,
}

impl Hit {
    /// Whether the hit is on the front of its surface for a ray along `dir`: the side a
    /// triangle's winding order faces, a sphere's outside (where Embree's geometric normal
    /// `ng` points, in Embree 3 and 4 alike).
    pub fn is_front(&self, dir: Vec3) -> bool {
        self.ng.dot(dir) < 0.0
    }
}

/// Whether a packet's rays are coherent (primary rays, lens samples of one pixel) or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayHint {
    /// Rays of a packet start near each other and point alike (Embree's coherent flag).
    Coherent,
    /// Rays go their own ways (secondary rays; Embree's incoherent flag).
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

/// Embree's bound on ray origin and direction components (`FLT_LARGE`); its ray checks
/// (asserted in Debian's build, a process abort) reject anything larger, NaN or infinite.
const EMBREE_LARGE: f32 = 1.844e18;

/// Whether Embree accepts the ray: origin and direction components finite and within
/// [`EMBREE_LARGE`], `tnear` and `tfar` not NaN.
fn embree_accepts(origin: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> bool {
    let small = |x: f32| x.abs() <= EMBREE_LARGE;
    origin.iter().chain(&dir).all(|&x| small(x)) && !tnear.is_nan() && !tfar.is_nan()
}

impl Ray {
    /// Whether Embree can trace this ray (see [`RayPacket16::set`]).
    pub fn is_traceable(&self) -> bool {
        embree_accepts(
            self.origin.to_array(),
            self.dir.to_array(),
            self.tnear,
            self.tfar,
        )
    }
}

/// The lanes (bit per lane) among `lanes` whose rays Embree accepts.
fn traceable_lanes(raw: &sys::RTCRay16, lanes: u32) -> u32 {
    let mut ok = 0;
    for lane in (0..LANES).filter(|&l| lanes & (1 << l) != 0) {
        let origin = [raw.org_x[lane], raw.org_y[lane], raw.org_z[lane]];
        let dir = [raw.dir_x[lane], raw.dir_y[lane], raw.dir_z[lane]];
        if embree_accepts(origin, dir, raw.tnear[lane], raw.tfar[lane]) {
            ok |= 1 << lane;
        }
    }
    ok
}

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

/// The ray every inactive lane holds: finite, with an empty segment (`tnear` 1 > `tfar` 0).
///
/// Embree has two conventions for an inactive lane, and a lane must be inactive under both:
/// its native 16-wide kernels (AVX-512) skip lanes whose valid-mask entry is 0, but on CPUs
/// without them `rtcIntersect16` / `rtcOccluded16` hand the packet to Embree's ray-stream
/// fallback, which ignores the mask and traces every lane with `tnear <= tfar`. Its 8- and
/// 4-wide kernels also assert that every ray they are given is finite. This is the one place
/// that makes a lane inactive; every path that deactivates lanes goes through it.
fn idle_lanes(raw: &mut sys::RTCRay16, idle: u32) {
    if idle & ((1 << LANES) - 1) == 0 {
        return;
    }
    // A select on every lane, not a store under a branch: it compiles to blends (a
    // branch per lane and field cost 5% of a path-traced render's time).
    let put = |x: &mut [f32; LANES], value: f32| {
        for (lane, x) in x.iter_mut().enumerate() {
            *x = if (idle >> lane) & 1 != 0 { value } else { *x };
        }
    };
    put(&mut raw.org_x, 0.0);
    put(&mut raw.org_y, 0.0);
    put(&mut raw.org_z, 0.0);
    put(&mut raw.dir_x, 0.0);
    put(&mut raw.dir_y, 0.0);
    put(&mut raw.dir_z, 1.0);
    put(&mut raw.tnear, 1.0);
    put(&mut raw.tfar, 0.0);
}

/// Bit `i` set: lane `i` of `valid` is active.
fn active_bits(valid: &Mask16) -> u32 {
    let mut bits = 0;
    for (lane, &v) in valid.0.iter().enumerate() {
        bits |= ((v != 0) as u32) << lane;
    }
    bits
}

/// Embree's 8- and 4-wide lane masks, aligned as rtcIntersect8/4 require.
#[repr(C, align(32))]
#[derive(Clone, Copy, Default)]
pub(super) struct Mask8(pub(super) [i32; 8]);
#[repr(C, align(16))]
#[derive(Clone, Copy, Default)]
pub(super) struct Mask4(pub(super) [i32; 4]);

const _: () = assert!(
    std::mem::align_of::<Mask8>() == 32
        && std::mem::align_of::<sys::RTCRayHit8>() == 32
        && std::mem::align_of::<sys::RTCRay8>() == 32
        && std::mem::align_of::<Mask4>() == 16
        && std::mem::align_of::<sys::RTCRayHit4>() == 16
        && std::mem::align_of::<sys::RTCRay4>() == 16
);

/// The pieces of `n` lanes that have an active lane: each piece's first lane and its active
/// lanes (bit per lane, counted from the piece's first).
fn active_parts(valid: &Mask16, n: usize) -> impl Iterator<Item = (usize, u32)> {
    let active = active_bits(valid);
    (0..LANES)
        .step_by(n)
        .map(move |offset| (offset, (active >> offset) & ((1 << n) - 1)))
        .filter(|&(_, lanes)| lanes != 0)
}

/// Copies lanes `offset..offset + N` of a 16-wide ray into an N-wide one.
macro_rules! copy_ray_part {
    ($dst:expr, $src:expr, $offset:expr, $n:expr) => {{
        let (dst, src, o) = ($dst, $src, $offset);
        dst.org_x.copy_from_slice(&src.org_x[o..o + $n]);
        dst.org_y.copy_from_slice(&src.org_y[o..o + $n]);
        dst.org_z.copy_from_slice(&src.org_z[o..o + $n]);
        dst.dir_x.copy_from_slice(&src.dir_x[o..o + $n]);
        dst.dir_y.copy_from_slice(&src.dir_y[o..o + $n]);
        dst.dir_z.copy_from_slice(&src.dir_z[o..o + $n]);
        dst.tnear.copy_from_slice(&src.tnear[o..o + $n]);
        dst.tfar.copy_from_slice(&src.tfar[o..o + $n]);
        dst.time.copy_from_slice(&src.time[o..o + $n]);
        dst.mask.copy_from_slice(&src.mask[o..o + $n]);
        dst.id.copy_from_slice(&src.id[o..o + $n]);
        dst.flags.copy_from_slice(&src.flags[o..o + $n]);
    }};
}

/// Generates `RayPacket16::for_each_part*` and `ShadowPacket16::for_each_part*` for one
/// narrower Embree packet width: the packet is handed to `query` in pieces of `$n` lanes
/// (pieces without an active lane are skipped), and what Embree wrote to the active lanes
/// (`tfar` and the hit) is copied back. Inactive lanes are neither copied back nor traced.
macro_rules! narrow_parts {
    ($n:literal, $hit_fn:ident, $shadow_fn:ident, $Mask:ident, $RayHit:ident, $Ray:ident) => {
        impl RayPacket16 {
            pub(super) fn $hit_fn(&mut self, mut query: impl FnMut(&$Mask, &mut sys::$RayHit)) {
                let mut part = sys::$RayHit::default();
                for (offset, lanes) in active_parts(&self.valid, $n) {
                    let mut valid = $Mask::default();
                    valid.0.copy_from_slice(&self.valid.0[offset..offset + $n]);
                    copy_ray_part!(&mut part.ray, &self.rayhit.ray, offset, $n);
                    for i in 0..$n {
                        part.hit.geomID[i] = sys::RTC_INVALID_GEOMETRY_ID;
                        part.hit.primID[i] = sys::RTC_INVALID_GEOMETRY_ID;
                        for level in part.hit.instID.iter_mut() {
                            level[i] = sys::RTC_INVALID_GEOMETRY_ID;
                        }
                    }
                    query(&valid, &mut part);
                    let (ray, hit) = (&mut self.rayhit.ray, &mut self.rayhit.hit);
                    for i in (0..$n).filter(|i| lanes & (1 << i) != 0) {
                        let lane = offset + i;
                        ray.tfar[lane] = part.ray.tfar[i];
                        hit.Ng_x[lane] = part.hit.Ng_x[i];
                        hit.Ng_y[lane] = part.hit.Ng_y[i];
                        hit.Ng_z[lane] = part.hit.Ng_z[i];
                        hit.u[lane] = part.hit.u[i];
                        hit.v[lane] = part.hit.v[i];
                        hit.primID[lane] = part.hit.primID[i];
                        hit.geomID[lane] = part.hit.geomID[i];
                        for (level, from) in hit.instID.iter_mut().zip(&part.hit.instID) {
                            level[lane] = from[i];
                        }
                    }
                }
            }
        }

        impl ShadowPacket16 {
            pub(super) fn $shadow_fn(&mut self, mut query: impl FnMut(&$Mask, &mut sys::$Ray)) {
                let mut part = sys::$Ray::default();
                for (offset, lanes) in active_parts(&self.valid, $n) {
                    let mut valid = $Mask::default();
                    valid.0.copy_from_slice(&self.valid.0[offset..offset + $n]);
                    copy_ray_part!(&mut part, &self.rays, offset, $n);
                    query(&valid, &mut part);
                    for i in (0..$n).filter(|i| lanes & (1 << i) != 0) {
                        self.rays.tfar[offset + i] = part.tfar[i];
                    }
                }
            }
        }
    };
}

narrow_parts!(
    8,
    for_each_part8,
    for_each_part8,
    Mask8,
    RTCRayHit8,
    RTCRay8
);
narrow_parts!(
    4,
    for_each_part4,
    for_each_part4,
    Mask4,
    RTCRayHit4,
    RTCRay4
);

/// Fills every lane with the segment from `origin` along `dir` for `t` in `[0, tfar]` and
/// returns the mask of the lanes among `wanted` that Embree can trace; the others get the idle ray.
fn fill_segments(
    raw: &mut sys::RTCRay16,
    wanted: u32,
    origin: &[[f32; LANES]; 3],
    dir: &[[f32; LANES]; 3],
    tfar: &[f32; LANES],
) -> Mask16 {
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
    let ok = traceable_lanes(raw, wanted);
    idle_lanes(raw, !ok);
    Mask16(std::array::from_fn(|lane| -(((ok >> lane) & 1) as i32)))
}

/// The lane bookkeeping both packets share; `$($ray).+` names the packet's `RTCRay16`.
macro_rules! lane_methods {
    ($packet:ident, $field:ident $(. $sub:ident)?, $ray_doc:literal) => {
        impl Default for $packet {
            fn default() -> Self {
                Self::new()
            }
        }

        impl $packet {
            /// A packet with every lane inactive.
            pub fn new() -> Self {
                let mut packet = Self {
                    $field: Default::default(),
                    valid: Mask16([0; LANES]),
                };
                packet.clear();
                packet
            }

            /// Deactivates every lane (each gets the idle ray; hits are left as they were).
            pub fn clear(&mut self) {
                self.valid.0 = [0; LANES];
                idle_lanes(&mut self.$field$(.$sub)?, u32::MAX);
            }

            /// Deactivates one lane: it gets the idle ray, and no Embree call writes it.
            ///
            /// # Panics
            /// When `lane >= LANES` (16).
            pub fn set_inactive(&mut self, lane: usize) {
                assert!(lane < LANES, "lane {lane} out of range");
                self.valid.0[lane] = 0;
                idle_lanes(&mut self.$field$(.$sub)?, 1 << lane);
            }

            /// Whether `lane` will be traced.
            ///
            /// # Panics
            /// When `lane >= LANES` (16).
            pub fn is_active(&self, lane: usize) -> bool {
                self.valid.0[lane] != 0
            }

            /// Puts `ray` in `lane` and activates it, or deactivates the lane and returns false
            /// when Embree cannot trace the ray.
            fn activate(&mut self, lane: usize, ray: &Ray) -> bool {
                if !ray.is_traceable() {
                    self.set_inactive(lane);
                    return false;
                }
                init_ray(&mut self.$field$(.$sub)?, lane, ray);
                self.valid.0[lane] = -1;
                true
            }

            /// Number of active lanes.
            pub fn active_count(&self) -> usize {
                self.valid.0.iter().filter(|&&v| v != 0).count()
            }

            #[doc = $ray_doc]
            ///
            /// # Panics
            /// When `lane >= LANES` (16).
            pub fn ray(&self, lane: usize) -> Ray {
                read_ray(&self.$field$(.$sub)?, lane)
            }
        }
    };
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

lane_methods!(
    RayPacket16,
    rayhit.ray,
    "The ray in `lane` (after tracing, `tfar` is the hit distance when it hit)."
);

/// The bit of Embree's ray `id` that marks a camera ray for hit filters (the low bits hold the
/// lane, which nothing reads back).
pub(super) const CAMERA_RAY: u32 = 1 << 31;

impl RayPacket16 {
    /// Marks every lane's ray as a camera ray, or not: hit filters see the mark
    /// ([`CandidateHit::camera`](super::CandidateHit::camera)), so a surface hidden from the
    /// camera can let camera rays through. [`RayPacket16::set`] clears it.
    pub fn set_camera(&mut self, camera: bool) {
        for id in self.rayhit.ray.id.iter_mut() {
            *id = if camera {
                *id | CAMERA_RAY
            } else {
                *id & !CAMERA_RAY
            };
        }
    }

    /// Activates `lane` with `ray` and no hit, and returns true; a ray Embree cannot trace
    /// (non-finite, or beyond its range: see [`Ray::is_traceable`]) leaves the lane inactive
    /// and returns false, so no input can abort Embree.
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set(&mut self, lane: usize, ray: &Ray) -> bool {
        if !self.activate(lane, ray) {
            return false;
        }
        let hit = &mut self.rayhit.hit;
        hit.geomID[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        hit.primID[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        for level in hit.instID.iter_mut() {
            level[lane] = sys::RTC_INVALID_GEOMETRY_ID;
        }
        true
    }

    /// Fills every lane from structure-of-arrays origins and directions (x, y, z components)
    /// with `tnear` 0, no far limit and no hit, and activates lanes `0..active` (the others
    /// are inactive and get an idle finite ray, whatever `origin` and `dir` hold there). Equal
    /// to `clear` then `set` of each active lane: a lane whose ray Embree cannot trace stays
    /// inactive ([`RayPacket16::is_active`] tells). An `active` above 16 activates every lane.
    pub fn set_lanes(
        &mut self,
        active: usize,
        origin: &[[f32; LANES]; 3],
        dir: &[[f32; LANES]; 3],
    ) {
        let wanted = if active >= LANES {
            u32::MAX
        } else {
            (1u32 << active) - 1
        };
        self.set_lanes_masked(wanted, origin, dir);
    }

    /// [`RayPacket16::set_lanes`] activating the lanes whose bit is set in `wanted` (lane
    /// `i` is bit `i`): rays a lens blocked need not be traced.
    pub fn set_lanes_masked(
        &mut self,
        wanted: u32,
        origin: &[[f32; LANES]; 3],
        dir: &[[f32; LANES]; 3],
    ) {
        let hit = &mut self.rayhit.hit;
        hit.geomID = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        hit.primID = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        for level in hit.instID.iter_mut() {
            *level = [sys::RTC_INVALID_GEOMETRY_ID; LANES];
        }
        let tfar = [f32::INFINITY; LANES];
        self.valid = fill_segments(&mut self.rayhit.ray, wanted, origin, dir, &tfar);
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

lane_methods!(
    ShadowPacket16,
    rays,
    "The shadow ray in `lane` (after tracing, `tfar` is -inf when it was blocked)."
);

impl ShadowPacket16 {
    /// Activates `lane` with the shadow ray `ray` and returns true; a ray Embree cannot trace
    /// leaves the lane inactive and returns false (see [`RayPacket16::set`]).
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn set(&mut self, lane: usize, ray: &Ray) -> bool {
        self.activate(lane, ray)
    }

    /// Fills every lane with the segment from `origin` along `dir` for `t` in `[0, tfar]`
    /// (structure of arrays) and activates the lanes whose bit is set in `active`; the others
    /// get an idle finite ray, whatever the arrays hold there (NaN included). Equal to `clear`
    /// then `set` of each active lane (an untraceable ray leaves its lane inactive).
    pub fn set_segments(
        &mut self,
        active: u32,
        origin: &[[f32; LANES]; 3],
        dir: &[[f32; LANES]; 3],
        tfar: &[f32; LANES],
    ) {
        self.valid = fill_segments(&mut self.rays, active, origin, dir, tfar);
    }

    /// True when the active ray in `lane` is blocked (Embree sets its `tfar` to -inf).
    ///
    /// # Panics
    /// When `lane >= LANES` (16).
    pub fn occluded(&self, lane: usize) -> bool {
        self.is_active(lane) && self.rays.tfar[lane] == f32::NEG_INFINITY
    }
}
