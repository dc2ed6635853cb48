//! The aperture: its outline (the shape of out-of-focus highlights), the area-preserving
//! warps from lens sample numbers in [0, 1)^2 onto it, and the lens filter that weights
//! samples by where they cross it.

use std::f32::consts::{FRAC_PI_4, PI, TAU};

use glam::Vec2;

use crate::embree::LANES;

/// The outline of the aperture, which is also the shape of out-of-focus highlights (bokeh).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ApertureShape {
    /// 0 for a circular aperture, else the number of diaphragm blades (>= 3).
    pub blades: u32,
    /// Rotation of a polygonal aperture, degrees.
    pub rotation_deg: f32,
    /// Anamorphic squeeze: the aperture's height over its width (1 = round bokeh).
    pub anamorphic: f32,
}

impl ApertureShape {
    /// Whether `blades` is a number of blades: 0 (a circular aperture) or at least 3.
    pub fn blades_ok(blades: u32) -> bool {
        blades == 0 || blades >= 3
    }

    /// The area of the aperture in lens units (the unit disc or polygon [`aperture_point`]
    /// maps onto, stretched by the anamorphic ratio): the camera's area times the radius^2.
    pub fn area(&self) -> f32 {
        let unit = if self.blades >= 3 {
            let n = self.blades as f32;
            0.5 * n * (TAU / n).sin()
        } else {
            PI
        };
        unit * self.anamorphic
    }

    /// Whether `lens` (lens units, as [`aperture_point`] gives them) is inside the aperture.
    pub fn contains(&self, lens: Vec2) -> bool {
        let q = Vec2::new(lens.x, lens.y / self.anamorphic);
        if self.blades >= 3 {
            // Inside every edge: [`polygon`]'s corners are at rotation + k 2 pi / n.
            let n = self.blades as f32;
            let rot = self.rotation_deg.to_radians();
            let apothem = (PI / n).cos();
            (0..self.blades).all(|k| {
                let a = rot + TAU * (k as f32 + 0.5) / n;
                q.dot(Vec2::new(a.cos(), a.sin())) <= apothem
            })
        } else {
            q.length_squared() <= 1.0
        }
    }

    /// Whether it is the unit disc (not polygonal, not stretched).
    pub fn is_round(&self) -> bool {
        self.blades < 3 && self.anamorphic == 1.0
    }

    /// The corners of a polygonal aperture in lens units (as [`polygon`] and
    /// [`aperture_point`] place them); none for a round or oval one.
    fn corners(&self) -> impl Iterator<Item = Vec2> + '_ {
        let n = if self.blades >= 3 { self.blades } else { 0 };
        let rot = self.rotation_deg.to_radians();
        (0..n).map(move |k| {
            let a = rot + TAU * k as f32 / n as f32;
            Vec2::new(a.cos(), a.sin() * self.anamorphic)
        })
    }

    /// Half its width and half its height, lens units: it lies within
    /// `[-x, x] x [-y, y]`.
    pub fn half_extents(&self) -> Vec2 {
        if self.blades >= 3 {
            self.corners().fold(Vec2::ZERO, |m, c| m.max(c.abs()))
        } else {
            Vec2::new(1.0, self.anamorphic)
        }
    }

    /// The largest distance of its points from the lens centre, lens units.
    pub fn outer_radius(&self) -> f32 {
        if self.blades >= 3 {
            self.corners().fold(0.0, |m, c| m.max(c.length()))
        } else {
            self.anamorphic.max(1.0)
        }
    }

    /// Its outline, to take chords of.
    pub fn outline(&self) -> Outline {
        let corners: Vec<Vec2> = self.corners().collect();
        if corners.is_empty() {
            return Outline {
                chains: None,
                anamorphic: self.anamorphic,
            };
        }
        // The corners run counter-clockwise: from the bottom up the right side, from the
        // top down the left. A flat bottom or top edge belongs to both sides' ends.
        let n = corners.len();
        let pick = |better: &dyn Fn(Vec2, Vec2) -> bool| {
            (0..n).fold(0, |best, k| {
                if better(corners[k], corners[best]) {
                    k
                } else {
                    best
                }
            })
        };
        let bottom_right = pick(&|a, b| a.y < b.y || (a.y == b.y && a.x > b.x));
        let bottom_left = pick(&|a, b| a.y < b.y || (a.y == b.y && a.x < b.x));
        let top_right = pick(&|a, b| a.y > b.y || (a.y == b.y && a.x > b.x));
        let top_left = pick(&|a, b| a.y > b.y || (a.y == b.y && a.x < b.x));
        let walk = |from: usize, to: usize| {
            let mut chain = vec![corners[from]];
            let mut k = from;
            while k != to {
                k = (k + 1) % n;
                chain.push(corners[k]);
            }
            chain
        };
        let right = walk(bottom_right, top_right);
        let mut left = walk(top_left, bottom_left);
        left.reverse();
        Outline {
            chains: Some((left, right)),
            anamorphic: self.anamorphic,
        }
    }
}

