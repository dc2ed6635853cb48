//! The blur spot of a film point: where the rays the lens passes from it cross a plane in
//! front of the lens, carried back to the film. The blur table the adaptive sampler trusts
//! (`blur_table.rs`) is made of these, so they must not come out small.
//!
//! A spot comes in two parts. [`SpotRays`] is what depends on the film point alone, traced
//! once ([`RealLens::spot_rays`]): the passing points of a grid over its pupil bound, its
//! pupil's rim in [`RIM_DIRECTIONS`] directions, with their rays, and the two chief rays
//! that measure the magnification. [`SpotRays::spot_px`] is what depends on the plane:
//! where those rays cross it, the extremes refined between rim directions and inside the
//! pupil, which trace rays of their own. The blur table evaluates each film radius's
//! [`SpotRays`] at all its knots: the shared part is about 40% of a spot's rays.

use std::f64::consts::TAU;

use glam::DVec2;

use super::RealLens;
use crate::camera::optics::LensRay;

/// Grid (per axis) over the pupil bound: the passing points the spot's inside is searched
/// from, and that find a passing point when the bound's middle is blocked.
const SPOT_GRID: usize = 16;
/// Directions in which a spot's pupil rim is first found.
const RIM_DIRECTIONS: usize = 32;
/// The angle between neighbouring rim directions.
const RIM_STEP: f64 = TAU / RIM_DIRECTIONS as f64;
/// Golden-section steps that refine each of the spot's four extremes between the directions
/// either side of the best (the bracket shrinks to 2% of its width).
const REFINE_STEPS: usize = 8;
/// Bisection steps that find the rim along one direction (to 2^-18 of the bound).
const RIM_STEPS: usize = 18;
/// Steps of the compass search that refines each of the spot's extremes inside the pupil.
const COMPASS_STEPS: usize = 32;

/// The passing region around a passing point of a film point's pupil bound: a convex
/// region (an intersection of the surfaces' discs as seen from the film point).
struct Region {
    /// The passing point, in [0, 1]^2 of the bound.
    centre: DVec2,
    /// The rays through the rim's points in [`RIM_DIRECTIONS`] directions from `centre`,
    /// the `k`th at angle `k` [`RIM_STEP`] (`None`: blocked).
    rim: Vec<Option<LensRay>>,
    /// The passing points of a grid over the bound, with their rays.
    grid: Vec<(DVec2, LensRay)>,
}

/// Where film point `f`'s rays pass the lens, in [0, 1]^2 of its pupil bound.
enum Passing {
    /// A region around a passing point.
    Around(Region),
    /// Grid points that pass, with their rays, with none passing at their mean.
    Scattered(Vec<(DVec2, LensRay)>),
}

/// The part of a film point's blur spot that no depth plane changes: which of its rays the
/// lens passes, and the rays that measure its magnification.
pub(super) struct SpotRays<'a> {
    lens: &'a RealLens,
    /// The film point (lens space, mm).
    f: DVec2,
    /// Where its rays pass (`None`: nowhere).
    passing: Option<Passing>,
    /// The chief rays (through the middle of `f`'s own pupil bound) of the film points
    /// `h` mm either side of `f` along its radius (`None`: blocked).
    chiefs: [Option<LensRay>; 2],
    /// See `chiefs`.
    h: f64,
}

