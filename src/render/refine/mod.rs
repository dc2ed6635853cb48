//! Error-controlled adaptive sampling: the seed's sample sites and interpolation, with the
//! sample interval and each site's number of samples chosen from an error estimate instead of
//! a constant (the seed's open problem).
//!
//! 1. **A-priori bound.** A surface blurred by a CoC of C pixels is its sharp image convolved
//!    with a disc of diameter C, so nothing in that region is narrower than C: a lattice of
//!    interval C / 2 ([`START_K`]) puts a traced point within C / 2 of every pixel, and every
//!    blurred feature (even a bokeh disc with a hard rim) touches one. As interpolation error
//!    grows with the interval squared, the start interval scales with the tolerance's square
//!    root ([`start_k`]: C / 2 at 1 code value). These intervals, made conservative near
//!    sharper pixels, are upper bounds.
//! 2. **A-posteriori check.** Every cell of the lattice also traces its centre. Any traced
//!    pixel inside a cell (its centre, or a corner of a finer neighbour on its edge) is
//!    compared with the cell's interpolation at that pixel; a difference beyond the tolerance
//!    plus the noise both carry (from the sites' sample variance) halves the cell, whose new
//!    corners and centres are traced in the next round. Cells that pass are interpolated as
//!    a biquadratic (`Cell::weights`) through their corners, centre and edges' middles,
//!    traced by a finer neighbour or estimated from the cells of their size either side
//!    (`middle_between`, exact for quadratics; the corners' line at a bucket's border),
//!    clamped to the values it blends: a blurred edge crossing a cell curves through it
//!    smoothly, where the fan of triangles through the centre it replaced left teeth.
//! 3. **Samples where variance is.** A site that blur reaches starts with `max(aa, 16,
//!    spp / 4)` samples (at most `spp`) and doubles them, up to `spp`, while the standard
//!    error of its mean exceeds half the tolerance: bright bokeh and edges behind blur get
//!    `spp`, flat blur stops early. Fewer than 16 samples are never trusted to have
//!    converged: a few samples that all land on one side of an edge look noise-free. Nor
//!    are samples that agree while a much brighter sample was seen within the CoC's reach
//!    (a small highlight behind the blur that this site's samples happened to miss): the
//!    site keeps sampling while one such sample more would move it beyond the limit.
//! 4. **Samples in proportion to noise where nothing is interpolated.** With the path
//!    tracer a site whose start interval is 1 (in focus, or barely blurred) is its pixel's
//!    only estimate, and its error is its light noise: it starts with 16 samples (at most
//!    `spp`) and grows the same way up to a most set by its neighbours' noise against a
//!    frame-wide scale ([`allocation`]), at most the larger of `spp` and `aa` in focus and
//!    `spp` in the blur: quiet pixels stop early, noisy ones take it all, for about the image
//!    error of that many samples everywhere.
//! 5. **In-focus sites gather.** With reuse, a site that no blur reaches also adds its
//!    samples to its neighbours through their pixel filters ([`super::gather`]): a layer per
//!    bucket, summed over the frame in bucket order, replaces those sites' own means.
//!
//! With [`super::RenderSettings::transparent`] the coverage (alpha) takes part in both
//! checks like a colour channel, 255 code values from empty to opaque, its noise from the
//! hits' Bernoulli variance: a dark object on an empty background differs only there.
//!
//! Rounds repeat until no cell fails and no site wants samples. Differences and noise are
//! measured in 8-bit sRGB code values continued above 1 ([`super::estimate::code`]), the
//! units of the tolerance. Every decision depends only on the estimates, which depend only on
//! the pixel and its sample indices, so the image is the same for any thread count.

use std::time::Instant;

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use super::allocation::{self, FocusBudget};
use super::estimate::{Estimate, code3};
use super::gather::{Gather, Layer, SLOTS, Slot, Slots};
use super::maps;
use super::reuse::{Kernel, Nearest, SiteRecords};
use super::site::SiteShader;
use super::{Progress, Tally};
use crate::limits::{MemoryError, try_collect, try_copy, try_vec};

mod lending;

/// Start interval as a fraction of the CoC at a tolerance of 1 code value (see the module
/// documentation).
pub const START_K: f32 = 0.5;

/// The start interval's fraction of the CoC for `tolerance`: interpolation error grows with
/// the square of the interval, so the interval that keeps it in bounds grows with the
/// tolerance's square root (within 1/4 and 1 of the CoC).
pub fn start_k(tolerance: f32) -> f32 {
    (START_K * tolerance.sqrt()).clamp(0.25, 1.0)
}
/// A difference counts as real when it exceeds the tolerance by this many standard errors.
const NOISE_Z: f32 = 2.0;
/// The fewest samples whose variance is trusted to stop a site early: with fewer, samples
/// that happen to agree (all on one side of an edge behind the blur) look converged.
const MIN_TRUSTED: u32 = 16;
/// A site keeps sampling while its standard error exceeds this fraction of the tolerance.
const SAMPLING_SHARE: f32 = 0.5;

/// What the error-controlled rule produced.
pub struct Refined {
    /// Colour with the coverage as alpha.
    pub color: Vec<Vec4>,
    /// Final interval of every pixel's cell.
    pub interval: Vec<u32>,
    /// Samples traced per pixel (0: interpolated).
    pub samples: Vec<u32>,
    /// The sites whose value rests on their neighbours' lent samples too ([`super::reuse`]).
    pub borrowed: Vec<bool>,
    /// Rounds of shading and checking.
    pub rounds: u32,
    /// Worker-thread seconds spent on the buckets, summed over threads.
    pub work_seconds: f64,
    /// Of `work_seconds`, those spent lending samples between sites ([`super::reuse`]): their
    /// ratio is lending's share of the work.
    pub lend_seconds: f64,
}

impl Refined {
    /// Lending's share of the work on the buckets, 0 to 1 (0 when none was timed).
    pub fn lend_share(&self) -> f64 {
        if self.work_seconds > 0.0 {
            (self.lend_seconds / self.work_seconds).min(1.0)
        } else {
            0.0
        }
    }
}

