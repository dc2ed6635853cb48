//! The one primitive every render mode shares: trace a 16-wide packet and shade its hits
//! (direct light with `occluded16` shadow packets, ambient, one optional mirror bounce).

use glam::Vec3;

use crate::embree::{Geometry, Hit, LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
use crate::scene::World;
use crate::shade::{self, Light, LightSample, Surface, SurfacePoints16};

/// How many bounces [`RayCounts`] tells apart; the last entry counts every bounce from
/// `BOUNCE_SLOTS - 1` on.
pub const BOUNCE_SLOTS: usize = 16;

/// Rays traced, by kind and by bounce.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RayCounts {
    /// Camera rays (pinhole and lens rays).
    pub primary: u64,
    /// Occlusion rays towards lights.
    pub shadow: u64,
    /// Bounce rays (the path tracer's, the direct integrator's mirror reflections).
    pub secondary: u64,
    /// Intersected rays by bounce: the camera rays at 0, the `i`-th bounce's at `i`.
    pub by_bounce: [u64; BOUNCE_SLOTS],
    /// Shadow rays by the bounce of the vertex they leave (0: where camera rays hit).
    pub shadow_by_bounce: [u64; BOUNCE_SLOTS],
}

impl RayCounts {
    /// Rays of every kind.
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.secondary
    }

    /// Adds `other`'s counts to these, kind by kind.
    pub fn add(&mut self, other: &RayCounts) {
        self.primary += other.primary;
        self.shadow += other.shadow;
        self.secondary += other.secondary;
        for i in 0..BOUNCE_SLOTS {
            self.by_bounce[i] += other.by_bounce[i];
            self.shadow_by_bounce[i] += other.shadow_by_bounce[i];
        }
    }
}

/// The kind of rays in a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayKind {
    /// Camera rays (pinhole and lens rays), intersected.
    Primary,
    /// Occlusion rays towards lights (`occluded16`).
    Shadow,
    /// Mirror reflection rays, intersected.
    Secondary,
}

/// One packet exactly as it was handed to Embree, for replaying without shading.
#[derive(Debug, Clone)]
pub struct RecordedPacket {
    /// The rays' kind: [`RayKind::Shadow`] packets are replayed as occlusion queries, the others
    /// as intersections.
    pub kind: RayKind,
    /// The coherence hint the packet was traced with.
    pub hint: RayHint,
    /// Bit `i` set: lane `i` is active.
    pub active: u16,
    /// Every lane's ray (those of inactive lanes are not traced).
    pub rays: [Ray; LANES],
}

/// What tracing did: ray counts, and (when `log` is `Some`) every packet traced, in order.
#[derive(Debug, Default)]
pub struct Tally {
    /// Rays traced, by kind.
    pub counts: RayCounts,
    /// Every packet traced, in order; `None` when not recording.
    pub log: Option<Vec<RecordedPacket>>,
    /// The bounce the rays being counted belong to (0: camera rays and their hits).
    pub(super) bounce: u32,
}

impl Tally {
    /// A tally that also records packets when `record` is set.
    pub fn new(record: bool) -> Self {
        Self {
            counts: RayCounts::default(),
            log: record.then(Vec::new),
            bounce: 0,
        }
    }

    /// Appends another tally (its packets after this one's).
    pub fn merge(&mut self, other: Tally) {
        self.counts.add(&other.counts);
        if let (Some(log), Some(more)) = (&mut self.log, other.log) {
            log.extend(more);
        }
    }

    pub(super) fn count(&mut self, kind: RayKind, active: usize) {
        let n = active as u64;
        let slot = (self.bounce as usize).min(BOUNCE_SLOTS - 1);
        match kind {
            RayKind::Shadow => self.counts.shadow_by_bounce[slot] += n,
            _ => self.counts.by_bounce[slot] += n,
        }
        match kind {
            RayKind::Primary => self.counts.primary += n,
            RayKind::Shadow => self.counts.shadow += n,
            RayKind::Secondary => self.counts.secondary += n,
        }
    }

