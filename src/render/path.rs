//! The path tracer: unidirectional paths with next-event estimation and multiple importance
//! sampling (power heuristic), Russian roulette, and Cycles' bounce limits per kind, traced
//! 16 paths at a time. A site's lens samples stay one packet for the camera hit and every
//! bounce after it (incoherent after the first); each bounce's light samples go as one
//! `occluded16` packet. Nothing is allocated per ray.

use glam::{Vec2, Vec3};

use super::glossy_light::{Found, GlossyPaths, LampKey, Lit, eligible, receives};
use super::light_choice::LightTraced;
use super::trace::{self, RayKind, Tally, lane_vec};
use crate::embree::{LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
use crate::sampler::{PATH_DIMENSIONS, SampleKey, path_numbers};
use crate::scene::World;
use crate::scene::emitters::{EmitterSample, Receiver, punctual_sample};
use crate::settings::{PathLimits, Strategy};
use crate::shade::{Bsdf, Lobe, Scattering, SurfacePoints16};

/// One bounce's random numbers of one path: 0-2 pick an emitter and a point on it, 3-5 the
/// BSDF's lobe and direction, 6 Russian roulette, 8-9 a direction towards the world.
type Numbers = [f32; PATH_DIMENSIONS];

/// Per-thread scratch space for [`trace_path`].
#[derive(Default)]
pub struct PathScratch {
    shadow: ShadowPacket16,
    points: SurfacePoints16,
    /// While the first surfaces' light samples are taken for [`FirstHits::view_dependent`]:
    /// the part of their light the specular lobes carry.
    view_dependent: Option<[Vec3; LANES]>,
}

/// One path's state between bounces.
#[derive(Clone, Copy)]
struct Lane {
    /// What the path's radiance is multiplied by so far.
    throughput: Vec3,
    /// Density of the direction the path last took (for MIS at the emitter it finds).
    pdf: f32,
    /// The last direction came from a delta lobe (or the camera): emitters found get full
    /// weight.
    delta: bool,
    /// The surface it left, as light sampling there picked lamps for it.
    from: Receiver,
    /// The smallest density of the non-delta directions the path took so far (infinite on
    /// the camera ray): what the glossy filter ([`PathLimits::filter_glossy`]) reads.
    min_pdf: f32,
    diffuse: u32,
    glossy: u32,
    transmission: u32,
    /// Where its last direction left a glossy surface that its rough first surface's
    /// direction found, the diffuse layer's share of that direction's BSDF value: of a lamp
    /// whose caustics light paths take ([`GlossyPaths::drops`]) it keeps only that.
    caustic: Option<Vec3>,
}

impl Lane {
    /// A camera ray's state (its origin is set per lane).
    const CAMERA: Self = Self {
        throughput: Vec3::ONE,
        pdf: 1.0,
        delta: true,
        from: Receiver::at(Vec3::ZERO),
        min_pdf: f32::INFINITY,
        diffuse: 0,
        glossy: 0,
        transmission: 0,
        caustic: None,
    };
}

/// The power heuristic (beta = 2) weight of a strategy of density `a` against one of `b`.
#[inline]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 { a2 / (a2 + b2) } else { 0.0 }
}

/// The weight of an emitter a BSDF sample of density `bsdf` found, which a light sample finds
/// with density `light`.
#[inline]
fn bsdf_weight(strategy: Strategy, bsdf: f32, light: f32) -> f32 {
    match strategy {
        Strategy::Mis => power_heuristic(bsdf, light),
        Strategy::BsdfOnly => 1.0,
        Strategy::LightOnly if light > 0.0 => 0.0,
        Strategy::LightOnly => 1.0,
    }
}

/// The weight of a (non-delta) light sample of density `light`, which a BSDF sample finds with
/// density `bsdf`.
#[inline]
fn light_weight(strategy: Strategy, light: f32, bsdf: f32) -> f32 {
    match strategy {
        Strategy::Mis => power_heuristic(light, bsdf),
        Strategy::LightOnly => 1.0,
        Strategy::BsdfOnly => 0.0,
    }
}

/// `c` scaled down so that no component exceeds `clamp`.
#[inline]
fn clamped(c: Vec3, clamp: f32) -> Vec3 {
    let m = c.max_element();
    if m > clamp { c * (clamp / m) } else { c }
}

/// What one bounce found at the lanes that hit, for the next-event and BSDF samples.
struct Vertices {
    bsdf: [Bsdf; LANES],
    origins: trace::Origins,
    /// Geometric normals as Embree reports them (not unit: only the glossy weight needs them,
    /// and normalises them where it does).
    ng: [Vec3; LANES],
    /// Distances from the rays' origins.
    t: [f32; LANES],
}

