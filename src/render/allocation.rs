//! How many samples an in-focus path-traced site takes: in proportion to its noise.
//!
//! In focus, nothing is interpolated: every pixel is a site and its error is its own noise,
//! sigma^2 / n for a per-sample standard deviation sigma. With a budget of samples, the
//! squared error summed over the image is least when n is proportional to sigma (a flat wall
//! in light needs fewer than a glossy floor in shadow), and the gain over giving every pixel
//! the same n is mean(sigma^2) / mean(sigma)^2 at equal error.
//!
//! - **The scale** is frame-wide: a pilot traces a sparse grid of points and sets the noise
//!   `sigma_ref` that takes `spp` samples: the largest whose expected squared error over the
//!   pilot's points is within [`ERROR_ALLOWANCE`] of `spp` samples everywhere. Pixels
//!   noisier than that take `spp` (no more: `spp` stays each pixel's most), quieter ones
//!   `spp * sigma / sigma_ref`, never fewer than the site's first samples.
//! - **Each site's sigma** is pooled from its eight neighbours' first samples (never its
//!   own: a site whose own samples decided how many it takes would be biased, fewer where
//!   its first samples happened to miss a rare bright path). The pilot pools the same way.
//!
//! The pilot's points lie on a grid fixed by the frame's size, so a region renders the same
//! pixels as the whole frame; its cost is about one sample per pixel of a small frame and
//! vanishes on large ones (at most [`PILOT_POINTS`] points of 8 pixels).

use rayon::prelude::*;

use super::Tally;
use super::estimate::{Estimate, code};
use super::site::{SiteScratch, SiteShader};

/// About how many points the pilot traces, whatever the frame's size.
pub const PILOT_POINTS: usize = 500;
/// How much more squared error than `spp` samples everywhere the allocation may expect on the
/// pilot's points (5%: 0.2 dB), in exchange for the samples it saves; the error is only
/// expected, as the pilot's noise is only estimated.
pub const ERROR_ALLOWANCE: f64 = 0.05;
/// The pilot's grid is never finer than this (pixels).
const MIN_STRIDE: usize = 8;

/// One sample's standard deviation, in code values at the noise a mean of `spp` such samples
/// has: `(code(y + s / sqrt(spp)) - code(y)) * sqrt(spp)` for the per-sample deviation `s`
/// of luminance, or 255 times the coverage's with `alpha`, whichever is larger. None with
/// fewer than two samples.
pub fn sample_noise(e: &Estimate, spp: u32, alpha: bool) -> Option<f32> {
    let n_eff = e.effective_samples();
    let se = e.std_error();
    if !se.is_finite() || n_eff <= 0.0 {
        return None;
    }
    let root = (spp.max(1) as f32).sqrt();
    let y = super::estimate::luminance(e.mean()).max(0.0);
    let s = se * n_eff.sqrt();
    let mut sigma = (code(y + s / root) - code(y)) * root;
    if alpha {
        sigma = sigma.max(e.coverage_error_code() * n_eff.sqrt());
    }
    sigma.is_finite().then_some(sigma)
}

/// The root mean square of `sigmas` (None when empty): the noise of a pool of samples.
fn pooled(sigmas: impl Iterator<Item = f32>) -> Option<f32> {
    let (mut sum, mut count) = (0.0f64, 0u32);
    for s in sigmas {
        sum += f64::from(s) * f64::from(s);
        count += 1;
    }
    (count > 0).then(|| (sum / f64::from(count)).sqrt() as f32)
}

/// The pooled noise of pixel `p`'s in-focus neighbours (the 3 x 3 square around it, less
/// itself) in a `width` x `height` window of `noise` (None: not traced, or blurred).
pub fn neighbours_noise(
    noise: &[Option<f32>],
    p: usize,
    width: usize,
    height: usize,
) -> Option<f32> {
    let (x, y) = ((p % width) as isize, (p / width) as isize);
    let ring = (-1..=1isize)
        .flat_map(|dy| (-1..=1isize).map(move |dx| (dx, dy)))
        .filter(|&d| d != (0, 0));
    pooled(ring.filter_map(|(dx, dy)| {
        let (qx, qy) = (x + dx, y + dy);
        if qx < 0 || qy < 0 || qx >= width as isize || qy >= height as isize {
            return None;
        }
        noise[qy as usize * width + qx as usize]
    }))
}

