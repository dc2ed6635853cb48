//! The reuse kernel of an aperture that is not the unit disc (a polygon of diaphragm blades,
//! an anamorphic oval): `K(d) = (1 / A) ∫_aperture f(d + s (l.x, -l.y)) dl` is no longer a
//! function of `|d|`, so it is tabulated over the plane. The filter is separable, so a row
//! of it meets the aperture's image in one span (the aperture is convex), whose filter mass
//! and first moment come from the filter's cumulative sums: a row costs two lookups, not a
//! grid of points.
//!
//! For a shift of either sign the same table serves: the filter is symmetric, so the kernel
//! of shift `-s` at `d`, tilt and all, is that of `s` at `-d` (the image through the lens
//! turns over with the shift's sign; an odd number of blades shows it).

use std::sync::OnceLock;

use glam::{Vec2, Vec3};
use wide::{f32x8, i32x8};

use super::lanes::LANES;
use super::{MIN_SHIFT, OCTAVES, Reach};
use crate::camera::aperture::{ApertureShape, Outline};
use crate::filter::FilterDensity;

/// Grid cells per axis over the kernel's box `[-E.x, E.x] x [-E.y, E.y]`: at least this
/// many, and a cell at most the filter's half width, up to the most (a wide blur's rim,
/// where the kernel falls to 0 across the filter's width, stays that sharp).
const FEWEST_CELLS: usize = 64;
const MOST_CELLS: usize = 256;
/// Shift rows per doubling: a sample reads the nearest (see [`Table::for_sample`]).
const ROWS_PER_OCTAVE: usize = 16;
/// Rows of the filter integrated (midpoints), and cells of its cumulative sums.
const FILTER_ROWS: usize = 48;
const CUMULATIVE: usize = 2048;

/// `(K0, M)` on a grid per shift row for a shift `s > 0`: `K = K0 - g . M` for a surface
/// whose shift changes by `g` per pixel, `M(d)` the mean over the aperture of the filter at
/// `x = d + s (l.x, -l.y)` times `(d - x) / s` (as [`super::Kernel`]'s radial table, with the
/// first moment a vector: the aperture is not round). A row is worked out when a sample
/// first needs it: a frame whose blur is a few pixels reads a fifth of them.
#[derive(Debug, Clone)]
pub struct Table {
    /// The aperture's half extents (lens units): a row of shift `s` covers
    /// `|d| <= s half + reach` per axis, `reach` the filter's half width.
    half: Vec2,
    /// Where the kernel is cut round (its filter part is the filter's half width).
    footprint: Reach,
    /// What a row is worked out from.
    source: Source,
    /// Per shift row, its grid.
    rows: Vec<OnceLock<Grid>>,
}

/// One shift row's nodes: `(K0, M.x, M.y)` by grid row, then grid column.
#[derive(Debug, Clone)]
struct Grid {
    /// Cells per axis.
    cells: usize,
    nodes: Vec<Vec3>,
}

/// What a [`Table`]'s rows are worked out from.
#[derive(Debug, Clone)]
struct Source {
    area: f32,
    outline: Outline,
    cumulative: Cumulative,
    /// The filter's rows (midpoints): height and mass.
    filter_rows: Vec<(f32, f32)>,
    /// The filter's mass and first moment along a whole row.
    whole: (f32, f32),
    /// Its mass over the plane (1 but for the sums' rounding).
    total: f32,
}

/// The filter's density per axis, its cumulative mass and first moment.
#[derive(Debug, Clone)]
struct Cumulative {
    lo: f32,
    per_cell: f32,
    /// At cell boundaries: `∫ f` and `∫ x f` from `-reach`.
    mass: Vec<f32>,
    moment: Vec<f32>,
}

impl Cumulative {
    fn new(f: &FilterDensity) -> Self {
        let reach = f.reach();
        let step = 2.0 * reach / CUMULATIVE as f32;
        let (mut mass, mut moment) = (vec![0.0f32], vec![0.0f32]);
        let (mut m, mut x1) = (0.0f64, 0.0f64);
        for i in 0..CUMULATIVE {
            let x = -reach + (i as f32 + 0.5) * step;
            let w = f64::from(f.at(x) * step);
            m += w;
            x1 += w * f64::from(x);
            mass.push(m as f32);
            moment.push(x1 as f32);
        }
        Self {
            lo: -reach,
            per_cell: 1.0 / step,
            mass,
            moment,
        }
    }

    /// `(∫ f, ∫ x f)` from `-reach` to `x`.
    fn at(&self, x: f32) -> (f32, f32) {
        let t = ((x - self.lo) * self.per_cell).clamp(0.0, CUMULATIVE as f32);
        let i = (t as usize).min(CUMULATIVE - 1);
        let f = t - i as f32;
        let lerp = |v: &[f32]| v[i] + (v[i + 1] - v[i]) * f;
        (lerp(&self.mass), lerp(&self.moment))
    }
}

