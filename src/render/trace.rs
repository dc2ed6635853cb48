//! The one primitive every render mode shares: trace a 16-wide packet and shade its hits
//! (direct light with `occluded16` shadow packets, ambient, one optional mirror bounce).

use glam::Vec3;

use crate::embree::{LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
use crate::scene::World;
use crate::shade::{self, Light, LightSample, SurfacePoints16};

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
    points: SurfacePoints16,
    bounce: Option<Box<(RayPacket16, Scratch)>>,
}

impl Scratch {
    pub fn new() -> Self {
        Self::default()
    }
}

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
    // Lanes whose ray hit a surface (bit per lane).
    let hits = packet.hit_mask();
    let dir = packet.dirs();
    let view = |lane: usize| Vec3::new(dir[0][lane], dir[1][lane], dir[2][lane]);
    for lane in 0..LANES {
        if packet.is_active(lane) && hits & (1 << lane) == 0 {
            radiance[lane] = world.background.radiance(view(lane));
            t_hit[lane] = f32::INFINITY;
        }
    }
    if hits == 0 {
        return;
    }
    let points = &mut scratch.points;
    world.surface_points16(packet, hits, points);
    let mut material_of = [0usize; LANES];
    let mut albedo = [Vec3::ZERO; LANES];
    let tfar = packet.tfars();
    for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
        let hit = packet.hit(lane).expect("lanes in `hits` hit");
        let m = world.material_index(&hit);
        let material = &world.materials[m];
        albedo[lane] = material.diffuse.sample(points.uv[lane]);
        radiance[lane] = albedo[lane] * world.ambient * (1.0 - material.mirror);
        t_hit[lane] = tfar[lane];
        material_of[lane] = m;
    }

    let shadow = &mut scratch.shadow;
    let (pos, nrm) = (&points.position, &points.normal);
    // Shadow rays and light samples of all lanes, as structure of arrays.
    let mut origin = [[0.0f32; LANES]; 3];
    let mut to_light = [[0.0f32; LANES]; 3];
    let mut seg_end = [0.0f32; LANES];
    let mut distance = [0.0f32; LANES];
    let mut irradiance = [[0.0f32; LANES]; 3];
    for light in &world.lights {
        // Light::sample, written out over all lanes.
        match *light {
            Light::Point {
                position,
                intensity,
            } => {
                for lane in 0..LANES {
                    let d = [
                        position.x - pos[0][lane],
                        position.y - pos[1][lane],
                        position.z - pos[2][lane],
                    ];
                    let dist2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).max(1e-12);
                    let dist = dist2.sqrt();
                    for k in 0..3 {
                        to_light[k][lane] = d[k] / dist;
                        irradiance[k][lane] = intensity[k] / dist2;
                    }
                    distance[lane] = dist;
                }
            }
            Light::Directional { .. } => {
                let ls = light.sample(Vec3::ZERO);
                for k in 0..3 {
                    to_light[k] = [ls.dir[k]; LANES];
                    irradiance[k] = [ls.irradiance[k]; LANES];
                }
                distance = [ls.distance; LANES];
            }
        }
        let mut lit = 0u32;
        for lane in 0..LANES {
            let cos = nrm[0][lane] * to_light[0][lane]
                + nrm[1][lane] * to_light[1][lane]
                + nrm[2][lane] * to_light[2][lane];
            // A NaN cosine (a degenerate normal) is unlit: Embree must never see a NaN ray.
            lit |= ((cos > 0.0) as u32) << lane;
            // surface_epsilon, then the segment towards the light.
            let max = |a: f32, b: f32| if a > b { a } else { b };
            let extent = max(
                pos[0][lane].abs(),
                max(pos[1][lane].abs(), pos[2][lane].abs()),
            );
            let eps = 1e-4 * (1.0 + extent);
            seg_end[lane] = if distance[lane].is_finite() {
                distance[lane] * (1.0 - 1e-4) - eps
            } else {
                f32::INFINITY
            };
            for k in 0..3 {
                origin[k][lane] = pos[k][lane] + nrm[k][lane] * eps;
            }
        }
        let lit = lit & hits;
        if lit == 0 {
            continue;
        }
        // Unlit lanes (misses among them, whose points are infinite) are inactive: the packet
        // replaces their NaN with an idle ray.
        shadow.set_segments(lit, &origin, &to_light, &seg_end);
        tally.count(RayKind::Shadow, lit.count_ones() as usize);
        tally.record(RayKind::Shadow, RayHint::Coherent, |l| {
            shadow.is_active(l).then(|| shadow.ray(l))
        });
        world.scene.occluded16(shadow, RayHint::Coherent);
        for lane in (0..LANES).filter(|&l| lit & (1 << l) != 0) {
            if !shadow.occluded(lane) {
                let ls = LightSample {
                    dir: Vec3::new(to_light[0][lane], to_light[1][lane], to_light[2][lane]),
                    distance: distance[lane],
                    irradiance: Vec3::new(
                        irradiance[0][lane],
                        irradiance[1][lane],
                        irradiance[2][lane],
                    ),
                };
                let material = &world.materials[material_of[lane]];
                radiance[lane] +=
                    shade::direct(material, albedo[lane], &points.get(lane), view(lane), &ls);
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
        let sp = &points.get(lane);
        let d = view(lane);
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

/// Traces the active lanes of `packet` (primary rays) for their hit distance alone, without
/// shading: `t_hit` gets the distance, infinite for misses (inactive lanes are left as they
/// were). The depth pass's primitive.
pub fn trace_depth(
    world: &World,
    packet: &mut RayPacket16,
    t_hit: &mut [f32; LANES],
    tally: &mut Tally,
) {
    tally.count(RayKind::Primary, packet.active_count());
    tally.record(RayKind::Primary, RayHint::Coherent, |l| {
        packet.is_active(l).then(|| packet.ray(l))
    });
    world.scene.intersect16(packet, RayHint::Coherent);
    let hits = packet.hit_mask();
    let tfar = packet.tfars();
    for lane in (0..LANES).filter(|&l| packet.is_active(l)) {
        t_hit[lane] = if hits & (1 << lane) != 0 {
            tfar[lane]
        } else {
            f32::INFINITY
        };
    }
}
