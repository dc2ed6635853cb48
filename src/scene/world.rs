//! The world: a [`SceneDesc`] checked and built into a committed Embree scene, with the
//! materials, lights and sky that shade its hits.

use std::f32::consts::{PI, TAU};
use std::sync::Arc;

use glam::{Vec2, Vec3};

use super::{Background, MAX_LIGHT_VALUE, MAX_MATERIAL_VALUE, MeshMaterials, Object, SceneDesc};
use crate::embree::{
    self, CandidateHit, Device, EmbreeError, Geometry, GeometryId, Hit, HitFilter, LANES, Ray,
    RayPacket16, SceneBuilder, Spheres, TriangleMesh,
};
use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::MAX_COORDINATE;
use crate::shade::{
    Alpha, AlphaMode, Light, LightObject, Material, SurfacePoint, SurfacePoints16, Texture,
};

/// Why a scene could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene has no objects.
    #[error("the scene has no objects")]
    Empty,
    /// An object refers to a material index the scene does not have.
    #[error("object {object} uses material {material}, but the scene has {count} materials")]
    MissingMaterial {
        /// Index of the object in [`SceneDesc::objects`].
        object: usize,
        /// The material index it uses.
        material: usize,
        /// Number of materials in the scene.
        count: usize,
    },
    /// A value the world cannot use (non-finite or out of range), or a per-triangle material
    /// list of the wrong length.
    #[error("{what} must be {expected}")]
    Invalid {
        /// What the value is (`object 3's radius`, ...).
        what: String,
        /// What it must be.
        expected: &'static str,
    },
    /// Primitives piled up in one place, which every ray there would test
    /// ([`super::stacking`]).
    #[error(
        "{} primitives at most {} across are piled up within {} of ({}, {}, {}): every ray \
         there would test them all (at most {} may share a place; exact repeats are skipped \
         when loading, near ones are not)",
        .0.count, .0.size, .0.size, .0.at.x, .0.at.y, .0.at.z, super::stacking::MAX_STACKED
    )]
    Stacked(super::stacking::Stack),
    /// Embree failed to build the scene.
    #[error(transparent)]
    Embree(#[from] EmbreeError),
    /// What the scene's emitters need to be sampled could not be allocated (boxed: it is
    /// rare and large).
    #[error(transparent)]
    Memory(Box<crate::limits::MemoryError>),
}

impl From<crate::limits::MemoryError> for SceneError {
    fn from(e: crate::limits::MemoryError) -> Self {
        Self::Memory(Box::new(e))
    }
}

/// Material lookup for one Embree geometry.
#[derive(Debug, Clone)]
enum GeometryMaterials {
    One(usize),
    PerPrimitive(Vec<u32>),
}

impl GeometryMaterials {
    /// The material of primitive `prim` (`None` for a primitive beyond the list).
    fn of(&self, prim: u32) -> Option<usize> {
        match self {
            Self::One(m) => Some(*m),
            Self::PerPrimitive(ids) => ids.get(prim as usize).map(|&m| m as usize),
        }
    }
}

/// Embree's hit filter for surfaces some rays pass through: alpha (MASK: alpha below the
/// cutoff; BLEND: with probability 1 - alpha, by [`blend_coin`]), which camera, mirror and shadow
/// rays all pass, and light objects ([`LightObject`]), which shadow rays pass, camera rays pass
/// unless they are visible to the camera, and every ray passes from behind when one-sided.
struct SurfaceFilter {
    /// The mesh (`None` for the spheres, which are opaque and have no back).
    mesh: Option<TriangleMesh>,
    materials: GeometryMaterials,
    /// What every material lets through, by material index.
    rules: Arc<[PassRule]>,
}

/// What one material lets through.
#[derive(Clone)]
struct PassRule {
    alpha: Option<Alpha>,
    light: Option<LightObject>,
    one_sided: bool,
}

impl PassRule {
    fn of(m: &Material) -> Self {
        Self {
            alpha: m.maps.alpha.clone(),
            light: m.light,
            one_sided: m.one_sided,
        }
    }

    /// Whether any ray may pass through a surface of this material on a mesh (alpha or a
    /// light object) or on a sphere (a light object only: spheres stay opaque to alpha).
    fn passes(&self, mesh: bool) -> bool {
        self.light.is_some() || (mesh && self.alpha.is_some())
    }
}

