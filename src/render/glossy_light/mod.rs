//! Lamps seen in glossy surfaces (point and spot lights, and emissive triangles and spheres),
//! traced from the light as well as from the camera: light tracing through one reflection,
//! combined with the camera's strategies by multiple importance sampling.
//!
//! **Why.** A lamp's highlight on a polished surface (brass, chrome, lacquer) is, out of focus,
//! a bokeh disc of the lamp's mirror image. A camera sample there finds it only when its lens
//! position happens to look along the reflection (a fraction: sharp highlight / disc), so at
//! 16 or 128 samples the disc is a cloud of speckles, and more samples barely help. From the
//! light's side the same paths are easy: a direction from the lamp that meets the glossy
//! surface, then either
//! - **t = 1**: a point on the aperture, uniformly, and a shadow ray between the two (good where
//!   the lobe is wider than the aperture seen from the surface), or
//! - **t = 0**: a direction drawn from the surface's BSDF, followed to the lens plane; it counts
//!   where it crosses the aperture (good for near-mirrors, whose narrow lobes fall into the
//!   aperture whole).
//!
//! The thin lens says where on the film each landed path belongs ([`crate::camera::Lens::film_point`])
//! and it is splatted there, as [`super::light_trace`] does for small lamps.
//!
//! **Weights.** The camera's strategies (a film point and a lens point, then the lamp by
//! next-event estimation or, for an emitter, by a BSDF sample) and the two light strategies
//! sample the same paths (lamp point y, surface point x, lens point u). Their densities,
//! counted per steradian at u, per unit lens area and per steradian of y seen from x, with `N`
//! light paths, `n` camera samples per pixel (`spp`), `A` the aperture's area:
//! - camera, light sample: `n per_sr / A * p_l` (`per_sr`: film area per steradian at u,
//!   [`crate::camera::Landing`]; `p_l` the light sample's density of y, 1 for a punctual
//!   light);
//! - camera, BSDF sample (emitters only): `n per_sr / A * p_f`, p_f the BSDF's density of the
//!   direction towards y;
//! - t = 1: `N p_u p_y / A`, with `p_u` the light path's density of x converted to the solid
//!   angle at u: `p_w cos_l / d_l^2 * d_u^2 / cos_u` (p_w the lamp's direction density, cos and
//!   d the angles to x's geometric normal and the distances to the lamp and to u), and `p_y`
//!   its density of the lamp's point (1 for a punctual light; `Source::position_density`);
//! - t = 0: `N p_u p_y p_b cos_a / d_u^2`, p_b the BSDF's density of the direction towards u
//!   given the lamp's, cos_a that direction's angle to the view axis.
//!
//! Each takes the power heuristic's share of the path; the shares sum to one whatever the
//! surface, so the sum of the estimators is unbiased. Both sides compute them from the same
//! quantities (`GlossyPaths::densities`); where the lamp's direction sampling cannot reach a
//! point (outside every cone below) the camera's strategies share it as they would alone.
//!
//! **Which paths.** The first surface a lamp's ray meets, when its BSDF is glossy
//! ([`eligible`]: no rougher than [`MAX_ROUGHNESS`], opaque, not a perfect mirror) and it is
//! out of focus (a CoC of at least [`MIN_COC_PX`]: a sharp highlight is found as well by the
//! camera's stratified samples), seen directly through a thin lens with an aperture, in the
//! path tracer with light tracing on. The lamps: every point and spot light sampled at every
//! vertex, and (with multiple importance sampling and room for a bounce, which the camera's
//! BSDF strategy needs) the [`MAX_PRIMITIVE_LAMPS`] most powerful emissive triangles and
//! spheres; a triangle's paths start uniformly over its area, a sphere's uniformly over the
//! disc it shows the path's direction. Suns and the world stay with the camera (they have no
//! position to trace from), as do emitters beyond that count.
//!
//! **Caustics** (`caustic.rs`). Each lamp also takes a second set of paths, with its own pilot
//! and budget (`Role`): on from the glossy surface by a BSDF sample to the rough surface it
//! lights, and from there into the lens. Those paths are the light paths' alone (a partition,
//! not a mixture: the camera drops them). A parallel sun takes these paths too, from discs
//! across its beam (`beam.rs`); its highlights stay with the camera.
//!
//! **Where the lamp's paths go.** Directions are drawn within cones around the bounds of the
//! geometry whose materials can be glossy, each cone's directions on a [`GRID`] x [`GRID`] grid
//! (`Aim`): from a punctual light or an emissive sphere's centre, cones that hold each bound
//! as seen from all of the lamp; from the point an emissive triangle's path leaves (drawn
//! first), cones that hold the bound alone (a softbox's cones from its centre would hold a
//! small ball in a sliver of their directions).
//! Only a small patch of a curved mirror sends a lamp's light into the lens, so a pilot of
//! [`PILOT`] paths drawn evenly measures how much light each cell lands, and the render's paths
//! draw cells in proportion to it ([`DEFENSIVE`] of them evenly, so nothing the pilot missed
//! loses its density). Point and spot lights take [`PILOT`] pilot paths each, emitters share
//! [`EMITTER_PILOTS`] times that. A lamp whose pilot lands nothing is left to the camera
//! entirely. The paths number a quarter of a dense render's camera samples, shared by the
//! lamps in proportion to the light their pilots landed ([`SHARED`] of them evenly). A light
//! path's direction density is its cell's, as drawn; the camera's side measures the cell from
//! the direction, which within float rounding of a cell's edge may give its neighbour's: the
//! weights there need not sum to one, the only (bounded, negligible) departure from an
//! unbiased estimate (`Lamp::pdf`).
//!
//! **Deterministic.** Paths are numbered per lamp (Owen-scrambled Sobol points keyed by it),
//! traced in fixed blocks and splatted in block order: the image is the same for any thread
//! count, and a region gets exactly the splats the full frame gives it (every region traces
//! every path: a reflection may land anywhere).

use std::collections::{HashMap, HashSet};
use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3};

