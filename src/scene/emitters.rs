//! Everything that emits light, as the path tracer samples it: punctual lights (point, spot,
//! sun), emissive triangles and spheres (area lights are emissive geometry), and the world.
//!
//! Each next-event estimate takes up to three kinds of sample: one per punctual light when there
//! are few ([`Emitters::always`]; with more, one per sun), one of the world
//! ([`Emitters::sample_world`]) when it emits, and one of an emitter picked from the rest
//! ([`Emitters::sample`]) by what it may send to the point, its power over its distance squared
//! within its cone of emission ([`super::light_tree`]), then a direction towards it.
//! The world has its own sample because no power estimate weighs it fairly against local
//! lights: a sky's power grows with the scene's size while what it sends to a point does not,
//! so picked by power a dim sky over a large floor starves a bright lamp next to the point.
//! [`Emitters::pdf_hit`] and [`Emitters::pdf_world`] give the density of the sample kind that
//! can draw a direction a BSDF sample found, so multiple importance sampling can weigh the two
//! strategies.

use std::collections::HashMap;
use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use crate::embree::{Geometry, GeometryId, Hit};
use crate::limits::{MemoryError, check_budget, try_with_capacity};
use crate::shade::{Light, Material, SunDisc, luminance};

use super::World;
pub use super::light_tree::Receiver;
use super::light_tree::{LightBounds, LightTree};

/// One emitter.
#[derive(Debug, Clone, Copy)]
enum Emitter {
    /// A point, spot or directional light (a delta: only next-event estimation finds it), by
    /// its index in [`Emitters::punctual`] (a light inline would take four times the room of
    /// every emissive triangle's entry).
    Punctual(u32),
    /// A triangle of an emissive mesh.
    Triangle { geometry: u32, prim: u32 },
    /// An emissive sphere.
    Sphere { geometry: u32, prim: u32 },
}

/// A direction towards an emitter, drawn from a point.
#[derive(Debug, Clone, Copy)]
pub struct EmitterSample {
    /// Unit direction from the point towards the light.
    pub dir: Vec3,
    /// Distance to the light along `dir` (infinite for the sun and the world).
    pub distance: f32,
    /// Radiance arriving along `dir` (for punctual lights: the irradiance, intensity / d^2).
    pub radiance: Vec3,
    /// Solid-angle density of `dir` including the probability of picking the emitter; for a
    /// punctual light, the picking probability alone.
    pub pdf: f32,
    /// A punctual light: no BSDF sample can find it.
    pub delta: bool,
    /// The emissive primitive drawn, as (geometry, primitive); `None` for punctual lights and
    /// the world.
    pub primitive: Option<(u32, u32)>,
}

/// The sample of punctual `light` seen from `p`: its one direction (for a spot with a radius or
/// a sun with an angle, one drawn with `u`: [`Light::sample_area`]), with the irradiance it
/// sends there as the radiance and a density of 1 (no BSDF sample can find it, so its light
/// sample alone estimates its light). A sun with an angle is the exception: rays that leave
/// the scene find its disc ([`Emitters::suns_seen`]), so its sample is an ordinary one, the
/// disc's radiance with its solid-angle density, to be weighed against BSDF sampling.
pub fn punctual_sample(light: &Light, p: Vec3, u: Vec2) -> EmitterSample {
    if let Some(disc) = light.sun_disc() {
        return EmitterSample {
            dir: disc.sample(u),
            distance: f32::INFINITY,
            radiance: disc.radiance,
            pdf: disc.pdf,
            delta: false,
            primitive: None,
        };
    }
    let ls = light.sample_area(p, u);
    EmitterSample {
        dir: ls.dir,
        distance: ls.distance,
        radiance: ls.irradiance,
        pdf: 1.0,
        delta: true,
        primitive: None,
    }
}

/// What building the emitters' distribution allocates per emitter: the list (12 bytes), bounds
/// (56), index (about 15), the tree's nodes (160), its build's order (4) and its paths and
/// powers (16): 263, with room. (Peak resident memory grew by 202 bytes per emitter for 898,000
/// emissive triangles, against the same mesh not emitting: the allocator reuses what parsing
/// freed. Taken at that, a 980,000-triangle mesh was admitted under a 320 MiB cgroup and
/// killed by its OOM killer.)
const BYTES_PER_EMITTER: u128 = 280;