/// A lattice cell: the corners (x0, y0) to (x1, y1), clipped at the image border.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Cell {
    size: u32,
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Cell {
    /// The cell pixel (x, y) with interval `size` interpolates in.
    fn of(x: usize, y: usize, size: u32, width: usize, height: usize) -> Self {
        let (x0, x1) = maps::cell(x, size, width);
        let (y0, y1) = maps::cell(y, size, height);
        Self {
            size,
            x0,
            y0,
            x1,
            y1,
        }
    }

    fn contains(&self, x: usize, y: usize) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    fn is_corner(&self, x: usize, y: usize) -> bool {
        (x == self.x0 || x == self.x1) && (y == self.y0 || y == self.y1)
    }

    /// The traced centre, for cells at least 2 pixels across both ways.
    fn centre(&self) -> Option<(usize, usize)> {
        (self.x1 >= self.x0 + 2 && self.y1 >= self.y0 + 2)
            .then(|| ((self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2))
    }

    /// The pixels (indices in a window `width` wide) the interpolation at (x, y) blends,
    /// with their weights, those of weight zero left out ([`Cell::weights`]); `known` says
    /// which pixels are traced.
    fn points(
        &self,
        width: usize,
        (x, y): (usize, usize),
        centre: Option<(usize, usize)>,
        known: impl Fn(usize) -> bool,
    ) -> impl Iterator<Item = (usize, f32)> {
        let known = |(px, py): (usize, usize)| known(py * width + px);
        (self.weights(x, y, centre, known).into_iter())
            .filter(|&(_, w)| w != 0.0)
            .map(move |((px, py), w)| (py * width + px, w))
    }

    /// The points the interpolation at (x, y) blends and their weights. Without `centre`,
    /// bilinear over the corners. With it, the biquadratic through the 3 x 3 nodes of the
    /// corners, the centre and the edges' middles (at the centre's column and row), where
    /// an edge's middle is its traced value when `known` (a finer neighbour's corner) and
    /// else the corners' line there. So on an edge it is the line, or the parabola through
    /// the traced middle, that the cell's neighbour meets; inside, a value that curves
    /// across the cell (a blurred edge) follows the centre smoothly, where a fan of
    /// triangles through it left teeth along the edge. It is exact for bilinear functions
    /// plus any multiple of the centre's bump. Weights sum to 1 but the far nodes' may be
    /// negative: see [`blend`].
    fn weights(
        &self,
        x: usize,
        y: usize,
        centre: Option<(usize, usize)>,
        known: impl Fn((usize, usize)) -> bool,
    ) -> [((usize, usize), f32); 9] {
        let (x0, y0, x1, y1) = (self.x0, self.y0, self.x1, self.y1);
        let mut out = [((x0, y0), 0.0); 9];
        let Some((cx, cy)) = centre else {
            let fraction = |p: usize, lo: usize, hi: usize| {
                if hi > lo {
                    (p - lo) as f32 / (hi - lo) as f32
                } else {
                    0.0
                }
            };
            let (tx, ty) = (fraction(x, x0, x1), fraction(y, y0, y1));
            out[0] = ((x0, y0), (1.0 - tx) * (1.0 - ty));
            out[1] = ((x1, y0), tx * (1.0 - ty));
            out[2] = ((x1, y1), tx * ty);
            out[3] = ((x0, y1), (1.0 - tx) * ty);
            return out;
        };
        // Each axis's quadratic Lagrange weights at p for the nodes lo < c < hi.
        let lagrange = |p: usize, lo: usize, c: usize, hi: usize| {
            let (p, lo, c, hi) = (p as f32, lo as f32, c as f32, hi as f32);
            [
                (p - c) * (p - hi) / ((lo - c) * (lo - hi)),
                (p - lo) * (p - hi) / ((c - lo) * (c - hi)),
                (p - lo) * (p - c) / ((hi - lo) * (hi - c)),
            ]
        };
        let (wx, wy) = (lagrange(x, x0, cx, x1), lagrange(y, y0, cy, y1));
        let (xs, ys) = ([x0, cx, x1], [y0, cy, y1]);
        // Where the line between an untraced middle's corners crosses it.
        let (tx, ty) = (
            (cx - x0) as f32 / (x1 - x0) as f32,
            (cy - y0) as f32 / (y1 - y0) as f32,
        );
        for j in 0..3 {
            for i in 0..3 {
                let (node, w) = ((xs[i], ys[j]), wx[i] * wy[j]);
                let slot = &mut out[j * 3 + i];
                slot.0 = node;
                slot.1 += w;
                // An edge's middle not traced: its weight goes to the edge's corners.
                let middle_of = match (i, j) {
                    (1, 0) | (1, 2) => Some((tx, j * 3, j * 3 + 2)),
                    (0, 1) | (2, 1) => Some((ty, i, 6 + i)),
                    _ => None,
                };
                if let Some((t, a, b)) = middle_of.filter(|_| !known(node)) {
                    out[j * 3 + i].1 -= w;
                    out[a].1 += w * (1.0 - t);
                    out[b].1 += w * t;
                }
            }
        }
        out
    }
}

/// The least and greatest of some values, channel by channel.
#[derive(Debug, Clone, Copy)]
struct Span {
    lo: Vec4,
    hi: Vec4,
}

impl Span {
    /// No value yet.
    const EMPTY: Self = Self {
        lo: Vec4::splat(f32::INFINITY),
        hi: Vec4::splat(f32::NEG_INFINITY),
    };

    fn of(values: impl IntoIterator<Item = Vec4>) -> Self {
        values.into_iter().fold(Self::EMPTY, Self::with)
    }

    fn with(self, v: Vec4) -> Self {
        Self {
            lo: self.lo.min(v),
            hi: self.hi.max(v),
        }
    }

    /// `v` clamped into the span (`max` then `min`, not `clamp`); an empty span keeps it.
    fn clamp(self, v: Vec4) -> Vec4 {
        if self.lo.x <= self.hi.x {
            v.max(self.lo).min(self.hi)
        } else {
            v
        }
    }
}

/// The interpolation `Σ w v` of `points` (pixel, weight), with `value` each point's (given
/// its weight too), clamped channel by channel to the points' [`Span`]: the biquadratic's far
/// corners weigh negatively, so next to one bright corner (a bokeh disc's rim) it would dip
/// below its darkest point, below zero on black. Clamped, it never leaves the values it
/// blends (none of a flat region's, nor a linear one's, which it reproduces). None when
/// `value` gives None.
fn blend(
    points: impl Iterator<Item = (usize, f32)>,
    mut value: impl FnMut(usize, f32) -> Option<Vec4>,
) -> Option<Vec4> {
    let (mut sum, mut span) = (Vec4::ZERO, Span::EMPTY);
    for (p, w) in points {
        let v = value(p, w)?;
        sum += v * w;
        span = span.with(v);
    }
    Some(span.clamp(sum))
}

/// The interpolation (colour and coverage) at (x, y) from the traced points, with the
/// standard errors of its luminance and coverage in code values, or None when a point it
/// needs is not traced (yet).
fn interpolate_at(
    traced: &Traced,
    width: usize,
    cell: &Cell,
    (x, y): (usize, usize),
    centre: Option<(usize, usize)>,
) -> Option<(Vec4, f32, f32)> {
    // The point compared is never one of the nodes it is compared with.
    let q = y * width + x;
    let known = |p: usize| p != q && traced.est[p].n > 0;
    let (mut var, mut var_alpha) = (0.0, 0.0);
    let points = cell.points(width, (x, y), centre, known);
    let value = blend(points, |p, w| {
        let e = &traced.est[p];
        if e.n == 0 {
            return None;
        }
        let (se, se_alpha) = traced.noise(p);
        var += w * w * se * se;
        var_alpha += w * w * se_alpha * se_alpha;
        Some(e.mean_rgba())
    })?;
    Some((value, var.sqrt(), var_alpha.sqrt()))
}

/// Every pixel's estimate, with what the checks read of each traced one computed once per
/// round: its standard error and its mean, in code values.
struct Traced {
    est: Vec<Estimate>,
    /// With sample reuse, each pixel's samples kept for lending ([`super::reuse`]).
    records: Option<Vec<SiteRecords>>,
    /// With gathering, what each in-focus site's samples give the pixels around it.
    slots: Option<Vec<Slots>>,
    /// [`Estimate::std_error_code`]: infinite while unknown (fewer than two samples).
    se: Vec<f32>,
    /// [`Estimate::coverage_error_code`], likewise.
    se_alpha: Vec<f32>,
    code: Vec<Vec3>,
}

impl Traced {
    /// For the pixels of a window, `blurred` or not; with `reuse`, the blurred ones keep
    /// their samples (the others take no part in it); with `gather`, the others gather
    /// theirs ([`super::gather`]).
    fn new(blurred: &[bool], reuse: bool, gather: bool) -> Result<Self, MemoryError> {
        let n = blurred.len();
        let records = |&b: &bool| {
            if b {
                SiteRecords::default()
            } else {
                SiteRecords::unlent()
            }
        };
        let slots = if gather && blurred.iter().any(|&b| !b) {
            let empty = [Slot::default(); SLOTS];
            Some(try_vec(n, empty, "the gathered samples")?)
        } else {
            None
        };
        Ok(Self {
            est: vec![Estimate::default(); n],
            records: reuse.then(|| blurred.iter().map(records).collect()),
            slots,
            se: vec![f32::INFINITY; n],
            se_alpha: vec![f32::INFINITY; n],
            code: vec![Vec3::ZERO; n],
        })
    }

    /// With reuse, room for the samples each site takes next (`from` -> `to`;
    /// [`SiteRecords::reserve`]).
    fn make_room(&mut self, from: &[u32], to: &[u32]) -> Result<(), MemoryError> {
        for (p, site) in self.records.iter_mut().flatten().enumerate() {
            site.reserve(to[p].saturating_sub(from[p]) as usize)?;
        }
        Ok(())
    }

    /// Recomputes the cached values of the pixels in `changed`.
    fn update(&mut self, changed: &[usize]) {
        for &p in changed {
            let e = &self.est[p];
            self.se[p] = e.std_error_code();
            self.se_alpha[p] = e.coverage_error_code();
            self.code[p] = code3(e.mean());
        }
    }

    /// The standard errors of luminance and coverage in code values for the check; unknown
    /// (one sample) counts as none, so a single-sample site never hides a difference.
    fn noise(&self, p: usize) -> (f32, f32) {
        let known = |se: f32| if se.is_finite() { se } else { 0.0 };
        (known(self.se[p]), known(self.se_alpha[p]))
    }
}

/// Marks in `need` the corners of `cell` and its centre, when it has one, and lists the
/// pixels newly marked in `pending`.
fn mark_needed(need: &mut [bool], pending: &mut Vec<usize>, cell: &Cell, width: usize) {
    let corners = [
        (cell.x0, cell.y0),
        (cell.x1, cell.y0),
        (cell.x0, cell.y1),
        (cell.x1, cell.y1),
    ];
    for (x, y) in corners.into_iter().chain(cell.centre()) {
        let p = y * width + x;
        if !need[p] {
            need[p] = true;
            pending.push(p);
        }
    }
}

/// The pixels of a cell within `width` x `height` (half-open: its right and bottom corners
/// belong to the next cell).
fn cell_pixels(c: &Cell, width: usize, height: usize) -> impl Iterator<Item = (usize, usize)> {
    let s = c.size as usize;
    (c.y0..(c.y0 + s).min(height))
        .flat_map(move |y| (c.x0..(c.x0 + s).min(width)).map(move |x| (x, y)))
}

/// Checks `cells` (sorted, without repeats): every traced pixel in a cell's closure other
/// than its corners (its centre, or corners of finer neighbours on its edges) is compared
/// with the cell's interpolation there. With `alpha` the coverage is compared too (255 code
/// values from empty to opaque). Returns the cells that fail, each with the interval it
/// should be split to.
fn failed_cells(
    traced: &Traced,
    cells: &[Cell],
    width: usize,
    tolerance: f32,
    alpha: bool,
) -> Vec<(Cell, u32)> {
    cells
        .iter()
        .filter_map(|cell| {
            let mut worst = 0.0f32;
            for qy in cell.y0..=cell.y1 {
                for qx in cell.x0..=cell.x1 {
                    let q = qy * width + qx;
                    if traced.est[q].n == 0 || cell.is_corner(qx, qy) {
                        continue;
                    }
                    let centre = cell.centre().filter(|&c| c != (qx, qy));
                    let Some((value, se, se_alpha)) =
                        interpolate_at(traced, width, cell, (qx, qy), centre)
                    else {
                        continue;
                    };
                    let threshold =
                        |se: f32, se_q: f32| tolerance + NOISE_Z * (se * se + se_q * se_q).sqrt();
                    let (se_q, se_alpha_q) = traced.noise(q);
                    let diff = (traced.code[q] - code3(value.truncate()))
                        .abs()
                        .max_element();
                    worst = worst.max(diff / threshold(se, se_q));
                    if alpha {
                        let diff = 255.0 * (traced.est[q].coverage() - value.w).abs();
                        worst = worst.max(diff / threshold(se_alpha, se_alpha_q));
                    }
                }
            }
            // Interpolation error grows as the interval squared: split far enough at once
            // that the error would fall within the threshold.
            (worst > 1.0).then(|| {
                let levels = (0.5 * worst.log2()).ceil().max(1.0) as u32;
                let to = cell.size >> levels.min(cell.size.trailing_zeros());
                (*cell, to.max(1))
            })
        })
        .collect()
}

/// Lowers the interval of every (owned) pixel in each failed cell of bucket `b` to the one
/// its split asks for; marks the new cells' corners and centres as needed and lists the new
/// cells.
fn split(
    interval: &mut [u32],
    need: &mut [bool],
    pending: &mut Vec<usize>,
    cells: &[(Cell, u32)],
    b: &Bucket,
) -> Vec<Cell> {
    let (width, height) = (b.w, b.h);
    let mut new_cells = Vec::new();
    for &(c, to) in cells {
        for (x, y) in cell_pixels(&c, b.owned_w, b.owned_h) {
            let v = &mut interval[y * width + x];
            if *v == c.size {
                *v = to;
                let cell = Cell::of(x, y, to, width, height);
                if new_cells.last() != Some(&cell) {
                    mark_needed(need, pending, &cell, width);
                    new_cells.push(cell);
                }
            }
        }
    }
    new_cells
}

/// The bucket's cells whose closure holds pixel p: those of p and of its left, upper and
/// upper-left neighbours that the bucket owns.
fn cells_around<'a>(
    p: usize,
    interval: &'a [u32],
    b: &'a Bucket,
) -> impl Iterator<Item = Cell> + 'a {
    let (width, height) = (b.w, b.h);
    let (x, y) = (p % width, p / width);
    [
        (x, y),
        (x.wrapping_sub(1), y),
        (x, y.wrapping_sub(1)),
        (x.wrapping_sub(1), y.wrapping_sub(1)),
    ]
    .into_iter()
    .filter(move |&(rx, ry)| b.owns(rx, ry))
    .map(move |(rx, ry)| Cell::of(rx, ry, interval[ry * width + rx], width, height))
    .filter(move |c| c.size >= 2 && c.contains(x, y))
}