use super::light_trace::{Splat, splat_blocks};
use super::region::Region;
use super::site::SiteShader;
use super::trace::{RayKind, Tally, trace_depth, trace_shadows};
use super::{Progress, RenderError};
use crate::camera::{ApertureShape, Camera, CameraLens, Landing, Lens, LensFilter};
use crate::embree::{GeometryId, LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
use crate::limits::{MemoryError, try_with_capacity};
use crate::sampler::{path_numbers, sample_key};
use crate::scene::World;
use crate::scene::emitters::{
    PrimitivePoint, Receiver, primitive_bounds, primitive_point, punctual_sample,
    sphere_point_facing,
};
use crate::settings::{Integrator, Mode, RenderSettings, Strategy};
use crate::shade::{Bsdf, Light, Material, SurfacePoint, SurfacePoints16, basis, luminance};

mod beam;
mod caustic;

pub use caustic::receives;

use beam::Beam;

/// Surfaces at most this rough (perceptual roughness, GGX alpha = its square) take light paths.
/// Rougher lobes are wide enough that the camera's lens samples find the lamp's reflection
/// often; light paths spent there would mostly be outweighed.
pub const MAX_ROUGHNESS: f32 = 0.3;
/// Surfaces blurred less than this (circle of confusion, pixels) stay with the camera: its
/// stratified samples find a sharp highlight as well as light paths scattered over the film
/// would, and better.
pub const MIN_COC_PX: f32 = 4.0;
/// Light paths per work item.
const BLOCK: u32 = 4096;
/// Keys the light paths' sample streams apart from the camera's and the small lamps'.
const SALT: u64 = 0x676c_6f73_7379_5f6c;
/// Light paths per camera sample of a dense render (all lamps together).
const PATHS_PER_SAMPLE: f64 = 0.25;
/// The most cones a lamp samples directions in (more glossy spheres share one per geometry).
const MAX_CONES: usize = 64;
/// Cells per side of a cone's grid of directions, which the pilot paths weigh.
pub const GRID: usize = 16;
/// Pilot paths per lamp: where the lamp's light lands, to draw the render's paths there (and
/// how many of them each lamp gets).
pub const PILOT: u32 = 65536;
/// Emissive primitives share [`PILOT`] times this many pilot paths (at most [`PILOT`] and at
/// least [`MIN_PILOT`] each): a scene may have dozens of small lamps, most of whose
/// reflections the camera finds well.
pub const EMITTER_PILOTS: usize = 2;
/// The fewest pilot paths a lamp takes.
pub const MIN_PILOT: u32 = 4096;
/// The share of the light paths split evenly between the lamps; the rest go to each in
/// proportion to the light its pilot landed.
pub const SHARED: f64 = 0.1;
/// The most emissive primitives that take light paths (the most powerful; the others stay
/// with the camera).
pub const MAX_PRIMITIVE_LAMPS: usize = 32;
/// The share of each lamp's paths drawn evenly over its cones whatever the pilot found (so
/// every direction keeps a density and what the pilot missed is still found).
pub const DEFENSIVE: f32 = 0.25;

/// Whether the camera and the lamps share the light a surface of BSDF `b` reflects: glossy,
/// opaque and not a perfect mirror (whose reflection of a point lamp no path finds).
#[inline]
pub fn eligible(b: &Bsdf) -> bool {
    b.roughness <= MAX_ROUGHNESS && b.transmission <= 0.0 && !b.is_delta()
}

/// Whether a surface of `m` can be [`eligible`] somewhere (its roughness texture can only
/// lower the factor).
fn may_be_glossy(m: &Material) -> bool {
    m.transmission <= 0.0 && (m.roughness <= MAX_ROUGHNESS || m.maps.metal_rough.is_some())
}

/// A cone of directions from a lamp, sampled uniformly.
#[derive(Debug, Clone, Copy)]
struct Cone {
    axis: Vec3,
    /// 1 - the cosine of its half-angle (2: every direction), kept as such: a small or far
    /// sphere's cone has a cosine within a few float steps of 1.
    one_minus: f32,
    /// 1 / its solid angle.
    inv_solid_angle: f32,
}

impl Cone {
    /// The cone from `from` that holds the sphere at `centre` of `radius`.
    fn towards(from: Vec3, centre: Vec3, radius: f32) -> Option<Self> {
        let v = centre - from;
        let d = v.length();
        if !(d.is_finite() && radius.is_finite()) {
            return None;
        }
        if d <= radius * 1.001 {
            return Some(Self {
                axis: Vec3::Z,
                one_minus: 2.0,
                inv_solid_angle: 1.0 / (4.0 * PI),
            });
        }
        let sin2 = (radius / d).powi(2);
        let cos = (1.0 - sin2).max(0.0).sqrt();
        // 1 - cos without cancellation for small cones.
        let one_minus = sin2 / (1.0 + cos);
        (one_minus > 0.0).then(|| Self {
            axis: v / d,
            one_minus,
            inv_solid_angle: 1.0 / (TAU * one_minus),
        })
    }

    /// Where unit `dir` is in the unit square [`Cone::sample`] maps onto the cone, if inside.
    fn square(&self, dir: Vec3) -> Option<Vec2> {
        // 1 - cos as |dir - axis|^2 / 2: exact for small angles, where 1 - dot is not.
        let one_minus = 0.5 * (dir - self.axis).length_squared();
        let u1 = one_minus / self.one_minus;
        if u1.is_nan() || u1 > 1.0 {
            return None;
        }
        let (t, b) = basis(self.axis);
        let u2 = dir.dot(b).atan2(dir.dot(t)) / TAU;
        Some(Vec2::new(u1, if u2 < 0.0 { u2 + 1.0 } else { u2 }))
    }

    /// The cell of the cone's [`GRID`] x [`GRID`] grid that unit square position `q` is in.
    fn cell(q: Vec2) -> usize {
        let i = ((q.x * GRID as f32) as usize).min(GRID - 1);
        let j = ((q.y * GRID as f32) as usize).min(GRID - 1);
        i * GRID + j
    }

    /// A direction uniformly within the cone, from a point `u` of the unit square. Drawn by
    /// 1 - cos theta, as [`Cone::square`] measures it back: through cos theta, a small cone's
    /// rows of cells would blur by float steps of 1.
    fn sample(&self, u: Vec2) -> Vec3 {
        let one_minus = (u.x * self.one_minus).min(2.0);
        let sin = (one_minus * (2.0 - one_minus)).max(0.0).sqrt();
        let (s, c) = (TAU * u.y).sin_cos();
        let (t, b) = basis(self.axis);
        (t * (c * sin) + b * (s * sin) + self.axis * (1.0 - one_minus)).normalize()
    }
}

/// Where a lamp's light paths are aimed: one cone per glossy sphere (cone `k` holds sphere
/// `k`), each cone's directions on a [`GRID`] x [`GRID`] grid.
#[derive(Debug, Clone)]
enum Aim {
    /// Cones from the lamp's centre, each holding its sphere as seen from all of the lamp:
    /// punctual lights and emissive spheres, whose directions are drawn before their points.
    Fixed(Vec<Cone>),
    /// Cones from the point a path leaves, each holding one glossy sphere (centre, radius):
    /// emissive triangles, whose points are drawn first. A panel's cones from its centre
    /// would have to hold a small ball as seen from every point of it: a 2 cm chrome ball 5 m
    /// from a 4 x 2 m softbox fills 1 / 40000 of such a cone, so its pilot found nothing and
    /// the ball's defocused reflection of the panel stayed with the camera, speckled.
    FromPoint(Vec<(Vec3, f32)>),
    /// Discs across a parallel sun's beam, one per glossy sphere: its paths' starts are drawn,
    /// their direction is the sun's.
    Beam(Beam),
}

impl Aim {
    /// How many cones.
    fn len(&self) -> usize {
        match self {
            Self::Fixed(cones) => cones.len(),
            Self::FromPoint(spheres) => spheres.len(),
            Self::Beam(beam) => beam.len(),
        }
    }

    /// Cone `k` for a path leaving the lamp's point `from` (ignored by fixed cones); `None`
    /// when no direction from there reaches its sphere.
    fn cone(&self, k: usize, from: Vec3) -> Option<Cone> {
        match self {
            Self::Fixed(cones) => Some(cones[k]),
            Self::FromPoint(spheres) => {
                let (centre, radius) = spheres[k];
                Cone::towards(from, centre, radius)
            }
            Self::Beam(_) => None,
        }
    }
}

/// Where a lamp's light paths start.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// Light `light` of [`crate::scene::emitters::Emitters::always`]: a point or spot light.
    Punctual { light: usize, position: Vec3 },
    /// Light `light` of [`crate::scene::emitters::Emitters::always`]: a parallel sun (no
    /// angle), whose paths start across its beam ([`Beam`]) and take caustics only.
    Sun { light: usize },
    /// An emissive triangle, its points drawn uniformly by area.
    Triangle {
        geometry: u32,
        prim: u32,
        /// Unit normal of its front face.
        normal: Vec3,
        inv_area: f32,
    },
    /// An emissive sphere, its points drawn uniformly over the disc it shows the path's
    /// direction (the half that faces it, by the cosine).
    Sphere {
        geometry: u32,
        prim: u32,
        center: Vec3,
        radius: f32,
        /// 1 / (pi radius^2).
        inv_disc: f32,
    },
}

/// How a camera path found a lamp.
#[derive(Debug, Clone, Copy)]
pub(super) enum Found {
    /// By next-event estimation from its first surface.
    LightSample,
    /// By a BSDF sample from its first surface that hit an emitter.
    BsdfSample,
}

/// Which lamp a camera-side light sample, or an emitter a camera path found, belongs to.
#[derive(Debug, Clone, Copy)]
pub(super) enum LampKey {
    /// Light `i` of [`crate::scene::emitters::Emitters::always`].
    Punctual(usize),
    /// Emissive primitive (geometry, primitive).
    Primitive(u32, u32),
}

