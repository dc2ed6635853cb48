//! Which emitter a light sample goes to: a bounding volume hierarchy over the emitters that
//! picks, from any point, the ones likely to light it most (many-light sampling after Conty
//! Estevez and Kulla, "Importance Sampling of Many Lights with Adaptive Tree Splitting", 2018,
//! as pbrt-v4's `BVHLightSampler` builds and walks it).
//!
//! Picking by power alone treats a street of a hundred lamps as one light: a point under one
//! lamp picks it once in a hundred draws, and the ninety-nine others, far off, send it almost
//! nothing. Here every node bounds its emitters by a box, their total power and the cone of
//! directions they emit in. A draw walks down from the root and takes each child with the
//! mean of two shares of the children's *importance* at the point: power over the squared
//! distance to the box's centre (pbrt's and Cycles' estimate) and to the box's nearest point
//! (which finds the nearest lamps of a long street from its end), each times the cosine of the
//! angle by which the point lies outside the emission cone and the cosine at the receiving
//! surface (either side, so glass still takes light from behind), and zero only where no
//! emitter of the node can send light. The probability of any one emitter
//! ([`LightTree::pmf`]) is the product along the path the draw takes to it, followed by the
//! bits each emitter keeps of that path.
//!
//! Every emitter keeps a probability above zero wherever it can light the point, so the
//! estimate stays unbiased; the importance, a heuristic, sets only its variance. It knows
//! nothing of the surface's reflection: a glossy floor reflecting a far lamp gets that lamp
//! rarely from the walk alone. So a share [`DEFENSIVE`] of the draws picks by power alone, as
//! before the tree, and so does the share of the surface's light that a narrow glossy lobe
//! reflects (the caller's `glossy`); every probability is the mixture's, so no emitter is
//! picked less often than that share of its power-only probability (defensive importance
//! sampling).

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Quat, Vec3};

use crate::limits::{MemoryError, try_collect, try_vec};

/// The nearest a point inside a node's box is taken to be to its light, as a fraction of the
/// box's half-diagonal, squared: a tenth. (Taken as touching, a box holding the point would
/// take every draw, however little its lamps send against a bright window further off.)
const NEAR_CLAMP: f32 = 0.01;
/// The least squared distance the importance divides by (a point on a point light).
const MIN_DISTANCE2: f32 = 1e-12;
/// The share of draws that pick by power alone (see the module documentation).
pub const DEFENSIVE: f32 = 0.2;
/// Buckets per axis the build tries splits between.
const BUCKETS: usize = 12;
/// The deepest a path may go: a path is kept as one bit per level.
const MAX_DEPTH: u32 = 63;

/// What a node knows of its emitters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightBounds {
    lo: Vec3,
    hi: Vec3,
    /// Total power (luminance-weighted; only ratios matter).
    phi: f32,
    /// Axis of the cone holding every emitter's main direction (unit).
    w: Vec3,
    /// Cosine of that cone's half-angle.
    cos_o: f32,
    /// That half-angle (radians), kept for the build's unions.
    theta_o: f32,
    /// Cosine of the angle beyond a main direction up to which light leaves.
    cos_e: f32,
    /// Whether light also leaves against the main direction (both faces of a triangle).
    two_sided: bool,
}

impl LightBounds {
    /// An emitter within the box `lo`..`hi` of power `phi` whose light leaves within the
    /// angle `acos(cos_e)` of directions in the cone of axis `w` and half-angle `acos(cos_o)`
    /// (and of their opposites when `two_sided`).
    pub fn new(
        lo: Vec3,
        hi: Vec3,
        phi: f32,
        w: Vec3,
        cos_o: f32,
        cos_e: f32,
        two_sided: bool,
    ) -> Self {
        // A cone without an axis emits everywhere.
        let (w, cos_o) = w.try_normalize().map_or((Vec3::Z, -1.0), |w| (w, cos_o));
        Self {
            lo: lo.min(hi),
            hi: hi.max(lo),
            phi: phi.max(0.0),
            w,
            cos_o: cos_o.clamp(-1.0, 1.0),
            theta_o: cos_o.clamp(-1.0, 1.0).acos(),
            cos_e: cos_e.clamp(-1.0, 1.0),
            two_sided,
        }
    }

    /// Light leaving a point (or a box) in every direction: a point light or a sphere.
    pub fn everywhere(lo: Vec3, hi: Vec3, phi: f32) -> Self {
        Self::new(lo, hi, phi, Vec3::Z, -1.0, 0.0, false)
    }