/// The brightest sample near every pixel: within the square of half-size CoC / 2 (at least
/// 2), the reach of one blurred highlight, from log-quantised per-site peaks.
struct Peaks {
    levels: Vec<Vec<u8>>,
}

/// Per pixel, the [`Peaks`] level whose square covers its reach, CoC / 2 (2 to `max`): a
/// property of the CoC map, so made once per render.
fn reach_levels(coc: &[f32], max: u32) -> Result<Vec<u8>, MemoryError> {
    let levels = coc.iter().map(|&c| {
        let r = (0.5 * c).clamp(2.0, max as f32);
        r.log2().ceil().max(1.0) as u8
    });
    try_collect(levels, "the highlight reach map")
}

impl Peaks {
    /// 8 steps per doubling (9% resolution), 2^-16 to 2^16.
    fn quantise(l: f32) -> u8 {
        if l <= 0.0 {
            0
        } else {
            (8.0 * l.log2() + 128.0).ceil().clamp(1.0, 255.0) as u8
        }
    }

    fn value(q: u8) -> f32 {
        if q == 0 {
            0.0
        } else {
            ((f32::from(q) - 128.0) / 8.0).exp2()
        }
    }

    /// `top`: the largest of the [`reach_levels`].
    fn new(est: &[Estimate], width: usize, height: usize, top: u8) -> Result<Self, MemoryError> {
        let peak: Vec<u8> = est.iter().map(|e| Self::quantise(e.peak())).collect();
        Ok(Self {
            levels: maps::square_maxima(&peak, width, height, u32::from(top))?,
        })
    }

    /// The brightest sample within `level`'s square around pixel p.
    fn near(&self, p: usize, level: u8) -> f32 {
        Self::value(self.levels[usize::from(level) - 1][p])
    }
}

/// A bucket of the image: the square of `size` pixels whose top left is (x0, y0), plus the
/// column and row beyond it that its cells' right and bottom corners lie on (its closure).
/// Cells never cross a bucket (they are at most `max_interval` across and aligned to their
/// size), so each bucket refines on its own, from the frame's maps and its own samples only.
#[derive(Debug, Clone, Copy)]
struct Bucket {
    x0: usize,
    y0: usize,
    /// The closure's size (the owned pixels plus the shared column and row, inside the image).
    w: usize,
    h: usize,
    /// The pixels the bucket interpolates: `owned_w` x `owned_h` from its top left.
    owned_w: usize,
    owned_h: usize,
}