    pub(super) fn record(
        &mut self,
        kind: RayKind,
        hint: RayHint,
        lanes: impl Fn(usize) -> Option<Ray>,
    ) {
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
                    lanes.for_each(|l| {
                        shadow.set(l, &rec.rays[l]);
                    });
                    scene.occluded16(&mut shadow, rec.hint);
                } else {
                    packet.clear();
                    lanes.for_each(|l| {
                        packet.set(l, &rec.rays[l]);
                    });
                    scene.intersect16(&mut packet, rec.hint);
                }
                rays += rec.active.count_ones() as u64;
            }
            rays
        })
        .sum()
}

/// Rays leaving a surface (shadow and mirror rays) start this far along the normal, relative
/// to the largest magnitude involved in finding the hit (see [`leaving_origins`]): 16 units in
/// the last place (2^-19). Over about a million probes on every ISA (spheres of radius 0.01 to
/// 1e5, triangles, grazing lights, hit distances up to 1e4), no shadow ray needed more than
/// 3.5 units in the last place to miss the surface it left.
const OFFSET_SCALE: f32 = 16.0 * f32::EPSILON;

/// The largest coordinate magnitude of the primitive `hit` found: a sphere's centre and radius,
/// a triangle's vertices. Embree's analytic sphere test cancels terms of size radius^2 (and
/// subtracts the centre from the ray origin), so both its hit distance and its answer for a ray
/// leaving the sphere are off by a few units in the last place of these, not of the hit point:
/// on a radius-1000 ground sphere near the origin that is up to 3e-4, three times an offset
/// scaled by the hit point's magnitude alone (1e-4 there).
pub(super) fn primitive_extent(world: &World, hit: &Hit) -> f32 {
    match world.scene.geometry(hit.geometry) {
        Geometry::Spheres(s) => s
            .center(hit.prim)
            .abs()
            .max_element()
            .max(s.radius(hit.prim)),
        Geometry::Mesh(m) => m.indices()[hit.prim as usize]
            .iter()
            .map(|&v| Vec3::from(m.positions()[v as usize]).abs().max_element())
            .fold(0.0, f32::max),
    }
}

/// How far rays leaving `p` on a mesh with vertex normals must be lifted to start on the smooth
/// surface those normals describe rather than on the flat triangle: the shadow terminator fix
/// of Hanika ("Hacking the Shadow Terminator", Ray Tracing Gems II, 2021). Each corner's
/// tangent plane (its normal turned to the side `facing` is on) pulls `p` up onto it when `p`
/// lies below, weighted by the barycentrics. Without it, points lit by the interpolated normal
/// but facing away from the light by the flat triangle (or its neighbours) shadow themselves
/// in facets along the terminator. Zero for spheres and meshes without normals.
pub(super) fn terminator_lift(world: &World, hit: &Hit, p: Vec3, facing: Vec3) -> Vec3 {
    let Geometry::Mesh(m) = world.scene.geometry(hit.geometry) else {
        return Vec3::ZERO;
    };
    let Some(normals) = m.normals() else {
        return Vec3::ZERO;
    };
    let corners = m.indices()[hit.prim as usize].map(|v| v as usize);
    let weights = [1.0 - hit.u - hit.v, hit.u, hit.v];
    // Normalised when the mesh was built.
    let normal = |i: usize| Vec3::from(normals[corners[i]]);
    let interpolated: Vec3 = (0..3).map(|i| weights[i] * normal(i)).sum();
    let side = if interpolated.dot(facing) < 0.0 {
        -1.0
    } else {
        1.0
    };
    (0..3)
        .map(|i| {
            let n = side * normal(i);
            let below = (p - Vec3::from(m.positions()[corners[i]])).dot(n).min(0.0);
            -weights[i] * below * n
        })
        .sum()
}

/// Where rays leave each lane's hit point.
pub(super) struct Origins {
    /// The origins of rays leaving on the side the ray came from (shadow, mirror and
    /// reflected rays).
    pub(super) above: [[f32; LANES]; 3],
    /// The origins of rays leaving through the surface (transmitted rays): the hit point moved
    /// as far the other way, without the terminator lift.
    pub(super) below: [[f32; LANES]; 3],
    /// How far an origin may be from the hit point, to shorten segments towards lights.
    pub(super) reach: [f32; LANES],
}