impl Source {
    /// Whether it is an emissive primitive (not a light of the scene's list).
    fn is_primitive(&self) -> bool {
        matches!(self, Self::Triangle { .. } | Self::Sphere { .. })
    }

    /// Keys its light paths' sample stream (punctual lights by their index, as before
    /// emissive primitives took light paths too).
    fn stream(&self) -> u64 {
        match *self {
            Self::Punctual { light, .. } | Self::Sun { light } => light as u64,
            Self::Triangle { geometry, prim, .. } | Self::Sphere { geometry, prim, .. } => {
                (1 << 63) | u64::from(geometry) << 32 | u64::from(prim)
            }
        }
    }

    /// The density, per steradian seen from the surface point `x`, with which its light paths
    /// start at the lamp's point `d_light` from `x` along unit `to_light` (1 for a punctual
    /// light, which has one point).
    fn position_density(&self, x: Vec3, to_light: Vec3, d_light: f32) -> f32 {
        let d2 = d_light * d_light;
        match *self {
            Self::Punctual { .. } | Self::Sun { .. } => 1.0,
            Self::Triangle {
                normal, inv_area, ..
            } => {
                let cos = normal.dot(to_light).abs();
                if cos > 0.0 { inv_area * d2 / cos } else { 0.0 }
            }
            Self::Sphere {
                center,
                radius,
                inv_disc,
                ..
            } => {
                // Uniform over the disc the sphere shows the path's direction: a point at
                // cosine cos has density cos / (pi r^2) per area, d^2 / (pi r^2) per
                // steradian; none on the half facing away.
                let n = (x + to_light * d_light - center) / radius;
                if -n.dot(to_light) > 0.0 {
                    inv_disc * d2
                } else {
                    0.0
                }
            }
        }
    }
}

/// What a lamp's light paths are for. A source takes two lamps, so that each has its own
/// pilot: a highlight's cells and a caustic's are different directions, and the camera's
/// weights for a highlight read the highlight lamp's cells alone (drawn towards the floors
/// a ball lights, a highlight's paths would thin out and leave its speckle to the camera).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// Reflections in a blurred glossy surface, into the lens (t = 1 and t = 0).
    Highlights,
    /// Light a glossy surface throws onto a rough one, into the lens ([`caustic`]).
    Caustics,
}

/// A caustic lamp's pilot is its highlight lamp's over this (at least [`MIN_PILOT`]): each
/// of its paths traces a ray more, and its pilot is a fixed cost of every render with a
/// glossy surface under a lamp (the full pilot cost 0.2 s of a 2.8 s render of the
/// `defocus` comparison scene at 320 px, 16 spp).
const CAUSTIC_PILOT_DIVISOR: u32 = 4;

/// Keys caustic lamps' sample streams apart from their sources' highlight lamps'.
const CAUSTIC_STREAM: u64 = 0x6361_7573_7469_6373;

/// One lamp's light paths.
#[derive(Debug, Clone)]
struct Lamp {
    source: Source,
    role: Role,
    /// Light paths to trace.
    paths: u32,
    aim: Aim,
    /// Probability of each cell of each cone's grid (cone-major, [`GRID`]^2 per cone).
    cells: Vec<f32>,
    /// Running sum of `cells` (the last entry is 1).
    cdf: Vec<f32>,
}

impl Lamp {
    /// A lamp drawing directions as `aim` says, each cell alike.
    fn new(source: Source, role: Role, paths: u32, aim: Aim) -> Self {
        let n = aim.len() * GRID * GRID;
        let mut lamp = Self {
            source,
            role,
            paths,
            aim,
            cells: Vec::new(),
            cdf: Vec::new(),
        };
        lamp.set_cells(vec![1.0 / n as f32; n]);
        lamp
    }

    /// Draws cell `k` with probability `cells[k]` (normalised here).
    fn set_cells(&mut self, mut cells: Vec<f32>) {
        let sum: f64 = cells.iter().map(|&p| f64::from(p)).sum();
        let mut run = 0.0f64;
        self.cdf = (cells.iter_mut())
            .map(|p| {
                *p = (f64::from(*p) / sum) as f32;
                run += f64::from(*p);
                run as f32
            })
            .collect();
        if let Some(last) = self.cdf.last_mut() {
            *last = 1.0;
        }
        self.cells = cells;
    }

    /// The density (per steradian) of drawing unit direction `dir` from the lamp's point
    /// `from`; `drawn`: the cell it was drawn in, if known.
    ///
    /// Which cell a direction lies in is measured back from it, and within float rounding of
    /// a cell's edge may come out as its neighbour's, whose probability can be 10^4 times
    /// smaller. A light path's own cell is therefore taken as drawn: its density is then
    /// never underestimated by more than the other cones' share, so its weight stays bounded
    /// and the only departure from an unbiased estimate is bounded by the share of the light
    /// that falls within rounding of an edge.
    fn pdf(&self, from: Vec3, dir: Vec3, drawn: Option<usize>) -> f32 {
        let per_cell = (GRID * GRID) as f32;
        (0..self.aim.len())
            .filter_map(|k| {
                let c = self.aim.cone(k, from)?;
                let cell = match drawn {
                    Some(d) if d / (GRID * GRID) == k => d,
                    _ => k * GRID * GRID + Cone::cell(c.square(dir)?),
                };
                Some(self.cells[cell] * per_cell * c.inv_solid_angle)
            })
            .sum()
    }

    /// A direction from the lamp's point `from` by three uniform numbers (the first picks the
    /// cell) and its cell; `None` when the cell's cone is empty from there.
    fn sample(&self, from: Vec3, u: [f32; 3]) -> Option<(Vec3, usize)> {
        let c = self.draw_cell(u[0]);
        let (k, ij) = (c / (GRID * GRID), c % (GRID * GRID));
        let q = Vec2::new(
            ((ij / GRID) as f32 + u[1]) / GRID as f32,
            ((ij % GRID) as f32 + u[2]) / GRID as f32,
        );
        Some((self.aim.cone(k, from)?.sample(q), c))
    }

    /// Keys its paths' sample stream.
    fn stream(&self) -> u64 {
        match self.role {
            Role::Highlights => self.source.stream(),
            Role::Caustics => self.source.stream() ^ CAUSTIC_STREAM,
        }
    }

    /// The cell that uniform number `u` draws.
    fn draw_cell(&self, u: f32) -> usize {
        self.cdf
            .partition_point(|&f| f <= u)
            .min(self.cdf.len() - 1)
    }

    /// What a path brings the surface point `at` it lit first, per unit of that surface's
    /// `F / cos` (its BSDF with the shading cosine, over the geometric one): the lamp's light
    /// over the density of the path's reaching that point per unit area across its direction.
    /// `None` where that density is 0.
    fn flux(&self, at: &Lit) -> Option<Vec3> {
        let per_area = match &self.aim {
            Aim::Beam(beam) => beam.density(&self.cells, at.x, at.drawn),
            _ => {
                let y = at.x + at.to_light * at.d_light;
                let p_w = self.pdf(y, -at.to_light, at.drawn);
                let p_y = self.source.position_density(at.x, at.to_light, at.d_light);
                p_w * p_y / (at.d_light * at.d_light)
            }
        };
        (per_area > 0.0 && per_area.is_finite()).then(|| at.irradiance / per_area)
    }