impl Bucket {
    fn new(x0: usize, y0: usize, size: usize, width: usize, height: usize) -> Self {
        Self {
            x0,
            y0,
            w: (size + 1).min(width - x0),
            h: (size + 1).min(height - y0),
            owned_w: size.min(width - x0),
            owned_h: size.min(height - y0),
        }
    }

    fn owns(&self, x: usize, y: usize) -> bool {
        x < self.owned_w && y < self.owned_h
    }

    /// The image's pixels in the closure (`closure = true`) or the owned ones.
    fn region(&self, closure: bool) -> super::Region {
        let (w, h) = if closure {
            (self.w, self.h)
        } else {
            (self.owned_w, self.owned_h)
        };
        super::Region {
            x0: self.x0 as u32,
            y0: self.y0 as u32,
            x1: (self.x0 + w) as u32,
            y1: (self.y0 + h) as u32,
        }
    }

    /// The closure's part of a full-frame map.
    fn slice<T: Copy>(&self, full: &[T], width: usize) -> Vec<T> {
        self.region(true).crop(full, width)
    }
}

/// The frame-wide maps every bucket reads (all from the depth pass).
struct Maps<'a> {
    /// The error-controlled rule's tolerance in effect.
    tolerance: f32,
    blur: &'a maps::Blur,
    start: Vec<u32>,
    reach: Vec<u8>,
    /// With sample reuse, its kernel for the render's pixel filter.
    kernel: Option<Kernel>,
    /// With sample reuse, the depth pass's shifts: what a nearer surface hides.
    nearest: Option<Nearest>,
    /// With paths, how many samples the sites of one pixel's interval take by their noise
    /// ([`allocation`]).
    focus: Option<FocusBudget>,
    /// With sample reuse, the in-focus sites' gathering ([`super::gather`]).
    gather: Option<Gather<'a>>,
}

/// Renders with the error-controlled rule at `tolerance`, given the blur that reaches each pixel,
/// the pixels of `region` (and of the buckets around them; the rest of the returned maps is
/// left empty: colour 0, no samples).
///
/// The image is worked on in buckets of `max_interval` pixels, each refined on its own (in
/// parallel) from the frame's depth pass and its own samples; with sample reuse its sites
/// then borrow from the buckets around it, in windows fixed by the frame (`lending`). So
/// any region of the image renders to the same pixels as the whole frame.
pub fn refine(
    shader: &SiteShader,
    tolerance: f32,
    (blur, depth): (&maps::Blur, &[f32]),
    region: &super::Region,
    progress: &dyn Progress,
    tally: &mut Tally,
) -> Result<Refined, super::RenderError> {
    let s = shader.settings;
    let (width, height) = (shader.camera.width as usize, shader.camera.height as usize);
    let start = maps::start_intervals(
        &blur.sharpest,
        width,
        height,
        start_k(tolerance),
        s.max_interval,
    )?;
    let focus = focus_budget(shader, blur, &start, tally);
    let lends = reuses(shader);
    // The sites no blur reaches gather each other's samples.
    let techniques = try_collect(blur.blurred.iter().map(|&b| !b), "the in-focus sites")?;
    let density = s.pixel_filter.density();
    let lending = (shader.camera.reprojection()).filter(|_| lends);
    let nearest = match &lending {
        Some(re) => Some(Nearest::from_depth(re, (width, height), depth)?),
        None => None,
    };
    let maps = Maps {
        tolerance,
        blur,
        start,
        reach: reach_levels(&blur.widest, s.max_interval)?,
        kernel: lending.map(|re| Kernel::new(&density, &re.aperture)),
        nearest,
        focus,
        gather: (s.path.reuse)
            .then(|| {
                Gather::new(
                    &techniques,
                    (width, height),
                    (shader.pixel_filter, density.reach()),
                )
            })
            .flatten(),
    };
    let layout = Layout::new(s.max_interval as usize, width, height);
    let wanted: Vec<bool> = (0..layout.count())
        .map(|i| region.overlaps(&layout.bucket(i).region(false)))
        .collect();
    let done = if maps.kernel.is_some() {
        lending::refine(shader, &maps, &layout, &wanted, progress, tally)?
    } else {
        refine_alone(shader, &maps, &layout, &wanted, progress, tally)?
    };
    super::check_cancelled(progress)?;
    let mut out = Refined {
        color: try_vec(width * height, Vec4::ZERO, "the pixels' colours")?,
        interval: try_copy(&maps.start, "the interval map")?,
        samples: try_vec(width * height, 0, "the pixels' sample counts")?,
        borrowed: try_vec(width * height, false, "the sites that borrowed")?,
        rounds: 0,
        work_seconds: done.work_seconds,
        lend_seconds: done.lend_seconds,
    };
    for (b, refined) in done.buckets {
        for y in 0..b.owned_h {
            for x in 0..b.owned_w {
                let (p, q) = ((b.y0 + y) * width + b.x0 + x, y * b.w + x);
                let gathered = (done.gathered.as_ref())
                    .filter(|_| techniques[p])
                    .and_then(|g| g[p].value());
                out.color[p] = gathered.unwrap_or(refined.color[q]);
                out.interval[p] = refined.interval[q];
                out.samples[p] = refined.samples[q];
                out.borrowed[p] = refined.borrowed[q];
            }
        }
        out.rounds = out.rounds.max(refined.rounds);
    }
    Ok(out)
}

/// The buckets' results and the worker-thread seconds spent on them.
struct Finished {
    /// Each wanted bucket's result over its closure, of which the owned pixels are final.
    buckets: Vec<(Bucket, Refined)>,
    work_seconds: f64,
    /// Of `work_seconds`, those spent lending.
    lend_seconds: f64,
    /// With gathering, the frame's pixels' gathered values (those of the sites that take
    /// part, in the wanted buckets, are final; [`super::gather`]).
    gathered: Option<Vec<Slot>>,
}

impl Finished {
    /// Nothing finished yet, with room for the frame's gathered values where `maps` gathers.
    fn new(maps: &Maps, layout: &Layout) -> Result<Self, MemoryError> {
        let frame = layout.width * layout.height;
        let gathered = (maps.gather.as_ref())
            .map(|_| try_vec(frame, Slot::default(), "the gathered samples"))
            .transpose()?;
        Ok(Self {
            buckets: Vec::new(),
            work_seconds: 0.0,
            lend_seconds: 0.0,
            gathered,
        })
    }

    /// Adds what a bucket's refinement gathered (`rounds`' layer, taken) into the frame.
    /// Called in the order buckets are refined, by index, whatever the region.
    fn gather(&mut self, rounds: &mut Rounds, frame_width: usize) {
        if let (Some(layer), Some(frame)) = (rounds.layer.take(), &mut self.gathered) {
            layer.add_to(frame, frame_width);
        }
    }
}

/// [`refine`] without sample reuse: each bucket on its own, all in parallel.
fn refine_alone(
    shader: &SiteShader,
    maps: &Maps,
    layout: &Layout,
    wanted: &[bool],
    progress: &dyn Progress,
    tally: &mut Tally,
) -> Result<Finished, super::RenderError> {
    let record_rays = shader.settings.record_rays;
    // With gathering, the buckets around the wanted ones are refined too: their in-focus
    // sites' samples reach the wanted pixels by their borders.
    let refined: Vec<usize> = (0..layout.count())
        .filter(|&i| wanted[i] || (maps.gather.is_some() && layout.around(i).any(|j| wanted[j])))
        .collect();
    progress.start("adaptive", refined.len() as u64);
    let done: Vec<_> = refined
        .par_iter()
        .map(|&i| {
            let b = layout.bucket(i);
            let mut local = Tally::new(record_rays);
            let started = Instant::now();
            let rounds = refine_bucket(shader, maps, &b, progress, &mut local);
            progress.advance(1);
            (i, b, rounds, local, started.elapsed().as_secs_f64())
        })
        .collect();
    let mut out = Finished::new(maps, layout)?;
    for (i, b, rounds, local, seconds) in done {
        tally.merge(local);
        let Some(mut rounds) = rounds? else {
            return Err(super::RenderError::Cancelled);
        };
        out.gather(&mut rounds, layout.width);
        if wanted[i] {
            out.buckets.push((b, rounds.finish(&b)));
        }
        out.work_seconds += seconds;
    }
    Ok(out)
}