/// The in-focus sample budget: how many samples a site of a given pooled noise takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FocusBudget {
    /// The most a site takes (the render's `spp`).
    pub spp: u32,
    /// The noise that takes `spp` samples (code values); 0 when nothing in focus was noisy
    /// (every site then keeps its first samples).
    pub sigma_ref: f32,
}

impl FocusBudget {
    /// The budget for sites that start with `first` samples and take at most `most`, from
    /// `sigmas`, the pilot's pooled noises: the fewest samples whose expected squared error
    /// over the pilot's points stays within [`ERROR_ALLOWANCE`] of `most` samples each (None
    /// without any point).
    pub fn from_pilot(sigmas: &[f32], most: u32, first: u32) -> Option<Self> {
        if sigmas.is_empty() {
            return None;
        }
        let n = sigmas.len() as f64;
        let squared_error = |b: &Self| {
            let sum: f64 = sigmas
                .iter()
                .map(|&s| f64::from(s).powi(2) / f64::from(b.target(Some(s), first)))
                .sum();
            sum / n
        };
        let dense = sigmas.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / n / f64::from(most);
        let top = sigmas.iter().copied().fold(0.0f32, f32::max);
        let at = |sigma_ref: f32| Self {
            spp: most,
            sigma_ref,
        };
        // Past `hi` every site keeps its first samples; the error grows with sigma_ref.
        let (mut lo, mut hi) = (0.0f32, top * most as f32 / first.max(1) as f32);
        let allowed = dense * (1.0 + ERROR_ALLOWANCE);
        if hi.is_nan() || hi <= 0.0 || squared_error(&at(hi)) <= allowed {
            return Some(at(hi.max(0.0)));
        }
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if squared_error(&at(mid)) <= allowed {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(at(lo))
    }

    /// The samples a site whose neighbours pooled `sigma` takes, at least `first` (its first
    /// samples) and at most `spp`; `spp` when its neighbours are unknown.
    pub fn target(&self, sigma: Option<f32>, first: u32) -> u32 {
        let Some(sigma) = sigma else {
            return self.spp;
        };
        if self.sigma_ref.is_nan() || self.sigma_ref <= 0.0 {
            return first.min(self.spp);
        }
        let n = (self.spp as f32 * sigma / self.sigma_ref).ceil();
        (n.min(self.spp as f32) as u32).max(first).min(self.spp)
    }
}

/// A window's sites' sample budgets: each site's first samples and most, where the site
/// takes samples by its noise lowered by its neighbours' noise once their first samples are
/// in.
pub struct Allotment {
    /// Samples each site starts with.
    pub first: Vec<u32>,
    /// The most each site takes.
    pub most: Vec<u32>,
    /// Whether the site takes samples by its noise, and whether its budget is settled.
    by_noise: Vec<bool>,
    settled: Vec<bool>,
    /// The by-noise sites' noise from their first samples ([`sample_noise`]).
    noise: Vec<Option<f32>>,
    budget: Option<FocusBudget>,
    alpha: bool,
    width: usize,
    height: usize,
}

impl Allotment {
    /// For a `width` x `height` window: each site's `first` and `most` samples as fixed
    /// rules give them, and `by_noise` where `budget` decides instead (starting at
    /// `first_by_noise`); `alpha` counts the coverage's noise too.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mut first: Vec<u32>,
        most: Vec<u32>,
        by_noise: Vec<bool>,
        first_by_noise: u32,
        budget: Option<FocusBudget>,
        alpha: bool,
        (width, height): (usize, usize),
    ) -> Self {
        let by_noise: Vec<bool> = by_noise.iter().map(|&b| b && budget.is_some()).collect();
        for (f, _) in first.iter_mut().zip(&by_noise).filter(|(_, b)| **b) {
            *f = first_by_noise;
        }
        let n = width * height;
        Self {
            first,
            most,
            by_noise,
            settled: vec![false; n],
            noise: vec![None; n],
            budget,
            alpha,
            width,
            height,
        }
    }