impl Table {
    /// The kernel of a filter of density `f` (per axis) over `aperture`, a convex shape of
    /// lens positions sampled uniformly, cut round at `footprint`.
    pub fn new(f: &FilterDensity, aperture: &ApertureShape, footprint: Reach) -> Self {
        let reach = f.reach();
        let cumulative = Cumulative::new(f);
        let dy = 2.0 * reach / FILTER_ROWS as f32;
        let filter_rows: Vec<(f32, f32)> = (0..FILTER_ROWS)
            .map(|j| {
                let y = -reach + (j as f32 + 0.5) * dy;
                (y, f.at(y) * dy)
            })
            .filter(|&(_, w)| w > 0.0)
            .collect();
        let whole = cumulative.at(reach);
        let total = filter_rows.iter().map(|&(_, w)| w).sum::<f32>() * whole.0;
        Self {
            half: aperture.half_extents(),
            footprint,
            source: Source {
                area: aperture.area(),
                outline: aperture.outline(),
                cumulative,
                filter_rows,
                whole,
                total,
            },
            rows: (0..=OCTAVES * ROWS_PER_OCTAVE)
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// Shift row `k`'s grid, worked out on first use.
    fn row(&self, k: usize) -> &Grid {
        self.rows[k].get_or_init(|| self.work_out(k))
    }

    /// The shift of row `k`.
    fn shift(k: usize) -> f32 {
        MIN_SHIFT * (k as f32 / ROWS_PER_OCTAVE as f32).exp2()
    }

    /// Shift row `k`'s grid.
    fn work_out(&self, k: usize) -> Grid {
        let Source {
            area,
            outline,
            cumulative,
            filter_rows,
            whole,
            total,
        } = &self.source;
        let reach = self.footprint.filter;
        let s = Self::shift(k);
        let extent = self.half * s + Vec2::splat(reach);
        let cells =
            ((2.0 * extent.max_element() / reach).ceil() as usize).clamp(FEWEST_CELLS, MOST_CELLS);
        let nodes = cells + 1;
        let norm = 1.0 / (area * s * s * total);
        let mut out = Vec::with_capacity(nodes * nodes);
        let mut spans = Vec::with_capacity(filter_rows.len());
        for iy in 0..nodes {
            let d_y = extent.y * (2.0 * iy as f32 / cells as f32 - 1.0);
            // Film row y sees lens height -(y - d.y) / s (film y is down, lens y up): the
            // lens span there, scaled to pixels.
            spans.clear();
            spans.extend(filter_rows.iter().filter_map(|&(y, w)| {
                let (l, r) = outline.chord(-(y - d_y) / s)?;
                Some((s * l, s * r, w, d_y - y))
            }));
            for ix in 0..nodes {
                let d_x = extent.x * (2.0 * ix as f32 / cells as f32 - 1.0);
                let mut v = Vec3::ZERO;
                for &(l, r, w, toward) in &spans {
                    let (lo, hi) = (d_x + l, d_x + r);
                    if hi <= -reach || lo >= reach {
                        continue;
                    }
                    // Where the span holds the whole row (most of a wide blur), the sums
                    // are the row's.
                    let ((m0, x0), (m1, x1)) = if lo <= -reach && hi >= reach {
                        ((0.0, 0.0), *whole)
                    } else {
                        (cumulative.at(lo), cumulative.at(hi))
                    };
                    let mass = m1 - m0;
                    // The first moment of `(d - x) / s` (x the film position).
                    v += w * Vec3::new(mass, (d_x * mass - (x1 - x0)) / s, toward * mass / s);
                }
                out.push(v * norm);
            }
        }
        Grid { cells, nodes: out }
    }

    /// The kernel for one sample's signed shift and shift gradient: the nearest shift
    /// row's, stretched over the sample's box and scaled by the boxes' areas so that it
    /// stays a density (where the blur outgrows the filter the boxes' ratio is the shifts',
    /// which also makes the uniform inside nearly exact). A row is a sixteenth of an octave
    /// from the next, so the blur's rim moves by at most a quarter percent of the box (0.03
    /// px at a shift of 9 px): a small bias, where two rows' nodes interpolated cost a third
    /// of a bladed render's lending (every sample reads tens of them).
    pub fn for_sample(&self, shift: f32, gradient: Vec2) -> ShiftTable<'_> {
        let s = shift.abs();
        let top = (OCTAVES * ROWS_PER_OCTAVE) as f32;
        let k = ((s / MIN_SHIFT).log2() * ROWS_PER_OCTAVE as f32)
            .round()
            .clamp(0.0, top) as usize;
        let extent = |s: f32| self.half * s + Vec2::splat(self.footprint.filter);
        let (box_k, own) = (extent(Self::shift(k)), extent(s));
        let grid = self.row(k);
        let cells = grid.cells as f32;
        ShiftTable {
            row: &grid.nodes,
            cells: grid.cells,
            scale: (box_k.x * box_k.y) / (own.x * own.y),
            cut2: self.footprint.of(s).powi(2),
            per_px: Vec2::splat(cells / 2.0) / own,
            sign: if shift < 0.0 { -1.0 } else { 1.0 },
            gradient,
        }
    }
}

/// [`Table`] for one sample, from [`Table::for_sample`].
#[derive(Debug, Clone, Copy)]
pub struct ShiftTable<'a> {
    /// The shift row nearest its shift, its cells per axis, and the scale that makes it a
    /// density over the sample's box.
    row: &'a [Vec3],
    cells: usize,
    scale: f32,
    /// The square of the footprint's radius ([`Reach`]): 0 beyond.
    cut2: f32,
    /// Grid cells per pixel of offset, per axis: the box the kernel is zero beyond spans
    /// the grid.
    per_px: Vec2,
    /// The shift's sign: a negative shift's kernel at `d` is the table's at `-d`.
    sign: f32,
    gradient: Vec2,
}