impl Origins {
    /// Where a ray leaving lane `lane` starts: above the surface when it leaves on the side
    /// the shading normal faces (`above`), else below it.
    pub(super) fn at(&self, lane: usize, above: bool) -> Vec3 {
        let side = if above { &self.above } else { &self.below };
        Vec3::new(side[0][lane], side[1][lane], side[2][lane])
    }
}

/// The origins of rays leaving each lane's hit point (shadow and mirror rays alike), and how
/// far each origin may be from the hit point (`reach`, to shorten segments towards lights).
/// The origin is the hit point, lifted by `lift` ([`terminator_lift`]), then moved along the
/// normal by [`OFFSET_SCALE`] times the largest of the hit point's magnitude, the hit distance
/// times the ray direction's magnitude (the point `org + t dir` is rounded at that size) and
/// the hit primitive's `extent` ([`primitive_extent`]). Everything is relative, so tiny scenes
/// keep tiny offsets (no light leaking under small objects) and huge primitives get the offsets
/// their rounding needs (no acne). Written over all lanes at once so it vectorises; lanes that
/// missed (infinite `t`) get non-finite origins and must stay inactive.
pub(super) fn leaving_origins(
    position: &[[f32; LANES]; 3],
    normal: &[[f32; LANES]; 3],
    dir: [&[f32; LANES]; 3],
    t: &[f32; LANES],
    extent: &[f32; LANES],
    lift: &[[f32; LANES]; 3],
) -> Origins {
    // `f32::max` with its NaN handling would not vectorise; no input here is NaN on a hit lane.
    let max = |a: f32, b: f32| if a > b { a } else { b };
    let mut out = Origins {
        above: [[0.0f32; LANES]; 3],
        below: [[0.0f32; LANES]; 3],
        reach: [0.0f32; LANES],
    };
    for lane in 0..LANES {
        let p = max(
            position[0][lane].abs(),
            max(position[1][lane].abs(), position[2][lane].abs()),
        );
        let d = max(
            dir[0][lane].abs(),
            max(dir[1][lane].abs(), dir[2][lane].abs()),
        );
        let offset = OFFSET_SCALE * max(max(p, t[lane] * d), extent[lane]);
        let (lx, ly, lz) = (lift[0][lane], lift[1][lane], lift[2][lane]);
        out.reach[lane] = offset + (lx * lx + ly * ly + lz * lz).sqrt();
        for k in 0..3 {
            let (p, n) = (position[k][lane], normal[k][lane]);
            out.above[k][lane] = p + lift[k][lane] + n * offset;
            out.below[k][lane] = p - n * offset;
        }
    }
    out
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
    /// Empty scratch space (the bounce packet is built on first use).
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
    // Lanes whose ray hit a surface (bit per lane).
    let hits = trace_depth(world, packet, kind, hint, t_hit, tally);
    let dir = packet.dirs();
    for (lane, radiance) in radiance.iter_mut().enumerate() {
        if packet.is_active(lane) && hits & (1 << lane) == 0 {
            *radiance = world.background.radiance(lane_vec(dir, lane));
        }
    }
    if hits == 0 {
        return;
    }
    let points = &mut scratch.points;
    world.surface_points16(packet, hits, points);
    let hit = surfaces_hit(world, packet, hits, points, radiance);
    let Origins {
        above: origin,
        reach,
        ..
    } = leaving_origins(
        &points.position,
        &points.normal,
        dir,
        packet.tfars(),
        &hit.extent,
        &hit.lift,
    );
    let leaving = Leaving {
        hits,
        origin: &origin,
        reach: &reach,
        surface: &hit.surface,
    };
    for light in &world.lights {
        add_direct(
            world,
            light,
            &leaving,
            points,
            dir,
            &mut scratch.shadow,
            radiance,
            tally,
        );
    }
    let reflects = |lane: usize| hits & (1 << lane) != 0 && hit.surface[lane].mirror > 0.0;
    if bounces == 0 || !(0..LANES).any(reflects) {
        return;
    }
    let (mirror, next) = &mut **scratch
        .bounce
        .get_or_insert_with(|| Box::new((RayPacket16::new(), Scratch::new())));
    mirror.clear();
    for lane in (0..LANES).filter(|&l| reflects(l)) {
        let n = points.get(lane).normal;
        let d = lane_vec(dir, lane);
        let r = d - 2.0 * d.dot(n) * n;
        let o = Vec3::new(origin[0][lane], origin[1][lane], origin[2][lane]);
        mirror.set(lane, &Ray::new(o, r));
    }
    let mut reflected = [Vec3::ZERO; LANES];
    let mut t_unused = [0.0; LANES];
    tally.bounce += 1;
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
    tally.bounce -= 1;
    for lane in 0..LANES {
        if mirror.is_active(lane) {
            radiance[lane] += reflected[lane] * hit.surface[lane].mirror;
        }
    }
}