    /// Settles the budgets of the sites in `pending` that have their first samples, from
    /// their neighbours' noise recorded so far.
    pub fn settle(&mut self, pending: &[usize], est: &[Estimate]) {
        let Some(budget) = self.budget else { return };
        for &p in pending {
            if self.by_noise[p] && !self.settled[p] && est[p].n > 0 {
                let sigma = neighbours_noise(&self.noise, p, self.width, self.height);
                self.most[p] = budget.target(sigma, self.first[p]).min(self.most[p]);
                self.settled[p] = true;
            }
        }
    }

    /// Records the noise of the sites in `shaded` that took their first samples.
    pub fn record(&mut self, shaded: &[usize], est: &[Estimate]) {
        let Some(budget) = self.budget else { return };
        for &p in shaded {
            if self.by_noise[p] && !self.settled[p] {
                self.noise[p] = sample_noise(&est[p], budget.spp, self.alpha);
            }
        }
    }
}

/// The pilot's points in a `width` x `height` frame: a grid of stride chosen for about
/// [`PILOT_POINTS`] points, each with its 3 x 3 square inside the frame.
fn pilot_points(width: usize, height: usize) -> Vec<(usize, usize)> {
    let area = (width * height) as f64;
    let stride = ((area / PILOT_POINTS as f64).sqrt() as usize).max(MIN_STRIDE);
    let start = stride / 2;
    let along = |n: usize| {
        (start..n.saturating_sub(1))
            .step_by(stride)
            .filter(|&c| c >= 1)
    };
    along(height)
        .flat_map(|y| along(width).map(move |x| (x, y)))
        .collect()
}