    /// The power it was given (luminance-weighted; only ratios matter).
    pub fn power(&self) -> f32 {
        self.phi
    }

    fn centroid(&self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }

    fn union(&self, b: &Self) -> Self {
        let mut u = *self;
        u.merge(b);
        u
    }

    /// Grows these bounds to hold `b` too ([`LightBounds::union`] in place).
    fn merge(&mut self, b: &Self) {
        let cone = (self.w, self.cos_o, self.theta_o);
        (self.w, self.cos_o, self.theta_o) = cone_union(cone, (b.w, b.cos_o, b.theta_o));
        self.lo = self.lo.min(b.lo);
        self.hi = self.hi.max(b.hi);
        self.phi += b.phi;
        self.cos_e = self.cos_e.min(b.cos_e);
        self.two_sided |= b.two_sided;
    }

    /// What these bounds' emitters may send to `p`, up to a common factor (the tree's estimate
    /// by the distance to the box's centre; see the module documentation).
    #[cfg(test)]
    fn importance(&self, p: Vec3) -> f32 {
        Probe::of(self).importance(&Receiver::at(p)).0
    }

    /// pbrt-v4's measure of the solid angle a cone of emission covers, for the build's cost.
    fn direction_measure(&self) -> f32 {
        let theta_o = self.theta_o;
        let theta_e = self.cos_e.clamp(-1.0, 1.0).acos();
        let theta_w = (theta_o + theta_e).min(PI);
        let sin_o = safe_sqrt(1.0 - self.cos_o * self.cos_o);
        2.0 * PI * (1.0 - self.cos_o)
            + FRAC_PI_2
                * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o
                    + self.cos_o)
    }

    fn surface_area(&self) -> f32 {
        let d = self.hi - self.lo;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
}

/// What [`Probe::importance`] reads of a node's bounds, worked out once at the build.
#[derive(Debug, Clone, Copy)]
struct Probe {
    lo: Vec3,
    hi: Vec3,
    centre: Vec3,
    /// Half the box's diagonal.
    radius: f32,
    phi: f32,
    w: Vec3,
    cos_o: f32,
    sin_o: f32,
    cos_e: f32,
    two_sided: bool,
}

impl Probe {
    fn of(b: &LightBounds) -> Self {
        Self {
            lo: b.lo,
            hi: b.hi,
            centre: b.centroid(),
            radius: 0.5 * (b.hi - b.lo).length(),
            phi: b.phi,
            w: b.w,
            cos_o: b.cos_o,
            sin_o: safe_sqrt(1.0 - b.cos_o * b.cos_o),
            cos_e: b.cos_e,
            two_sided: b.two_sided,
        }
    }

    /// How much light the node's emitters may send to `p`, up to a common factor, two ways:
    /// power over the squared distance to the box's centre (at least half the box's
    /// half-diagonal, as Cycles clamps it), and power over the squared distance to the box's
    /// nearest point (at least [`NEAR_CLAMP`]; near an upper bound: the box's light may all be
    /// there, as a street's nearest lamps are for a point at one end of it). Both times the
    /// cosine of the smallest angle between a direction from the box to `p` and a direction in
    /// the emission cone (zero when that angle is beyond the emission's spread) and the cosine
    /// at the receiving surface, each less the angle the box subtends.
    #[inline]
    fn importance(&self, r: &Receiver) -> (f32, f32) {
        let p = r.p;
        let v = p - self.centre;
        let d2_centre = v.length_squared();
        let r2 = self.radius * self.radius;
        // Inside the box's sphere every direction may reach p, at any angle to its surface.
        let mut weight = self.phi;
        if d2_centre > r2 {
            let inv_d = d2_centre.sqrt().recip();
            let wi = v * inv_d;
            // The angle the box subtends from p.
            let sin_b2 = r2 * inv_d * inv_d;
            let b = (sin_b2.sqrt(), safe_sqrt(1.0 - sin_b2));
            if self.cos_o > -1.0 {
                let mut cos_w = self.w.dot(wi);
                if self.two_sided {
                    cos_w = cos_w.abs();
                }
                let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
                let (cos_x, sin_x) = sub_clamped((sin_w, cos_w), (self.sin_o, self.cos_o));
                let cos_p = sub_clamped((sin_x, cos_x), b).0;
                if cos_p <= self.cos_e {
                    return (0.0, 0.0);
                }
                weight *= cos_p;
            } else if self.cos_e >= 1.0 {
                return (0.0, 0.0);
            }
            // Light arriving along the surface lights it little (either side: glass and thin
            // sheets take light from behind).
            if r.n != Vec3::ZERO {
                let cos_i = r.n.dot(wi).abs().min(1.0);
                weight *= sub_clamped((safe_sqrt(1.0 - cos_i * cos_i), cos_i), b).0;
            }
        } else if self.cos_e >= 1.0 {
            return (0.0, 0.0);
        }
        let d2_near = (p - p.clamp(self.lo, self.hi))
            .length_squared()
            .max(NEAR_CLAMP * r2);
        let at = |d2: f32| {
            let importance = weight / d2.max(MIN_DISTANCE2);
            if importance.is_finite() {
                importance.max(0.0)
            } else {
                0.0
            }
        };
        (at(d2_centre.max(0.25 * r2)), at(d2_near))
    }
}