/// An aperture's outline ([`ApertureShape::outline`]): a polygon's left and right sides,
/// each from its bottom up (so a chord is two binary searches however many blades), or an
/// oval.
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    chains: Option<(Vec<Vec2>, Vec<Vec2>)>,
    anamorphic: f32,
}

impl Outline {
    /// The span of x over the aperture at height `y` (lens units, as [`aperture_point`]
    /// gives them), `None` where the line misses it: the aperture is convex, so that is all
    /// of it.
    pub fn chord(&self, y: f32) -> Option<(f32, f32)> {
        let Some((left, right)) = &self.chains else {
            let v = y / self.anamorphic;
            let half = (1.0 - v * v).sqrt();
            return (v.abs() <= 1.0).then_some((-half, half));
        };
        Some((side_at(left, y)?, side_at(right, y)?))
    }
}

/// Where a side of a convex polygon (its corners from the bottom up) crosses height `y`.
fn side_at(side: &[Vec2], y: f32) -> Option<f32> {
    let i = side.partition_point(|p| p.y < y);
    if i == side.len() {
        return None;
    }
    if i == 0 {
        return (side[0].y == y).then_some(side[0].x);
    }
    let (a, b) = (side[i - 1], side[i]);
    Some(a.x + (b.x - a.x) * (y - a.y) / (b.y - a.y))
}

impl Default for ApertureShape {
    fn default() -> Self {
        Self {
            blades: 0,
            rotation_deg: 0.0,
            anamorphic: 1.0,
        }
    }
}

/// Shirley & Chiu's concentric map from the unit square to the unit disc (area-preserving,
/// low distortion, so stratification survives).
pub fn concentric_disc(u: Vec2) -> Vec2 {
    let (x, y) = concentric_xy(u.x, u.y);
    Vec2::new(x, y)
}

/// [`concentric_disc`] on coordinates, without branches (the choice of wedge is random per
/// sample, so a branch mispredicts half the time; selects also let batches vectorise).
#[inline(always)]
fn concentric_xy(ux: f32, uy: f32) -> (f32, f32) {
    let a = 2.0 * ux - 1.0;
    let b = 2.0 * uy - 1.0;
    // phi = pi/4 * t with |t| <= 1 when |a| > |b|, else pi/2 - pi/4 * t, whose cosine and
    // sine are the first case's swapped; so only |angle| <= pi/4 is ever evaluated.
    let first = a.abs() > b.abs();
    let (r, other) = if first { (a, b) } else { (b, a) };
    let (s, c) = sin_cos_quarter(FRAC_PI_4 * (other / r));
    let (x, y) = if first {
        (r * c, r * s)
    } else {
        (r * s, r * c)
    };
    // The centre maps to itself (0 / 0 above).
    if a == 0.0 && b == 0.0 {
        (0.0, 0.0)
    } else {
        (x, y)
    }
}

/// sin and cos for |x| <= pi/4 by their Taylor series to x^11 / x^12 (error below 2e-9, far
/// under f32 precision): the concentric map runs once per lens sample, and libm's general
/// sincosf was a visible share of a dense render.
#[inline(always)]
fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let sin = x
        * (1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0
                    + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0 - x2 / 39_916_800.0)))));
    let cos = 1.0
        + x2 * (-0.5
            + x2 * (1.0 / 24.0
                + x2 * (-1.0 / 720.0
                    + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0 + x2 / 479_001_600.0)))));
    (sin, cos)
}