    /// Where path `u` (its numbers: 0-2 the direction, 6-7 the point on an emitter) leaves
    /// the lamp, its direction and the cell drawn; `None` when it carries nothing (an
    /// emitter's back, an empty cone).
    fn start(&self, world: &World, u: &[f32; 10]) -> Option<(Start, Vec3, usize)> {
        let on = Vec2::new(u[6], u[7]);
        let dir_u = [u[0], u[1], u[2]];
        match self.source {
            Source::Punctual { position, .. } => {
                let (dir, cell) = self.sample(position, dir_u)?;
                let start = Start {
                    origin: position,
                    point: position,
                    radiance: Vec3::ZERO,
                };
                Some((start, dir, cell))
            }
            // A start across the beam, in a cell drawn as a cone's.
            Source::Sun { .. } => {
                let Aim::Beam(beam) = &self.aim else {
                    return None;
                };
                let cell = self.draw_cell(dir_u[0]);
                let origin = beam.start(cell, Vec2::new(dir_u[1], dir_u[2]));
                let start = Start {
                    origin,
                    point: origin,
                    radiance: Vec3::ZERO,
                };
                Some((start, beam.dir(), cell))
            }
            // The point first: the direction's cones are aimed from it.
            Source::Triangle { geometry, prim, .. } => {
                let p = primitive_point(world, geometry, prim, on)?;
                let (dir, cell) = self.sample(p.position, dir_u)?;
                Some((Start::leaving(world, (geometry, prim), p, dir)?, dir, cell))
            }
            // The direction first: the point is drawn on the disc facing it.
            Source::Sphere {
                geometry,
                prim,
                center,
                radius,
                ..
            } => {
                let (dir, cell) = self.sample(center, dir_u)?;
                let p = sphere_point_facing(center, radius, dir, on);
                Some((Start::leaving(world, (geometry, prim), p, dir)?, dir, cell))
            }
        }
    }
}

/// The densities of one path under the strategies (module documentation).
#[derive(Debug, Clone, Copy)]
pub(super) struct Densities {
    /// The camera's, finding the lamp by a light sample.
    camera: f32,
    /// The camera's, finding an emissive primitive by a BSDF sample (0 for punctual lights).
    bsdf: f32,
    t1: f32,
    t0: f32,
}

impl Densities {
    fn sum_sq(&self) -> f32 {
        self.camera * self.camera + self.t1 * self.t1 + self.t0 * self.t0 + self.bsdf * self.bsdf
    }

    /// The power-heuristic weight of the strategy of density `own`; `None` where the sum is
    /// not usable.
    fn weight(&self, own: f32) -> Option<f32> {
        let s = self.sum_sq();
        (s > 0.0 && s.is_finite()).then(|| own * own / s)
    }
}

/// The lamps traced through glossy reflections in a render, and the thin lens they land
/// through (chosen per render from the scene, the camera and the settings).
#[derive(Debug, Clone)]
pub struct GlossyPaths {
    lamps: Vec<Lamp>,
    /// For each light of [`crate::scene::emitters::Emitters::always`], its lamp.
    by_light: Vec<Option<usize>>,
    /// The lamp of each emissive primitive that has one, by (geometry, primitive).
    by_prim: HashMap<(u32, u32), usize>,
    /// Whether each light of [`crate::scene::emitters::Emitters::always`] has a caustic lamp.
    caustic_lights: Vec<bool>,
    /// The emissive primitives that have a caustic lamp.
    caustic_prims: HashSet<(u32, u32)>,
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    /// Aperture radius, scene units.
    radius: f32,
    aperture: ApertureShape,
    /// The aperture's area, scene units squared.
    area: f32,
    /// Side of a pixel on the plane at unit distance.
    pixel: f32,
    /// Camera samples per pixel (the camera's density per film area).
    spp: f32,
    /// CoC in pixels per unit of |1 / focus distance - 1 / depth|.
    coc_scale: f32,
    /// 1 / the focus distance.
    inv_focus: f32,
    lens_weight_mean: f32,
}

impl GlossyPaths {
    /// The lamps of `world` whose glossy reflections a render through `camera` with
    /// `settings` also traces from the light; `None` when there are none or the render cannot
    /// (not the path tracer with light tracing, a pinhole, a real lens).
    pub(super) fn choose(
        world: &World,
        camera: &Camera,
        settings: &RenderSettings,
        lens_weight_mean: f32,
    ) -> Option<Self> {
        let CameraLens::Thin(thin) = &camera.lens else {
            return None;
        };
        if settings.integrator != Integrator::Path
            || !settings.path.light_tracing
            || settings.mode == Mode::Pinhole
            || thin.aperture_radius.is_nan()
            || thin.aperture_radius <= 0.0
        {
            return None;
        }
        let spheres = glossy_bounds(world);
        if spheres.is_empty() {
            return None;
        }
        let sources = lamp_sources(world, settings);
        if sources.is_empty() {
            return None;
        }
        let caustics = caustic::allowed(&settings.path);
        let lamps = lamps(world, (camera, settings), &spheres, sources, caustics);
        if lamps.is_empty() {
            return None;
        }
        let aperture = thin.aperture;
        let mut g = Self {
            lamps,
            by_light: Vec::new(),
            by_prim: HashMap::new(),
            caustic_lights: Vec::new(),
            caustic_prims: HashSet::new(),
            eye: camera.eye,
            forward: camera.forward,
            right: camera.right,
            up: camera.up,
            radius: thin.aperture_radius,
            aperture,
            area: aperture.area() * thin.aperture_radius.powi(2),
            pixel: 2.0 * camera.tan_half_vfov / camera.height as f32,
            spp: settings.spp as f32,
            coc_scale: 2.0
                * thin.aperture_radius
                * aperture.anamorphic.max(1.0)
                * camera.pixels_per_unit(),
            inv_focus: thin.inv_focus_distance,
            lens_weight_mean,
        };
        g.guide(world, camera, settings);
        // Lamps whose pilot landed nothing are left to the camera (its weight for them is 1).
        g.lamps.retain(|l| l.paths > 0);
        g.by_light = vec![None; world.emitters.always.len()];
        g.caustic_lights = vec![false; world.emitters.always.len()];
        for (i, l) in g.lamps.iter().enumerate() {
            match (l.source, l.role) {
                (Source::Punctual { light, .. } | Source::Sun { light }, Role::Highlights) => {
                    g.by_light[light] = Some(i);
                }
                (Source::Punctual { light, .. } | Source::Sun { light }, Role::Caustics) => {
                    g.caustic_lights[light] = true;
                }
                (
                    Source::Triangle { geometry, prim, .. } | Source::Sphere { geometry, prim, .. },
                    role,
                ) => {
                    if role == Role::Highlights {
                        g.by_prim.insert((geometry, prim), i);
                    } else {
                        g.caustic_prims.insert((geometry, prim));
                    }
                }
            }
        }
        (!g.lamps.is_empty()).then_some(g)
    }

    /// Draws each lamp's directions where its light lands: [`PILOT`] paths drawn evenly
    /// over its cones say how much light each cell of their grids sends into the lens (its
    /// share after the weights, with the render's counts); the render's paths then draw
    /// cells in proportion to it, [`DEFENSIVE`] evenly. Deterministic: fixed numbers, summed
    /// in order. (A pilot that fails for memory leaves the even draw, which is as unbiased.)
    fn guide(&mut self, world: &World, camera: &Camera, settings: &RenderSettings) {
        let landed = self.pilot(world, camera, settings);
        // Each role shares its own budget: caustics take nothing from highlights.
        for role in [Role::Highlights, Role::Caustics] {
            self.share_paths(role, &landed);
        }
    }