/// The point a light sample is drawn for: where it is, its surface's (shading) normal (zero
/// for none) and [`crate::shade::Bsdf::glossy_share`] of its surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Receiver {
    /// Where the light sample leaves from.
    pub p: Vec3,
    /// Its surface's normal (either side), or zero.
    pub n: Vec3,
    /// The share of its light a narrow glossy lobe reflects, in [0, 1].
    pub glossy: f32,
}

impl Receiver {
    /// A point with no surface to weigh directions by, matte.
    pub const fn at(p: Vec3) -> Self {
        Self {
            p,
            n: Vec3::ZERO,
            glossy: 0.0,
        }
    }
}

/// The probability of walking to the first of two children with importances `a` and `b`
/// ([`Probe::importance`]): the mean of the two estimates' shares, so a child whose box holds
/// the point (the nearest lamps) gets at least half, and one far off about its share of
/// power over distance squared. `None` when neither child can light the point.
fn first_share(a: (f32, f32), b: (f32, f32)) -> Option<f32> {
    let share = |x: f32, y: f32| {
        let total = x + y;
        (total > 0.0 && total.is_finite()).then(|| x / total)
    };
    let centre = share(a.0, b.0);
    let near = share(a.1, b.1);
    match (centre, near) {
        (Some(c), Some(n)) => Some(0.5 * (c + n)),
        (c, n) => c.or(n),
    }
}

fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

/// (cos, sin) of the angle a - b, clamped at zero (a and b given as (sin, cos)).
fn sub_clamped((sin_a, cos_a): (f32, f32), (sin_b, cos_b): (f32, f32)) -> (f32, f32) {
    if cos_a > cos_b {
        (1.0, 0.0)
    } else {
        (cos_a * cos_b + sin_a * sin_b, sin_a * cos_b - cos_a * sin_b)
    }
}

/// The angle between unit vectors, accurate for nearly parallel and opposite ones.
fn angle_between(a: Vec3, b: Vec3) -> f32 {
    if a.dot(b) < 0.0 {
        PI - 2.0 * ((a + b).length() * 0.5).min(1.0).asin()
    } else {
        2.0 * ((b - a).length() * 0.5).min(1.0).asin()
    }
}

/// The smallest cone (axis, cosine of half-angle) holding both cones.
fn cone_union(a: (Vec3, f32, f32), b: (Vec3, f32, f32)) -> (Vec3, f32, f32) {
    // The common cases first, without trigonometry: a cone of every direction, and the
    // same axis (a flat emissive mesh's triangles).
    if a.1 <= -1.0 {
        return a;
    }
    if b.1 <= -1.0 {
        return b;
    }
    if a.0 == b.0 {
        return if a.2 >= b.2 { a } else { b };
    }
    let (theta_a, theta_b) = (a.2, b.2);
    let theta_d = angle_between(a.0, b.0);
    if (theta_d + theta_b).min(PI) <= theta_a {
        return a;
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return b;
    }
    let theta_o = 0.5 * (theta_a + theta_d + theta_b);
    let axis = a.0.cross(b.0);
    if theta_o >= PI || axis.length_squared() == 0.0 {
        return (a.0, -1.0, PI);
    }
    // Turn a's axis towards b's until the cone reaches both.
    let w = Quat::from_axis_angle(axis.normalize(), theta_o - theta_a) * a.0;
    (w.normalize(), theta_o.cos(), theta_o)
}

#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Probe,
    /// A leaf's emitter, or an interior node's second child (its first follows it).
    index: u32,
    leaf: bool,
}