/// The frame's buckets: `nx` x `ny` squares of `size` pixels, row by row.
struct Layout {
    size: usize,
    nx: usize,
    ny: usize,
    width: usize,
    height: usize,
}

impl Layout {
    fn new(size: usize, width: usize, height: usize) -> Self {
        Self {
            size,
            nx: width.div_ceil(size),
            ny: height.div_ceil(size),
            width,
            height,
        }
    }

    fn count(&self) -> usize {
        self.nx * self.ny
    }

    /// The buckets of the 3 x 3 block around bucket `i` that lie in the frame.
    fn around(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let (bx, by) = (i % self.nx, i / self.nx);
        let xs = bx.saturating_sub(1)..(bx + 2).min(self.nx);
        (by.saturating_sub(1)..(by + 2).min(self.ny))
            .flat_map(move |y| xs.clone().map(move |x| y * self.nx + x))
    }

    /// Bucket `i` (row by row).
    fn bucket(&self, i: usize) -> Bucket {
        let (bx, by) = (i % self.nx, i / self.nx);
        Bucket::new(
            bx * self.size,
            by * self.size,
            self.size,
            self.width,
            self.height,
        )
    }
}

/// A bucket whose rounds are done: its sites' samples, before lending.
struct Rounds {
    traced: Traced,
    interval: Vec<u32>,
    rounds: u32,
    /// With gathering, what its in-focus sites give the pixels around them.
    layer: Option<Layer>,
}

impl Rounds {
    /// Its sites' records, with reuse (lending reads them only then).
    fn records(&self) -> &[SiteRecords] {
        self.traced
            .records
            .as_ref()
            .expect("lending records samples")
    }

    /// The bytes its sites' records hold (none without reuse).
    fn record_bytes(&self) -> usize {
        let records = self.traced.records.iter().flatten();
        records.map(SiteRecords::bytes).sum()
    }

    /// The result without lending: every site keeps its own samples' mean.
    fn finish(&self, b: &Bucket) -> Refined {
        self.result(b, &self.traced.est, vec![false; b.w * b.h])
    }

    /// Bucket `b`'s result with its sites' values `est`, those in `borrowed` lent.
    fn result(&self, b: &Bucket, est: &[Estimate], borrowed: Vec<bool>) -> Refined {
        Refined {
            color: final_colour(est, &self.interval, b),
            interval: self.interval.clone(),
            samples: self.traced.est.iter().map(|e| e.n).collect(),
            borrowed,
            rounds: self.rounds,
            // Counted by the caller.
            work_seconds: 0.0,
            lend_seconds: 0.0,
        }
    }
}

/// Whether the site at a pixel of start interval `start` takes samples by its noise
/// ([`allocation`]): it is its pixel's only estimate (interval 1: nothing is interpolated
/// from it) and no unseen highlight may hide behind its samples ([`maps::Blur::unseen`]).
fn by_noise(start: u32, unseen: bool) -> bool {
    start == 1 && !unseen
}

/// With paths, the budget of the sites that take samples by their noise, from the frame's
/// pilot ([`allocation::pilot`]); None when in-focus sites take a fixed count (the direct
/// integrator's `aa`).
fn focus_budget(
    shader: &SiteShader,
    blur: &maps::Blur,
    start: &[u32],
    tally: &mut Tally,
) -> Option<FocusBudget> {
    let budget = Budget::new(shader.settings);
    // Nothing to allot when the first samples are already the most (16 spp or fewer).
    if !budget.by_noise || budget.first_by_noise() >= budget.in_focus {
        return None;
    }
    let mask: Vec<bool> = (start.iter().zip(&blur.unseen))
        .map(|(&i, &u)| by_noise(i, u))
        .collect();
    allocation::pilot(
        shader,
        &mask,
        budget.first_by_noise(),
        budget.in_focus,
        tally,
    )
}

/// Whether adaptive sites lend samples ([`super::reuse`]): asked for, with paths (which say how
/// rough a surface is), the box lens filter, and a lens whose images move rigidly (a thin
/// lens, whatever its aperture's shape).
fn reuses(shader: &SiteShader) -> bool {
    let s = shader.settings;
    s.path.reuse
        && s.integrator == super::Integrator::Path
        && s.filter == crate::camera::LensFilter::Box
        && s.mode == super::Mode::Adaptive
        && shader.camera.reprojection().is_some()
}

/// The error-controlled rule inside one bucket; the result covers the bucket's closure, of
/// which the owned pixels are the bucket's. `None` when `progress` cancelled it (polled
/// every round).
fn refine_bucket(
    shader: &SiteShader,
    maps: &Maps,
    b: &Bucket,
    progress: &dyn Progress,
    tally: &mut Tally,
) -> Result<Option<Rounds>, MemoryError> {
    let s = shader.settings;
    let full_width = shader.camera.width as usize;
    let (width, height) = (b.w, b.h);
    let tolerance = maps.tolerance;
    let blurred = b.slice(&maps.blur.blurred, full_width);
    let (mut allot, mut interval) = allotment(s, maps, b, full_width);
    let reach = b.slice(&maps.reach, full_width);
    let top_reach = reach.iter().copied().max().unwrap_or(1);
    let mut traced = Traced::new(&blurred, maps.kernel.is_some(), maps.gather.is_some())?;
    // Pixels whose sample count may have to grow: newly needed ones and unconverged sites.
    let (mut need, mut pending) = first_sites(&interval, b);
    // Samples per pixel before and after this round's shading.
    let (mut from, mut to) = (vec![0u32; width * height], vec![0u32; width * height]);
    // Cells resized by the last split: their checks must run again even if no point changed.
    let mut resized: Vec<Cell> = Vec::new();
    let mut scratch = super::SiteScratch::new();
    let mut rounds = 0;
    loop {
        if progress.cancelled() {
            return Ok(None);
        }
        pending.sort_unstable();
        pending.dedup();
        allot.settle(&pending, &traced.est);
        let target = |p: usize| allot.most[p];
        let sampling = (s.transparent, SAMPLING_SHARE * tolerance);
        let window = ((&reach[..], top_reach), (width, height));
        let work = round_work(&allot, &traced, (&mut pending, &mut to), window, sampling)?;
        if work.is_empty() && resized.is_empty() {
            break;
        }
        rounds += 1;
        traced.make_room(&from, &to)?;
        shade_changed_rows(
            (shader, maps),
            b,
            (&from, &to),
            &mut traced,
            &mut scratch,
            tally,
        );
        traced.update(&work);
        // Check every cell a new sample or a split touched.
        let mut dirty = std::mem::take(&mut resized);
        for &p in &work {
            from[p] = to[p];
            if traced.est[p].n < target(p) {
                pending.push(p);
            }
            dirty.extend(cells_around(p, &interval, b));
        }
        allot.record(&work, &traced.est);
        dirty.sort_unstable();
        dirty.dedup();
        let mut failed = failed_cells(&traced, &dirty, width, tolerance, s.transparent);
        failed.sort_unstable();
        resized = split(&mut interval, &mut need, &mut pending, &failed, b);
    }

    let layer = gathered(maps, b, &mut traced, shader.camera)?;
    Ok(Some(Rounds {
        traced,
        interval,
        rounds,
        layer,
    }))
}