/// Refuses `count` emitters whose distribution the memory budget cannot hold. Under a cgroup
/// limit no allocation fails (the kernel kills the process when the pages are touched: exit
/// 137, no message), so the fallible allocations alone would not catch it. Few emitters are
/// not checked (nothing to read from `/proc` for them).
fn check_emitters_budget(count: usize) -> Result<(), MemoryError> {
    if count < 4096 {
        return Ok(());
    }
    check_budget(
        "the emitters' light tree (about 280 bytes per emissive triangle or sphere)",
        count as u128 * BYTES_PER_EMITTER,
    )
}

/// How many primitives `geometry` has.
fn primitive_count(geometry: &Geometry) -> usize {
    match geometry {
        Geometry::Mesh(m) => m.triangle_count(),
        Geometry::Spheres(s) => s.len(),
    }
}

/// Emissive primitive `prim` of geometry `g` (`geometry`) of material `material`, and what it
/// may send where ([`LightBounds`]).
fn emitter_bounds(
    geometry: &Geometry,
    g: u32,
    prim: u32,
    material: &Material,
) -> (Emitter, LightBounds) {
    let sides = if material.one_sided { 1.0 } else { 2.0 };
    let power = |area: f32| sides * PI * area * luminance(material.emission);
    match geometry {
        Geometry::Mesh(m) => {
            let [a, b, c] =
                (m.indices()[prim as usize]).map(|v| Vec3::from(m.positions()[v as usize]));
            let n = (b - a).cross(c - a);
            let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
            // Light leaves its front face (the winding's normal) or both.
            let two_sided = !material.one_sided;
            let bounds = LightBounds::new(lo, hi, power(0.5 * n.length()), n, 1.0, 0.0, two_sided);
            (Emitter::Triangle { geometry: g, prim }, bounds)
        }
        Geometry::Spheres(s) => {
            let (c, r) = (s.center(prim), s.radius(prim));
            let bounds = LightBounds::everywhere(c - r, c + r, power(4.0 * PI * r * r));
            (Emitter::Sphere { geometry: g, prim }, bounds)
        }
    }
}

/// The emitters of a world and the distribution they are picked from.
#[derive(Debug, Default)]
pub struct Emitters {
    /// Punctual lights sampled at every vertex (when there are at most
    /// [`Emitters::ALWAYS_SAMPLED`]): each gets its own shadow ray, so a scene of a few lamps
    /// under a bright sky has no noise from choosing between them.
    pub always: Vec<Light>,
    /// The punctual lights picked from the tree.
    punctual: Vec<Light>,
    list: Vec<Emitter>,
    /// Picks from `list` by what each may send to a point.
    tree: LightTree,
    /// Emitter index of each emissive triangle or sphere, by (geometry, primitive).
    by_prim: HashMap<(u32, u32), u32>,
    /// Whether the world emits and can be sampled ([`Emitters::sample_world`]).
    world: bool,
    /// The discs of suns with an angle (all in [`Emitters::always`]): what
    /// [`Emitters::suns_seen`] looks through for every ray that leaves the scene.
    suns: Vec<SunDisc>,
}

impl Emitters {
    /// The most punctual lights sampled at every vertex; with more, the point and spot lights
    /// join the emitters picked from (suns, which no position tells apart, stay sampled at
    /// every vertex).
    pub const ALWAYS_SAMPLED: usize = 8;