/// A number in [0, 1) fixed by a ray (origin, direction) and the primitive it meets: BLEND's
/// coin. The same for every thread count, packet width and traversal order.
fn blend_coin(hit: &CandidateHit) -> f32 {
    let (o, d) = (hit.origin, hit.dir);
    let mut x = crate::sampler::hash64(hit.prim as u64 ^ 0xa1fa_b1e4_d000_0000);
    for c in [o.x, o.y, o.z, d.x, d.y, d.z] {
        x = crate::sampler::hash64(x ^ c.to_bits() as u64);
    }
    (x >> 40) as f32 / (1u64 << 24) as f32
}

impl HitFilter for SurfaceFilter {
    fn accept(&self, hit: &CandidateHit) -> bool {
        let Some(rule) = self.materials.of(hit.prim).and_then(|m| self.rules.get(m)) else {
            return true;
        };
        let mesh = self
            .mesh
            .as_ref()
            .filter(|mesh| (hit.prim as usize) < mesh.triangle_count());
        if let Some(light) = rule.light {
            let from_behind = || mesh.is_some_and(|m| m.face_normal(hit.prim).dot(hit.dir) > 0.0);
            if hit.shadow || (hit.camera && !light.camera) || (rule.one_sided && from_behind()) {
                return false;
            }
        }
        let (Some(alpha), Some(mesh)) = (&rule.alpha, mesh) else {
            return true;
        };
        // As shading does: the mesh's UVs, else the hit's world (x, z).
        let uv = mesh.uv(hit.prim, hit.u, hit.v).unwrap_or_else(|| {
            let [a, b, c] =
                mesh.indices()[hit.prim as usize].map(|i| Vec3::from(mesh.positions()[i as usize]));
            let p = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
            Vec2::new(p.x, p.z)
        });
        match alpha.mode {
            AlphaMode::Mask { cutoff } => alpha.at(uv) >= cutoff,
            AlphaMode::Blend => {
                let a = alpha.at(uv);
                a >= 1.0 || (a > 0.0 && blend_coin(hit) < a)
            }
        }
    }
}

/// Adds every sphere of the scene as one geometry (filtered when a light object is among them)
/// and returns its material lookup.
fn add_spheres(
    builder: &mut SceneBuilder,
    spheres: Vec<(Vec3, f32)>,
    materials: Vec<u32>,
    rules: &Arc<[PassRule]>,
) -> Result<GeometryMaterials, EmbreeError> {
    let spheres = Spheres::new(spheres)?;
    let passes = materials.iter().any(|&m| rules[m as usize].passes(false));
    let lookup = GeometryMaterials::PerPrimitive(materials);
    if passes {
        let filter = SurfaceFilter {
            mesh: None,
            materials: lookup.clone(),
            rules: rules.clone(),
        };
        builder.add_spheres_filtered(spheres, Arc::new(filter))?;
    } else {
        builder.add_spheres(spheres)?;
    }
    Ok(lookup)
}

/// A scene ready to trace: the committed Embree scene and everything needed to shade hits.
pub struct World {
    /// The committed Embree scene.
    pub scene: embree::Scene,
    /// The materials, as in [`SceneDesc::materials`].
    pub materials: Vec<Material>,
    geometry_materials: Vec<GeometryMaterials>,
    /// Some material has a normal map (else surface points skip looking for one).
    normal_mapped: bool,
    /// Lights that cast shadows.
    pub lights: Vec<Light>,
    /// Ambient light (linear RGB), unshadowed: adds albedo x ambient x (1 - mirror) to every
    /// hit.
    pub ambient: Vec3,
    /// What rays that hit nothing see.
    pub background: Background,
    /// Everything that emits, as the path tracer samples it.
    pub emitters: super::emitters::Emitters,
}

fn check_value(
    what: impl Fn() -> String,
    ok: bool,
    expected: &'static str,
) -> Result<(), SceneError> {
    if ok {
        Ok(())
    } else {
        Err(SceneError::Invalid {
            what: what(),
            expected,
        })
    }
}

fn colour_ok(c: Vec3, max: f32) -> bool {
    c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= max
}

fn point_ok(p: Vec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORDINATE
}

/// What a colour value is checked against.
const COLOUR: &str = "finite and from 0 to 1e6";