/// Traces the segments from `origin` along `dir` up to `tfar` of the lanes in `lit` as one
/// shadow packet, counted (and recorded) in `tally`; `shadow.occluded(lane)` then answers.
#[allow(clippy::too_many_arguments)]
pub(super) fn trace_shadows(
    world: &World,
    shadow: &mut ShadowPacket16,
    lit: u32,
    origin: &[[f32; LANES]; 3],
    dir: &[[f32; LANES]; 3],
    tfar: &[f32; LANES],
    hint: RayHint,
    tally: &mut Tally,
) {
    shadow.set_segments(lit, origin, dir, tfar);
    tally.count(RayKind::Shadow, lit.count_ones() as usize);
    tally.record(RayKind::Shadow, hint, |l| {
        shadow.is_active(l).then(|| shadow.ray(l))
    });
    world.scene.occluded16(shadow, hint);
}

/// Lane `lane` of a structure-of-arrays vector.
pub(super) fn lane_vec(v: [&[f32; LANES]; 3], lane: usize) -> Vec3 {
    Vec3::new(v[0][lane], v[1][lane], v[2][lane])
}

/// What the lanes that hit found: their surfaces, and what [`leaving_origins`] needs.
struct SurfacesHit {
    surface: [Surface; LANES],
    extent: [f32; LANES],
    lift: [[f32; LANES]; 3],
}

/// The surfaces of the lanes in `hits`; starts each lane's radiance with its ambient and
/// emitted terms.
fn surfaces_hit(
    world: &World,
    packet: &RayPacket16,
    hits: u32,
    points: &SurfacePoints16,
    radiance: &mut [Vec3; LANES],
) -> SurfacesHit {
    let mut out = SurfacesHit {
        surface: [Surface {
            albedo: Vec3::ZERO,
            specular: Vec3::ZERO,
            shininess: 0.0,
            mirror: 0.0,
        }; LANES],
        extent: [0.0f32; LANES],
        lift: [[0.0f32; LANES]; 3],
    };
    for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
        let hit = packet.hit(lane).expect("lanes in `hits` hit");
        let material = world.material(&hit);
        let s = material.surface(points.uv[lane]);
        out.surface[lane] = s;
        radiance[lane] =
            s.albedo * world.ambient * (1.0 - s.mirror) + material.emitted(points.uv[lane]);
        out.extent[lane] = primitive_extent(world, &hit);
        let sp = points.get(lane);
        let up = terminator_lift(world, &hit, sp.position, sp.normal);
        for k in 0..3 {
            out.lift[k][lane] = up[k];
        }
    }
    out
}

/// The lanes that hit, where rays leave them ([`leaving_origins`]) and what they are made of.
struct Leaving<'a> {
    hits: u32,
    origin: &'a [[f32; LANES]; 3],
    reach: &'a [f32; LANES],
    surface: &'a [Surface; LANES],
}

/// One light's samples for every lane, as structure of arrays ([`Light::sample`] written out
/// over all lanes, so it vectorises).
struct LightLanes {
    to_light: [[f32; LANES]; 3],
    distance: [f32; LANES],
    irradiance: [[f32; LANES]; 3],
}