impl Vertices {
    /// Each surface's BSDF seen from its ray (`wo` reversed, at the shading normals of
    /// `points`), set up once for the light sample, the BSDF sample and the evaluations made
    /// there; none for the lanes not in `hits` and where nothing scatters.
    fn scattering(
        &self,
        hits: u32,
        wo: &[Vec3; LANES],
        points: &SurfacePoints16,
    ) -> [Option<Scattering>; LANES] {
        std::array::from_fn(|l| {
            let n = points.get(l).normal;
            (hits & (1 << l) != 0)
                .then(|| self.bsdf[l].at(n, wo[l]))
                .flatten()
        })
    }
}

/// A camera ray's first surface where light paths share the light reflected there
/// ([`GlossyPaths::applies`]): what weighing an emitter its BSDF sample finds takes.
#[derive(Clone, Copy)]
struct SharedVertex {
    b: Bsdf,
    n: Vec3,
    ng: Vec3,
    x: Vec3,
    /// Unit direction and distance back to the lens.
    to_lens: Vec3,
    d_lens: f32,
}

impl SharedVertex {
    /// The lanes of `hits` whose first surface (`v`, seen along `wo`) light paths share.
    fn note(
        g: &GlossyPaths,
        hits: u32,
        v: &Vertices,
        wo: &[Vec3; LANES],
        points: &SurfacePoints16,
    ) -> [Option<Self>; LANES] {
        std::array::from_fn(|l| {
            let applies = hits & (1 << l) != 0 && g.applies(&v.bsdf[l], wo[l], v.t[l]);
            applies.then(|| {
                let p = points.get(l);
                Self {
                    b: v.bsdf[l],
                    n: p.normal,
                    ng: v.ng[l],
                    x: p.position,
                    to_lens: wo[l],
                    d_lens: v.t[l],
                }
            })
        })
    }

    /// This surface as an emitter's point `y` lights it, which a light sample draws with
    /// density `nee`.
    fn lit(&self, y: Vec3, nee: f32) -> Option<Lit> {
        let v = y - self.x;
        let d = v.length();
        (d > 0.0).then(|| Lit {
            b: self.b,
            n: self.n,
            ng: self.ng,
            x: self.x,
            to_light: v / d,
            d_light: d,
            irradiance: Vec3::ZERO,
            nee,
            drawn: None,
        })
    }
}

/// What each camera ray of a packet hit first.
#[derive(Debug, Clone, Copy)]
pub struct FirstHits {
    /// Hit distance (infinite for misses).
    pub t: [f32; LANES],
    /// [`Bsdf::view_alpha`] there: over what angle what the ray found may change with the
    /// viewpoint (infinite for misses: the world looks the same along parallel rays; 0
    /// where the integrator does not say).
    pub view_alpha: [f32; LANES],
    /// The geometric normal there, world space, not normalised (zero for misses).
    pub normal: [Vec3; LANES],
    /// When asked for (`Some` before tracing), the part of each lane's radiance that the
    /// first surface's specular lobes carry ([`Bsdf::eval_diffuse`] says what the rest is):
    /// what may change across the aperture faster than [`FirstHits::view_alpha`] allows.
    pub view_dependent: Option<[Vec3; LANES]>,
}

impl FirstHits {
    /// Notes the hit distances `t` of the lanes in `active` (misses: the world, seen alike
    /// from anywhere).
    fn note_distances(&mut self, active: u32, t: &[f32; LANES]) {
        for lane in (0..LANES).filter(|&l| active & (1 << l) != 0) {
            self.t[lane] = t[lane];
            self.view_alpha[lane] = f32::INFINITY;
            self.normal[lane] = Vec3::ZERO;
        }
    }

    /// Notes the BSDFs and geometric normals of the surfaces the lanes in `hits` found.
    fn note_surfaces(&mut self, hits: u32, bsdf: &[Bsdf; LANES], ng: &[Vec3; LANES]) {
        for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
            self.view_alpha[lane] = bsdf[lane].view_alpha();
            self.normal[lane] = ng[lane];
        }
    }
}

impl Default for FirstHits {
    fn default() -> Self {
        Self {
            t: [f32::INFINITY; LANES],
            view_alpha: [0.0; LANES],
            normal: [Vec3::ZERO; LANES],
            view_dependent: None,
        }
    }
}