    /// The emitters of `world`: its lights, its emissive primitives, and its background when it
    /// is not black. A memory error when their distribution cannot be allocated (about 280
    /// bytes per emissive triangle or sphere while building, 210 after; from 4096 of them on,
    /// checked against the memory budget first).
    pub fn build(world: &World) -> Result<Self, MemoryError> {
        let mut always = Vec::new();
        let mut punctual = Vec::new();
        let mut picked = Vec::new();
        for light in &world.lights {
            let bounds = (world.lights.len() > Self::ALWAYS_SAMPLED)
                .then(|| punctual_bounds(light))
                .flatten();
            match bounds {
                Some(b) => {
                    picked.push((Emitter::Punctual(punctual.len() as u32), b));
                    punctual.push(*light);
                }
                None => always.push(*light),
            }
        }
        // Counted first, so everything is allocated once and fallibly.
        let emissive = |g: u32, prim: u32| {
            let material = world.material_of(GeometryId(g), prim);
            (material.emission != Vec3::ZERO).then_some(material)
        };
        let geometries = world.scene.geometries();
        let count = |g: usize, geometry: &Geometry| {
            (0..primitive_count(geometry) as u32)
                .filter(|&prim| emissive(g as u32, prim).is_some())
                .count()
        };
        let primitives: usize = (geometries.iter().enumerate())
            .map(|(g, x)| count(g, x))
            .sum();
        let total = primitives + picked.len();
        check_emitters_budget(total)?;
        let mut list = try_with_capacity(total, "the emitters")?;
        let mut bounds = try_with_capacity(total, "the emitters' bounds")?;
        let mut by_prim = HashMap::new();
        by_prim.try_reserve(primitives).map_err(|_| {
            let entry = size_of::<((u32, u32), u32)>() as u128;
            MemoryError::allocation("the emitters' index", primitives as u128 * entry)
        })?;
        for (emitter, b) in picked {
            list.push(emitter);
            bounds.push(b);
        }
        for (g, geometry) in geometries.iter().enumerate() {
            let g = g as u32;
            for prim in 0..primitive_count(geometry) as u32 {
                let Some(material) = emissive(g, prim) else {
                    continue;
                };
                let (emitter, b) = emitter_bounds(geometry, g, prim, material);
                if b.power() > 0.0 && b.power().is_finite() {
                    by_prim.insert((g, prim), list.len() as u32);
                    list.push(emitter);
                    bounds.push(b);
                }
            }
        }
        let world_emits = match &world.background.map {
            Some(map) => map.can_sample(),
            None => {
                let sky = world.background.horizon.max(world.background.zenith);
                luminance(sky) > 0.0
            }
        };
        let suns = always.iter().filter_map(Light::sun_disc).collect();
        Ok(Self {
            always,
            punctual,
            list,
            tree: LightTree::build(&bounds)?,
            by_prim,
            world: world_emits,
            suns,
        })
    }

    /// Whether there is nothing to sample.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty() && self.always.is_empty() && !self.world
    }

    /// Whether the world emits, so [`Emitters::sample_world`] draws directions.
    pub fn samples_world(&self) -> bool {
        self.world
    }

    /// Whether any emitter is drawn by [`Emitters::sample`] (the others are
    /// [`Emitters::always`]).
    pub fn has_distribution(&self) -> bool {
        !self.list.is_empty()
    }

    /// Picks an emitter for receiver `r` with `u0` (by what it may send there) and draws a
    /// direction towards it from `r.p` with `u1`, `u2`. `None` when nothing was drawn (no
    /// emitters, or one that sends nothing towards `r.p`).
    pub fn sample(&self, world: &World, r: &Receiver, u: [f32; 3]) -> Option<EmitterSample> {
        let p = r.p;
        let (i, pick) = self.tree.sample(r, u[0])?;
        let u = Vec2::new(u[1], u[2]);
        let s = match self.list[i as usize] {
            Emitter::Punctual(k) => usable(punctual_sample(&self.punctual[k as usize], p, u))?,
            Emitter::Triangle { geometry, prim } | Emitter::Sphere { geometry, prim } => {
                sample_primitive(world, geometry, prim, p, u)?
            }
        };
        Some(EmitterSample {
            pdf: s.pdf * pick,
            ..s
        })
    }

    /// The emissive triangles and spheres, as (geometry, primitive), in a fixed order. (With
    /// more than [`Emitters::ALWAYS_SAMPLED`] punctual lights those are picked too; they are not
    /// primitives and not listed.)
    pub fn primitives(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.list.iter().filter_map(|e| match *e {
            Emitter::Punctual(_) => None,
            Emitter::Triangle { geometry, prim } | Emitter::Sphere { geometry, prim } => {
                Some((geometry, prim))
            }
        })
    }

    /// Draws a direction towards the world with `u` (by its map's importance, else uniformly
    /// over the sphere). `None` when the world does not emit or sends nothing along it.
    pub fn sample_world(&self, world: &World, u: Vec2) -> Option<EmitterSample> {
        if !self.world {
            return None;
        }
        let s = match &world.background.map {
            Some(map) => {
                let s = map.sample(u)?;
                EmitterSample {
                    dir: s.dir,
                    distance: f32::INFINITY,
                    radiance: s.radiance,
                    pdf: s.pdf,
                    delta: false,
                    primitive: None,
                }
            }
            None => {
                let dir = uniform_sphere(u);
                EmitterSample {
                    dir,
                    distance: f32::INFINITY,
                    radiance: world.background.radiance(dir),
                    pdf: 1.0 / (4.0 * PI),
                    delta: false,
                    primitive: None,
                }
            }
        };
        usable(s)
    }

    /// The density [`Emitters::sample`] draws direction `dir` for receiver `from` with, for a
    /// ray that found emissive primitive `hit` at `at` (zero if it is not an emitter).
    pub fn pdf_hit(&self, world: &World, hit: &Hit, from: &Receiver, at: Vec3, dir: Vec3) -> f32 {
        self.pdf_primitive(world, hit.geometry.0, hit.prim, from, at, dir)
    }

    /// The density [`Emitters::sample`] draws direction `dir` for receiver `r` with, towards
    /// point `at` of primitive `prim` of geometry `geometry` (zero if it is not an emitter).
    pub fn pdf_primitive(
        &self,
        world: &World,
        geometry: u32,
        prim: u32,
        r: &Receiver,
        at: Vec3,
        dir: Vec3,
    ) -> f32 {
        let from = r.p;
        let Some(&i) = self.by_prim.get(&(geometry, prim)) else {
            return 0.0;
        };
        let pick = self.tree.pmf(r, i);
        if pick <= 0.0 {
            return 0.0;
        }
        match world.scene.geometry(GeometryId(geometry)) {
            Geometry::Mesh(m) => {
                let n = m.face_normal(prim);
                let area = 0.5 * n.length();
                let cos = n.normalize_or_zero().dot(dir).abs();
                let d2 = (at - from).length_squared();
                if cos <= 0.0 || area <= 0.0 {
                    0.0
                } else {
                    pick * d2 / (cos * area)
                }
            }
            Geometry::Spheres(s) => {
                pick * sphere_pdf(s.center(prim), s.radius(prim), from, at, dir)
            }
        }
    }

    /// The discs of suns with an angle that unit direction `dir` (a ray leaving the scene)
    /// sees: for each, its radiance and the density its own light sample (every sun is in
    /// [`Emitters::always`]) draws `dir` with.
    pub fn suns_seen(&self, dir: Vec3) -> impl Iterator<Item = (Vec3, f32)> + '_ {
        (self.suns.iter())
            .filter(move |disc| disc.contains(dir))
            .map(|disc| (disc.radiance, disc.pdf))
    }

    /// The density [`Emitters::sample_world`] draws world direction `dir` with (zero when the
    /// world does not emit).
    pub fn pdf_world(&self, world: &World, dir: Vec3) -> f32 {
        match (self.world, &world.background.map) {
            (true, Some(map)) => map.pdf(dir),
            (true, None) => 1.0 / (4.0 * PI),
            (false, _) => 0.0,
        }
    }
}