/// The tree over a list of emitters, which keep their indices.
#[derive(Debug, Clone, Default)]
pub struct LightTree {
    nodes: Vec<Node>,
    /// For each emitter, the path from the root to its leaf: bit d set where level d takes
    /// the second child.
    trail: Vec<u64>,
    /// Each emitter's share of the total power.
    power: Vec<f32>,
    /// Running sum of `power` (the last entry is 1).
    cdf: Vec<f32>,
}

impl LightTree {
    /// The tree over `emitters` (emitter i is `emitters[i]`), or the memory error naming what
    /// could not be allocated (about 180 bytes per emitter while building, 175 after). Large
    /// subtrees are built in parallel.
    pub fn build(emitters: &[LightBounds]) -> Result<Self, MemoryError> {
        let n = emitters.len();
        let total: f64 = emitters.iter().map(|b| b.phi as f64).sum();
        let share = |b: &LightBounds| {
            if total > 0.0 && total.is_finite() {
                (b.phi as f64 / total) as f32
            } else {
                1.0 / n as f32
            }
        };
        let power = try_collect(emitters.iter().map(share), "the light tree's powers")?;
        let mut sum = 0.0f64;
        let running = |&p: &f32| {
            sum += p as f64;
            sum as f32
        };
        let cdf = try_collect(power.iter().map(running), "the light tree's powers")?;
        let build = Build { bounds: emitters };
        let mut order = try_collect(0..n as u32, "the light tree's build")?;
        let placeholder = Node {
            bounds: Probe::of(&LightBounds::everywhere(Vec3::ZERO, Vec3::ZERO, 0.0)),
            index: 0,
            leaf: true,
        };
        // A subtree over m emitters takes exactly 2 m - 1 nodes, in depth-first order.
        let mut nodes = try_vec((2 * n).saturating_sub(1), placeholder, "the light tree")?;
        if n > 0 {
            build.subtree(&mut nodes, 0, &mut order, 0);
        }
        let mut trail = try_vec(n, 0u64, "the light tree's paths")?;
        set_trails(&nodes, &mut trail);
        Ok(Self {
            nodes,
            trail,
            power,
            cdf,
        })
    }

    /// Whether there is no emitter to pick.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Picks an emitter for receiver `r` with `u` in [0, 1): its index and the probability it was
    /// picked with ([`LightTree::pmf`]). `None` when there is none to pick. The receiver's
    /// `glossy`, the share of its light that comes through a narrow glossy lobe, which
    /// reflects lamps by direction, not by distance, sets how many more draws than
    /// [`DEFENSIVE`] pick by power.
    pub fn sample(&self, r: &Receiver, u: f32) -> Option<(u32, f32)> {
        let by_power = by_power(r.glossy);
        let (i, walked) = if u < by_power {
            let u = u / by_power;
            let i = self.cdf.partition_point(|&c| c <= u);
            let i = (i < self.power.len()).then_some(i as u32)?;
            (i, self.walk_pmf(r, i))
        } else {
            let u = ((u - by_power) / (1.0 - by_power)).clamp(0.0, ONE_MINUS_EPSILON);
            self.walk(r, u)?
        };
        // The same sum as `pmf`'s, so the two agree to the bit.
        let pmf = by_power * self.power[i as usize] + (1.0 - by_power) * walked;
        (pmf > 0.0).then_some((i, pmf))
    }

    /// The probability [`LightTree::sample`] picks emitter `i` for receiver `r` with.
    pub fn pmf(&self, r: &Receiver, i: u32) -> f32 {
        let Some(&power) = self.power.get(i as usize) else {
            return 0.0;
        };
        let by_power = by_power(r.glossy);
        by_power * power + (1.0 - by_power) * self.walk_pmf(r, i)
    }

    /// [`first_share`] of nodes `a` and `b` for `r`.
    fn first_share(&self, a: usize, b: usize, r: &Receiver) -> Option<f32> {
        let (na, nb) = (&self.nodes[a].bounds, &self.nodes[b].bounds);
        first_share(na.importance(r), nb.importance(r))
    }