/// Traces the pilot: for every grid point whose 3 x 3 square takes samples by noise
/// (`by_noise`, frame wide), its eight neighbours' first `first` samples, and returns the
/// budget of at most `most` samples from their pooled noise (None without such a point). The
/// samples are those the sites take first, so the pilot repeats work rather than changing any
/// pixel's samples.
pub fn pilot(
    shader: &SiteShader,
    by_noise: &[bool],
    first: u32,
    most: u32,
    tally: &mut Tally,
) -> Option<FocusBudget> {
    let s = shader.settings;
    let (width, height) = (shader.camera.width as usize, shader.camera.height as usize);
    let points: Vec<(usize, usize)> = pilot_points(width, height)
        .into_iter()
        .filter(|&(x, y)| {
            (y - 1..=y + 1).all(|qy| {
                by_noise[qy * width + x - 1..=qy * width + x + 1]
                    .iter()
                    .all(|&f| f)
            })
        })
        .collect();
    let traced: Vec<(Option<f32>, Tally)> = points
        .par_iter()
        .map_init(SiteScratch::new, |scratch, &(x, y)| {
            let mut local = Tally::new(s.record_rays);
            let mut noise = [None; 9];
            for dy in 0..3 {
                let mut row = [Estimate::default(); 3];
                let to = [first, if dy == 1 { 0 } else { first }, first];
                shader.shade_row(
                    (x - 1, y + dy - 1),
                    &[0; 3],
                    &to,
                    &mut row,
                    None,
                    None,
                    scratch,
                    &mut local,
                );
                for (dx, e) in row.iter().enumerate() {
                    noise[dy * 3 + dx] = sample_noise(e, most, s.transparent);
                }
            }
            (neighbours_noise(&noise, 4, 3, 3), local)
        })
        .collect();
    let mut sigmas = Vec::with_capacity(traced.len());
    for (sigma, local) in traced {
        sigmas.extend(sigma);
        tally.merge(local);
    }
    FocusBudget::from_pilot(&sigmas, most, first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_proportional_targets_between_first_and_spp() {
        let b = FocusBudget {
            spp: 64,
            sigma_ref: 5.0 / 3.0,
        };
        assert_eq!(b.target(Some(2.0), 16), 64, "noisier than sigma_ref: spp");
        assert_eq!(b.target(Some(1.0), 16), 39, "ceil(64 * 0.6)");
        assert_eq!(
            b.target(Some(0.1), 16),
            16,
            "never fewer than the first samples"
        );
        assert_eq!(b.target(None, 16), 64, "unknown neighbours: spp");
        let quiet = FocusBudget {
            spp: 64,
            sigma_ref: 0.0,
        };
        assert_eq!(quiet.target(Some(0.0), 16), 16);
    }

    #[test]
    fn the_pilot_scale_keeps_the_expected_error_within_the_allowance() {
        // One noisy point in ten: the quiet ones give up samples, within the allowance.
        let mut sigmas = vec![1.0f32; 9];
        sigmas.push(10.0);
        let b = FocusBudget::from_pilot(&sigmas, 64, 16).unwrap();
        let dense: f64 = sigmas.iter().map(|&s| f64::from(s * s) / 64.0).sum();
        let ours: f64 = (sigmas.iter())
            .map(|&s| f64::from(s * s) / f64::from(b.target(Some(s), 16)))
            .sum();
        assert!(
            ours <= dense * (1.0 + ERROR_ALLOWANCE) + 1e-9,
            "{ours} vs {dense}"
        );
        assert!(
            ours >= dense * (1.0 + 0.9 * ERROR_ALLOWANCE),
            "it spends the allowance"
        );
        assert_eq!(b.target(Some(10.0), 16), 64);
        assert!(b.target(Some(1.0), 16) < 64);
        // Equal noise everywhere: nothing to move, every site keeps (nearly) `spp`.
        let flat = FocusBudget::from_pilot(&[3.0; 20], 64, 16).unwrap();
        assert!(flat.target(Some(3.0), 16) >= 60);
        // No noise anywhere: the first samples suffice.
        let quiet = FocusBudget::from_pilot(&[0.0; 5], 64, 16).unwrap();
        assert_eq!(quiet.target(Some(0.0), 16), 16);
        assert!(FocusBudget::from_pilot(&[], 64, 16).is_none());
    }

    #[test]
    fn neighbours_pool_without_the_pixel_itself() {
        let mut noise = vec![Some(3.0); 9];
        noise[4] = Some(1000.0);
        noise[0] = None;
        assert_eq!(neighbours_noise(&noise, 4, 3, 3), Some(3.0));
        // A corner sees three neighbours: (1, 0) = 3, (0, 1) = 3, (1, 1) = 1000.
        let corner = neighbours_noise(&noise, 0, 3, 3).unwrap();
        let expected = ((9.0 + 9.0 + 1e6) / 3.0f32).sqrt();
        assert!((corner - expected).abs() < 1e-2);
        assert_eq!(neighbours_noise(&[None; 4], 0, 2, 2), None);
    }

    #[test]
    fn pilot_grid_is_sparse_inside_the_frame_and_at_least_8_apart() {
        for (w, h) in [(3, 3), (10, 7), (320, 240), (1920, 1080)] {
            let pts = pilot_points(w, h);
            assert!(pts.len() <= 2 * PILOT_POINTS, "{w}x{h}: {}", pts.len());
            for &(x, y) in &pts {
                assert!(
                    x >= 1 && y >= 1 && x + 1 < w && y + 1 < h,
                    "{w}x{h}: ({x}, {y})"
                );
            }
            if w >= 320 {
                assert!(pts.len() >= PILOT_POINTS / 2, "{w}x{h}: {}", pts.len());
            }
        }
        assert!(pilot_points(2, 2).is_empty());
    }

    #[test]
    fn sample_noise_scales_like_a_standard_deviation() {
        let mut e = Estimate::default();
        assert_eq!(sample_noise(&e, 64, false), None);
        for i in 0..64 {
            let v = if i % 2 == 0 { 0.4 } else { 0.6 };
            e.add(glam::Vec3::splat(v), 1.0, true);
        }
        // Per-sample deviation 0.1 (x sqrt(64/63)); at 64 spp it moves code(0.5) by about
        // code'(0.5) * 0.1 / 8, times 8.
        let sigma = sample_noise(&e, 64, false).unwrap();
        let slope = (code(0.5 + 1e-3) - code(0.5 - 1e-3)) / 2e-3;
        assert!(
            (sigma / (slope * 0.1) - 1.0).abs() < 0.03,
            "{sigma} vs {}",
            slope * 0.1
        );
    }
}
