//! Caustics: a lamp's light reflected by a glossy surface onto a rough one, traced from the
//! lamp and connected to the lens (light tracing's t = 1 at the second surface).
//!
//! **Why.** A polished object beside a floor throws the lamps it reflects onto the floor. A
//! camera path finds that light only when the direction it draws at the floor happens to
//! fall into the tiny solid angle in which the glossy surface shows the lamp (a brass cube
//! under a softbox: about 1 in 10^3 of the floor's directions), so the caustic is a cloud of
//! fireflies at any sample count a render can afford, and reuse spreads each into a blotch.
//! From the lamp the same paths are easy: the lamp's paths already aim at the glossy geometry
//! (`Aim`); one BSDF sample there finds the floor, and a uniform point of the aperture and a
//! shadow ray carry it to the film.
//!
//! **A partition, not a mixture.** The light of paths lamp -> G -> D -> lens that G's
//! specular lobes reflect, with G the first surface the lamp's light meets, glossy
//! ([`eligible`]), and D the first surface a camera ray meets, rough and opaque ([`receives`]),
//! is estimated by light paths alone; the camera drops it (where its first surface was a D
//! and its second a glossy G, its light samples from G of a lamp that takes caustic paths
//! count only G's diffuse layer, and so do its BSDF samples from G that find such an
//! emitter: [`GlossyPaths::drops`]). Each side decides from the surfaces' materials and the
//! lamp alone, so every path's light is counted exactly once and the sum stays unbiased. A
//! glossy plastic's diffuse layer keeps lighting the floor by the camera's samples, which find
//! it well. Both sides need the same bounce limits to reach such a path ([`allowed`]: at
//! least two bounces, one diffuse and two glossy, and no Filter Glossy, which would make G's
//! roughness depend on the camera path) and a thin lens with an aperture (as for every light
//! path here). A glossy D, a delta lobe at G and a sun with an angle stay with the camera,
//! which renders the path space Cycles does: a smooth mirror's caustic of a point light is in
//! neither.
//!
//! **The splat.** With `F(wo, wi) = f |n . wi|` ([`Bsdf::eval`]; `F_G` its specular part),
//! geometric cosines `c` and `N` paths, a path reaching D through lens position u lands
//! `F_D(u, G) / c_D,in * F_G(D, y) c_G,out / (c_G,in p_G) * Φ * per_sr c_u / (N d_u^2)`:
//! the light-tracing throughput (`Φ`, the lamp's light over the density of the path's
//! reaching G per unit area across its direction, `Lamp::flux`: `E d_y^2 / (p_w p_y)` as in
//! the direct strategies, `E / p_beam` for a sun; then G's BSDF sample of density `p_G`),
//! converted from the area densities of G and D to what the camera integrates over (shading
//! cosines in `F`, the geometric ones from the conversions), and carried into the lens as
//! `t = 1` does.

use glam::{Vec2, Vec3};

use super::{Connections, GlossyPaths, Lamp, Lit, View, eligible};
use crate::camera::{Landing, Lens, LensFilter};
use crate::embree::{LANES, Ray, RayHint, RayPacket16};
use crate::render::light_trace::Splat;
use crate::render::trace::{RayKind, Tally, trace_depth};
use crate::scene::World;
use crate::settings::PathLimits;
use crate::shade::{Bsdf, SurfacePoints16};

/// The [`Connections`] slot of caustic paths.
pub(super) const SLOT: usize = 2;

/// Whether a surface of BSDF `b` met first by a camera ray takes its caustics from light
/// paths: rough (not [`eligible`]), opaque and not all deltas.
#[inline]
pub fn receives(b: &Bsdf) -> bool {
    !eligible(b) && !b.is_delta() && b.transmission <= 0.0
}

/// Whether the camera can find every caustic path under `limits` (module documentation), so
/// light paths may take them over.
pub(super) fn allowed(limits: &PathLimits) -> bool {
    limits.total >= 2 && limits.diffuse >= 1 && limits.glossy >= 2 && limits.filter_glossy == 0.0
}

/// A light path leaving its glossy surface G for the surface it lights.
#[derive(Clone, Copy)]
pub(super) struct Leaving {
    /// What it carries to the next surface, before that surface's BSDF: the lamp's light
    /// times G's BSDF over their densities (module documentation), without `1 / N`.
    carried: Vec3,
    /// Its unit direction away from G.
    dir: Vec3,
}

/// One packet's rays from glossy surfaces onwards.
pub(super) struct Bounces {
    packet: RayPacket16,
    points: SurfacePoints16,
    t_hit: [f32; LANES],
    leaving: [Option<Leaving>; LANES],
}

impl Bounces {
    pub(super) fn new() -> Self {
        Self {
            packet: RayPacket16::new(),
            points: SurfacePoints16::default(),
            t_hit: [f32::INFINITY; LANES],
            leaving: [None; LANES],
        }
    }

