//! The one primitive every render mode shares: trace a 16-wide packet and shade its hits
//! (direct light with `occluded16` shadow packets, ambient, one optional mirror bounce).

use glam::Vec3;

use crate::embree::{LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
use crate::scene::World;
use crate::shade::{self, SurfacePoint};

/// Rays traced, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RayCounts {
    /// Camera rays (pinhole and lens rays).
    pub primary: u64,
    /// Occlusion rays towards lights.
    pub shadow: u64,
    /// Mirror reflection rays.
    pub secondary: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.secondary
    }

    pub fn add(&mut self, other: &RayCounts) {
        self.primary += other.primary;
        self.shadow += other.shadow;
        self.secondary += other.secondary;
    }
}

/// The kind of rays in a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    Primary,
    Shadow,
    Secondary,
}

/// One packet exactly as it was handed to Embree, for replaying without shading.
#[derive(Debug, Clone)]
pub struct RecordedPacket {
    pub kind: RayKind,
    pub hint: RayHint,
    /// Bit `i` set: lane `i` is active.
    pub active: u16,
    pub rays: [Ray; LANES],
}

/// What tracing did: ray counts, and (when `log` is `Some`) every packet traced, in order.
#[derive(Debug, Default)]
pub struct Tally {
    pub counts: RayCounts,
    pub log: Option<Vec<RecordedPacket>>,
}

impl Tally {
    /// A tally that also records packets when `record` is set.
    pub fn new(record: bool) -> Self {
        Self {
            counts: RayCounts::default(),
            log: record.then(Vec::new),
        }
    }

    /// Appends another tally (its packets after this one's).
    pub fn merge(&mut self, other: Tally) {
        self.counts.add(&other.counts);
        if let (Some(log), Some(more)) = (&mut self.log, other.log) {
            log.extend(more);
        }
    }

    fn count(&mut self, kind: RayKind, active: usize) {
        let n = active as u64;
        match kind {
            RayKind::Primary => self.counts.primary += n,
            RayKind::Shadow => self.counts.shadow += n,
            RayKind::Secondary => self.counts.secondary += n,
        }
    }

    fn record(&mut self, kind: RayKind, hint: RayHint, lanes: impl Fn(usize) -> Option<Ray>) {
        if let Some(log) = &mut self.log {
            let mut packet = RecordedPacket {
                kind,
                hint,
                active: 0,
                rays: [Ray::new(Vec3::ZERO, Vec3::Z); LANES],
            };
            for lane in 0..LANES {
                if let Some(ray) = lanes(lane) {
                    packet.active |= 1 << lane;
                    packet.rays[lane] = ray;
                }
            }
            log.push(packet);
        }
    }
}

/// Traces recorded packets again, intersection only (no shading, no sampling), in parallel.
/// Returns the number of rays traced.
pub fn replay(scene: &crate::embree::Scene, packets: &[RecordedPacket]) -> u64 {
    use rayon::prelude::*;
    packets
        .par_chunks(64)
        .map(|chunk| {
            let mut packet = RayPacket16::new();
            let mut shadow = ShadowPacket16::new();
            let mut rays = 0u64;
            for rec in chunk {
                let lanes = (0..LANES).filter(|l| rec.active & (1 << l) != 0);
                if rec.kind == RayKind::Shadow {
                    shadow.clear();
                    lanes.for_each(|l| shadow.set(l, &rec.rays[l]));
                    scene.occluded16(&mut shadow, rec.hint);
                } else {
                    packet.clear();
                    lanes.for_each(|l| packet.set(l, &rec.rays[l]));
                    scene.intersect16(&mut packet, rec.hint);
                }
                rays += rec.active.count_ones() as u64;
            }
            rays
        })
        .sum()
}

/// Offset for rays leaving a surface, scaled to the magnitude of the position so it survives
/// f32 rounding far from the origin.
fn surface_epsilon(p: Vec3) -> f32 {
    1e-4 * (1.0 + p.abs().max_element())
}

/// Per-thread scratch space for [`trace_and_shade`]: the shadow packet and, built on first
/// use, the packet and scratch space of the next mirror bounce. Reusing it keeps packets
/// (about 2 KB each) from being built and zeroed per call.
#[derive(Default)]
pub struct Scratch {
    shadow: ShadowPacket16,
    bounce: Option<Box<(RayPacket16, Scratch)>>,
}

impl Scratch {
    pub fn new() -> Self {
        Self::default()
    }
}

const NO_POINT: SurfacePoint = SurfacePoint {
    position: Vec3::ZERO,
    normal: Vec3::ZERO,
    uv: glam::Vec2::ZERO,
};