    /// Traces each lamp's pilot, sets its cells from where the pilot's light landed, and
    /// returns the light each pilot landed per path (`None`: its pilot failed, keep its even
    /// share).
    fn pilot(
        &mut self,
        world: &World,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Vec<Option<f32>> {
        let seed = settings.seed ^ SALT ^ 0x0070_696c_6f74;
        let count = self.lamps.len();
        let emitters = |role: Role| {
            (self.lamps.iter())
                .filter(|l| l.role == role && l.source.is_primitive())
                .count()
        };
        // A role's emissive primitives share a pilot budget of [`EMITTER_PILOTS`] lamps' worth.
        let shared = |role: Role| {
            let shared = (PILOT as usize * EMITTER_PILOTS / emitters(role).max(1)) as u32;
            shared.clamp(MIN_PILOT, PILOT)
        };
        let pilots: Vec<u32> = (self.lamps.iter())
            .map(|l| {
                let n = if l.source.is_primitive() {
                    shared(l.role)
                } else {
                    PILOT
                };
                match l.role {
                    Role::Highlights => n,
                    Role::Caustics => (n / CAUSTIC_PILOT_DIVISOR).max(MIN_PILOT),
                }
            })
            .collect();
        let mut landed = vec![None; count];
        for (i, out) in landed.iter_mut().enumerate() {
            let (lamp, pilot) = (&self.lamps[i], pilots[i]);
            let Ok((splats, _)) = self.trace_block(world, camera, settings, lamp, seed, 0..pilot)
            else {
                continue;
            };
            let n = lamp.cells.len();
            let mut score = vec![0.0f32; n];
            for (s, cell) in &splats {
                score[*cell] += s.value.max_element();
            }
            let total: f32 = score.iter().sum();
            *out = Some(total / pilot as f32);
            if !(total > 0.0 && total.is_finite()) {
                continue;
            }
            let even = DEFENSIVE / n as f32;
            let cells = score
                .iter()
                .map(|&s| even + (1.0 - DEFENSIVE) * s / total)
                .collect();
            self.lamps[i].set_cells(cells);
        }
        landed
    }

    /// Shares the paths of the lamps of `role` between them in proportion to the light their
    /// pilots `landed` ([`SHARED`] of them evenly); a lamp whose pilot landed nothing gets
    /// none: nothing it sends through a glossy reflection lands, so the camera keeps it all.
    fn share_paths(&mut self, role: Role, landed: &[Option<f32>]) {
        let of_role = |l: &Lamp| l.role == role;
        let budget: f64 = (self.lamps.iter().filter(|l| of_role(l)))
            .map(|l| f64::from(l.paths))
            .sum();
        let live = (self.lamps.iter().zip(landed))
            .filter(|(l, t)| of_role(l) && t.is_none_or(|t| t != 0.0))
            .count();
        let usable = |t: &Option<f32>| t.filter(|t| t.is_finite()).map_or(0.0, f64::from);
        let sum: f64 = (self.lamps.iter().zip(landed))
            .filter(|(l, _)| of_role(l))
            .map(|(_, t)| usable(t))
            .sum();
        for (lamp, t) in self.lamps.iter_mut().zip(landed) {
            if !of_role(lamp) {
                continue;
            }
            if *t == Some(0.0) {
                lamp.paths = 0;
                continue;
            }
            let part = if sum > 0.0 {
                usable(t) / sum
            } else {
                1.0 / live as f64
            };
            let share = SHARED / live as f64 + (1.0 - SHARED) * part;
            lamp.paths = (budget * share).ceil().clamp(1.0, f64::from(u32::MAX)) as u32;
        }
    }

    /// The light paths a render traces.
    pub fn paths(&self) -> u64 {
        self.lamps.iter().map(|l| u64::from(l.paths)).sum()
    }

    /// The camera's share, by the strategy that `found` the lamp, of the light lamp `key`
    /// sends to the eye by one reflection at a camera ray's first surface `at`, seen along unit
    /// `to_lens` (back along the camera ray) from `d_lens` away; `None` where light paths do
    /// not share it (the lamp has none, or the surface takes none).
    pub(super) fn camera_weight(
        &self,
        found: Found,
        key: LampKey,
        at: &Lit,
        to_lens: Vec3,
        d_lens: f32,
    ) -> Option<f32> {
        let d = self.shared(key, at, to_lens, d_lens)?;
        d.weight(match found {
            Found::LightSample => d.camera,
            Found::BsdfSample => d.bsdf,
        })
    }

    /// The densities of a path from lamp `key` through `at` into the lens, where light paths
    /// share it.
    fn shared(&self, key: LampKey, at: &Lit, to_lens: Vec3, d_lens: f32) -> Option<Densities> {
        let lamp = match key {
            LampKey::Punctual(light) => (*self.by_light.get(light)?)?,
            LampKey::Primitive(g, p) => *self.by_prim.get(&(g, p))?,
        };
        if !self.applies(&at.b, to_lens, d_lens) {
            return None;
        }
        self.densities(&self.lamps[lamp], at, to_lens, d_lens)
    }

    /// Whether the camera drops the light of lamp `key` that reaches it through a glossy
    /// surface from a rough first surface, the caustic light paths take over ([`caustic`]).
    /// The caller has checked the surfaces ([`receives`] first, [`eligible`] second).
    pub(super) fn drops(&self, key: LampKey) -> bool {
        match key {
            LampKey::Punctual(light) => self.caustic_lights.get(light) == Some(&true),
            LampKey::Primitive(g, p) => self.caustic_prims.contains(&(g, p)),
        }
    }

    /// Whether some lamp's light paths take over its caustics ([`caustic`]): only then does
    /// the camera path note which of its first surfaces receive them.
    pub(super) fn takes_caustics(&self) -> bool {
        self.caustic_lights.contains(&true) || !self.caustic_prims.is_empty()
    }

    /// Whether some emissive primitive takes light paths (so the camera's BSDF samples that
    /// find one are weighed against them).
    pub(super) fn shares_emitters(&self) -> bool {
        !self.by_prim.is_empty()
    }

    /// Whether light paths share the light reflected at a camera ray's first surface of BSDF
    /// `b`, seen along unit `to_lens` from `d_lens` away ([`eligible`] and blurred).
    pub(super) fn applies(&self, b: &Bsdf, to_lens: Vec3, d_lens: f32) -> bool {
        eligible(b) && self.blurred(d_lens * -to_lens.dot(self.forward))
    }

    /// Whether a surface at `depth` along the view axis is blurred enough to take light paths
    /// ([`MIN_COC_PX`]).
    fn blurred(&self, depth: f32) -> bool {
        self.coc_scale * (self.inv_focus - 1.0 / depth.max(1e-6)).abs() >= MIN_COC_PX
    }

    /// The three strategies' densities of the path lamp -> `at` -> lens, along unit `to_lens`
    /// for `d_lens` (module documentation).
    fn densities(&self, lamp: &Lamp, at: &Lit, to_lens: Vec3, d_lens: f32) -> Option<Densities> {
        let Lit {
            ref b,
            n,
            ng,
            x,
            to_light,
            d_light,
            nee,
            ..
        } = *at;
        let ng = ng.normalize_or(Vec3::Z);
        let c = -to_lens.dot(self.forward);
        let cos_u = ng.dot(to_lens).abs();
        if !(c > 0.0 && cos_u > 0.0 && d_lens > 0.0) {
            return None;
        }
        let per_sr = 1.0 / (c * c * c * self.pixel * self.pixel);
        let camera = self.spp * per_sr / self.area;
        // A BSDF sample finds an emissive primitive (not a punctual light).
        let bsdf = match lamp.source {
            Source::Punctual { .. } | Source::Sun { .. } => 0.0,
            _ => camera * b.pdf(n, to_lens, to_light),
        };
        let camera = camera * nee;
        let p_w = lamp.pdf(x + to_light * d_light, -to_light, at.drawn);
        let pos = lamp.source.position_density(x, to_light, d_light);
        if !(p_w > 0.0 && pos > 0.0) {
            return Some(Densities {
                camera,
                bsdf,
                t1: 0.0,
                t0: 0.0,
            });
        }
        let cos_l = ng.dot(to_light).abs();
        let p_u = p_w * cos_l / (d_light * d_light) * (d_lens * d_lens) / cos_u * pos;
        let count = lamp.paths as f32;
        let p_b = b.pdf(n, to_light, to_lens);
        let d = Densities {
            camera,
            bsdf,
            t1: count * p_u / self.area,
            t0: count * p_u * p_b * c / (d_lens * d_lens),
        };
        (d.t1.is_finite() && d.t0.is_finite() && d.bsdf.is_finite()).then_some(d)
    }

    /// The lens position (unit aperture coordinates, as [`Lens::lens_point`] gives them)
    /// where a ray from `from` along unit `dir` crosses the lens plane, and the distance to
    /// it; `None` when it misses the aperture.
    fn lens_crossing(&self, from: Vec3, dir: Vec3) -> Option<(Vec2, f32)> {
        let along = dir.dot(self.forward);
        if along.is_nan() || along >= 0.0 {
            return None;
        }
        let t = (self.eye - from).dot(self.forward) / along;
        if !(t > 0.0 && t.is_finite()) {
            return None;
        }
        let p = from + dir * t - self.eye;
        let lens = Vec2::new(p.dot(self.right), p.dot(self.up)) / self.radius;
        self.aperture.contains(lens).then_some((lens, t))
    }

    /// Traces the light paths for the render `shader` describes and adds what lands in
    /// `region` to `image` (the full frame's colours, row-major).
    pub(super) fn trace(
        &self,
        shader: &SiteShader,
        region: &Region,
        progress: &dyn Progress,
        tally: &mut Tally,
        image: &mut [Vec3],
    ) -> Result<(), RenderError> {
        let items: Vec<(usize, u32)> = (self.lamps.iter().enumerate())
            .flat_map(|(i, l)| (0..l.paths).step_by(BLOCK as usize).map(move |f| (i, f)))
            .collect();
        let block = |&(i, first): &(usize, u32)| {
            let lamp = &self.lamps[i];
            let end = first.saturating_add(BLOCK).min(lamp.paths);
            let (world, camera, settings) = (shader.world, shader.camera, shader.settings);
            let seed = settings.seed ^ SALT;
            let (splats, tally) =
                self.trace_block(world, camera, settings, lamp, seed, first..end)?;
            Ok((splats.into_iter().map(|(s, ..)| s).collect(), tally))
        };
        splat_blocks(
            shader,
            "glossy lights",
            &items,
            block,
            region,
            progress,
            tally,
            image,
        )
    }

    /// Traces paths `range` of `lamp` (numbered in the sample stream `seed`), 16 at a time,
    /// and returns the splats of those that reach the lens, each with the cell of the lamp's
    /// direction grid its path left through.
    #[allow(clippy::too_many_arguments)]
    fn trace_block(
        &self,
        world: &World,
        camera: &Camera,
        settings: &RenderSettings,
        lamp: &Lamp,
        seed: u64,
        range: std::ops::Range<u32>,
    ) -> Result<(Vec<(Splat, usize)>, Tally), MemoryError> {
        let mut tally = Tally::new(settings.record_rays);
        let (first, end) = (range.start, range.end);
        let mut splats = try_with_capacity(2 * (end - first) as usize, "the light paths' splats")?;
        let view = View {
            camera,
            share: settings.exposure.exp2() / self.lens_weight_mean,
            filter: settings.filter,
        };
        let mut packet = RayPacket16::new();
        let mut points = SurfacePoints16::default();
        let mut shadow = ShadowPacket16::new();
        let mut t_hit = [f32::INFINITY; LANES];
        let mut bounces = caustic::Bounces::new();
        for start in (first..end).step_by(LANES) {
            let count = (end - start).min(LANES as u32);
            let numbers: [[f32; 10]; LANES] = std::array::from_fn(|l| {
                let j = start + (l as u32).min(count - 1);
                path_numbers(sample_key(seed, lamp.stream(), j), 0)
            });
            packet.clear();
            let mut cells = [0usize; LANES];
            let mut starts = [None; LANES];
            for (lane, u) in numbers.iter().enumerate().take(count as usize) {
                let Some((start, dir, cell)) = lamp.start(world, u) else {
                    continue;
                };
                cells[lane] = cell;
                starts[lane] = Some(start);
                packet.set(lane, &Ray::new(start.origin, dir));
            }
            let (kind, hint) = (RayKind::Secondary, RayHint::Incoherent);
            let hits = trace_depth(world, &mut packet, kind, hint, &mut t_hit, &mut tally);
            if hits == 0 {
                continue;
            }
            world.surface_points16(&packet, hits, &mut points);
            let mut connections = Connections::default();
            bounces.clear();
            let dirs = packet.dirs();
            for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
                let (Some(hit), Some(start)) = (packet.hit(lane), starts[lane]) else {
                    continue;
                };
                let sp = points.get(lane);
                let d = Vec3::new(dirs[0][lane], dirs[1][lane], dirs[2][lane]);
                let b = world.material(&hit).bsdf(sp.uv, hit.is_front(d));
                if !eligible(&b) {
                    continue;
                }
                let Some(at) = start.lights(world, &lamp.source, cells[lane], b, &sp, hit.ng)
                else {
                    continue;
                };
                let u = &numbers[lane];
                // A caustic: on to the surface G's BSDF sample finds (whether or not G is
                // blurred: what it lights may be).
                if lamp.role == Role::Caustics {
                    bounces.leave(lamp, lane, &at, [u[3], u[4], u[5]]);
                    continue;
                }
                self.highlight(&view, lamp, (lane, &at, u), &mut connections);
            }
            // The caustics' lens points, numbered apart from the paths' first numbers.
            let lens_u = |lane: usize| {
                let j = start + lane as u32;
                let u = path_numbers(sample_key(seed, lamp.stream(), j), 1);
                Vec2::new(u[0], u[1])
            };
            let count = lamp.paths as f32;
            let here = (world, &view, count);
            bounces.land(self, here, lens_u, &mut connections, &mut tally);
            connections.trace(world, &mut shadow, &mut tally, &cells, &mut splats);
        }
        Ok((splats, tally))
    }