/// This round's work in a bucket (`width` x `height`, each pixel's highlight reach
/// `reach`, the greatest `top_reach`): the `pending` sites (drained) that want samples,
/// each's new count in `to`. A site starts with its first samples, then doubles them up to
/// its most while its noise (with `transparent`, its coverage's too) is above `limit`, or
/// while a highlight seen within its reach could move it that far.
fn round_work(
    allot: &allocation::Allotment,
    traced: &Traced,
    (pending, to): (&mut Vec<usize>, &mut [u32]),
    ((reach, top_reach), (width, height)): ((&[u8], u8), (usize, usize)),
    (transparent, limit): (bool, f32),
) -> Result<Vec<usize>, MemoryError> {
    let (first, target) = (|p: usize| allot.first[p], |p: usize| allot.most[p]);
    // A site that looks converged by its variance must also not be missing a highlight
    // seen nearby; the peaks map is only built when some site is in that position.
    // Noisier than the limit: the colour, or with transparency the coverage.
    let noisy = |p: usize| traced.se[p] > limit || (transparent && traced.se_alpha[p] > limit);
    let calm = |p: usize| {
        let n = traced.est[p].n;
        n > 0 && n < target(p) && !noisy(p)
    };
    let peaks = pending
        .iter()
        .any(|&p| calm(p))
        .then(|| Peaks::new(&traced.est, width, height, top_reach))
        .transpose()?;
    let mut work = Vec::new();
    for p in pending.drain(..) {
        let e = &traced.est[p];
        let unsure = || {
            noisy(p)
                || peaks
                    .as_ref()
                    .is_some_and(|k| e.unseen_code(k.near(p, reach[p])) > limit)
        };
        let want = if e.n == 0 {
            first(p)
        } else if e.n < target(p) && unsure() {
            (2 * e.n).min(target(p))
        } else {
            continue;
        };
        to[p] = want;
        work.push(p);
    }
    Ok(work)
}

/// Each site's first and most samples in bucket `b` of a frame `full_width` wide, and its
/// start intervals; where a site takes samples by its noise, its most is lowered by its
/// neighbours' noise once they are known ([`allocation`]).
fn allotment(
    s: &super::RenderSettings,
    maps: &Maps,
    b: &Bucket,
    full_width: usize,
) -> (allocation::Allotment, Vec<u32>) {
    let budget = Budget::new(s);
    let blurred = b.slice(&maps.blur.blurred, full_width);
    let unseen = b.slice(&maps.blur.unseen, full_width);
    let start = b.slice(&maps.start, full_width);
    let n = b.w * b.h;
    let allot = allocation::Allotment::new(
        (0..n)
            .map(|p| budget.first(blurred[p], unseen[p]))
            .collect(),
        blurred.iter().map(|&b| budget.target(b)).collect(),
        (0..n).map(|p| by_noise(start[p], unseen[p])).collect(),
        budget.first_by_noise(),
        maps.focus,
        s.transparent,
        (b.w, b.h),
    );
    (allot, start)
}

/// How many samples a site starts with and may grow to, blurred or in focus.
struct Budget {
    spp: u32,
    aa: u32,
    /// The most an in-focus site takes. The direct integrator needs only anti-aliasing there;
    /// paths carry light noise in focus too, so an in-focus site takes up to the larger of
    /// `spp` and `aa`, as many as its noise asks for ([`allocation`]).
    in_focus: u32,
    /// Whether in-focus sites start at [`MIN_TRUSTED`] and take samples by their noise.
    by_noise: bool,
}

impl Budget {
    fn new(s: &super::RenderSettings) -> Self {
        let by_noise = s.integrator == super::Integrator::Path;
        Self {
            spp: s.spp,
            aa: s.aa,
            in_focus: if by_noise { s.spp.max(s.aa) } else { s.aa },
            by_noise,
        }
    }

    fn target(&self, blurred: bool) -> u32 {
        if blurred { self.spp } else { self.in_focus }
    }

    /// `unseen`: see [`maps::Blur::unseen`].
    fn first(&self, blurred: bool, unseen: bool) -> u32 {
        if unseen {
            self.target(blurred)
        } else if blurred {
            (self.spp / 4).max(self.aa).max(MIN_TRUSTED).min(self.spp)
        } else {
            self.aa
        }
    }

    /// The first samples of a site that takes them by its noise: too few are never trusted.
    fn first_by_noise(&self) -> u32 {
        MIN_TRUSTED.min(self.spp)
    }
}

/// The sites the owned pixels' starting cells need: a mask over the bucket and their list.
fn first_sites(interval: &[u32], b: &Bucket) -> (Vec<bool>, Vec<usize>) {
    let (width, height) = (b.w, b.h);
    let mut need = vec![false; width * height];
    let mut pending = Vec::new();
    for y in 0..b.owned_h {
        for x in 0..b.owned_w {
            let cell = Cell::of(x, y, interval[y * width + x], width, height);
            mark_needed(&mut need, &mut pending, &cell, width);
        }
    }
    (need, pending)
}

/// Shades the rows of bucket `b` whose sample counts grow this round (`from` -> `to`).
fn shade_changed_rows(
    (shader, maps): (&SiteShader, &Maps),
    b: &Bucket,
    (from, to): (&[u32], &[u32]),
    traced: &mut Traced,
    scratch: &mut super::SiteScratch,
    tally: &mut Tally,
) {
    let width = b.w;
    for y in 0..b.h {
        let row = y * width..(y + 1) * width;
        if from[row.clone()] != to[row.clone()] {
            shader.shade_row(
                (b.x0, b.y0 + y),
                &from[row.clone()],
                &to[row.clone()],
                &mut traced.est[row.clone()],
                traced.records.as_mut().map(|r| &mut r[row.clone()]),
                (maps.gather.as_ref())
                    .zip(traced.slots.as_mut())
                    .map(|(g, s)| (g, &mut s[row])),
                scratch,
                tally,
            );
        }
    }
}

/// With gathering, the layer of bucket `b`: what its own in-focus sites' samples (their
/// slots, over their estimates' weights) give the pixels around them ([`super::gather`]).
/// The slots are dropped.
fn gathered(
    maps: &Maps,
    b: &Bucket,
    traced: &mut Traced,
    camera: &crate::camera::Camera,
) -> Result<Option<Layer>, MemoryError> {
    let (Some(gather), Some(slots)) = (&maps.gather, traced.slots.take()) else {
        return Ok(None);
    };
    let frame = (camera.width as usize, camera.height as usize);
    let mut layer = Layer::new((b.x0, b.y0), (b.owned_w, b.owned_h), frame)?;
    for y in 0..b.owned_h {
        for x in 0..b.owned_w {
            let at = (b.x0 + x, b.y0 + y);
            let e = &traced.est[y * b.w + x];
            if gather.takes_part(at) && e.n > 0 {
                layer.spread(gather, &slots[y * b.w + x], e.weight(), at);
            }
        }
    }
    Ok(Some(layer))
}

/// The bucket's colours once refinement ends, from its sites' values `est`: sites keep
/// them, the owned pixels between them are interpolated from their cells, through the
/// middles of their edges too where [`estimated_middles`] finds them.
fn final_colour(est: &[Estimate], interval: &[u32], b: &Bucket) -> Vec<Vec4> {
    let (width, height) = (b.w, b.h);
    // The last cell's middles: a row's pixels in one cell come one after another.
    let mut last: Option<(Cell, Middles)> = None;
    (0..width * height)
        .map(|p| {
            let e = &est[p];
            let (x, y) = (p % width, p / width);
            if e.n > 0 || !b.owns(x, y) {
                return e.mean_rgba();
            }
            let cell = Cell::of(x, y, interval[p], width, height);
            if let Some(value) = along_edge(est, b, &cell, (x, y)) {
                return value;
            }
            let middles = match last {
                Some((c, middles)) if c == cell => middles,
                _ => estimated_middles(est, b, &cell),
            };
            last = Some((cell, middles));
            let middle = |q: usize| middles.iter().flatten().find(|m| m.0 == q).map(|m| m.1);
            let traced = |q: usize| est[q].n > 0;
            let points = cell.points(width, (x, y), cell.centre(), |q| {
                traced(q) || middle(q).is_some()
            });
            let value = blend(points, |q, _| {
                if traced(q) {
                    Some(est[q].mean_rgba())
                } else {
                    middle(q)
                }
            });
            value.expect("every corner and centre of every cell is traced before the loop ends")
        })
        .collect()
}