/// Uniform map from the unit square to a regular polygon with `blades` corners on the unit
/// circle: `u.x` picks a triangle of the fan (and is reused within it), `u.y` the radius.
pub fn polygon(u: Vec2, blades: u32, rotation_rad: f32) -> Vec2 {
    let n = blades as f32;
    let scaled = u.x * n;
    let k = scaled.floor().min(n - 1.0);
    let t = scaled - k;
    let a0 = rotation_rad + TAU * k / n;
    let a1 = rotation_rad + TAU * (k + 1.0) / n;
    let edge = Vec2::new(a0.cos(), a0.sin()) * (1.0 - t) + Vec2::new(a1.cos(), a1.sin()) * t;
    edge * u.y.sqrt()
}

/// A point on the aperture in lens units (the unit disc or polygon, stretched vertically by
/// the anamorphic ratio); the camera scales it by the aperture radius.
pub fn aperture_point(u: Vec2, shape: &ApertureShape) -> Vec2 {
    let p = if shape.blades >= 3 {
        polygon(u, shape.blades, shape.rotation_deg.to_radians())
    } else {
        concentric_disc(u)
    };
    Vec2::new(p.x, p.y * shape.anamorphic)
}

/// [`aperture_point`] of 16 samples given as structure of arrays (as
/// [`crate::sampler::PixelSampler::get16`] returns them), bit for bit equal to it lane by lane.
pub fn aperture_points16(
    u: &[f32; LANES],
    v: &[f32; LANES],
    shape: &ApertureShape,
) -> ([f32; LANES], [f32; LANES]) {
    let mut x = [0.0f32; LANES];
    let mut y = [0.0f32; LANES];
    if shape.blades >= 3 {
        for lane in 0..LANES {
            let p = aperture_point(Vec2::new(u[lane], v[lane]), shape);
            (x[lane], y[lane]) = (p.x, p.y);
        }
    } else {
        let stretch = shape.anamorphic;
        for lane in 0..LANES {
            let (px, py) = concentric_xy(u[lane], v[lane]);
            x[lane] = px;
            y[lane] = py * stretch;
        }
    }
    (x, y)
}

/// How lens samples are weighted when averaged: the filter over the CoC that the seed leaves
/// open. The weight depends on the sample's radius on the (unstretched) aperture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum LensFilter {
    /// Every sample counts equally: a uniformly bright aperture (a real lens's bokeh).
    #[default]
    Box,
    /// Weight 1 - r: softer bokeh edges.
    Tent,
    /// Weight exp(-r^2 / (2 * 0.5^2)): a smooth, Gaussian-like blur.
    Gaussian,
}

impl LensFilter {
    /// The weight of a lens sample at `aperture_point` (on the aperture as sampled, its y
    /// stretched by `anamorphic`; the radius is taken after undoing the stretch).
    pub fn weight(self, aperture_point: Vec2, anamorphic: f32) -> f32 {
        let r2 = || Vec2::new(aperture_point.x, aperture_point.y / anamorphic).length_squared();
        match self {
            Self::Box => 1.0,
            Self::Tent => (1.0 - r2().sqrt()).max(0.0) + 1e-3,
            Self::Gaussian => (-r2() / (2.0 * 0.25)).exp(),
        }
    }
}