/// Every number that reaches the renderer is finite and in a range that keeps every ray
/// within what Embree accepts and every shading term finite (see [`MAX_COORDINATE`],
/// [`MAX_MATERIAL_VALUE`], [`MAX_LIGHT_VALUE`]).
fn check_ranges(desc: &SceneDesc) -> Result<(), SceneError> {
    for (i, m) in desc.materials.iter().enumerate() {
        check_material(i, m)?;
    }
    for (i, light) in desc.lights.iter().enumerate() {
        check_light(i, light)?;
    }
    check_value(
        || "ambient".into(),
        colour_ok(desc.ambient, MAX_MATERIAL_VALUE),
        COLOUR,
    )?;
    check_value(
        || "background".into(),
        colour_ok(desc.background.horizon, MAX_MATERIAL_VALUE)
            && colour_ok(desc.background.zenith, MAX_MATERIAL_VALUE),
        COLOUR,
    )?;
    for (i, object) in desc.objects.iter().enumerate() {
        let extent = match object {
            Object::Sphere { center, radius, .. } => center
                .is_finite()
                .then(|| center.abs().max_element() + radius.abs()),
            Object::Mesh { mesh, .. } => Some(
                mesh.positions()
                    .iter()
                    .map(|p| Vec3::from(*p).abs().max_element())
                    .fold(0.0, f32::max),
            ),
        };
        check_value(
            || format!("object {i}'s geometry"),
            extent.is_some_and(|e| e <= MAX_COORDINATE),
            "within 1e15 of the origin (after its transform)",
        )?;
    }
    Ok(())
}

/// The largest index of refraction a material may have (diamond is 2.4).
const MAX_IOR: f32 = 10.0;

/// [`check_ranges`] of material `i` (also run by the scene file's loader on each
/// `[[materials]]` table, to place the error).
pub(crate) fn check_material(i: usize, m: &Material) -> Result<(), SceneError> {
    match &m.base_color {
        Texture::Constant(c) => check_value(
            || format!("material {i}'s colour"),
            colour_ok(*c, MAX_MATERIAL_VALUE),
            COLOUR,
        )?,
        Texture::Procedural { a, b, scale, .. } => {
            check_value(
                || format!("material {i}'s pattern colours"),
                colour_ok(*a, MAX_MATERIAL_VALUE) && colour_ok(*b, MAX_MATERIAL_VALUE),
                COLOUR,
            )?;
            check_value(
                || format!("material {i}'s pattern scale"),
                scale.is_finite() && scale.abs() <= MAX_MATERIAL_VALUE,
                "finite and at most 1e6 in magnitude",
            )?;
        }
        Texture::Image { tint, .. } => check_value(
            || format!("material {i}'s texture tint"),
            colour_ok(*tint, MAX_MATERIAL_VALUE),
            COLOUR,
        )?,
    }
    check_value(
        || format!("material {i}'s metallic and roughness"),
        (0.0..=1.0).contains(&m.metallic) && (0.0..=1.0).contains(&m.roughness),
        "from 0 to 1",
    )?;
    check_value(
        || format!("material {i}'s transmission"),
        (0.0..=1.0).contains(&m.transmission),
        "from 0 to 1",
    )?;
    check_value(
        || format!("material {i}'s ior"),
        (1.0..=MAX_IOR).contains(&m.ior),
        "from 1 to 10",
    )?;
    check_value(
        || format!("material {i}'s emission"),
        colour_ok(m.emission, MAX_MATERIAL_VALUE),
        COLOUR,
    )?;
    if let Some(alpha) = &m.maps.alpha {
        let cutoff_ok = match alpha.mode {
            AlphaMode::Mask { cutoff } => cutoff.is_finite() && cutoff >= 0.0,
            AlphaMode::Blend => true,
        };
        check_value(
            || format!("material {i}'s alpha"),
            (0.0..=1.0).contains(&alpha.factor) && cutoff_ok,
            "from 0 to 1, with a finite cutoff >= 0",
        )?;
    }
    if let Some(normal) = &m.maps.normal {
        check_value(
            || format!("material {i}'s normal map scale"),
            normal.scale.is_finite() && normal.scale.abs() <= MAX_MATERIAL_VALUE,
            "finite and at most 1e6 in magnitude",
        )?;
    }
    Ok(())
}

/// The largest spot light radius accepted (scene units).
const MAX_LIGHT_RADIUS: f32 = 1e6;