    /// Clears the lanes for the next packet.
    pub(super) fn clear(&mut self) {
        self.packet.clear();
        self.leaving = [None; LANES];
    }

    /// Lane `lane`'s light path, which lit the glossy point `at` from `lamp`, leaves it by a
    /// BSDF sample drawn with `u` (nothing when the sample is a delta or carries nothing).
    pub(super) fn leave(&mut self, lamp: &Lamp, lane: usize, at: &Lit, u: [f32; 3]) {
        let Some(bs) = at.b.sample(at.n, at.to_light, u) else {
            return;
        };
        if bs.delta || bs.pdf.is_nan() || bs.pdf <= 0.0 {
            return;
        }
        let Some(flux) = lamp.flux(at) else {
            return;
        };
        let ng = at.ng.normalize_or(Vec3::Z);
        let (cos_in, cos_out) = (ng.dot(at.to_light).abs(), ng.dot(bs.wi).abs());
        // The specular lobes' part: the diffuse layer's stays with the camera.
        let (f, _, diffuse) = at.b.eval_pdf_diffuse(at.n, bs.wi, at.to_light);
        let carried = (f - diffuse).max(Vec3::ZERO) * flux * (cos_out / (cos_in * bs.pdf));
        if !(carried.max_element() > 0.0 && carried.is_finite()) {
            return;
        }
        // Off the surface by a little more than its position's rounding, on the side it
        // leaves by, so the ray cannot find the point it leaves.
        let lift = 1e-4 * (1.0 + at.x.abs().max_element());
        let origin = at.x + ng * lift.copysign(ng.dot(bs.wi));
        self.packet.set(lane, &Ray::new(origin, bs.wi));
        self.leaving[lane] = Some(Leaving {
            carried,
            dir: bs.wi,
        });
    }

    /// Traces the rays that left, and adds to `connections` (slot [`SLOT`]) the splat of each
    /// that meets a surface taking caustics, through the lens point `lens_u(lane)` picks.
    pub(super) fn land(
        &mut self,
        paths: &GlossyPaths,
        (world, view, count): (&World, &View, f32),
        lens_u: impl Fn(usize) -> Vec2,
        connections: &mut Connections,
        tally: &mut Tally,
    ) {
        if self.leaving.iter().all(Option::is_none) {
            return;
        }
        let (kind, hint) = (RayKind::Secondary, RayHint::Incoherent);
        let hits = trace_depth(world, &mut self.packet, kind, hint, &mut self.t_hit, tally);
        if hits == 0 {
            return;
        }
        world.surface_points16(&self.packet, hits, &mut self.points);
        for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
            let (Some(hit), Some(leaving)) = (self.packet.hit(lane), self.leaving[lane]) else {
                continue;
            };
            let sp = self.points.get(lane);
            let b = world.material(&hit).bsdf(sp.uv, hit.is_front(leaving.dir));
            if !receives(&b) {
                continue;
            }
            let x = sp.position;
            let lens = view.camera.lens.lens_point(lens_u(lane));
            let o = paths.eye + (paths.right * lens.x + paths.up * lens.y) * paths.radius;
            let (v, d_lens) = (o - x, (o - x).length());
            if d_lens.is_nan() || d_lens <= 0.0 {
                continue;
            }
            let to_lens = v / d_lens;
            let surface = (b, sp.normal, hit.ng.normalize_or(Vec3::Z));
            if let Some(s) = landing(view, surface, &leaving, lens, (to_lens, d_lens), count) {
                connections.add(SLOT, lane, x, to_lens, d_lens, s);
            }
        }
    }
}

/// The splat of a caustic path arriving as `leaving` at a surface of BSDF `b` (shading normal
/// `n`, unit geometric normal `ng`) and carried on to lens position `lens` along unit
/// `to_lens` for `d_lens`; `None` when it carries nothing or misses the film. `count`: the
/// lamp's paths. Visibility is the caller's.
fn landing(
    view: &View,
    (b, n, ng): (Bsdf, Vec3, Vec3),
    leaving: &Leaving,
    lens: Vec2,
    (to_lens, d_lens): (Vec3, f32),
    count: f32,
) -> Option<Splat> {
    let to_g = -leaving.dir;
    let (cos_in, cos_u) = (ng.dot(to_g).abs(), ng.dot(to_lens).abs());
    if !(cos_in > 0.0 && cos_u > 0.0) {
        return None;
    }
    let Landing { film, per_sr, .. } = view.camera.film_point(lens, -to_lens)?;
    let lens_weight = if view.filter == LensFilter::Box {
        1.0
    } else {
        view.camera.lens.weight(view.filter, lens)
    };
    let into_lens = per_sr * cos_u / (count * d_lens * d_lens) * view.share * lens_weight;
    let value = b.eval(n, to_lens, to_g) * leaving.carried * (into_lens / cos_in);
    (value.max_element() > 0.0 && value.is_finite()).then_some(Splat { film, value })
}