    /// The walk down the tree alone: an emitter and its probability.
    fn walk(&self, r: &Receiver, mut u: f32) -> Option<(u32, f32)> {
        let mut node = 0;
        let mut pmf = 1.0f32;
        loop {
            let n = self.nodes.get(node)?;
            if n.leaf {
                return (node > 0 || n.bounds.importance(r).0 > 0.0).then_some((n.index, pmf));
            }
            let (a, b) = (node + 1, n.index as usize);
            let pa = self.first_share(a, b, r)?;
            if u < pa {
                node = a;
                pmf *= pa;
                u = (u / pa).min(ONE_MINUS_EPSILON);
            } else {
                node = b;
                pmf *= 1.0 - pa;
                u = ((u - pa) / (1.0 - pa)).clamp(0.0, ONE_MINUS_EPSILON);
            }
        }
    }

    /// The probability [`LightTree::walk`] reaches emitter `i` for receiver `r` with.
    fn walk_pmf(&self, r: &Receiver, i: u32) -> f32 {
        let Some(&trail) = self.trail.get(i as usize) else {
            return 0.0;
        };
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        if root.leaf {
            return if root.bounds.importance(r).0 > 0.0 {
                1.0
            } else {
                0.0
            };
        }
        let (mut node, mut trail, mut pmf) = (0, trail, 1.0f32);
        loop {
            let n = &self.nodes[node];
            if n.leaf {
                return pmf;
            }
            let (a, b) = (node + 1, n.index as usize);
            let Some(pa) = self.first_share(a, b, r) else {
                return 0.0;
            };
            if trail & 1 == 0 {
                node = a;
                pmf *= pa;
            } else {
                node = b;
                pmf *= 1.0 - pa;
            }
            trail >>= 1;
        }
    }
}

/// Subtrees over fewer emitters than this are built on the calling thread.
const PARALLEL_BUILD: usize = 4096;
/// The most emitters of a node whose bounds are binned to choose its split: a larger node
/// bins an even spread of this many of them (the cut then applies to all), so each emitter is
/// binned on the 11 levels below 2048 and not on every level above (binning all of them at
/// every level, two million emissive triangles took about 10 s to build; now about 3).
const BINNED: usize = 2048;

/// The emitters a tree is built over.
struct Build<'a> {
    bounds: &'a [LightBounds],
}

impl Build<'_> {
    /// Fills `nodes` (exactly `2 order.len() - 1` of them, the first at index `base` of the
    /// whole tree) with the subtree over the emitters `order` lists: the node, its first
    /// child's subtree right after it, then its second's. Returns the subtree's bounds: each
    /// node's are its children's union (as pbrt-v4 builds them), so every emitter's bounds are
    /// merged once per level it rises.
    fn subtree(
        &self,
        nodes: &mut [Node],
        base: usize,
        order: &mut [u32],
        depth: u32,
    ) -> LightBounds {
        if let [index] = *order {
            let bounds = self.bounds[index as usize];
            nodes[0] = Node {
                bounds: Probe::of(&bounds),
                index,
                leaf: true,
            };
            return bounds;
        }
        let mid = self.split(order, depth);
        let second = base + 2 * mid;
        let (node, below) = nodes
            .split_first_mut()
            .expect("2 n - 1 nodes for n >= 2 emitters");
        let (first_nodes, second_nodes) = below.split_at_mut(2 * mid - 1);
        let (first, rest) = order.split_at_mut(mid);
        let (a, b) = if first.len() + rest.len() >= PARALLEL_BUILD {
            rayon::join(
                || self.subtree(first_nodes, base + 1, first, depth + 1),
                || self.subtree(second_nodes, second, rest, depth + 1),
            )
        } else {
            (
                self.subtree(first_nodes, base + 1, first, depth + 1),
                self.subtree(second_nodes, second, rest, depth + 1),
            )
        };
        let bounds = a.union(&b);
        *node = Node {
            bounds: Probe::of(&bounds),
            index: second as u32,
            leaf: false,
        };
        bounds
    }
}

/// Writes each emitter's path from the root ([`LightTree::trail`]) by walking `nodes`.
fn set_trails(nodes: &[Node], trail: &mut [u64]) {
    // (node, its path, its depth); at most one pending second child per level.
    let mut stack = vec![(0usize, 0u64, 0u32)];
    while let Some((node, path, depth)) = stack.pop() {
        let Some(n) = nodes.get(node) else {
            continue;
        };
        if n.leaf {
            trail[n.index as usize] = path;
        } else {
            stack.push((n.index as usize, path | (1 << depth), depth + 1));
            stack.push((node + 1, path, depth + 1));
        }
    }
}