/// Traces the active lanes of `packet` (camera rays) as paths and writes each lane's radiance
/// to `radiance` and what its camera ray hit to `first`; inactive lanes are left as they
/// were. `keys` are the samples' keys ([`crate::sampler::sample_key`]).
#[allow(clippy::too_many_arguments)]
pub fn trace_path(
    world: &World,
    packet: &mut RayPacket16,
    keys: &[SampleKey; LANES],
    limits: &PathLimits,
    light_traced: &LightTraced,
    radiance: &mut [Vec3; LANES],
    first: &mut FirstHits,
    scratch: &mut PathScratch,
    tally: &mut Tally,
) {
    let mut lanes = camera_lanes(packet, radiance);
    let mut t = [f32::INFINITY; LANES];
    let mut shared = [None; LANES];
    let mut split = ViewSplit::begin(first, scratch);
    let mut caustics = Caustics::new(light_traced);
    let (mut kind, mut hint) = (RayKind::Primary, RayHint::Coherent);
    for bounce in 0..=limits.total {
        tally.bounce = bounce;
        let active = lanes_where(u32::MAX, |l| packet.is_active(l));
        if active == 0 {
            break;
        }
        let hits = trace::trace_depth(world, packet, kind, hint, &mut t, tally);
        if bounce == 0 {
            first.note_distances(active, &t);
        }
        // An emitter found at this bounce has scattered `bounce` times, a light sample taken
        // here once more.
        let weigh = (clamp_after(limits, bounce), limits.strategy);
        add_world(
            world,
            packet,
            (active & !hits, bounce),
            &lanes,
            weigh,
            radiance,
        );
        if hits == 0 {
            break;
        }
        // The emitters light tracing sees through the lens send nothing to camera rays.
        let unseen = (bounce == 0).then_some(light_traced);
        let glossy = light_traced.glossy.as_ref();
        let found = glossy.filter(|_| bounce == 1).map(|g| (g, &shared));
        let lights = (unseen, caustics.paths, found);
        let mut v = vertices(
            world, packet, hits, &lanes, weigh, lights, scratch, radiance,
        );
        filter_glossy(&mut v.bsdf, hits, &lanes, limits.filter_glossy);
        if bounce == 0 {
            first.note_surfaces(hits, &v.bsdf, &v.ng);
        }
        let chain = caustics.chain(bounce, hits, &v.bsdf);
        if bounce == limits.total {
            break;
        }
        let numbers = hit_numbers(keys, hits, bounce);
        let dir = packet.dirs();
        let wo: [Vec3; LANES] = std::array::from_fn(|l| -lane_vec(dir, l));
        let scattering = v.scattering(hits, &wo, &scratch.points);
        let glossy_share = std::array::from_fn(|l| v.bsdf[l].glossy_share());
        if bounce == 0
            && let Some(g) = glossy.filter(|g| g.shares_emitters())
        {
            shared = SharedVertex::note(g, hits, &v, &wo, &scratch.points);
        }
        let at = Shading {
            hits,
            strategy: limits.strategy,
            v: &v,
            wo: &wo,
            scattering: &scattering,
            glossy_share: &glossy_share,
            numbers: &numbers,
            lanes: &lanes,
            glossy: light_traced.glossy.as_ref().filter(|_| bounce == 0),
            caustic: caustics.paths.map(|g| (g, chain)),
        };
        let clamp = clamp_after(limits, bounce + 1);
        next_event(world, &at, clamp, scratch, radiance, tally);
        let mut split_here = split.as_mut().filter(|_| bounce == 0);
        if let Some(s) = split_here.as_deref_mut() {
            s.lit(first, scratch, radiance);
        }
        let drawn = (&v, &scattering, &glossy_share, &numbers, &scratch.points);
        scatter_lanes(drawn, (limits, bounce), &mut lanes, split_here, packet);
        note_caustics(chain, &scattering, packet, &mut lanes);
        kind = RayKind::Secondary;
        hint = RayHint::Incoherent;
    }
    tally.bounce = 0;
    if let Some(s) = split {
        s.finish(first, scratch, radiance);
    }
}

/// The light paths that take caustics over ([`GlossyPaths::drops`]), and the lanes whose
/// first surface receives them.
struct Caustics<'a> {
    paths: Option<&'a GlossyPaths>,
    receivers: u32,
}

impl<'a> Caustics<'a> {
    fn new(light_traced: &'a LightTraced) -> Self {
        Self {
            paths: (light_traced.glossy.as_ref()).filter(|g| g.takes_caustics()),
            receivers: 0,
        }
    }