/// A direction from `p` towards emissive primitive `prim` of geometry `geometry`, drawn with
/// `u` as [`Emitters::sample`] draws it once that primitive is picked (its density leaves the
/// picking out). `None` for a primitive that is not a triangle or sphere, or that sends nothing
/// towards `p`.
pub fn sample_primitive(
    world: &World,
    geometry: u32,
    prim: u32,
    p: Vec3,
    u: Vec2,
) -> Option<EmitterSample> {
    usable(match world.scene.geometry(GeometryId(geometry)) {
        Geometry::Mesh(_) => sample_triangle(world, geometry, prim, p, u)?,
        Geometry::Spheres(_) => sample_sphere(world, geometry, prim, p, u)?,
    })
}

/// `s` if it can be used: a finite, positive density and some radiance.
fn usable(s: EmitterSample) -> Option<EmitterSample> {
    let ok = s.pdf > 0.0 && s.pdf.is_finite() && s.radiance.max_element() > 0.0;
    ok.then_some(s)
}

/// The axis-aligned bounds (low and high corners) of primitive `prim` of geometry `geometry`.
pub fn primitive_bounds(world: &World, geometry: u32, prim: u32) -> (Vec3, Vec3) {
    match world.scene.geometry(GeometryId(geometry)) {
        Geometry::Mesh(m) => {
            let [a, b, c] =
                m.indices()[prim as usize].map(|v| Vec3::from(m.positions()[v as usize]));
            (a.min(b).min(c), a.max(b).max(c))
        }
        Geometry::Spheres(s) => {
            let (center, r) = (s.center(prim), s.radius(prim));
            (center - Vec3::splat(r), center + Vec3::splat(r))
        }
    }
}

/// A point of a primitive, drawn uniformly by area.
#[derive(Debug, Clone, Copy)]
pub struct PrimitivePoint {
    /// The point.
    pub position: Vec3,
    /// Unit normal: a triangle's front face (its winding's), a sphere's outward one.
    pub normal: Vec3,
    /// Texture coordinates there (as surface points compute them).
    pub uv: Vec2,
    /// The primitive's area (its uniform density is the inverse).
    pub area: f32,
}

