//! Where a parallel sun's light paths start: it has no position, so its paths start on discs
//! across its beam, one over each glossy bound as the sun sees it, outside the scene (so the
//! first surface a path meets is the first the sun lights there). A disc's points are drawn on
//! a [`GRID`] x [`GRID`] grid of equal areas (radius by its square root, angle evenly), whose
//! cells the pilot weighs as it weighs a cone's. The sun's paths take caustics only
//! ([`super::caustic`]); its highlights in blurred glossy surfaces stay with the camera.

use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3};

use super::{Cone, GRID};
use crate::shade::basis;

/// Discs across a sun's beam.
#[derive(Debug, Clone)]
pub(super) struct Beam {
    /// Unit direction the light travels in.
    dir: Vec3,
    /// Unit vectors across the beam.
    t: Vec3,
    b: Vec3,
    /// Per disc: its centre (a glossy bound's), radius, and how far back along the beam its
    /// paths start (outside the scene).
    discs: Vec<(Vec3, f32, f32)>,
}

impl Beam {
    /// The beam of a sun shining along `dir` (any length) over the glossy bounds `spheres`
    /// (centre, radius) of a scene whose geometry lies within the sphere `scene`.
    pub(super) fn new(dir: Vec3, spheres: &[(Vec3, f32)], scene: (Vec3, f32)) -> Option<Self> {
        let dir = dir.try_normalize()?;
        let (t, b) = basis(dir);
        let (centre, radius) = scene;
        let discs = (spheres.iter())
            .filter(|&&(_, r)| r > 0.0 && r.is_finite())
            .map(|&(c, r)| {
                // Back past every point of the scene: from a start this far behind a point
                // of the disc, the scene's sphere lies wholly ahead.
                let back = 1.01 * (radius + (c - centre).length() + r) + 1e-3;
                (c, r, back)
            })
            .collect::<Vec<_>>();
        (!discs.is_empty()).then_some(Self { dir, t, b, discs })
    }

    /// How many discs.
    pub(super) fn len(&self) -> usize {
        self.discs.len()
    }

    /// The unit direction its light travels in.
    pub(super) fn dir(&self) -> Vec3 {
        self.dir
    }

    /// The start of the path through cell `cell` (disc-major, [`GRID`]^2 per disc) at `q` of
    /// the unit square within the cell.
    pub(super) fn start(&self, cell: usize, q: Vec2) -> Vec3 {
        let (k, ij) = (cell / (GRID * GRID), cell % (GRID * GRID));
        let (c, r, back) = self.discs[k];
        let s = Vec2::new(
            ((ij / GRID) as f32 + q.x) / GRID as f32,
            ((ij % GRID) as f32 + q.y) / GRID as f32,
        );
        let (sin, cos) = (TAU * s.y).sin_cos();
        let rho = r * s.x.sqrt();
        c + (self.t * cos + self.b * sin) * rho - self.dir * back
    }

    /// The density, per unit area across the beam, with which paths drawn by cell
    /// probabilities `cells` pass `x`; `drawn`: the cell a path through `x` was drawn in,
    /// taken as its own (as `Lamp::pdf` does, for the same reason).
    pub(super) fn density(&self, cells: &[f32], x: Vec3, drawn: Option<usize>) -> f32 {
        let per_cell = (GRID * GRID) as f32;
        (self.discs.iter().enumerate())
            .filter_map(|(k, &(c, r, _))| {
                let v = x - c;
                let (a, b) = (v.dot(self.t), v.dot(self.b));
                let s = (a * a + b * b) / (r * r);
                if s.is_nan() || s > 1.0 {
                    return None;
                }
                let cell = match drawn {
                    Some(d) if d / (GRID * GRID) == k => d,
                    _ => {
                        let angle = b.atan2(a) / TAU;
                        let angle = if angle < 0.0 { angle + 1.0 } else { angle };
                        k * GRID * GRID + Cone::cell(Vec2::new(s, angle))
                    }
                };
                Some(cells[cell] * per_cell / (PI * r * r))
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn starts_lie_behind_the_scene_and_their_cells_are_measured_back() {
        let spheres = [
            (Vec3::new(1.0, 0.5, 2.0), 0.4),
            (Vec3::new(-1.0, 0.2, 3.0), 0.7),
        ];
        let scene = (Vec3::ZERO, 5.0);
        let beam = Beam::new(Vec3::new(0.3, -1.0, 0.2), &spheres, scene).unwrap();
        let n = beam.len() * GRID * GRID;
        let even = vec![1.0 / n as f32; n];
        for cell in (0..n).step_by(7) {
            let o = beam.start(cell, Vec2::new(0.3, 0.6));
            assert!((o - scene.0).length() > scene.1, "{o} inside the scene");
            // A point along the path, measured back, is in the cell it was drawn in (or,
            // inside both discs, counts both).
            let x = o + beam.dir() * 20.0;
            let alone = beam.density(&even, x, None);
            let own = even[cell] * (GRID * GRID) as f32;
            let disc = spheres[cell / (GRID * GRID)].1;
            assert!(alone >= own / (PI * disc * disc) * 0.999, "{cell}: {alone}");
        }
        // Off every disc: no density.
        assert_eq!(beam.density(&even, Vec3::new(40.0, 0.0, 0.0), None), 0.0);
    }

    #[test]
    fn the_discs_density_integrates_to_one() {
        // Uneven cells over one disc: the density summed over a fine grid across the beam.
        let spheres = [(Vec3::ZERO, 1.0)];
        let beam = Beam::new(Vec3::Y, &spheres, (Vec3::ZERO, 1.0)).unwrap();
        let n = GRID * GRID;
        let mut cells: Vec<f32> = (0..n).map(|i| 1.0 + (i % 5) as f32).collect();
        let sum: f32 = cells.iter().sum();
        cells.iter_mut().for_each(|c| *c /= sum);
        let steps = 800;
        let h = 2.0 / steps as f32;
        let mut total = 0.0f64;
        for i in 0..steps {
            for j in 0..steps {
                let (a, b) = (-1.0 + (i as f32 + 0.5) * h, -1.0 + (j as f32 + 0.5) * h);
                let x = beam.t * a + beam.b * b;
                total += f64::from(beam.density(&cells, x, None) * h * h);
            }
        }
        assert!((total - 1.0).abs() < 0.01, "{total}");
    }
}