/// Apertures of every kind, for tests: round, an oval, six blades, five blades stretched,
/// a square (flat top and bottom edges) and 1024 blades.
#[cfg(test)]
pub(crate) fn test_shapes() -> [ApertureShape; 6] {
    let shape = |blades, rotation_deg, anamorphic| ApertureShape {
        blades,
        rotation_deg,
        anamorphic,
    };
    [
        ApertureShape::default(),
        shape(0, 0.0, 1.7),
        shape(6, 15.0, 1.0),
        shape(5, 0.0, 0.6),
        shape(4, 45.0, 1.0),
        shape(1024, 3.0, 1.3),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::PixelSampler;

    #[test]
    fn batches_equal_single_samples_bit_for_bit() {
        let shapes = test_shapes();
        for pixel in 0..200u64 {
            let s = PixelSampler::new(3, pixel * 7919);
            for first in [0u32, 16, 32, 48, 1024, 4096 + 32, 7, u32::MAX - 15] {
                let (u, v) = s.get16(first);
                for shape in &shapes {
                    let (x, y) = aperture_points16(&u, &v, shape);
                    for lane in 0..LANES {
                        let p = aperture_point(Vec2::new(u[lane], v[lane]), shape);
                        assert_eq!(
                            (x[lane].to_bits(), y[lane].to_bits()),
                            (p.x.to_bits(), p.y.to_bits())
                        );
                    }
                }
            }
        }
    }

    /// The concentric map as first written, with branches: the branchless one must agree.
    fn concentric_disc_branching(u: Vec2) -> Vec2 {
        let a = 2.0 * u.x - 1.0;
        let b = 2.0 * u.y - 1.0;
        if a == 0.0 && b == 0.0 {
            return Vec2::ZERO;
        }
        if a.abs() > b.abs() {
            let (s, c) = sin_cos_quarter(FRAC_PI_4 * (b / a));
            Vec2::new(a * c, a * s)
        } else {
            let (s, c) = sin_cos_quarter(FRAC_PI_4 * (a / b));
            Vec2::new(b * s, b * c)
        }
    }

    #[test]
    fn branchless_concentric_map_is_unchanged() {
        let n = 257;
        for i in 0..=n {
            for j in 0..=n {
                let u = Vec2::new(i as f32 / n as f32, j as f32 / n as f32);
                let (a, b) = (concentric_disc(u), concentric_disc_branching(u));
                assert_eq!(
                    (a.x.to_bits(), a.y.to_bits()),
                    (b.x.to_bits(), b.y.to_bits()),
                    "{u}"
                );
            }
        }
        for u in [
            Vec2::splat(0.5),
            Vec2::new(0.5, 0.0),
            Vec2::new(0.0, 0.5),
            Vec2::ZERO,
        ] {
            let (a, b) = (concentric_disc(u), concentric_disc_branching(u));
            assert_eq!(
                (a.x.to_bits(), a.y.to_bits()),
                (b.x.to_bits(), b.y.to_bits()),
                "{u}"
            );
        }
    }

    #[test]
    fn fast_sin_cos_matches_libm() {
        for i in -100..=100 {
            let x = FRAC_PI_4 * i as f32 / 100.0;
            let (s, c) = sin_cos_quarter(x);
            assert!(
                (s - x.sin()).abs() < 2e-7 && (c - x.cos()).abs() < 2e-7,
                "{x}"
            );
        }
        let p = concentric_disc(Vec2::new(0.9, 0.3));
        let (a, b) = (0.8f32, -0.4f32);
        let phi = FRAC_PI_4 * b / a;
        assert!((p - Vec2::new(a * phi.cos(), a * phi.sin())).length() < 1e-6);
    }

    #[test]
    fn disc_map_stays_inside_and_preserves_area() {
        // Count mapped points of a fine grid inside the disc of radius 0.5: a quarter of all.
        let n = 200;
        let mut inside_half = 0;
        for i in 0..n {
            for j in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let p = concentric_disc(u);
                assert!(p.length() <= 1.0 + 1e-6);
                if p.length() < 0.5 {
                    inside_half += 1;
                }
            }
        }
        let frac = inside_half as f32 / (n * n) as f32;
        assert!((frac - 0.25).abs() < 0.01, "{frac}");
    }

    #[test]
    fn contains_and_area_match_the_sample_map() {
        for shape in [
            ApertureShape::default(),
            ApertureShape {
                blades: 5,
                rotation_deg: 10.0,
                anamorphic: 1.6,
            },
            ApertureShape {
                blades: 6,
                rotation_deg: 0.0,
                anamorphic: 0.7,
            },
        ] {
            // Every sample is inside; slightly outside the outline is not.
            for i in 0..64u32 {
                let u = Vec2::new((i % 8) as f32 / 8.0 + 0.06, (i / 8) as f32 / 8.0 + 0.06);
                let p = aperture_point(u, &shape);
                assert!(shape.contains(p), "{shape:?} {p:?}");
                let far = aperture_point(Vec2::new(u.x, 1.0), &shape) * 1.01;
                assert!(!shape.contains(far), "{shape:?} {far:?}");
            }
            // The share of a grid over the bounding box inside is the area over the box's.
            let (w, h) = (1.0f32, shape.anamorphic);
            let n = 400;
            let inside = (0..n * n)
                .filter(|k| {
                    let x = ((k % n) as f32 + 0.5) / n as f32 * 2.0 - 1.0;
                    let y = ((k / n) as f32 + 0.5) / n as f32 * 2.0 - 1.0;
                    shape.contains(Vec2::new(x * w, y * h))
                })
                .count();
            let area = inside as f32 / (n * n) as f32 * 4.0 * w * h;
            assert!(
                (area / shape.area() - 1.0).abs() < 0.01,
                "{shape:?}: {area} vs {}",
                shape.area()
            );
        }
    }

    #[test]
    fn polygon_map_is_uniform_and_inside() {
        let n = 200;
        let blades = 6;
        let apothem = (std::f32::consts::PI / blades as f32).cos();
        let mut inner = 0;
        for i in 0..n {
            for j in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let p = polygon(u, blades, 0.3);
                // Inside the hexagon: within the apothem of every edge normal.
                for k in 0..blades {
                    let mid = 0.3 + TAU * (k as f32 + 0.5) / blades as f32;
                    assert!(p.dot(Vec2::new(mid.cos(), mid.sin())) <= apothem + 1e-5);
                }
                if p.length() < 0.5 * apothem {
                    inner += 1;
                }
            }
        }
        // The disc of radius apothem/2 covers pi a^2 / 4 of the hexagon's area 6 a^2 tan(pi/6).
        let expected = std::f32::consts::PI * 0.25 / (6.0 * (std::f32::consts::PI / 6.0).tan());
        let frac = inner as f32 / (n * n) as f32;
        assert!((frac - expected).abs() < 0.01, "{frac} vs {expected}");
    }

    #[test]
    fn filters_weight_the_centre_most() {
        for f in [LensFilter::Box, LensFilter::Tent, LensFilter::Gaussian] {
            assert!(f.weight(Vec2::ZERO, 1.0) >= f.weight(Vec2::new(0.9, 0.0), 1.0));
            assert!(f.weight(Vec2::new(0.9, 0.0), 1.0) > 0.0);
        }
        assert!(
            LensFilter::Gaussian.weight(Vec2::ZERO, 1.0)
                > LensFilter::Gaussian.weight(Vec2::X, 1.0) * 2.0
        );
    }

    /// A point is inside the aperture exactly where its height's chord holds its x, and no
    /// sample lies beyond the half extents or the outer radius (which some come close to).
    #[test]
    fn chords_and_extents_bound_the_aperture() {
        let shapes = test_shapes();
        for shape in &shapes {
            let (half, outer) = (shape.half_extents(), shape.outer_radius());
            let outline = shape.outline();
            let (mut reached, mut farthest) = (Vec2::ZERO, 0.0f32);
            for i in 0..4000u32 {
                let p = Vec2::new(
                    (i as f32 * 0.618_034).fract() * 4.0 - 2.0,
                    (i as f32 * 0.414_214).fract() * 4.0 - 2.0,
                );
                let in_chord = outline
                    .chord(p.y)
                    .is_some_and(|(l, r)| l <= p.x && p.x <= r);
                // Points within rounding of the outline may fall either way.
                let near_edge = [-1e-4, 1e-4].iter().any(|&e| {
                    shape.contains(p + Vec2::splat(e)) != shape.contains(p - Vec2::splat(e))
                });
                if !near_edge {
                    assert_eq!(in_chord, shape.contains(p), "{shape:?} at {p}");
                }
                let q = aperture_point(Vec2::new(p.x * 0.25 + 0.5, p.y * 0.25 + 0.5), shape);
                reached = reached.max(q.abs());
                farthest = farthest.max(q.length());
            }
            assert!(reached.cmple(half * 1.0001).all() && reached.cmpgt(half * 0.95).all());
            assert!(
                farthest <= outer * 1.0001 && farthest > outer * 0.95,
                "{shape:?}"
            );
        }
    }
}