impl ShiftTable<'_> {
    /// `K` at offset `d` (pixels) from the site: the centre minus the site's pixel centre;
    /// 0 beyond its footprint.
    #[inline]
    pub fn at(&self, d: Vec2) -> f32 {
        if d.length_squared() >= self.cut2 {
            return 0.0;
        }
        let (cells, nodes) = (self.cells, self.cells + 1);
        let u = d * self.sign;
        let g = (u * self.per_px + Vec2::splat(cells as f32 / 2.0))
            .clamp(Vec2::ZERO, Vec2::splat(cells as f32));
        let (ix, iy) = ((g.x as usize).min(cells - 1), (g.y as usize).min(cells - 1));
        let (fx, fy) = (g.x - ix as f32, g.y - iy as f32);
        let i = iy * nodes + ix;
        let t = &self.row[i..i + nodes + 2];
        let top = t[0] * (1.0 - fx) + t[1] * fx;
        let bottom = t[nodes] * (1.0 - fx) + t[nodes + 1] * fx;
        let v = (top * (1.0 - fy) + bottom * fy) * self.scale;
        (v.x - self.gradient.dot(Vec2::new(v.y, v.z))).max(0.0)
    }

    /// [`ShiftTable::at`] at eight offsets `(dx, dy)`, the same to the bit lane by lane, for
    /// the lanes set in `wanted`, which lie within its footprint (the others are 0): the
    /// lending loop's blocks ([`super::lanes`]). Only the loads are lane by lane.
    #[inline]
    pub fn at_lanes(&self, (dx, dy): (f32x8, f32x8), wanted: u32) -> f32x8 {
        let (cells, nodes) = (self.cells, self.cells + 1);
        let grid = |d: f32x8, per_px: f32| {
            (d * f32x8::splat(self.sign) * f32x8::splat(per_px) + f32x8::splat(cells as f32 / 2.0))
                .max(f32x8::ZERO)
                .min(f32x8::splat(cells as f32))
        };
        let (gx, gy) = (grid(dx, self.per_px.x), grid(dy, self.per_px.y));
        let last = i32x8::splat(cells as i32 - 1);
        let (ix, iy) = (gx.fast_trunc_int().min(last), gy.fast_trunc_int().min(last));
        let (fx, fy) = (gx - ix.round_float(), gy - iy.round_float());
        let index = (iy * i32x8::splat(nodes as i32) + ix).to_array();
        // The four nodes' three columns, lane by lane.
        let mut corners = [[[0.0f32; LANES]; 3]; 4];
        for j in super::bits(wanted) {
            let i = index[j] as usize;
            let t = &self.row[i..i + nodes + 2];
            for (node, v) in corners.iter_mut().zip([t[0], t[1], t[nodes], t[nodes + 1]]) {
                (node[0][j], node[1][j], node[2][j]) = (v.x, v.y, v.z);
            }
        }
        let (one_x, one_y) = (f32x8::ONE - fx, f32x8::ONE - fy);
        let v = |c: usize| {
            let top = f32x8::from(corners[0][c]) * one_x + f32x8::from(corners[1][c]) * fx;
            let bottom = f32x8::from(corners[2][c]) * one_x + f32x8::from(corners[3][c]) * fx;
            (top * one_y + bottom * fy) * f32x8::splat(self.scale)
        };
        let tilt = f32x8::splat(self.gradient.x) * v(1) + f32x8::splat(self.gradient.y) * v(2);
        (v(0) - tilt).max(f32x8::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::aperture::test_shapes;
    use crate::filter::{PixelFilter, PixelFilterKind};

    /// The footprint a [`super::super::Kernel`] cuts a table round at.
    fn footprint(f: &FilterDensity, shape: &ApertureShape) -> Reach {
        Reach {
            filter: f.reach(),
            outer: shape.outer_radius(),
            half: shape.half_extents(),
        }
    }

    /// The test apertures other than the disc, but for the 1024 blades (whose inside test,
    /// corner by corner, the film integral below would take long over).
    fn shapes() -> impl Iterator<Item = ApertureShape> {
        test_shapes()
            .into_iter()
            .filter(|s| !s.is_round() && s.blades <= 8)
    }

    /// The kernel integrates to 1 over the plane, for narrow and wide blur of either sign.
    #[test]
    fn the_kernel_is_a_density() {
        for kind in [PixelFilterKind::Box, PixelFilterKind::BlackmanHarris] {
            let f = PixelFilter::new(kind).density();
            for shape in shapes() {
                let table = Table::new(&f, &shape, footprint(&f, &shape));
                for s in [0.5f32, 1.3, 4.0, -17.0, 120.0, 3000.0] {
                    let k = table.for_sample(s, Vec2::ZERO);
                    let steps = 400;
                    let extent = Vec2::splat(k.cells as f32 / 2.0) / k.per_px;
                    let cell = extent * 2.0 / steps as f32;
                    let mut mass = 0.0f64;
                    for j in 0..steps {
                        for i in 0..steps {
                            let d = -extent + cell * Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
                            mass += f64::from(k.at(d) * cell.x * cell.y);
                        }
                    }
                    assert!(
                        (mass - 1.0).abs() < 0.02,
                        "{kind:?} {shape:?}, s = {s}: {mass}"
                    );
                }
            }
        }
    }

    /// The tabulated kernel, tilt and all, is the filter's mass over the film positions
    /// whose lens positions image `d` there, each weighted by its image's stretch
    /// `1 + g . (l.x, -l.y)` (integrated over the film on a fine grid, with the aperture's
    /// own inside test): for a polygon turned over by a negative shift too (five blades, so
    /// it shows), inside the blur, across its rim and at a corner. Within 3% of the inside's
    /// value (2.2% measured, at a square's corner): a sample reads its nearest shift row,
    /// whose rim lies up to a quarter percent of the box away (0.03 px at a shift of 9 px),
    /// where the kernel falls steeply.
    #[test]
    fn the_kernel_is_the_filter_averaged_over_the_aperture() {
        let f = PixelFilter::new(PixelFilterKind::BlackmanHarris).density();
        let reach = f.reach();
        let n = 400;
        let cell = 2.0 * reach / n as f32;
        let film: Vec<(Vec2, f32)> = (0..n * n)
            .map(|i| {
                let x = Vec2::new((i % n) as f32 + 0.5, (i / n) as f32 + 0.5) * cell - reach;
                (x, f.at(x.x) * f.at(x.y) * cell * cell)
            })
            .collect();
        for shape in shapes() {
            let table = Table::new(&f, &shape, footprint(&f, &shape));
            for (shift, gradient) in [
                (9.0f32, Vec2::ZERO),
                (-9.0, Vec2::ZERO),
                (9.0, Vec2::new(0.15, -0.1)),
                (-6.0, Vec2::new(-0.1, 0.2)),
            ] {
                let k = table.for_sample(shift, gradient);
                let inside = 1.0 / (shape.area() * shift * shift);
                for d in [
                    Vec2::ZERO,
                    Vec2::new(3.0, -2.0),
                    Vec2::new(8.5, 0.5),
                    Vec2::new(-1.0, 8.8),
                    Vec2::new(6.0, 6.0),
                    Vec2::new(-7.5, -4.0),
                ] {
                    // x = d + shift (l.x, -l.y).
                    let want: f32 = film
                        .iter()
                        .map(|&(x, w)| {
                            let r = (x - d) / shift;
                            let l = Vec2::new(r.x, -r.y);
                            if shape.contains(l) {
                                w * (1.0 + gradient.dot(r))
                            } else {
                                0.0
                            }
                        })
                        .sum::<f32>()
                        * inside;
                    let got = k.at(d);
                    assert!(
                        (got - want).abs() < 0.03 * inside,
                        "{shape:?}, shift {shift}, g {gradient}, d {d}: {got} vs {want} \
                         (inside {inside})"
                    );
                }
            }
        }
    }
}