    /// The lanes of `hits`, at surfaces of BSDFs `bsdf` at bounce `bounce`, whose light from a
    /// lamp is a caustic: at bounce 1, those at a glossy surface that their rough first
    /// surface's direction found (noted at bounce 0); none elsewhere.
    fn chain(&mut self, bounce: u32, hits: u32, bsdf: &[Bsdf; LANES]) -> u32 {
        if self.paths.is_none() {
            return 0;
        }
        match bounce {
            0 => {
                self.receivers = lanes_where(hits, |l| receives(&bsdf[l]));
                0
            }
            1 => lanes_where(hits & self.receivers, |l| eligible(&bsdf[l])),
            _ => 0,
        }
    }
}

/// [`FirstHits::view_dependent`] while the paths are traced.
#[derive(Default)]
struct ViewSplit {
    /// The radiance once the first surfaces' light samples are in (none: no path got there).
    after_first: Option<[Vec3; LANES]>,
    /// Per lane, the specular share of what the path carries after its first scattering.
    shares: [Vec3; LANES],
}

impl ViewSplit {
    /// Before the paths start, when `first` asks for the split: the first light samples
    /// taken ([`next_event`] at the first surfaces) note the part of their light the
    /// specular lobes reflect in `scratch`.
    fn begin(first: &FirstHits, scratch: &mut PathScratch) -> Option<Self> {
        first.view_dependent.is_some().then(|| {
            scratch.view_dependent = Some([Vec3::ZERO; LANES]);
            Self::default()
        })
    }

    /// Once the first surfaces' light samples are in: their specular part is the first
    /// surfaces', and later light samples are not split.
    fn lit(&mut self, first: &mut FirstHits, scratch: &mut PathScratch, radiance: &[Vec3; LANES]) {
        first.view_dependent = scratch.view_dependent.take();
        self.after_first = Some(*radiance);
    }

    /// Adds to the view-dependent part what the paths gathered after their first
    /// scattering, divided as that scattering divided its weight (and stops the split of
    /// light samples if no path reached a surface).
    fn finish(self, first: &mut FirstHits, scratch: &mut PathScratch, radiance: &[Vec3; LANES]) {
        scratch.view_dependent = None;
        if let (Some(vd), Some(after)) = (first.view_dependent.as_mut(), self.after_first) {
            for lane in 0..LANES {
                vd[lane] += (radiance[lane] - after[lane]) * self.shares[lane];
            }
        }
    }
}

/// The share, per channel, of a first scattering's weight that the specular lobes carry: 1
/// from a delta lobe, else `1 - eval_diffuse / (pdf weight)` at the direction drawn.
fn first_specular_share(at: &Scattering, ray: &Ray, s: &Lane) -> Vec3 {
    if s.delta {
        return Vec3::ONE;
    }
    // At the first bounce the throughput is the weight, `f |cos| / pdf`.
    specular_share(s.throughput * s.pdf, at.eval_diffuse(ray.dir))
}