// Indexing lanes across several arrays (structure of arrays) is what lets this vectorise.
#[allow(clippy::needless_range_loop)]
fn light_lanes(light: &Light, pos: &[[f32; LANES]; 3]) -> LightLanes {
    let mut out = LightLanes {
        to_light: [[0.0f32; LANES]; 3],
        distance: [0.0f32; LANES],
        irradiance: [[0.0f32; LANES]; 3],
    };
    match light.positional() {
        Some(light) => {
            let position = light.position;
            for lane in 0..LANES {
                let d = [
                    position.x - pos[0][lane],
                    position.y - pos[1][lane],
                    position.z - pos[2][lane],
                ];
                let dist2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).max(1e-12);
                let dist = dist2.sqrt();
                let l = Vec3::new(d[0] / dist, d[1] / dist, d[2] / dist);
                let e = light.irradiance(l, dist2);
                for k in 0..3 {
                    out.to_light[k][lane] = l[k];
                    out.irradiance[k][lane] = e[k];
                }
                out.distance[lane] = dist;
            }
        }
        None => {
            let ls = light.sample(Vec3::ZERO);
            for k in 0..3 {
                out.to_light[k] = [ls.dir[k]; LANES];
                out.irradiance[k] = [ls.irradiance[k]; LANES];
            }
            out.distance = [ls.distance; LANES];
        }
    }
    out
}

/// Adds `light`'s direct contribution to the lanes that hit and see it, tracing one shadow
/// packet for them.
#[allow(clippy::too_many_arguments)]
fn add_direct(
    world: &World,
    light: &Light,
    leaving: &Leaving,
    points: &SurfacePoints16,
    dir: [&[f32; LANES]; 3],
    shadow: &mut ShadowPacket16,
    radiance: &mut [Vec3; LANES],
    tally: &mut Tally,
) {
    let nrm = &points.normal;
    let LightLanes {
        to_light,
        distance,
        irradiance,
    } = light_lanes(light, &points.position);
    let mut seg_end = [0.0f32; LANES];
    let mut lit = 0u32;
    for lane in 0..LANES {
        let cos = nrm[0][lane] * to_light[0][lane]
            + nrm[1][lane] * to_light[1][lane]
            + nrm[2][lane] * to_light[2][lane];
        // A NaN cosine (a degenerate normal) is unlit: Embree must never see a NaN ray.
        // Lanes the light sends nothing to (outside a spot's cone) need no shadow ray.
        let sent = irradiance[0][lane] + irradiance[1][lane] + irradiance[2][lane] > 0.0;
        lit |= ((cos > 0.0 && sent) as u32) << lane;
        // The segment from the leaving origin towards the light.
        seg_end[lane] = if distance[lane].is_finite() {
            distance[lane] * (1.0 - 1e-4) - leaving.reach[lane]
        } else {
            f32::INFINITY
        };
    }
    let lit = lit & leaving.hits;
    if lit == 0 {
        return;
    }
    // Unlit lanes (misses among them, whose points are infinite) are inactive: the packet
    // replaces their NaN with an idle ray.
    let (origin, hint) = (leaving.origin, RayHint::Coherent);
    trace_shadows(world, shadow, lit, origin, &to_light, &seg_end, hint, tally);
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
            let view = lane_vec(dir, lane);
            radiance[lane] += shade::direct(&leaving.surface[lane], &points.get(lane), view, &ls);
        }
    }
}

/// Traces the active lanes of `packet` (rays of `kind`), counting and recording them, for
/// their hit distance alone: `t_hit` gets the distance, infinite for misses (inactive lanes are
/// left as they were). Returns the lanes that hit (bit per lane). The depth pass uses it on
/// its own; [`trace_and_shade`] shades what it found.
pub fn trace_depth(
    world: &World,
    packet: &mut RayPacket16,
    kind: RayKind,
    hint: RayHint,
    t_hit: &mut [f32; LANES],
    tally: &mut Tally,
) -> u32 {
    tally.count(kind, packet.active_count());
    tally.record(kind, hint, |l| packet.is_active(l).then(|| packet.ray(l)));
    // Surfaces hidden from the camera (lights, by default Blender's) let camera rays through.
    packet.set_camera(kind == RayKind::Primary);
    world.scene.intersect16(packet, hint);
    let hits = packet.hit_mask();
    let tfar = packet.tfars();
    for lane in (0..LANES).filter(|&l| packet.is_active(l)) {
        t_hit[lane] = if hits & (1 << lane) != 0 {
            tfar[lane]
        } else {
            f32::INFINITY
        };
    }
    hits
}