impl RealLens {
    /// What film point `f`'s blur spot at any depth is found from.
    pub(super) fn spot_rays(&self, f: DVec2) -> SpotRays<'_> {
        // Both chief rays pass the middle of `f`'s own pupil bound: the bounds step from one
        // radial bin to the next, and a pair straddling a step measured the jump as well (up
        // to 20% off).
        let h = 0.01 * self.half_diagonal;
        let dir = if f.length() > 0.0 {
            f.normalize()
        } else {
            DVec2::X
        };
        let bound = self.bounds_at(f.length());
        let chief = |g: DVec2| self.trace_in(bound, g, DVec2::splat(0.5)).map(|(r, _)| r);
        SpotRays {
            lens: self,
            f,
            passing: self.passing(f),
            chiefs: [chief(f - dir * h), chief(f + dir * h)],
            h,
        }
    }

    /// A passing point near the middle of film point `f`'s pupil bound (the middle, else the
    /// mean of a grid's passing points) with its region; the grid's points alone when that
    /// mean is blocked; `None` when none passes.
    fn passing(&self, f: DVec2) -> Option<Passing> {
        let passes = |u: DVec2| self.trace(f, u).is_some();
        let grid: Vec<(DVec2, LensRay)> = (0..SPOT_GRID * SPOT_GRID)
            .filter_map(|k| {
                let (i, j) = (k % SPOT_GRID, k / SPOT_GRID);
                let u = (DVec2::new(i as f64, j as f64) + 0.5) / SPOT_GRID as f64;
                self.trace(f, u).map(|(r, _)| (u, r))
            })
            .collect();
        let middle = DVec2::splat(0.5);
        if passes(middle) {
            return Some(Passing::Around(self.region(f, middle, grid)));
        }
        if grid.is_empty() {
            return None;
        }
        let mean = grid.iter().map(|(u, _)| *u).sum::<DVec2>() / grid.len() as f64;
        Some(if passes(mean) {
            Passing::Around(self.region(f, mean, grid))
        } else {
            Passing::Scattered(grid)
        })
    }

    /// Film point `f`'s passing region around `centre`, its rim traced in each of the
    /// [`RIM_DIRECTIONS`] directions.
    fn region(&self, f: DVec2, centre: DVec2, grid: Vec<(DVec2, LensRay)>) -> Region {
        let rim = (0..RIM_DIRECTIONS)
            .map(|k| {
                let u = self.rim_point(f, centre, k as f64 * RIM_STEP);
                self.trace(f, u).map(|(r, _)| r)
            })
            .collect();
        Region { centre, rim, grid }
    }

    /// The point just inside the rim of the passing region around `centre` in direction
    /// `angle` (in [0, 1]^2 of film point `f`'s pupil bound).
    fn rim_point(&self, f: DVec2, centre: DVec2, angle: f64) -> DVec2 {
        let passes = |u: DVec2| self.trace(f, u).is_some();
        let dir = DVec2::new(angle.cos(), angle.sin());
        // The farthest step along dir inside the unit square.
        let reach = [dir.x, dir.y]
            .iter()
            .zip([centre.x, centre.y])
            .map(|(&d, c)| {
                if d > 0.0 {
                    (1.0 - c) / d
                } else if d < 0.0 {
                    -c / d
                } else {
                    f64::INFINITY
                }
            })
            .fold(f64::INFINITY, f64::min);
        if passes(centre + dir * reach) {
            return centre + dir * reach;
        }
        let (mut inside, mut outside) = (0.0, reach);
        for _ in 0..RIM_STEPS {
            let mid = 0.5 * (inside + outside);
            if passes(centre + dir * mid) {
                inside = mid;
            } else {
                outside = mid;
            }
        }
        centre + dir * inside
    }
}