/// Per channel, the share of a BSDF value `total` (`f |cos|`) that its diffuse part
/// `diffuse` is not (0 where `total` is).
fn specular_share(total: Vec3, diffuse: Vec3) -> Vec3 {
    let share = |t: f32, d: f32| {
        if t > 0.0 {
            (1.0 - d / t).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    Vec3::new(
        share(total.x, diffuse.x),
        share(total.y, diffuse.y),
        share(total.z, diffuse.z),
    )
}

/// The state of the camera rays of `packet`'s active lanes, whose radiance is cleared.
fn camera_lanes(packet: &RayPacket16, radiance: &mut [Vec3; LANES]) -> [Lane; LANES] {
    let mut lanes = [Lane::CAMERA; LANES];
    for lane in (0..LANES).filter(|&l| packet.is_active(l)) {
        radiance[lane] = Vec3::ZERO;
        lanes[lane].from = Receiver::at(packet.ray(lane).origin);
    }
    lanes
}

/// The clamp on light that reaches the camera after `scatterings` scatterings: light after at
/// most one is direct; the rest is indirect, what Cycles' "Indirect Light" clamp limits.
fn clamp_after(limits: &PathLimits, scatterings: u32) -> f32 {
    if scatterings <= 1 {
        f32::INFINITY
    } else {
        limits.clamp_indirect
    }
}

/// The random numbers of bounce `bounce` for the lanes in `hits` (the only ones that make
/// decisions there; the others get zeros).
fn hit_numbers(keys: &[SampleKey; LANES], hits: u32, bounce: u32) -> [Numbers; LANES] {
    std::array::from_fn(|l| {
        if hits & (1 << l) != 0 {
            path_numbers(keys[l], bounce)
        } else {
            [0.0; PATH_DIMENSIONS]
        }
    })
}

/// Adds the world's radiance to lanes in `missed` (their rays left the scene), and after a
/// bounce (`bounce` > 0) that of the suns' discs they see: Blender's lights are hidden from
/// camera rays, and glossy and refracted rays find them (a sun's glint in a mirror or glass).
fn add_world(
    world: &World,
    packet: &RayPacket16,
    (missed, bounce): (u32, u32),
    lanes: &[Lane; LANES],
    (clamp, strategy): (f32, Strategy),
    radiance: &mut [Vec3; LANES],
) {
    if missed == 0 {
        return;
    }
    let dir = packet.dirs();
    let emitters = &world.emitters;
    let weight = |s: &Lane, light_pdf: f32| {
        if s.delta {
            1.0
        } else {
            bsdf_weight(strategy, s.pdf, light_pdf)
        }
    };
    for lane in (0..LANES).filter(|&l| missed & (1 << l) != 0) {
        let s = &lanes[lane];
        let d = lane_vec(dir, lane);
        let le = world.background.radiance(d);
        let w = weight(s, emitters.pdf_world(world, d));
        radiance[lane] += clamped(s.throughput * le * w, clamp);
        if bounce > 0 {
            for (le, light_pdf) in emitters.suns_seen(d) {
                radiance[lane] += clamped(s.throughput * le * weight(s, light_pdf), clamp);
            }
        }
    }
}

/// The light paths that share a camera path's second surface's emission, with what its first
/// surfaces were ([`SharedVertex`]).
type SharedEmission<'a> = Option<(&'a GlossyPaths, &'a [Option<SharedVertex>; LANES])>;

/// The BSDFs and leaving origins of the lanes in `hits`; adds the emission they see (but not
/// that of primitives in `unseen`; of a caustic light paths take from `caustics`, only the
/// diffuse layer's part; weighted against the light paths of `found` where they share it).
#[allow(clippy::too_many_arguments)]
fn vertices(
    world: &World,
    packet: &RayPacket16,
    hits: u32,
    lanes: &[Lane; LANES],
    (clamp, strategy): (f32, Strategy),
    (unseen, caustics, found): (
        Option<&LightTraced>,
        Option<&GlossyPaths>,
        SharedEmission<'_>,
    ),
    scratch: &mut PathScratch,
    radiance: &mut [Vec3; LANES],
) -> Vertices {
    let points = &mut scratch.points;
    world.surface_points16(packet, hits, points);
    let dir = packet.dirs();
    let mut bsdf = [Bsdf::diffuse(Vec3::ZERO); LANES];
    let mut ng = [Vec3::Z; LANES];
    let mut extent = [0.0f32; LANES];
    let mut lift = [[0.0f32; LANES]; 3];
    for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
        let hit = packet.hit(lane).expect("lanes in `hits` hit");
        let sp = points.get(lane);
        let d = lane_vec(dir, lane);
        let material = world.material(&hit);
        let front = hit.is_front(d);
        let le = material.emitted_towards(sp.uv, front);
        let seen = || unseen.is_none_or(|u| !u.contains(hit.geometry.0, hit.prim));
        if le != Vec3::ZERO && seen() {
            let s = &lanes[lane];
            // Of a caustic the light paths take, the diffuse layer's part (a delta's
            // reflection they do not take).
            let key = LampKey::Primitive(hit.geometry.0, hit.prim);
            let keep = (s.caustic)
                .filter(|_| !s.delta && caustics.is_some_and(|g| g.drops(key)))
                .unwrap_or(Vec3::ONE);
            let w = if s.delta {
                1.0
            } else {
                let pdf_light = world.emitters.pdf_hit(world, &hit, &s.from, sp.position, d);
                // Where light paths share the emitter's reflection, the weight counts them.
                let shared = found.and_then(|(g, first)| {
                    let f = first[lane]?;
                    let at = f.lit(sp.position, pdf_light)?;
                    g.camera_weight(Found::BsdfSample, key, &at, f.to_lens, f.d_lens)
                });
                shared.unwrap_or_else(|| bsdf_weight(strategy, s.pdf, pdf_light))
            };
            radiance[lane] += clamped(s.throughput * keep * le * w, clamp);
        }
        bsdf[lane] = material.bsdf(sp.uv, front);
        ng[lane] = hit.ng;
        extent[lane] = trace::primitive_extent(world, &hit);
        let up = trace::terminator_lift(world, &hit, sp.position, sp.normal);
        for k in 0..3 {
            lift[k][lane] = up[k];
        }
    }
    let origins = trace::leaving_origins(
        &points.position,
        &points.normal,
        dir,
        packet.tfars(),
        &extent,
        &lift,
    );
    Vertices {
        bsdf,
        origins,
        ng,
        t: *packet.tfars(),
    }
}

/// Cycles' Filter Glossy ([`PathLimits::filter_glossy`]; 0: off): makes the BSDFs of the lanes
/// in `hits` at least as rough as GGX alpha `sqrt(1 - min_pdf / amount) / 2`, where `min_pdf`
/// is the least likely direction their path took so far. A camera ray's first surface keeps its
/// own roughness; after a diffuse bounce (density at most 1 / pi) alpha is at least 0.41 at
/// Cycles' default of 1. Next-event estimation and BSDF sampling both see the rougher lobe,
/// so the estimate stays consistent with it; what it estimates is the blurred caustic.
fn filter_glossy(bsdf: &mut [Bsdf; LANES], hits: u32, lanes: &[Lane; LANES], amount: f32) {
    if amount <= 0.0 {
        return;
    }
    for lane in (0..LANES).filter(|&l| hits & (1 << l) != 0) {
        let blur_pdf = lanes[lane].min_pdf / amount;
        if blur_pdf < 1.0 {
            let alpha = (1.0 - blur_pdf).sqrt() * 0.5;
            // Roughness is perceptual: GGX alpha is its square.
            let b = &mut bsdf[lane];
            b.roughness = b.roughness.max(alpha.sqrt());
        }
    }
}

/// One bounce's vertices as next-event estimation reads them.
struct Shading<'a> {
    /// The lanes that hit (bit per lane).
    hits: u32,
    /// How light and BSDF samples are weighed.
    strategy: Strategy,
    v: &'a Vertices,
    /// Unit directions towards the viewer (the reversed rays), and the BSDFs seen from
    /// them (none where nothing scatters).
    wo: &'a [Vec3; LANES],
    scattering: &'a [Option<Scattering>; LANES],
    /// [`Bsdf::glossy_share`] of each surface (after the glossy filter), once for all its
    /// light samples.
    glossy_share: &'a [f32; LANES],
    numbers: &'a [Numbers; LANES],
    lanes: &'a [Lane; LANES],
    /// At a camera ray's first surface: the lamps whose glossy reflections light paths share.
    glossy: Option<&'a GlossyPaths>,
    /// The light paths that take caustics over, and the lanes at a glossy surface whose
    /// light from their lamps is a caustic of a rough first surface.
    caustic: Option<(&'a GlossyPaths, u32)>,
}

/// Next-event estimation: a shadow packet for each always-sampled punctual light, one for the
/// world when it emits, and one for an emitter drawn per lane from the others, weighted against
/// BSDF sampling by the power heuristic.
fn next_event(
    world: &World,
    at: &Shading,
    clamp: f32,
    scratch: &mut PathScratch,
    radiance: &mut [Vec3; LANES],
    tally: &mut Tally,
) {
    let emitters = &world.emitters;
    for (i, light) in emitters.always.iter().enumerate() {
        let sample =
            |r: &Receiver, u: &Numbers| Some(punctual_sample(light, r.p, Vec2::new(u[1], u[2])));
        shadow_packet(world, at, clamp, sample, Some(i), scratch, radiance, tally);
    }
    if emitters.samples_world() {
        let sample =
            |_: &Receiver, u: &Numbers| emitters.sample_world(world, Vec2::new(u[8], u[9]));
        shadow_packet(world, at, clamp, sample, None, scratch, radiance, tally);
    }
    if emitters.has_distribution() {
        let sample = |r: &Receiver, u: &Numbers| emitters.sample(world, r, [u[0], u[1], u[2]]);
        shadow_packet(world, at, clamp, sample, None, scratch, radiance, tally);
    }
}

/// Draws one light sample per lane that hit with `sample` (for the lane's leaving origin and
/// surface, with its numbers), traces them as one shadow packet and adds the unoccluded ones.
/// `punctual` is the index of the punctual light sampled, whose glossy reflections light paths
/// may share.
#[allow(clippy::too_many_arguments)]
fn shadow_packet(
    world: &World,
    at: &Shading,
    clamp: f32,
    sample: impl Fn(&Receiver, &Numbers) -> Option<EmitterSample>,
    punctual: Option<usize>,
    scratch: &mut PathScratch,
    radiance: &mut [Vec3; LANES],
    tally: &mut Tally,
) {
    let points = &scratch.points;
    let mut origin = [[0.0f32; LANES]; 3];
    let mut to_light = [[0.0f32; LANES]; 3];
    let mut seg_end = [0.0f32; LANES];
    let mut contribution = [Vec3::ZERO; LANES];
    // The specular lobes' part of each contribution, when the first surfaces' light is split.
    let mut specular = scratch.view_dependent.map(|_| [Vec3::ZERO; LANES]);
    let mut lit = 0u32;
    let Shading {
        hits,
        v,
        scattering,
        glossy_share,
        numbers,
        lanes,
        ..
    } = *at;
    // A vertex whose BSDF is all deltas (a smooth mirror or clear glass) takes no light sample.
    let sampled = (0..LANES).filter(|&l| hits & (1 << l) != 0 && !v.bsdf[l].is_delta());
    for lane in sampled {
        let n = points.get(lane).normal;
        let r = Receiver {
            p: v.origins.at(lane, true),
            n,
            glossy: glossy_share[lane],
        };
        let Some(es) = sample(&r, &numbers[lane]) else {
            continue;
        };
        let Some(bsdf) = &scattering[lane] else {
            continue;
        };
        // The specular lobes' caustic of a lamp the light paths take is theirs.
        let key = lamp_key(&es, punctual);
        let dropped = (at.caustic.zip(key))
            .is_some_and(|((g, chain), key)| chain & (1 << lane) != 0 && g.drops(key));
        // With the split or a caustic dropped, the diffuse layer's part too (from the same
        // setup).
        let (f, bsdf_pdf, diffuse) = if specular.is_some() || dropped {
            bsdf.eval_pdf_diffuse(es.dir)
        } else {
            let (f, pdf) = bsdf.eval_pdf(es.dir);
            (f, pdf, Vec3::ZERO)
        };
        let f = if dropped { diffuse } else { f };
        if f == Vec3::ZERO {
            continue;
        }
        let w = light_sample_weight(at, lane, (n, points.get(lane).position), &es, key, bsdf_pdf);
        let c = lanes[lane].throughput * f * es.radiance * (w / es.pdf);
        if !(c.max_element() > 0.0 && c.is_finite()) {
            continue;
        }
        contribution[lane] = clamped(c, clamp);
        if let Some(sp) = specular.as_mut() {
            sp[lane] = contribution[lane] * specular_share(f, diffuse);
        }
        let o = v.origins.at(lane, es.dir.dot(n) >= 0.0);
        for k in 0..3 {
            origin[k][lane] = o[k];
            to_light[k][lane] = es.dir[k];
        }
        seg_end[lane] = if es.distance.is_finite() {
            es.distance * (1.0 - 1e-4) - v.origins.reach[lane]
        } else {
            f32::INFINITY
        };
        lit |= 1 << lane;
    }
    if lit == 0 {
        return;
    }
    let shadow = &mut scratch.shadow;
    let hint = RayHint::Incoherent;
    trace::trace_shadows(
        world, shadow, lit, &origin, &to_light, &seg_end, hint, tally,
    );
    for lane in (0..LANES).filter(|&l| lit & (1 << l) != 0) {
        if shadow.is_active(lane) && !shadow.occluded(lane) {
            radiance[lane] += contribution[lane];
            if let (Some(vd), Some(sp)) = (scratch.view_dependent.as_mut(), &specular) {
                vd[lane] += sp[lane];
            }
        }
    }
}

/// The multiple-importance weight of light sample `es` (drawn with density `es.pdf`,
/// which the BSDF would draw with `bsdf_pdf`) at lane `lane`'s vertex (shading normal and
/// position); `key`: the lamp it sampled, if light paths may leave it.
fn light_sample_weight(
    at: &Shading,
    lane: usize,
    (n, position): (Vec3, Vec3),
    es: &EmitterSample,
    key: Option<LampKey>,
    bsdf_pdf: f32,
) -> f32 {
    // Where light paths share the lamp's reflection here, the weight counts them too.
    let shared = at.glossy.zip(key).and_then(|(g, key)| {
        let lit = Lit {
            b: at.v.bsdf[lane],
            n,
            ng: at.v.ng[lane],
            x: position,
            to_light: es.dir,
            d_light: es.distance,
            irradiance: es.radiance,
            nee: if es.delta { 1.0 } else { es.pdf },
            drawn: None,
        };
        g.camera_weight(Found::LightSample, key, &lit, at.wo[lane], at.v.t[lane])
    });
    match (shared, es.delta) {
        (Some(w), _) => w,
        (None, true) => 1.0,
        (None, false) => light_weight(at.strategy, es.pdf, bsdf_pdf),
    }
}

/// The next rays of the lanes that scatter ([`scatter`]: `v`'s surfaces seen as
/// `scattering`, of glossy shares `glossy_share`, drawn with `numbers`, at the shading normals
/// of `points`) into `packet`, which is cleared first; with `split`, each lane's specular
/// share of its first scattering too.
fn scatter_lanes(
    (v, scattering, glossy_share, numbers, points): (
        &Vertices,
        &[Option<Scattering>; LANES],
        &[f32; LANES],
        &[Numbers; LANES],
        &SurfacePoints16,
    ),
    (limits, bounce): (&PathLimits, u32),
    lanes: &mut [Lane; LANES],
    mut split: Option<&mut ViewSplit>,
    packet: &mut RayPacket16,
) {
    packet.clear();
    for lane in 0..LANES {
        let Some(at) = &scattering[lane] else {
            continue;
        };
        let n = points.get(lane).normal;
        let u = &numbers[lane];
        let surface = (n, at, glossy_share[lane]);
        if let Some(ray) = scatter(v, lane, surface, u, limits, bounce, &mut lanes[lane]) {
            if let Some(s) = split.as_deref_mut() {
                s.shares[lane] = first_specular_share(at, &ray, &lanes[lane]);
            }
            packet.set(lane, &ray);
        }
    }
}

/// Draws the next direction of lane `lane` from its BSDF; updates the path's state and
/// returns the ray to trace, or `None` when the path ends (absorbed, out of bounces for its
/// kind, or stopped by Russian roulette).
#[allow(clippy::too_many_arguments)]
fn scatter(
    v: &Vertices,
    lane: usize,
    (n, at, glossy): (Vec3, &Scattering, f32),
    u: &Numbers,
    limits: &PathLimits,
    bounce: u32,
    s: &mut Lane,
) -> Option<Ray> {
    let sample = at.sample([u[3], u[4], u[5]])?;
    let (count, limit) = match sample.lobe {
        Lobe::Diffuse => (&mut s.diffuse, limits.diffuse),
        Lobe::Glossy => (&mut s.glossy, limits.glossy),
        Lobe::Transmission => (&mut s.transmission, limits.transmission),
    };
    if *count >= limit {
        return None;
    }
    *count += 1;
    let mut throughput = s.throughput * sample.weight;
    // Russian roulette after the third bounce, surviving with the throughput's largest
    // component (at most 0.95), so paths that carry little stop early and unbiasedly.
    if bounce >= 3 {
        let q = throughput.max_element().min(0.95);
        if u[6] >= q {
            return None;
        }
        throughput /= q;
    }
    if !(throughput.max_element() > 0.0 && throughput.is_finite()) {
        return None;
    }
    let origin = v.origins.at(lane, sample.wi.dot(n) >= 0.0);
    s.throughput = throughput;
    s.pdf = sample.pdf;
    s.delta = sample.delta;
    if !sample.delta {
        s.min_pdf = s.min_pdf.min(sample.pdf);
    }
    s.from = Receiver {
        p: origin,
        n,
        glossy,
    };
    Some(Ray::new(origin, sample.wi))
}

/// The lamp light sample `es` found, if light paths may leave it: the punctual light
/// `punctual` (its index) or an emissive primitive.
fn lamp_key(es: &EmitterSample, punctual: Option<usize>) -> Option<LampKey> {
    match (es.delta, punctual, es.primitive) {
        (true, Some(light), _) => Some(LampKey::Punctual(light)),
        (false, _, Some((g, p))) => Some(LampKey::Primitive(g, p)),
        _ => None,
    }
}

/// The lanes of `mask` for which `keep` holds.
fn lanes_where(mask: u32, keep: impl Fn(usize) -> bool) -> u32 {
    (0..LANES)
        .filter(|&l| mask & (1 << l) != 0 && keep(l))
        .fold(0, |m, l| m | 1 << l)
}

/// Notes in `lanes` the caustic share ([`Lane::caustic`]) of the directions drawn into `packet`
/// at the surfaces `scattering` of the lanes in `chain` (none elsewhere).
fn note_caustics(
    chain: u32,
    scattering: &[Option<Scattering>; LANES],
    packet: &RayPacket16,
    lanes: &mut [Lane; LANES],
) {
    let dir = packet.dirs();
    for (l, s) in lanes.iter_mut().enumerate() {
        s.caustic = None;
        if chain & (1 << l) == 0 || !packet.is_active(l) {
            continue;
        }
        if let Some(at) = &scattering[l] {
            let (f, _, diffuse) = at.eval_pdf_diffuse(lane_vec(dir, l));
            s.caustic = Some(Vec3::ONE - specular_share(f, diffuse));
        }
    }
}