    /// Adds lane `lane`'s connections into the lens from the glossy point `at` that `lamp`
    /// lit, drawn with numbers `u`, where it is blurred: t = 1 and t = 0.
    fn highlight(
        &self,
        view: &View,
        lamp: &Lamp,
        (lane, at, u): (usize, &Lit, &[f32; 10]),
        connections: &mut Connections,
    ) {
        let x = at.x;
        if !self.blurred((x - self.eye).dot(self.forward)) {
            return;
        }
        // t = 1: a uniform point of the aperture.
        let lens = view.camera.lens.lens_point(Vec2::new(u[8], u[9]));
        let o = self.eye + (self.right * lens.x + self.up * lens.y) * self.radius;
        let (v, d_lens) = ((o - x), (o - x).length());
        if d_lens > 0.0
            && let Some(s) = self.landing(view, lamp, at, 0, lens, v / d_lens, d_lens)
        {
            connections.add(0, lane, x, v / d_lens, d_lens, s);
        }
        // t = 0: the BSDF's direction, if it crosses the aperture.
        if let Some(bs) = at.b.sample(at.n, at.to_light, [u[3], u[4], u[5]])
            && !bs.delta
            && let Some((lens, d_lens)) = self.lens_crossing(x, bs.wi)
            && let Some(s) = self.landing(view, lamp, at, 1, lens, bs.wi, d_lens)
        {
            connections.add(1, lane, x, bs.wi, d_lens, s);
        }
    }

    /// The splat of the path from `lamp` to the surface point `at` and on to lens position
    /// `lens` (unit aperture coordinates), along unit `to_lens` for `d_lens`, by strategy
    /// `k` (0: t = 1, 1: t = 0), weighted by its power-heuristic share; `None` when it carries
    /// nothing or misses the film. Visibility is the caller's.
    #[allow(clippy::too_many_arguments)]
    fn landing(
        &self,
        view: &View,
        lamp: &Lamp,
        at: &Lit,
        k: usize,
        lens: Vec2,
        to_lens: Vec3,
        d_lens: f32,
    ) -> Option<Splat> {
        let Lit { b, n, .. } = *at;
        let q = self.densities(lamp, at, to_lens, d_lens)?;
        let Landing { film, per_sr, .. } = view.camera.film_point(lens, -to_lens)?;
        let own = if k == 0 { q.t1 } else { q.t0 };
        let lens_weight = if view.filter == LensFilter::Box {
            1.0
        } else {
            view.camera.lens.weight(view.filter, lens)
        };
        // F E per_sr / (A q_s), times the power heuristic's q_s^2 / sum q^2.
        let value = b.eval(n, to_lens, at.to_light)
            * at.irradiance
            * (per_sr * own / (self.area * q.sum_sq()) * view.share * lens_weight);
        (value.max_element() > 0.0 && value.is_finite()).then_some(Splat { film, value })
    }
}