/// [`check_ranges`] of light `i` (also run by the scene file's loader on each `[[lights]]`
/// table, to place the error).
pub(crate) fn check_light(i: usize, light: &Light) -> Result<(), SceneError> {
    let direction_ok = |d: Vec3| d.is_finite() && d.length_squared() > 0.0;
    let (place, power, place_ok) = match *light {
        Light::Point {
            position,
            intensity,
        } => (position, intensity, point_ok(position)),
        Light::Directional {
            direction,
            irradiance,
            angle,
        } => {
            check_value(
                || format!("light {i}'s sun angle ({angle} radians)"),
                (0.0..=std::f32::consts::PI).contains(&angle),
                "from 0 to pi",
            )?;
            (direction, irradiance, direction_ok(direction))
        }
        Light::Spot {
            position,
            direction,
            intensity,
            inner_angle,
            outer_angle,
            radius,
        } => {
            check_value(
                || format!("light {i}'s radius ({radius})"),
                (0.0..=MAX_LIGHT_RADIUS).contains(&radius),
                "from 0 to 1e6",
            )?;
            check_value(
                || format!("light {i}'s cone angles ({inner_angle}, {outer_angle} radians)"),
                (0.0..=std::f32::consts::FRAC_PI_2).contains(&outer_angle)
                    && (0.0..=outer_angle).contains(&inner_angle),
                "0 <= inner <= outer <= pi / 2",
            )?;
            (
                position,
                intensity,
                point_ok(position) && direction_ok(direction),
            )
        }
    };
    check_value(
        || format!("light {i}'s position or direction ({place:?})"),
        place_ok,
        "a position within 1e15 of the origin, or a non-zero direction",
    )?;
    check_value(
        || format!("light {i}'s intensity"),
        colour_ok(power, MAX_LIGHT_VALUE),
        "finite and from 0 to 1e12",
    )?;
    Ok(())
}

impl World {
    /// Validates the description and builds the Embree scene (the BVH) from it.
    pub fn build(desc: &SceneDesc, device: &Device) -> Result<World, SceneError> {
        if desc.objects.is_empty() {
            return Err(SceneError::Empty);
        }
        let count = desc.materials.len();
        let check_material = |object: usize, material: usize| {
            if material < count {
                Ok(())
            } else {
                Err(SceneError::MissingMaterial {
                    object,
                    material,
                    count,
                })
            }
        };
        // Lights and ambient light are checked with everything else numeric.
        check_ranges(desc)?;
        if let Some(stack) = super::stacking::find_stack(desc)? {
            return Err(SceneError::Stacked(stack));
        }

        let mut builder = SceneBuilder::new(device)?;
        let mut geometry_materials = Vec::new();
        let rules: Arc<[PassRule]> = desc.materials.iter().map(PassRule::of).collect();
        let mut spheres = Vec::new();
        let mut sphere_materials = Vec::new();
        for (i, object) in desc.objects.iter().enumerate() {
            match object {
                Object::Sphere {
                    center,
                    radius,
                    material,
                } => {
                    check_material(i, *material)?;
                    spheres.push((*center, *radius));
                    sphere_materials.push(*material as u32);
                }
                Object::Mesh { mesh, materials } => {
                    let lookup = match materials {
                        MeshMaterials::One(m) => {
                            check_material(i, *m)?;
                            GeometryMaterials::One(*m)
                        }
                        MeshMaterials::PerTriangle(ids) => {
                            if ids.len() != mesh.triangle_count() {
                                return Err(SceneError::Invalid {
                                    what: format!("object {i}'s per-triangle material list"),
                                    expected: "one entry per triangle",
                                });
                            }
                            if let Some(&bad) = ids.iter().find(|&&m| m as usize >= count) {
                                check_material(i, bad as usize)?;
                            }
                            GeometryMaterials::PerPrimitive(ids.clone())
                        }
                    };
                    let passes = match &lookup {
                        GeometryMaterials::One(m) => rules[*m].passes(true),
                        GeometryMaterials::PerPrimitive(ids) => {
                            ids.iter().any(|&m| rules[m as usize].passes(true))
                        }
                    };
                    if passes {
                        let filter = SurfaceFilter {
                            mesh: Some(mesh.clone()),
                            materials: lookup.clone(),
                            rules: rules.clone(),
                        };
                        builder.add_mesh_filtered(mesh.clone(), Arc::new(filter))?;
                    } else {
                        builder.add_mesh(mesh.clone())?;
                    }
                    geometry_materials.push(lookup);
                }
            }
        }
        if !spheres.is_empty() {
            let lookup = add_spheres(&mut builder, spheres, sphere_materials, &rules)?;
            geometry_materials.push(lookup);
        }
        let mut world = World {
            scene: builder.commit()?,
            materials: desc.materials.clone(),
            geometry_materials,
            normal_mapped: desc.materials.iter().any(|m| m.maps.normal.is_some()),
            lights: desc.lights.clone(),
            ambient: desc.ambient,
            background: desc.background.clone(),
            emitters: Default::default(),
        };
        world.emitters = super::emitters::Emitters::build(&world)?;
        Ok(world)
    }