/// A point drawn uniformly by area on primitive `prim` of geometry `geometry` with `u` (the
/// draws [`Emitters::sample`] makes on a triangle, or uniformly over a sphere); `None` for a
/// degenerate primitive.
pub fn primitive_point(world: &World, geometry: u32, prim: u32, u: Vec2) -> Option<PrimitivePoint> {
    let p = match world.scene.geometry(GeometryId(geometry)) {
        Geometry::Mesh(m) => {
            let [a, b, c] =
                m.indices()[prim as usize].map(|v| Vec3::from(m.positions()[v as usize]));
            let s = u.x.sqrt();
            let (bu, bv) = (s * (1.0 - u.y), s * u.y);
            let q = a * (1.0 - bu - bv) + b * bu + c * bv;
            let n = (b - a).cross(c - a);
            PrimitivePoint {
                position: q,
                normal: n.normalize_or_zero(),
                uv: m.uv(prim, bu, bv).unwrap_or(Vec2::new(q.x, q.z)),
                area: 0.5 * n.length(),
            }
        }
        Geometry::Spheres(s) => {
            let (center, r) = (s.center(prim), s.radius(prim));
            let n = uniform_sphere(u);
            PrimitivePoint {
                position: center + n * r,
                normal: n,
                uv: sphere_uv(n),
                area: 4.0 * PI * r * r,
            }
        }
    };
    (p.area > 0.0 && p.area.is_finite() && p.normal != Vec3::ZERO).then_some(p)
}

/// A point of the sphere at `center` of `radius`, drawn with `u` uniformly over the disc it
/// shows unit direction `dir`, on the half that faces `dir` (density cos / (pi r^2) per area,
/// cos the angle between its normal and `dir`): where a path leaving the sphere along `dir`
/// starts, by the light it sends that way.
pub fn sphere_point_facing(center: Vec3, radius: f32, dir: Vec3, u: Vec2) -> PrimitivePoint {
    let rho2 = u.x;
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    let (t, b) = crate::shade::basis(dir);
    let r = rho2.sqrt();
    let normal = (t * (r * c) + b * (r * s) + dir * (1.0 - rho2).max(0.0).sqrt()).normalize();
    PrimitivePoint {
        position: center + normal * radius,
        normal,
        uv: sphere_uv(normal),
        area: 4.0 * PI * radius * radius,
    }
}

/// What the light tree knows of a point or spot light: where its light leaves from, which way,
/// and its estimated power (luminance-weighted watts). `None` for a sun, whose light no
/// position tells apart: it is sampled at every vertex.
fn punctual_bounds(light: &Light) -> Option<LightBounds> {
    match *light {
        Light::Point {
            position,
            intensity,
        } => Some(LightBounds::everywhere(
            position,
            position,
            4.0 * PI * luminance(intensity),
        )),
        Light::Spot {
            position,
            direction,
            intensity,
            outer_angle,
            inner_angle,
            radius,
        } => {
            let cos = 0.5 * (inner_angle.cos() + outer_angle.cos());
            let power = 2.0 * PI * (1.0 - cos) * luminance(intensity);
            // Its disc lies within `radius` of the position; light leaves within the outer
            // cone around the axis.
            let r = Vec3::splat(radius.max(0.0));
            let cos_e = outer_angle.cos();
            Some(LightBounds::new(
                position - r,
                position + r,
                power,
                direction,
                1.0,
                cos_e,
                false,
            ))
        }
        Light::Directional { .. } => None,
    }
}

/// A uniformly distributed unit direction.
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn sample_triangle(world: &World, g: u32, prim: u32, p: Vec3, u: Vec2) -> Option<EmitterSample> {
    let Geometry::Mesh(m) = world.scene.geometry(GeometryId(g)) else {
        return None;
    };
    let [a, b, c] = m.indices()[prim as usize].map(|v| Vec3::from(m.positions()[v as usize]));
    // Uniform on the triangle: barycentrics (1 - sqrt(u0), u1 sqrt(u0)) weights of b and c.
    let s = u.x.sqrt();
    let (bu, bv) = (s * (1.0 - u.y), s * u.y);
    let q = a * (1.0 - bu - bv) + b * bu + c * bv;
    let n = (b - a).cross(c - a);
    let area = 0.5 * n.length();
    let d = q - p;
    let d2 = d.length_squared();
    if area <= 0.0 || d2 <= 0.0 {
        return None;
    }
    let dist = d2.sqrt();
    let dir = d / dist;
    let n = n / (2.0 * area);
    let cos = n.dot(dir);
    let material = world.material_of(GeometryId(g), prim);
    // The front face (winding order) faces away from the ray towards it when cos < 0.
    if cos == 0.0 || (material.one_sided && cos > 0.0) {
        return None;
    }
    let uv = m.uv(prim, bu, bv).unwrap_or(Vec2::new(q.x, q.z));
    Some(EmitterSample {
        dir,
        distance: dist,
        radiance: material.emitted(uv),
        pdf: d2 / (cos.abs() * area),
        delta: false,
        primitive: Some((g, prim)),
    })
}