/// The value at (x, y) of a pixel on a lattice line (its cell a segment one pixel thick,
/// between two corners `size` apart): the parabola through the corners and the segment's
/// middle, traced or estimated from the squares either side ([`middle_between`]), as the
/// cells either side see their shared edge; clamped to the three. None when the middle is
/// neither, or the pixel is not on such a segment (the corners' line then serves).
fn along_edge(est: &[Estimate], b: &Bucket, cell: &Cell, (x, y): (usize, usize)) -> Option<Vec4> {
    let s = cell.size as usize;
    let (x0, y0) = (cell.x0 as isize, cell.y0 as isize);
    let size = cell.size as isize;
    let (across, t, middle, sides) = if cell.y0 == cell.y1 && cell.x1 == cell.x0 + s {
        let sides = ((x0, y0 - size), (x0, y0));
        (false, x - cell.x0, (cell.x0 + s / 2, cell.y0), sides)
    } else if cell.x0 == cell.x1 && cell.y1 == cell.y0 + s {
        let sides = ((x0 - size, y0), (x0, y0));
        (true, y - cell.y0, (cell.x0, cell.y0 + s / 2), sides)
    } else {
        // A cell of interval 1 is a point: never a segment.
        return None;
    };
    let v = |(px, py): (usize, usize)| est[py * b.w + px].mean_rgba();
    let m = middle.1 * b.w + middle.0;
    let mid = if est[m].n > 0 {
        v(middle)
    } else {
        let first = traced_square(est, b, sides.0, cell.size)?;
        let second = traced_square(est, b, sides.1, cell.size)?;
        middle_between(est, b.w, &first, &second, across)
    };
    let (a, c) = (v((cell.x0, cell.y0)), v((cell.x1, cell.y1)));
    // The quadratic Lagrange weights at t of nodes 0, s / 2 and s.
    let u = t as f32 / s as f32;
    let w = [
        (1.0 - u) * (1.0 - 2.0 * u),
        4.0 * u * (1.0 - u),
        u * (2.0 * u - 1.0),
    ];
    let value = a * w[0] + mid * w[1] + c * w[2];
    Some(Span::of([a, mid, c]).clamp(value))
}

/// The square of `size` pixels whose top left is (x0, y0), as a cell, when it lies in the
/// bucket's closure and its corners and centre are traced (`est`).
fn traced_square(
    est: &[Estimate],
    b: &Bucket,
    (x0, y0): (isize, isize),
    size: u32,
) -> Option<Cell> {
    let s = size as isize;
    if size < 2 || x0 < 0 || y0 < 0 || x0 + s >= b.w as isize || y0 + s >= b.h as isize {
        return None;
    }
    let (x0, y0, s) = (x0 as usize, y0 as usize, size as usize);
    let cell = Cell {
        size,
        x0,
        y0,
        x1: x0 + s,
        y1: y0 + s,
    };
    let corners = [(x0, y0), (x0 + s, y0), (x0, y0 + s), (x0 + s, y0 + s)];
    let traced = corners
        .into_iter()
        .chain(cell.centre())
        .all(|(x, y)| est[y * b.w + x].n > 0);
    traced.then_some(cell)
}

/// A cell's edges' middles as (pixel, value), left, right, top and bottom, where known.
type Middles = [Option<(usize, Vec4)>; 4];

/// The middles of `cell`'s edges that no site traced but that the square of its size across
/// the edge lets be estimated ([`middle_between`]) where its corners and centre are traced
/// too, in the bucket's closure: each as (pixel, value). Either cell estimates the same
/// value, so they still meet without a seam; at the bucket's border, where the other square
/// is not at hand, the edge stays the corners' line on both sides of it. A cell clipped by
/// the image has none.
fn estimated_middles(est: &[Estimate], b: &Bucket, cell: &Cell) -> Middles {
    let mut out = [None; 4];
    let size = cell.size;
    let (s, x0, y0) = (size as isize, cell.x0 as isize, cell.y0 as isize);
    let Some((cx, cy)) = cell.centre() else {
        return out;
    };
    if cell.x1 - cell.x0 != size as usize || cell.y1 - cell.y0 != size as usize {
        return out;
    }
    let neighbour = |dx: isize, dy: isize| traced_square(est, b, (x0 + dx * s, y0 + dy * s), size);
    // (node, the cell left of or above the edge, the one right of or below it, across).
    let edges = [
        ((cell.x0, cy), neighbour(-1, 0).map(|n| (n, *cell)), true),
        ((cell.x1, cy), neighbour(1, 0).map(|n| (*cell, n)), true),
        ((cx, cell.y0), neighbour(0, -1).map(|n| (n, *cell)), false),
        ((cx, cell.y1), neighbour(0, 1).map(|n| (*cell, n)), false),
    ];
    for (o, ((x, y), pair, across)) in out.iter_mut().zip(edges) {
        let q = y * b.w + x;
        if est[q].n == 0 {
            *o = pair.map(|(first, second)| (q, middle_between(est, b.w, &first, &second, across)));
        }
    }
    out
}