impl SpotRays<'_> {
    /// The blur diameter (px) that a point at lens-space depth `z_plane` makes near the
    /// film point: the extent of where its rays cross that plane, times the local
    /// magnification from the plane back to the film, times `margin`; 0 where the lens
    /// passes none of them.
    pub(super) fn spot_px(&self, z_plane: f64, margin: f64) -> f32 {
        let Some((lo, hi)) = self.spread(z_plane) else {
            return 0.0;
        };
        // Magnification: how far the chief ray's point on the plane moves per film mm.
        let moved = |ray: Option<LensRay>| ray.and_then(|r| at_plane(r, z_plane));
        let (Some(a), Some(b)) = (moved(self.chiefs[0]), moved(self.chiefs[1])) else {
            return 0.0;
        };
        let per_mm = (a - b).length() / (2.0 * self.h);
        if per_mm <= 0.0 {
            return 0.0;
        }
        let extent = (hi - lo).max_element();
        (extent / per_mm / self.lens.pitch * margin) as f32
    }

    /// The least and greatest corners of where the film point's rays that the lens passes
    /// cross the plane at lens-space depth `z_plane` (mm); `None` where it passes none.
    fn spread(&self, z_plane: f64) -> Option<(DVec2, DVec2)> {
        match self.passing.as_ref()? {
            Passing::Around(region) => self.region_extent(region, z_plane),
            Passing::Scattered(points) => {
                extent(points.iter().filter_map(|&(_, r)| at_plane(r, z_plane)))
            }
        }
    }

    /// The least and greatest corners of where the rays of `region` cross the plane at
    /// lens-space depth `z_plane`. On the rim, [`RIM_DIRECTIONS`] directions, each side of
    /// each axis then refined between the directions either side of its best: a vignetted
    /// pupil is a narrow cat's eye whose extreme points lie between directions. Inside, from
    /// the grid's best point a compass search: wide open near the film's corners the rays'
    /// crossings fold over (aberration), and the spot's extremes lie inside the pupil (the
    /// double Gauss's spot at 10 km, 0.84 of the half diagonal out, was 18% wider than its
    /// rim's).
    fn region_extent(&self, region: &Region, z_plane: f64) -> Option<(DVec2, DVec2)> {
        let (l, f) = (self.lens, self.f);
        let plane = |u: DVec2| l.trace(f, u).and_then(|(r, _)| at_plane(r, z_plane));
        let at = |angle: f64| plane(l.rim_point(f, region.centre, angle));
        let crossing = |r: LensRay| at_plane(r, z_plane);
        let rim: Vec<Option<DVec2>> = region.rim.iter().map(|r| r.and_then(crossing)).collect();
        let inside: Vec<Option<DVec2>> = region.grid.iter().map(|&(_, r)| crossing(r)).collect();
        let (mut lo, mut hi) = extent(rim.iter().chain(&inside).flatten().copied())?;
        // Outside the bound the sampler draws no rays: those points count for nothing.
        let within = |u: DVec2| u.cmpge(DVec2::ZERO).all() && u.cmple(DVec2::ONE).all();
        for axis in 0..2 {
            for sign in [-1.0f64, 1.0] {
                let score = |p: Option<DVec2>| p.map_or(f64::NEG_INFINITY, |p| sign * p[axis]);
                let best_of = |points: &[Option<DVec2>]| {
                    (0..points.len()).max_by(|&a, &b| score(points[a]).total_cmp(&score(points[b])))
                };
                let mut top = f64::NEG_INFINITY;
                if let Some(k) = best_of(&rim) {
                    let k = k as f64;
                    top = golden_max((k - 1.0) * RIM_STEP, (k + 1.0) * RIM_STEP, |a| score(at(a)));
                }
                if let Some(k) = best_of(&inside) {
                    let value = |u: DVec2| {
                        if within(u) {
                            score(plane(u))
                        } else {
                            f64::NEG_INFINITY
                        }
                    };
                    let start = region.grid[k].0;
                    top = top.max(compass_max(start, 1.0 / SPOT_GRID as f64, value));
                }
                if sign > 0.0 {
                    hi[axis] = hi[axis].max(top);
                } else {
                    lo[axis] = lo[axis].min(-top);
                }
            }
        }
        Some((lo, hi))
    }
}

/// Where lens ray `(o, d)` crosses the plane at lens-space depth `z_plane`, if it goes
/// that way.
fn at_plane((o, d): LensRay, z_plane: f64) -> Option<DVec2> {
    let t = (z_plane - o.z) / d.z;
    (d.z > 0.0 && t.is_finite()).then(|| (o + d * t).truncate())
}

/// The least and greatest corners of `points` (`None` for none).
fn extent(points: impl Iterator<Item = DVec2>) -> Option<(DVec2, DVec2)> {
    points.fold(None, |acc, p| match acc {
        None => Some((p, p)),
        Some((lo, hi)) => Some((lo.min(p), hi.max(p))),
    })
}

/// The greatest value of `value` met by a golden-section search of `[a, b]` in
/// [`REFINE_STEPS`] steps: its maximum there when it has one peak.
fn golden_max(mut a: f64, mut b: f64, value: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut vc, mut vd) = (value(c), value(d));
    let mut best = vc.max(vd);
    for _ in 0..REFINE_STEPS {
        if vc >= vd {
            (b, d, vd) = (d, c, vc);
            c = b - g * (b - a);
            vc = value(c);
            best = best.max(vc);
        } else {
            (a, c, vc) = (c, d, vd);
            d = a + g * (b - a);
            vd = value(d);
            best = best.max(vd);
        }
    }
    best
}