/// Density of a direction towards a sphere drawn by [`sample_sphere`]: uniform in the cone it
/// fills as seen from `from` (outside), else uniform over its area.
fn sphere_pdf(center: Vec3, radius: f32, from: Vec3, at: Vec3, dir: Vec3) -> f32 {
    let d2 = (center - from).length_squared();
    let r2 = radius * radius;
    if d2 > r2 * 1.0001 {
        1.0 / (2.0 * PI * one_minus_cos_max(r2 / d2)).max(1e-30)
    } else {
        let n = (at - center).normalize_or_zero();
        let cos = n.dot(dir).abs();
        let area = 4.0 * PI * r2;
        if cos <= 0.0 {
            0.0
        } else {
            (at - from).length_squared() / (cos * area)
        }
    }
}

fn sample_sphere(world: &World, g: u32, prim: u32, p: Vec3, u: Vec2) -> Option<EmitterSample> {
    let Geometry::Spheres(s) = world.scene.geometry(GeometryId(g)) else {
        return None;
    };
    let (center, radius) = (s.center(prim), s.radius(prim));
    let material = world.material_of(GeometryId(g), prim);
    let to_c = center - p;
    let d2 = to_c.length_squared();
    let r2 = radius * radius;
    if d2 <= r2 * 1.0001 {
        // Inside (or on) the sphere: a uniform point on its surface.
        let n = uniform_sphere(u);
        let q = center + n * radius;
        let d = q - p;
        let dist2 = d.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let dir = d / dist2.sqrt();
        let pdf = sphere_pdf(center, radius, p, q, dir);
        return Some(EmitterSample {
            dir,
            distance: dist2.sqrt(),
            radiance: material.emitted(sphere_uv(n)),
            pdf,
            delta: false,
            primitive: Some((g, prim)),
        });
    }
    // Uniform in the cone of directions the sphere fills, drawn by 1 - cos theta: for a
    // small or far sphere cos theta is within a few ulps of 1, and 1 - cos would be noise.
    let cone = one_minus_cos_max(r2 / d2);
    let one_minus_cos = u.x * cone;
    let sin = (one_minus_cos * (2.0 - one_minus_cos)).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let w = to_c / d2.sqrt();
    let (t, b) = crate::shade::basis(w);
    let dir =
        (t * (sin * phi.cos()) + b * (sin * phi.sin()) + w * (1.0 - one_minus_cos)).normalize();
    // Nearest intersection with the sphere along dir (clamped for rays that graze it), from
    // the ray's distance to the centre measured directly: `d^2 - tc^2` would cancel to noise.
    let tc = to_c.dot(dir);
    let miss = (to_c - dir * tc).length_squared();
    let h2 = (r2 - miss).max(0.0);
    let dist = (tc - h2.sqrt()).max(0.0);
    let n = ((p + dir * dist) - center).normalize_or_zero();
    Some(EmitterSample {
        dir,
        distance: dist,
        radiance: material.emitted(sphere_uv(n)),
        pdf: 1.0 / (2.0 * PI * cone).max(1e-30),
        delta: false,
        primitive: Some((g, prim)),
    })
}

/// `1 - cos theta_max` of the cone a sphere fills, from `x = (r / d)^2` (sin^2 theta_max):
/// `1 - sqrt(1 - x)` written as `x / (1 + sqrt(1 - x))`, exact where the plain form loses
/// every digit (a 1 mm lamp at 2 m: x = 2.5e-7, below f32's resolution next to 1).
fn one_minus_cos_max(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x / (1.0 + (1.0 - x).sqrt())
}

/// Texture coordinates of a unit sphere normal (as surface points compute them).
fn sphere_uv(d: Vec3) -> Vec2 {
    Vec2::new(
        0.5 + d.z.atan2(d.x) / std::f32::consts::TAU,
        0.5 + d.y.clamp(-1.0, 1.0).asin() / PI,
    )
}