/// The middle of the edge between two squares of one size, `a` left of (`across`) or
/// above `b`: `(S1 + S2) / 8 + (ca + cb) / 2 - (F1 + F2 + F3 + F4) / 16` from the edge's
/// corners S, the cells' centres c and their far corners F, exact wherever the image is
/// quadratic over both cells (the corners' line alone is off by the curvature along the
/// edge, which the centres' departure from their corners' mean gives), clamped to the values
/// it is made of.
fn middle_between(est: &[Estimate], width: usize, a: &Cell, b: &Cell, across: bool) -> Vec4 {
    let v = |(x, y): (usize, usize)| est[y * width + x].mean_rgba();
    let (shared, far) = if across {
        (
            [(a.x1, a.y0), (a.x1, a.y1)],
            [(a.x0, a.y0), (a.x0, a.y1), (b.x1, b.y0), (b.x1, b.y1)],
        )
    } else {
        (
            [(a.x0, a.y1), (a.x1, a.y1)],
            [(a.x0, a.y0), (a.x1, a.y0), (b.x0, b.y1), (b.x1, b.y1)],
        )
    };
    let centres = [a.centre(), b.centre()].map(|c| c.expect("squares of 2 or more have centres"));
    let sum = |points: &[(usize, usize)]| points.iter().map(|&p| v(p)).sum::<Vec4>();
    let value = sum(&shared) / 8.0 + sum(&centres) / 2.0 - sum(&far) / 16.0;
    Span::of(shared.iter().chain(&centres).chain(&far).map(|&p| v(p))).clamp(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interpolation's value at (x, y) of `f` over `cell`'s nodes, unclamped.
    fn interpolated(
        cell: &Cell,
        (x, y): (usize, usize),
        known: impl Fn((usize, usize)) -> bool,
        f: impl Fn(usize, usize) -> f32,
    ) -> f32 {
        let ws = cell.weights(x, y, cell.centre(), known);
        let sum: f32 = ws.iter().map(|w| w.1).sum();
        assert!((sum - 1.0).abs() < 1e-5, "({x},{y}) sums to {sum}");
        ws.iter().map(|&((px, py), w)| f(px, py) * w).sum()
    }

    #[test]
    fn the_biquadratic_reproduces_what_its_nodes_determine() {
        // A whole cell, and one clipped by the image's border (its centre off the middle).
        for (cell, size) in [
            (Cell::of(5, 6, 8, 40, 40), 8),
            (Cell::of(33, 2, 8, 39, 40), 6),
        ] {
            let (x0, y0, x1, y1) = (cell.x0, cell.y0, cell.x1, cell.y1);
            assert_eq!(x1 - x0, size);
            let bump = |x: usize, y: usize| {
                let (x, y) = (x as f32, y as f32);
                (x - x0 as f32) * (x1 as f32 - x) * (y - y0 as f32) * (y1 as f32 - y)
            };
            // Bilinear plus the bump, from the corners and the centre alone.
            let f = |x: usize, y: usize| {
                let (xf, yf) = (x as f32, y as f32);
                0.25 * xf - 0.5 * yf + 0.03 * xf * yf + 3.0 + 0.2 * bump(x, y)
            };
            // Any biquadratic, once the edges' middles are traced too.
            let g = |x: usize, y: usize| {
                let (x, y) = (x as f32 - 30.0, y as f32 - 5.0);
                1.0 + 0.3 * x - 0.2 * y + 0.05 * x * x - 0.07 * y * y + 0.01 * x * x * y * y
            };
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let v = interpolated(&cell, (x, y), |_| false, f);
                    assert!((v - f(x, y)).abs() < 1e-3, "({x},{y}): {v} vs {}", f(x, y));
                    let v = interpolated(&cell, (x, y), |_| true, g);
                    assert!((v - g(x, y)).abs() < 1e-2, "({x},{y}): {v} vs {}", g(x, y));
                }
            }
            // On an edge only that edge's nodes count, so the neighbour meets it there.
            let (cx, _) = cell.centre().unwrap();
            for x in x0..=x1 {
                for known in [false, true] {
                    let ws = cell.weights(x, y0, cell.centre(), |_| known);
                    let on_edge =
                        |p: (usize, usize)| p == (x0, y0) || p == (x1, y0) || p == (cx, y0);
                    assert!(
                        ws.iter().all(|&(p, w)| on_edge(p) || w.abs() < 1e-6),
                        "{ws:?}"
                    );
                }
            }
        }
    }

    /// A bucket's sites on a lattice of 8 (corners and centres) with the values of `f`.
    fn lattice_of(f: impl Fn(usize, usize) -> f32) -> (Vec<Estimate>, Vec<u32>, Bucket) {
        let b = Bucket::new(0, 0, 64, 65, 65);
        let (w, h) = (b.w, b.h);
        let mut est = vec![Estimate::default(); w * h];
        for y in 0..h {
            for x in 0..w {
                let corner = x % 8 == 0 && y % 8 == 0;
                if corner || (x % 8 == 4 && y % 8 == 4) {
                    est[y * w + x].add(Vec3::splat(f(x, y)), 1.0, true);
                }
            }
        }
        (est, vec![8; w * h], b)
    }

    #[test]
    fn cells_of_one_size_reproduce_any_quadratic_between_their_sites() {
        // Rising across the bucket, so every value lies between its nodes' (the clamp's).
        let f = |x: usize, y: usize| {
            let (x, y) = (x as f32, y as f32);
            1.0 + 0.01 * x + 0.02 * y + 1e-4 * x * x + 2e-4 * x * y + 5e-5 * y * y
        };
        let (est, interval, b) = lattice_of(f);
        let colour = final_colour(&est, &interval, &b);
        // Away from the bucket's border (where edges keep the corners' line), exactly: the
        // edges' middles are estimated from the cells either side, inside and along them.
        let mut worst = 0.0f32;
        for y in 8..=56 {
            for x in 8..=56 {
                worst = worst.max((colour[y * b.w + x].x - f(x, y)).abs());
            }
        }
        assert!(worst < 1e-4, "{worst}");
        // At the border's cells the edge's middle is not at hand: the corners' line there.
        let (x, y) = (2, 4);
        let line = f(0, 0) + (f(0, 8) - f(0, 0)) * 0.5;
        let off = (colour[4 * b.w].x - line).abs();
        assert!(off < 1e-5, "{off}");
        assert!((colour[y * b.w + x].x - f(x, y)).abs() > 1e-5);
    }

    #[test]
    fn an_edge_middle_is_the_same_seen_from_either_side() {
        let f = |x: usize, y: usize| ((x * 7 + y * 13) % 11) as f32;
        let (est, _, b) = lattice_of(f);
        let square = |x0, y0| traced_square(&est, &b, (x0, y0), 8).unwrap();
        let (left, right, below) = (square(8, 8), square(16, 8), square(8, 16));
        let across = middle_between(&est, b.w, &left, &right, true);
        let down = middle_between(&est, b.w, &left, &below, false);
        // From the right cell's side its left edge, from the left cell's its right edge; from
        // the lower cell's its top edge, from the upper cell's its bottom edge.
        let (vertical, horizontal) = ((12 * b.w + 16, across), (16 * b.w + 12, down));
        for (cell, side, middle) in [
            (right, 0, vertical),
            (left, 1, vertical),
            (below, 2, horizontal),
            (left, 3, horizontal),
        ] {
            assert_eq!(estimated_middles(&est, &b, &cell)[side], Some(middle));
        }
        // A pixel on that edge follows the same parabola.
        let on_edge = Cell::of(16, 13, 8, b.w, b.h);
        let v = along_edge(&est, &b, &on_edge, (16, 12)).unwrap();
        assert_eq!(v, across);
        // Its values stay within the values it is made of.
        let lo = (0..b.w * b.h)
            .filter(|&p| est[p].n > 0)
            .map(|p| est[p].mean_rgba().x);
        assert!(lo.fold(f32::INFINITY, f32::min) <= across.x.min(down.x));
        assert!(across.x.max(down.x) <= 10.0);
    }

    #[test]
    fn the_interpolation_never_leaves_the_values_it_blends() {
        // One bright corner on black: the far corner's weight is negative, and unclamped
        // the far quarter of the cell would go below zero.
        let cell = Cell::of(1, 1, 8, 40, 40);
        let bright = |x: usize, y: usize| if (x, y) == (0, 0) { 100.0 } else { 0.0 };
        let raw = interpolated(&cell, (6, 6), |_| false, bright);
        assert!(raw < 0.0, "{raw}");
        let width = 40;
        for y in 0..=8 {
            for x in 0..=8 {
                let points = cell.points(width, (x, y), cell.centre(), |_| false);
                let value = blend(points, |p, _| {
                    Some(Vec4::splat(bright(p % width, p / width)))
                })
                .unwrap();
                assert!((0.0..=100.0).contains(&value.x), "({x},{y}): {value}");
            }
        }
        // A point it needs that is not traced gives nothing.
        let points = cell.points(width, (3, 3), cell.centre(), |_| false);
        assert_eq!(blend(points, |p, _| (p != 0).then_some(Vec4::ONE)), None);
    }

    #[test]
    fn start_intervals_shrink_with_the_tolerance() {
        assert_eq!(start_k(1.0), START_K);
        assert!(start_k(0.25) < start_k(1.0) && start_k(1.0) < start_k(4.0));
        assert_eq!(start_k(1e-6), 0.25);
        assert_eq!(start_k(1e6), 1.0);
    }

    #[test]
    fn cells_at_the_border_are_clipped_and_split() {
        let (w, h) = (10, 5);
        let cell = Cell::of(9, 4, 8, w, h);
        assert_eq!((cell.x0, cell.y0, cell.x1, cell.y1), (8, 0, 9, 4));
        assert_eq!(cell.centre(), None); // one pixel across
        let mut interval = vec![8u32; w * h];
        interval[0] = 4; // a finer pixel inside the same square keeps its interval
        let mut need = vec![false; w * h];
        let mut pending = Vec::new();
        let bucket = Bucket::new(0, 0, 64, w, h);
        let new_cells = split(
            &mut interval,
            &mut need,
            &mut pending,
            &[(Cell::of(1, 1, 8, w, h), 4)],
            &bucket,
        );
        assert!(
            new_cells.contains(&Cell::of(5, 1, 4, w, h)),
            "{new_cells:?}"
        );
        assert_eq!(pending.len(), need.iter().filter(|&&n| n).count());
        assert_eq!(interval[0], 4);
        assert!(interval[1..8].iter().all(|&i| i == 4));
        assert_eq!(interval[8], 8, "the next cell is untouched");
        // The new cells' corners (x = 4, 8 on rows 0 and 4) and centres are needed.
        for (x, y) in [(4, 0), (8, 0), (4, 4), (8, 4), (6, 2)] {
            assert!(need[y * w + x], "({x},{y})");
        }
    }
}