const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// The share of draws that pick by power for a surface whose light is `glossy` glossy: all of
/// them from half glossy up. (The glossy part's worst case, a far lamp in the lobe, costs
/// variance in proportion to 1 / share, the matte part's gain from the tree far less
/// than its share's; a wet street at night took 1.35 times the variance with the share
/// itself, 0.65.)
fn by_power(glossy: f32) -> f32 {
    let glossy = if glossy.is_nan() {
        0.0
    } else {
        glossy.clamp(0.0, 1.0)
    };
    DEFENSIVE + (1.0 - DEFENSIVE) * (2.0 * glossy).min(1.0)
}

impl Build<'_> {
    /// Reorders `order` (at least two emitters) into the node's two children and returns
    /// where the second starts: between the buckets along an axis that minimise pbrt-v4's cost
    /// (power times direction measure times surface area, with a penalty for thin axes; from
    /// at most [`BINNED`] of them), or at the median along the longest axis when the tree would
    /// otherwise grow too deep or no axis has extent.
    fn split(&self, order: &mut [u32], depth: u32) -> usize {
        let (bounds, centroid) = (self.bounds, |i: u32| self.bounds[i as usize].centroid());
        // The node's box and its emitters' centres' box.
        let (lo, hi, clo, chi) = order.iter().fold(
            (
                Vec3::INFINITY,
                Vec3::NEG_INFINITY,
                Vec3::INFINITY,
                Vec3::NEG_INFINITY,
            ),
            |(lo, hi, clo, chi), &i| {
                let (b, c) = (&bounds[i as usize], centroid(i));
                (lo.min(b.lo), hi.max(b.hi), clo.min(c), chi.max(c))
            },
        );
        let extent = chi - clo;
        // Median splits finish within log2(n) more levels.
        let levels_left = usize::BITS - (order.len() - 1).leading_zeros();
        let bucketed = depth + levels_left + 8 < MAX_DEPTH;
        let node_extent = hi - lo;
        // An even spread of at most BINNED of them choose the cut.
        let stride = order.len().div_ceil(BINNED);
        let bucket_of = |i: u32, dim: usize| {
            let t = (centroid(i)[dim] - clo[dim]) / extent[dim];
            ((t * BUCKETS as f32) as usize).min(BUCKETS - 1)
        };
        let mut best: Option<(f32, usize, usize)> = None;
        for dim in 0..3 {
            let flat = |x: f32| x.is_nan() || x <= 0.0;
            if !bucketed || flat(extent[dim]) || flat(node_extent[dim]) {
                continue;
            }
            let mut buckets: [Option<LightBounds>; BUCKETS] = [None; BUCKETS];
            for &i in order.iter().step_by(stride) {
                let b = &bounds[i as usize];
                match &mut buckets[bucket_of(i, dim)] {
                    Some(acc) => acc.merge(b),
                    empty => *empty = Some(*b),
                }
            }
            let kr = node_extent.max_element() / node_extent[dim];
            let cost = |b: &Option<LightBounds>| {
                b.map_or(0.0, |b| {
                    b.phi * b.direction_measure() * kr * b.surface_area()
                })
            };
            // Running unions from each end: what lies below and above every cut.
            let join = |acc: Option<LightBounds>, b: Option<LightBounds>| match (acc, b) {
                (Some(a), Some(b)) => Some(a.union(&b)),
                (a, b) => a.or(b),
            };
            let mut below = [None; BUCKETS];
            let mut above = [None; BUCKETS + 1];
            for k in 1..BUCKETS {
                below[k] = join(below[k - 1], buckets[k - 1]);
                let j = BUCKETS - k;
                above[j] = join(above[j + 1], buckets[j]);
            }
            for cut in 1..BUCKETS {
                let (below, above) = (below[cut], above[cut]);
                if below.is_none() || above.is_none() {
                    continue;
                }
                let c = cost(&below) + cost(&above);
                if best.is_none_or(|(bc, _, _)| c < bc) {
                    best = Some((c, dim, cut));
                }
            }
        }
        if let Some((_, dim, cut)) = best {
            let mut mid = 0;
            for k in 0..order.len() {
                if bucket_of(order[k], dim) < cut {
                    order.swap(k, mid);
                    mid += 1;
                }
            }
            if mid > 0 && mid < order.len() {
                return mid;
            }
        }
        let dim = extent.max_position();
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| centroid(a)[dim].total_cmp(&centroid(b)[dim]));
        mid
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic number in [0, 1) for draw `i` (a scrambled van der Corput sequence).
    fn uniform(i: u32) -> f32 {
        (i.reverse_bits() ^ 0x5bd1_e995) as f32 / 4_294_967_296.0
    }

    /// A mix of every kind of emitter: lamps along a street, one-sided and two-sided panels
    /// facing different ways, spots, and lamps at one position.
    fn emitters() -> Vec<LightBounds> {
        let mut list = Vec::new();
        for k in 0..40 {
            let c = Vec3::new(if k % 2 == 0 { -4.0 } else { 4.0 }, 3.0, 3.0 * k as f32);
            list.push(LightBounds::everywhere(
                c - 0.05,
                c + 0.05,
                1.0 + (k % 3) as f32,
            ));
        }
        for k in 0..12 {
            let c = Vec3::new(k as f32 - 6.0, 2.5, -2.0);
            let n = Vec3::new((k as f32).sin(), -1.0, (k as f32).cos());
            let (lo, hi) = (c - 0.3, c + 0.3);
            list.push(LightBounds::new(lo, hi, 5.0, n, 1.0, 0.0, k % 2 == 0));
        }
        for k in 0..6 {
            let c = Vec3::new(1.0, 4.0, k as f32);
            let axis = Vec3::new(0.2 * k as f32, -1.0, 0.0);
            let cos_e = (0.3 + 0.1 * k as f32).cos();
            list.push(LightBounds::new(c, c, 20.0, axis, 1.0, cos_e, false));
        }
        let same = Vec3::new(0.0, 1.0, 50.0);
        list.extend([LightBounds::everywhere(same, same, 3.0); 3]);
        list
    }

    /// A point of a surface facing a direction of its own, `glossy` glossy.
    fn matte(p: Vec3, glossy: f32) -> Receiver {
        let n = Vec3::new(p.z.sin(), 1.0, p.x.cos()).normalize();
        Receiver { p, n, glossy }
    }

    fn points() -> Vec<Vec3> {
        (0..40)
            .map(|i| {
                let u = [uniform(3 * i), uniform(3 * i + 1), uniform(3 * i + 2)];
                Vec3::new(16.0 * u[0] - 8.0, 5.0 * u[1], 130.0 * u[2] - 10.0)
            })
            .chain([Vec3::new(-4.0, 3.0, 0.0), Vec3::new(1.0, 4.0, 2.0)])
            .collect()
    }

    #[test]
    fn probabilities_sum_to_one_and_no_emitter_is_starved() {
        let list = emitters();
        let tree = LightTree::build(&list).unwrap();
        let total: f32 = list.iter().map(|b| b.phi).sum();
        for p in points() {
            let pmf: Vec<f32> = (0..list.len() as u32)
                .map(|i| tree.pmf(&Receiver::at(p), i))
                .collect();
            let sum: f32 = pmf.iter().sum();
            // A walk may end where no emitter below can reach the point (no light sample
            // then); where all can, the probabilities are complete.
            assert!((DEFENSIVE - 1e-4..=1.0 + 1e-4).contains(&sum), "{p}: {sum}");
            if list.iter().all(|b| b.importance(p) > 0.0) {
                assert!((sum - 1.0).abs() < 1e-4, "{p}: {sum}");
            }
            for (i, b) in list.iter().enumerate() {
                assert!(
                    pmf[i] >= DEFENSIVE * b.phi / total * 0.999,
                    "{p}: emitter {i}"
                );
            }
        }
    }

    #[test]
    fn draws_follow_the_probabilities() {
        let list = emitters();
        let tree = LightTree::build(&list).unwrap();
        let draws = 200_000u32;
        for (k, p) in points().into_iter().step_by(7).enumerate() {
            // Matte surfaces and glossy ones (more draws by power).
            let glossy = [0.0, 0.6][k % 2];
            let mut count = vec![0u32; list.len()];
            for d in 0..draws {
                let u = (d as f32 + 0.5) / draws as f32;
                if let Some((i, pmf)) = tree.sample(&matte(p, glossy), u) {
                    assert_eq!(pmf, tree.pmf(&matte(p, glossy), i));
                    count[i as usize] += 1;
                }
            }
            for (i, &c) in count.iter().enumerate() {
                let expected = tree.pmf(&matte(p, glossy), i as u32) * draws as f32;
                // Stratified draws: within a few draws of the expectation per level walked.
                let off = (c as f32 - expected).abs();
                assert!(
                    off <= 8.0 + 0.01 * expected,
                    "{p} {i}: {c} against {expected}"
                );
            }
        }
    }

    #[test]
    fn a_point_under_one_lamp_of_a_street_picks_it_most() {
        let list = emitters();
        let tree = LightTree::build(&list).unwrap();
        // Beneath lamp 10 (x = -4, z = 30), 0.5 m above the ground.
        let p = Vec3::new(-4.0, 0.5, 30.0);
        let lamp = tree.pmf(&Receiver::at(p), 10);
        let power_only = list[10].phi / list.iter().map(|b| b.phi).sum::<f32>();
        assert!(lamp > 20.0 * power_only, "{lamp} against {power_only}");
        // A near-mirror there picks by power more: the lamp it reflects may be any of them.
        let mirror = tree.pmf(&matte(p, 0.5), 10);
        assert!(
            (mirror - power_only).abs() < 1e-6,
            "{mirror} against {power_only}"
        );
        assert!(tree.pmf(&matte(p, 0.25), 10) < lamp);
        // Behind a one-sided panel facing down, the walk never picks it.
        let panel = 41; // odd: one-sided, facing down and away
        let above = Vec3::new(-5.0, 6.0, -2.0);
        let only_power = DEFENSIVE * list[panel].phi / list.iter().map(|b| b.phi).sum::<f32>();
        assert!((tree.pmf(&Receiver::at(above), panel as u32) - only_power).abs() < 1e-6);
    }

    #[test]
    fn a_large_tree_built_in_parallel_keeps_every_path() {
        // Past PARALLEL_BUILD the subtrees are built on several threads into one array.
        let mut list = Vec::new();
        for k in 0..3 * PARALLEL_BUILD as u32 {
            let u = [uniform(3 * k), uniform(3 * k + 1), uniform(3 * k + 2)];
            let c = Vec3::new(100.0 * u[0], 10.0 * u[1], 100.0 * u[2]);
            let n = Vec3::new(u[1] - 0.5, -1.0, u[0] - 0.5);
            list.push(LightBounds::new(
                c - 0.1,
                c + 0.1,
                1.0 + u[2],
                n,
                1.0,
                0.0,
                k % 3 == 0,
            ));
        }
        let tree = LightTree::build(&list).unwrap();
        assert_eq!(tree.nodes.len(), 2 * list.len() - 1);
        // Every emitter has one leaf, and its trail leads there.
        let mut leaves = vec![0u32; list.len()];
        for n in tree.nodes.iter().filter(|n| n.leaf) {
            leaves[n.index as usize] += 1;
        }
        assert!(leaves.iter().all(|&c| c == 1));
        for p in [Vec3::new(50.0, 0.0, 50.0), Vec3::new(-20.0, 5.0, 130.0)] {
            let r = matte(p, 0.0);
            for k in 0..2000 {
                let (i, pmf) = tree.sample(&r, uniform(k)).unwrap();
                assert_eq!(pmf, tree.pmf(&r, i), "emitter {i} from {p}");
            }
            let sum: f64 = (0..list.len() as u32).map(|i| tree.pmf(&r, i) as f64).sum();
            assert!((sum - 1.0).abs() < 1e-3, "{sum}");
        }
    }

    #[test]
    fn one_emitter_and_none() {
        let one = [LightBounds::everywhere(Vec3::ZERO, Vec3::ZERO, 1.0)];
        let tree = LightTree::build(&one).unwrap();
        assert_eq!(tree.sample(&Receiver::at(Vec3::ONE), 0.7), Some((0, 1.0)));
        let none = LightTree::build(&[]).unwrap();
        assert!(none.is_empty());
        assert_eq!(none.sample(&Receiver::at(Vec3::ONE), 0.3), None);
        assert_eq!(none.pmf(&Receiver::at(Vec3::ONE), 0), 0.0);
    }

    #[test]
    fn cones_merge_to_hold_both() {
        let a = (Vec3::X, 0.9f32, 0.9f32.acos());
        let b = (Vec3::Y, 0.8f32, 0.8f32.acos());
        let (w, cos, _) = cone_union(a, b);
        for (axis, c, _) in [a, b] {
            let edge_angle = w.dot(axis).clamp(-1.0, 1.0).acos() + c.acos();
            assert!(edge_angle <= cos.acos() + 1e-4);
        }
        assert_eq!(
            cone_union((Vec3::X, 1.0, 0.0), (-Vec3::X, 1.0, 0.0)).1,
            -1.0
        );
    }
}