/// What splats need of the render: where paths land, and their common factor.
struct View<'a> {
    camera: &'a Camera,
    /// Exposure over the mean lens weight.
    share: f32,
    filter: LensFilter,
}

/// A surface point a lamp lights, as both sides see it.
pub(super) struct Lit {
    pub(super) b: Bsdf,
    /// Shading normal (on the side of the ray that found the point).
    pub(super) n: Vec3,
    /// Geometric normal, any length (as Embree reports it: [`GlossyPaths::densities`]
    /// normalises it, so paths the weights never reach pay nothing for it).
    pub(super) ng: Vec3,
    /// The point.
    pub(super) x: Vec3,
    /// Unit direction and distance to the lamp (to the point of it the path reaches).
    pub(super) to_light: Vec3,
    pub(super) d_light: f32,
    /// What arrives from the lamp: a punctual light's irradiance (normal to its direction),
    /// an emitter's radiance.
    pub(super) irradiance: Vec3,
    /// The density, per steradian, with which the camera's light sample there draws the
    /// lamp's point (1 for a punctual light, which every light sample takes).
    pub(super) nee: f32,
    /// The cell of the lamp's directions a light path was drawn in (`None` on the camera's
    /// side; `Lamp::pdf`).
    pub(super) drawn: Option<usize>,
}

/// Where one light path leaves its lamp.
#[derive(Debug, Clone, Copy)]
struct Start {
    /// The ray's origin (off an emitter's surface, on the side the path leaves by).
    origin: Vec3,
    /// The lamp's point (a punctual light's position).
    point: Vec3,
    /// The radiance an emitter sends along the path (unused for punctual lights).
    radiance: Vec3,
}

impl Start {
    /// The start of a path leaving point `p` of emissive primitive (geometry, prim) along
    /// unit `dir`; `None` when it sends nothing that way.
    fn leaving(
        world: &World,
        (geometry, prim): (u32, u32),
        p: PrimitivePoint,
        dir: Vec3,
    ) -> Option<Self> {
        let cos = p.normal.dot(dir);
        if cos == 0.0 {
            return None;
        }
        let material = world.material_of(GeometryId(geometry), prim);
        let radiance = material.emitted_towards(p.uv, cos > 0.0);
        if radiance.max_element() <= 0.0 {
            return None;
        }
        // Off the surface by a little more than its position's rounding, so the ray cannot
        // find the primitive it leaves.
        let lift = 1e-4 * (1.0 + p.position.abs().max_element());
        Some(Self {
            origin: p.position + p.normal * lift.copysign(cos),
            point: p.position,
            radiance,
        })
    }

    /// The surface point `sp` (geometric normal `ng`, BSDF `b`) as this start, drawn in cell
    /// `cell` of its lamp's directions, lights it.
    fn lights(
        &self,
        world: &World,
        source: &Source,
        cell: usize,
        b: Bsdf,
        sp: &SurfacePoint,
        ng: Vec3,
    ) -> Option<Lit> {
        let x = sp.position;
        let (to_light, d_light, irradiance, nee) = match *source {
            Source::Punctual { light, .. } | Source::Sun { light } => {
                // Lamps are never extended lights (`lamp_sources`): no numbers needed.
                let es = punctual_sample(&world.emitters.always[light], x, Vec2::ZERO);
                (es.dir, es.distance, es.radiance, 1.0)
            }
            Source::Triangle { geometry, prim, .. } | Source::Sphere { geometry, prim, .. } => {
                let v = self.point - x;
                let d = v.length();
                if d <= 0.0 || d.is_nan() {
                    return None;
                }
                let to = v / d;
                let from = Receiver {
                    p: x,
                    n: sp.normal,
                    glossy: b.glossy_share(),
                };
                let nee =
                    (world.emitters).pdf_primitive(world, geometry, prim, &from, self.point, to);
                (to, d, self.radiance, nee)
            }
        };
        Some(Lit {
            b,
            n: sp.normal,
            ng,
            x,
            to_light,
            d_light,
            irradiance,
            nee,
            drawn: Some(cell),
        })
    }
}

/// One packet's connections from surface points to the lens, by strategy (0: t = 1, 1: t = 0,
/// [`caustic::SLOT`]: a caustic's t = 1): their shadow rays (from the lens towards the point)
/// and what each lands if unoccluded.
#[derive(Default)]
struct Connections {
    pending: [[Option<Splat>; LANES]; 3],
    origin: [[[f32; LANES]; 3]; 3],
    to_x: [[[f32; LANES]; 3]; 3],
    seg_end: [[f32; LANES]; 3],
}

impl Connections {
    /// Lane `lane`'s connection by strategy `k` from `x` along `to_lens` for `d_lens`.
    fn add(&mut self, k: usize, lane: usize, x: Vec3, to_lens: Vec3, d_lens: f32, s: Splat) {
        let o = x + to_lens * d_lens;
        for a in 0..3 {
            self.origin[k][a][lane] = o[a];
            self.to_x[k][a][lane] = -to_lens[a];
        }
        self.seg_end[k][lane] = d_lens * (1.0 - 1e-4);
        self.pending[k][lane] = Some(s);
    }

    /// Traces the shadow rays (a packet per strategy) and adds the unoccluded splats to
    /// `splats`, with the cell of each lane's direction.
    fn trace(
        &self,
        world: &World,
        shadow: &mut ShadowPacket16,
        tally: &mut Tally,
        cells: &[usize; LANES],
        splats: &mut Vec<(Splat, usize)>,
    ) {
        for k in 0..3 {
            let lit = (0..LANES)
                .filter(|&l| self.pending[k][l].is_some())
                .fold(0u32, |m, l| m | 1 << l);
            if lit == 0 {
                continue;
            }
            let (origin, to_x, seg_end) = (&self.origin[k], &self.to_x[k], &self.seg_end[k]);
            let hint = RayHint::Incoherent;
            trace_shadows(world, shadow, lit, origin, to_x, seg_end, hint, tally);
            for lane in (0..LANES).filter(|&l| lit & (1 << l) != 0) {
                if shadow.is_active(lane) && !shadow.occluded(lane) {
                    splats.extend(self.pending[k][lane].map(|s| (s, cells[lane])));
                }
            }
        }
    }
}

/// The lamps of `sources` (each with the centre and radius of a sphere that holds it) aimed
/// at the glossy bounds `spheres` of `world`, for a render through `camera` with `settings`,
/// each with an even share of the paths: a highlight lamp for each source but a sun, and with
/// `caustics` a caustic lamp for each.
fn lamps(
    world: &World,
    (camera, settings): (&Camera, &RenderSettings),
    spheres: &[(Vec3, f32)],
    sources: Vec<(Source, Vec3, f32)>,
    caustics: bool,
) -> Vec<Lamp> {
    let (lo, hi) = world.scene.bounds();
    let scene = (0.5 * (lo + hi), 0.5 * (hi - lo).length());
    let mut lamps = Vec::new();
    for (source, at, size) in sources {
        let aim = match source {
            Source::Triangle { .. } => Aim::FromPoint(spheres.to_vec()),
            Source::Sun { light } => {
                let Light::Directional { direction, .. } = world.emitters.always[light] else {
                    continue;
                };
                match Beam::new(direction, spheres, scene) {
                    Some(beam) => Aim::Beam(beam),
                    None => continue,
                }
            }
            _ => Aim::Fixed(
                (spheres.iter())
                    .filter_map(|&(c, r)| Cone::towards(at, c, r + size))
                    .collect(),
            ),
        };
        if aim.len() == 0 {
            continue;
        }
        if !matches!(source, Source::Sun { .. }) {
            lamps.push(Lamp::new(source, Role::Highlights, 1, aim.clone()));
        }
        if caustics {
            lamps.push(Lamp::new(source, Role::Caustics, 1, aim));
        }
    }
    // Each role's paths number a quarter of a dense render's camera samples.
    let (w, h) = (camera.width as f64, camera.height as f64);
    let total = PATHS_PER_SAMPLE * w * h * f64::from(settings.spp);
    for role in [Role::Highlights, Role::Caustics] {
        let count = lamps.iter().filter(|l| l.role == role).count();
        let paths = (total / count.max(1) as f64)
            .ceil()
            .clamp(1.0, f64::from(u32::MAX)) as u32;
        for lamp in lamps.iter_mut().filter(|l| l.role == role) {
            lamp.paths = paths;
        }
    }
    lamps
}