/// The greatest value of `value` met by a compass search from `start`: steps of `step`
/// along either axis, taken where they raise it, halved where none does, for
/// [`COMPASS_STEPS`] steps.
fn compass_max(start: DVec2, mut step: f64, value: impl Fn(DVec2) -> f64) -> f64 {
    let (mut at, mut best) = (start, value(start));
    for _ in 0..COMPASS_STEPS {
        let next = [DVec2::X, DVec2::NEG_X, DVec2::Y, DVec2::NEG_Y]
            .map(|d| {
                let p = at + d * step;
                (p, value(p))
            })
            .into_iter()
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match next {
            Some((p, v)) if v > best => (at, best) = (p, v),
            _ => step *= 0.5,
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::path::Path;
    use std::sync::Arc;

    use crate::camera::real_lens::BLUR_MARGIN;
    use crate::camera::{
        Camera, CameraError, CameraLens, CameraSpec, Focus, Prescription, RealLensSpec,
    };

    fn camera(
        name: &str,
        f_number: Option<f32>,
        focus: f32,
        sensor_width_mm: f32,
    ) -> Result<Camera, CameraError> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("lenses")
            .join(name);
        CameraSpec {
            width: 360,
            height: 240,
            focus: Focus::Distance(focus),
            real_lens: Some(RealLensSpec {
                prescription: Arc::new(Prescription::load(&path).unwrap()),
                f_number,
                sensor_width_mm,
            }),
            ..CameraSpec::default()
        }
        .build(|_| None)
    }

    /// The spread a fine grid over the pupil bound finds: 240 x 240 rays.
    fn brute(l: &RealLens, f: DVec2, z_plane: f64) -> Option<(DVec2, DVec2)> {
        let n = 240;
        extent((0..n * n).filter_map(|k| {
            let u = (DVec2::new((k % n) as f64, (k / n) as f64) + 0.5) / n as f64;
            l.trace(f, u).and_then(|(r, _)| at_plane(r, z_plane))
        }))
    }

    /// The spread holds what a fine grid of rays finds, at the film's centre and out to its
    /// corners, in focus and far from it: on the rim of a vignetted pupil and inside it where
    /// aberrated rays fold over (the double Gauss at 10 km, 0.84 of the half diagonal out,
    /// whose spread's height the rim alone put 18% short).
    #[test]
    fn the_spread_holds_what_a_fine_grid_of_rays_finds() {
        for (name, f_number) in [("double-gauss-50mm.dat", None), ("wide-22mm.dat", None)] {
            let c = camera(name, f_number, 4.0, 36.0).unwrap();
            let CameraLens::Real(l) = &c.lens else {
                unreachable!()
            };
            for s in [0.0, 0.3, 0.6, 0.836, 0.95] {
                let f = DVec2::new(s * l.half_diagonal, 0.0);
                for depth_m in [0.7, 4.0, 1e4] {
                    let z = l.eye_z + depth_m * 1000.0;
                    let (Some((lo, hi)), Some((blo, bhi))) =
                        (l.spot_rays(f).spread(z), brute(l, f, z))
                    else {
                        panic!("{name}: no rays at {s}");
                    };
                    let (size, grid) = (hi - lo, bhi - blo);
                    for axis in 0..2 {
                        assert!(
                            size[axis] >= 0.995 * grid[axis],
                            "{name} at {s} of the half diagonal, {depth_m} m: {size} against \
                             the grid's {grid}"
                        );
                    }
                }
            }
        }
    }

    /// A film point's shared rays, traced once, give its spot at every depth bit for bit as
    /// tracing them afresh for each depth does: every shipped lens's blur table.
    #[test]
    fn rays_traced_once_per_film_point_give_the_spots_traced_afresh() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses");
        for entry in std::fs::read_dir(dir).unwrap() {
            let name = entry.unwrap().file_name().into_string().unwrap();
            if !name.ends_with(".dat") {
                continue;
            }
            // The fisheye's image circle covers a 24 mm film, not a 36 mm one.
            let c = camera(&name, None, 2.0, 36.0)
                .or_else(|_| camera(&name, None, 2.0, 24.0))
                .unwrap();
            let CameraLens::Real(l) = &c.lens else {
                unreachable!()
            };
            let afresh = l.blur_table_of(|f| move |z| l.spot_rays(f).spot_px(z, BLUR_MARGIN));
            assert_eq!(afresh, l.blur, "{name}");
        }
    }

    #[test]
    fn the_golden_search_finds_a_peak_between_its_ends() {
        // The ends are 0.69 and 0.49 below the peak.
        let top = golden_max(0.0, 2.0, |x| 1.0 - (x - 1.3) * (x - 1.3));
        assert!((top - 1.0).abs() < 1e-3, "{top}");
    }

    #[test]
    fn the_compass_search_climbs_inside_a_region_and_stops_at_its_edge() {
        // A peak inside the unit square, from a corner cell's centre.
        let inside = |u: DVec2| -(u - DVec2::new(0.61, 0.37)).length_squared();
        let top = compass_max(DVec2::splat(1.0 / 32.0), 1.0 / 16.0, inside);
        assert!(top > -1e-4, "{top}");
        // Rising towards x = 0.8, where the region ends.
        let edge = |u: DVec2| if u.x <= 0.8 { u.x } else { f64::NEG_INFINITY };
        let top = compass_max(DVec2::splat(0.5), 1.0 / 16.0, edge);
        assert!(top > 0.8 - 1e-3 && top <= 0.8, "{top}");
    }
}