/// Traces the active lanes of `packet` (rays of `kind`) and writes each lane's radiance to
/// `radiance` (inactive lanes are left as they were). Writes the hit distance to `t_hit`
/// (infinite for misses). `bounces` is how many mirror reflections may still follow.
#[allow(clippy::too_many_arguments)]
pub fn trace_and_shade(
    world: &World,
    packet: &mut RayPacket16,
    kind: RayKind,
    hint: RayHint,
    radiance: &mut [Vec3; LANES],
    t_hit: &mut [f32; LANES],
    bounces: u32,
    scratch: &mut Scratch,
    tally: &mut Tally,
) {
    tally.count(kind, packet.active_count());
    tally.record(kind, hint, |l| packet.is_active(l).then(|| packet.ray(l)));
    world.scene.intersect16(packet, hint);
    // Lanes whose ray hit a surface (bit per lane), and what they hit.
    let mut hits = 0u32;
    let mut points = [NO_POINT; LANES];
    let mut material_of = [0usize; LANES];
    let mut albedo = [Vec3::ZERO; LANES];
    let mut dirs = [Vec3::ZERO; LANES];
    for lane in 0..LANES {
        if !packet.is_active(lane) {
            continue;
        }
        let ray = packet.ray(lane);
        dirs[lane] = ray.dir;
        match packet.hit(lane) {
            None => {
                radiance[lane] = world.background.radiance(ray.dir);
                t_hit[lane] = f32::INFINITY;
            }
            Some(hit) => {
                let sp = world.surface_point(&ray, &hit);
                let m = world.material_index(&hit);
                let material = &world.materials[m];
                albedo[lane] = material.diffuse.sample(sp.uv);
                radiance[lane] = albedo[lane] * world.ambient * (1.0 - material.mirror);
                t_hit[lane] = hit.t;
                points[lane] = sp;
                material_of[lane] = m;
                hits |= 1 << lane;
            }
        }
    }
    if hits == 0 {
        return;
    }

    let shadow = &mut scratch.shadow;
    let mut samples = [None; LANES];
    for light in &world.lights {
        shadow.clear();
        for lane in 0..LANES {
            if hits & (1 << lane) == 0 {
                continue;
            }
            let sp = &points[lane];
            let ls = light.sample(sp.position);
            if sp.normal.dot(ls.dir) <= 0.0 {
                samples[lane] = None;
                continue;
            }
            let eps = surface_epsilon(sp.position);
            let tfar = if ls.distance.is_finite() {
                ls.distance * (1.0 - 1e-4) - eps
            } else {
                f32::INFINITY
            };
            shadow.set(
                lane,
                &Ray::segment(sp.position + sp.normal * eps, ls.dir, 0.0, tfar),
            );
            samples[lane] = Some(ls);
        }
        let active = shadow.active_count();
        if active == 0 {
            continue;
        }
        tally.count(RayKind::Shadow, active);
        tally.record(RayKind::Shadow, RayHint::Coherent, |l| {
            shadow.is_active(l).then(|| shadow.ray(l))
        });
        world.scene.occluded16(shadow, RayHint::Coherent);
        for lane in 0..LANES {
            if hits & (1 << lane) == 0 {
                continue;
            }
            if let Some(ls) = &samples[lane] {
                if !shadow.occluded(lane) {
                    let material = &world.materials[material_of[lane]];
                    radiance[lane] +=
                        shade::direct(material, albedo[lane], &points[lane], dirs[lane], ls);
                }
            }
        }
    }

    let reflects =
        |lane: usize| hits & (1 << lane) != 0 && world.materials[material_of[lane]].mirror > 0.0;
    if bounces == 0 || !(0..LANES).any(reflects) {
        return;
    }
    let (mirror, next) = &mut **scratch
        .bounce
        .get_or_insert_with(|| Box::new((RayPacket16::new(), Scratch::new())));
    mirror.clear();
    for lane in (0..LANES).filter(|&l| reflects(l)) {
        let sp = &points[lane];
        let d = dirs[lane];
        let r = d - 2.0 * d.dot(sp.normal) * sp.normal;
        let eps = surface_epsilon(sp.position);
        mirror.set(lane, &Ray::new(sp.position + sp.normal * eps, r));
    }
    let mut reflected = [Vec3::ZERO; LANES];
    let mut t_unused = [0.0; LANES];
    trace_and_shade(
        world,
        mirror,
        RayKind::Secondary,
        RayHint::Incoherent,
        &mut reflected,
        &mut t_unused,
        bounces - 1,
        next,
        tally,
    );
    for lane in 0..LANES {
        if mirror.is_active(lane) {
            radiance[lane] += reflected[lane] * world.materials[material_of[lane]].mirror;
        }
    }
}