/// The lamps whose light paths a render may trace, each with the centre and radius of a
/// sphere that holds it: the point and spot lights, then (with multiple importance sampling
/// and room for a bounce, which the camera's BSDF strategy needs) the [`MAX_PRIMITIVE_LAMPS`]
/// most powerful emissive triangles and spheres.
fn lamp_sources(world: &World, settings: &RenderSettings) -> Vec<(Source, Vec3, f32)> {
    let mut sources: Vec<(Source, Vec3, f32)> = (world.emitters.always.iter().enumerate())
        // A spot with a radius shines from a disc facing what it lights, which paths leaving
        // one point do not follow: the camera's light samples alone estimate it.
        .filter(|(_, l)| !l.is_extended())
        .filter_map(|(light, l)| match *l {
            Light::Point { position, .. } | Light::Spot { position, .. } => {
                Some((Source::Punctual { light, position }, position, 0.0))
            }
            // A parallel sun takes caustics only, where they are taken at all.
            Light::Directional { .. } => {
                caustic::allowed(&settings.path).then_some((Source::Sun { light }, Vec3::ZERO, 0.0))
            }
        })
        .collect();
    let limits = &settings.path;
    let bounce = [limits.total, limits.diffuse, limits.glossy]
        .iter()
        .all(|&n| n >= 1);
    if !(bounce && limits.strategy == Strategy::Mis) {
        return sources;
    }
    let mut emitters: Vec<(f32, Source, Vec3, f32)> = Vec::new();
    for (geometry, prim) in world.emitters.primitives() {
        let material = world.material_of(GeometryId(geometry), prim);
        let (lo, hi) = primitive_bounds(world, geometry, prim);
        let (centre, size) = (0.5 * (lo + hi), 0.5 * (hi - lo).length());
        let (source, area) = match world.scene.geometry(GeometryId(geometry)) {
            crate::embree::Geometry::Mesh(m) => {
                let n = m.face_normal(prim);
                let normal = n.normalize_or_zero();
                let inv_area = 1.0 / (0.5 * n.length());
                let triangle = Source::Triangle {
                    geometry,
                    prim,
                    normal,
                    inv_area,
                };
                (triangle, 1.0 / inv_area)
            }
            crate::embree::Geometry::Spheres(s) => {
                let (center, radius) = (s.center(prim), s.radius(prim));
                let inv_disc = 1.0 / (PI * radius * radius);
                let sphere = Source::Sphere {
                    geometry,
                    prim,
                    center,
                    radius,
                    inv_disc,
                };
                (sphere, 4.0 / inv_disc)
            }
        };
        let power = luminance(material.emission) * area;
        if power > 0.0 && power.is_finite() && size.is_finite() {
            emitters.push((power, source, centre, size));
        }
    }
    // The most powerful first; ties keep the scene's order (a stable sort).
    emitters.sort_by(|a, b| b.0.total_cmp(&a.0));
    emitters.truncate(MAX_PRIMITIVE_LAMPS);
    sources.extend(emitters.into_iter().map(|(_, s, c, r)| (s, c, r)));
    sources
}

/// Bounding spheres (centre, radius) of the glossy geometry of `world`: one per mesh and one
/// per sphere while there are at most [`MAX_CONES`], else one per geometry, else one for all.
fn glossy_bounds(world: &World) -> Vec<(Vec3, f32)> {
    use crate::embree::Geometry;
    let bound = |lo: Vec3, hi: Vec3| (0.5 * (lo + hi), 0.5 * (hi - lo).length());
    let mut meshes = Vec::new();
    let mut spheres = Vec::new();
    let mut per_geometry = Vec::new();
    let (mut all_lo, mut all_hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for (g, geometry) in world.scene.geometries().iter().enumerate() {
        let id = GeometryId(g as u32);
        let glossy = |prim: u32| may_be_glossy(world.material_of(id, prim));
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        match geometry {
            Geometry::Mesh(m) => {
                for (prim, tri) in m.indices().iter().enumerate() {
                    if glossy(prim as u32) {
                        for &v in tri {
                            let p = Vec3::from(m.positions()[v as usize]);
                            lo = lo.min(p);
                            hi = hi.max(p);
                        }
                    }
                }
                if lo.x <= hi.x {
                    meshes.push(bound(lo, hi));
                }
            }
            Geometry::Spheres(s) => {
                for prim in (0..s.len() as u32).filter(|&p| glossy(p)) {
                    let (c, r) = (s.center(prim), s.radius(prim));
                    spheres.push((c, r));
                    lo = lo.min(c - Vec3::splat(r));
                    hi = hi.max(c + Vec3::splat(r));
                }
            }
        }
        if lo.x <= hi.x {
            per_geometry.push(bound(lo, hi));
            all_lo = all_lo.min(lo);
            all_hi = all_hi.max(hi);
        }
    }
    if meshes.len() + spheres.len() <= MAX_CONES {
        meshes.extend(spheres);
        meshes
    } else if per_geometry.len() <= MAX_CONES {
        per_geometry
    } else {
        vec![bound(all_lo, all_hi)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lamp's light paths draw cells whose probabilities can differ 10^4 times between
    /// neighbours, so a direction must be measured back into the cell it was drawn in: for a
    /// small far cone (a 5 cm ball 10 m away) even a 1e-3 share of mismatches would bias the
    /// image visibly.
    #[test]
    fn small_cones_give_directions_back_to_the_cells_they_were_drawn_in() {
        let cone = Cone::towards(Vec3::ZERO, Vec3::new(3.0, -7.0, 6.5), 0.05).unwrap();
        assert!(cone.one_minus < 2e-5, "a small cone: {}", cone.one_minus);
        let n = 1u32 << 16;
        let mut mismatched = 0;
        for i in 0..n {
            let key = crate::sampler::hash64(u64::from(i));
            let u = Vec2::new(
                (key >> 40) as f32 / (1u64 << 24) as f32,
                ((key >> 8) & 0xff_ffff) as f32 / (1u64 << 24) as f32,
            );
            let drawn = Cone::cell(u);
            let back = cone.square(cone.sample(u)).map(Cone::cell);
            if back != Some(drawn) {
                mismatched += 1;
            }
        }
        // Only directions within rounding of an edge may move.
        eprintln!("{mismatched} of {n} directions measured into another cell");
        assert!(
            (mismatched as f64) < 1e-3 * f64::from(n),
            "{mismatched} of {n} directions measured into another cell"
        );
    }

    /// A light path's density is its drawn cell's, whatever the direction measures back as.
    #[test]
    fn a_light_paths_density_is_its_drawn_cells() {
        let cone = Cone::towards(Vec3::ZERO, Vec3::new(0.0, 0.0, 10.0), 0.05).unwrap();
        let source = Source::Punctual {
            light: 0,
            position: Vec3::ZERO,
        };
        let mut lamp = Lamp::new(source, Role::Highlights, 1, Aim::Fixed(vec![cone]));
        // One cell holds nearly everything, its neighbours almost nothing.
        let mut cells = vec![1e-6f32; GRID * GRID];
        cells[5 * GRID + 7] = 1.0;
        lamp.set_cells(cells);
        let want = lamp.cells[5 * GRID + 7] * (GRID * GRID) as f32 * cone.inv_solid_angle;
        // A direction on the drawn cell's edge with its neighbour's row.
        let dir = cone.sample(Vec2::new(6.0 / GRID as f32, 7.5 / GRID as f32));
        let drawn = lamp.pdf(Vec3::ZERO, dir, Some(5 * GRID + 7));
        assert_eq!(drawn, want);
        let measured = lamp.pdf(Vec3::ZERO, dir, None);
        assert!(measured > 0.0 && measured <= want, "{measured} vs {want}");
    }
}