    /// The material of primitive `prim` of geometry `geometry`.
    pub fn material_of(&self, geometry: GeometryId, prim: u32) -> &Material {
        &self.materials[self.index_of(geometry, prim)]
    }

    /// Index into `materials` of the surface a hit found.
    pub fn material_index(&self, hit: &Hit) -> usize {
        self.index_of(hit.geometry, hit.prim)
    }

    fn index_of(&self, geometry: GeometryId, prim: u32) -> usize {
        match &self.geometry_materials[geometry.0 as usize] {
            GeometryMaterials::One(m) => *m,
            GeometryMaterials::PerPrimitive(ids) => ids[prim as usize] as usize,
        }
    }

    /// The material of the surface a hit found.
    pub fn material(&self, hit: &Hit) -> &Material {
        &self.materials[self.material_index(hit)]
    }

    /// [`World::surface_point`] of every lane of a traced `packet` whose bit is set in `hits`
    /// (lanes that hit; see [`RayPacket16::hit_mask`]), bit for bit equal to it. The
    /// arithmetic common to all lanes (positions, normalisation) runs over all 16 lanes at once;
    /// other lanes of `out` get unspecified values.
    pub fn surface_points16(&self, packet: &RayPacket16, hits: u32, out: &mut SurfacePoints16) {
        let (org, dir, t) = (packet.origins(), packet.dirs(), packet.tfars());
        let ng = packet.geometric_normals();
        for k in 0..3 {
            for lane in 0..LANES {
                out.position[k][lane] = org[k][lane] + dir[k][lane] * t[lane];
            }
        }
        let pos = &out.position;
        // Per lane, the vector whose normalize_or_zero is the normal (`raw`), unless the lane
        // already has its normal (`done`: interpolated mesh normals).
        let mut raw = [[0.0f32; LANES]; 3];
        let mut done = 0u32;
        let mut sphere = 0u32;
        for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
            let hit = packet.hit(lane).expect("lanes in `hits` hit");
            match self.scene.geometry(hit.geometry) {
                Geometry::Spheres(s) => {
                    let c = s.center(hit.prim);
                    let r = s.radius(hit.prim);
                    raw[0][lane] = (pos[0][lane] - c.x) / r;
                    raw[1][lane] = (pos[1][lane] - c.y) / r;
                    raw[2][lane] = (pos[2][lane] - c.z) / r;
                    sphere |= 1 << lane;
                }
                Geometry::Mesh(m) => {
                    match m
                        .shading_normal(hit.prim, hit.u, hit.v)
                        .filter(|n| *n != Vec3::ZERO)
                    {
                        Some(n) => {
                            for k in 0..3 {
                                out.normal[k][lane] = n[k];
                            }
                            done |= 1 << lane;
                        }
                        None => {
                            for k in 0..3 {
                                raw[k][lane] = ng[k][lane];
                            }
                        }
                    }
                }
            }
        }
        // normalize_or_zero, as glam evaluates it, in every lane.
        let mut unit = [[0.0f32; LANES]; 3];
        for lane in 0..LANES {
            let (x, y, z) = (raw[0][lane], raw[1][lane], raw[2][lane]);
            let rcp = 1.0 / (x * x + y * y + z * z).sqrt();
            let ok = rcp.is_finite() && rcp > 0.0;
            unit[0][lane] = if ok { x * rcp } else { 0.0 };
            unit[1][lane] = if ok { y * rcp } else { 0.0 };
            unit[2][lane] = if ok { z * rcp } else { 0.0 };
        }
        for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
            let normal = if done & (1 << lane) != 0 {
                Vec3::new(
                    out.normal[0][lane],
                    out.normal[1][lane],
                    out.normal[2][lane],
                )
            } else {
                Vec3::new(unit[0][lane], unit[1][lane], unit[2][lane])
            };
            let (uv, mesh_hit) = if sphere & (1 << lane) != 0 {
                let d = normal;
                let uv = Vec2::new(
                    0.5 + d.z.atan2(d.x) / TAU,
                    0.5 + d.y.clamp(-1.0, 1.0).asin() / PI,
                );
                (uv, None)
            } else {
                let hit = packet.hit(lane).expect("lanes in `hits` hit");
                let Geometry::Mesh(m) = self.scene.geometry(hit.geometry) else {
                    unreachable!("non-sphere lanes hit meshes")
                };
                let uv = m
                    .uv(hit.prim, hit.u, hit.v)
                    .unwrap_or(Vec2::new(pos[0][lane], pos[2][lane]));
                (uv, Some(hit))
            };
            out.uv[lane] = uv;
            let view = Vec3::new(dir[0][lane], dir[1][lane], dir[2][lane]);
            let normal = self.facing_normal(mesh_hit.as_ref(), uv, normal, view);
            for k in 0..3 {
                out.normal[k][lane] = normal[k];
            }
        }
    }

    /// The shading `normal` of a hit (`hit`: on a mesh, else None) turned to face against
    /// `view`: normal-mapped where the material has a normal map, the unperturbed normal then
    /// deciding the side.
    fn facing_normal(&self, hit: Option<&Hit>, uv: Vec2, normal: Vec3, view: Vec3) -> Vec3 {
        let bump = match hit {
            Some(hit) if self.normal_mapped => self.normal_map(hit, uv),
            _ => None,
        };
        let (base, normal) = bump.unwrap_or((normal, normal));
        if base.dot(view) > 0.0 {
            -normal
        } else {
            normal
        }
    }

    /// For a hit on a mesh with tangents whose material has a normal map: the unperturbed unit
    /// normal (interpolated, else the face normal in winding order, which the tangents'
    /// handedness refers to) and the normal-mapped one. `None` otherwise.
    fn normal_map(&self, hit: &Hit, uv: Vec2) -> Option<(Vec3, Vec3)> {
        let map = self.material(hit).maps.normal.as_ref()?;
        let Geometry::Mesh(m) = self.scene.geometry(hit.geometry) else {
            return None;
        };
        let (t, w) = m.tangent(hit.prim, hit.u, hit.v)?;
        let n = m
            .shading_normal(hit.prim, hit.u, hit.v)
            .filter(|n| *n != Vec3::ZERO)
            .unwrap_or_else(|| m.face_normal(hit.prim).normalize_or_zero());
        let t = (t - n * n.dot(t)).normalize_or_zero();
        if n == Vec3::ZERO || t == Vec3::ZERO {
            return None;
        }
        Some((n, map.perturb(uv, n, t, w)))
    }

    /// Position, shading normal (facing the ray) and texture coordinates of a hit.
    pub fn surface_point(&self, ray: &Ray, hit: &Hit) -> SurfacePoint {
        let position = ray.at(hit.t);
        let (normal, uv) = match self.scene.geometry(hit.geometry) {
            Geometry::Spheres(s) => {
                let d = ((position - s.center(hit.prim)) / s.radius(hit.prim)).normalize_or_zero();
                let uv = Vec2::new(
                    0.5 + d.z.atan2(d.x) / TAU,
                    0.5 + d.y.clamp(-1.0, 1.0).asin() / PI,
                );
                (d, uv)
            }
            Geometry::Mesh(m) => {
                let n = m
                    .shading_normal(hit.prim, hit.u, hit.v)
                    .filter(|n| *n != Vec3::ZERO)
                    .unwrap_or_else(|| hit.ng.normalize_or_zero());
                // Without UVs, project the world position onto the ground plane (x, z).
                let uv = m
                    .uv(hit.prim, hit.u, hit.v)
                    .unwrap_or(Vec2::new(position.x, position.z));
                (n, uv)
            }
        };
        let normal = self.facing_normal(Some(hit), uv, normal, ray.dir);
        SurfacePoint {
            position,
            normal,
            uv,
        }
    }
}

impl HasKind for SceneError {
    fn kind(&self) -> ErrorKind {
        match self {
            // Geometry Embree refused came from the scene.
            Self::Embree(e) => e.kind_or(ErrorKind::BadInput),
            // A budget of time the scene would exceed.
            Self::Stacked(_) | Self::Memory(_) => ErrorKind::ResourceLimit,
            _ => ErrorKind::BadInput,
        }
    }
}
