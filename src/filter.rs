//! The pixel (reconstruction) filter: how much each film position around a pixel's centre
//! counts towards that pixel.
//!
//! dofray samples the filter instead of weighting by it (filter importance sampling): a sample's
//! offset from the pixel centre is drawn with density proportional to the filter, so every
//! sample weighs the same and a pixel is the plain mean of its own samples. Nothing is splatted
//! to neighbours, so pixels stay independent and images bit-identical for any thread count.
//! The filters are separable (a product of the same 1D profile in x and y) and non-negative,
//! so sampling them is exact: the estimate converges to the filtered image itself.

/// The shape of the pixel filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum PixelFilterKind {
    /// Every position within the width counts equally (width 1: exactly the pixel's square).
    Box,
    /// A Gaussian with standard deviation width / 6, cut off at +-width / 2.
    Gaussian,
    /// The 4-term Blackman-Harris window over the width: nearly as sharp as a box, without its
    /// aliasing (the default, as in Blender's Cycles).
    #[default]
    BlackmanHarris,
}

/// A pixel filter: its shape and its full width (support) in pixels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PixelFilter {
    /// The filter's shape.
    pub kind: PixelFilterKind,
    /// Full width of the support in pixels: samples land within +-width / 2 of the centre.
    pub width: f32,
}

impl Default for PixelFilter {
    fn default() -> Self {
        Self::new(PixelFilterKind::BlackmanHarris)
    }
}

impl PixelFilter {
    /// The largest width accepted, in pixels.
    pub const MAX_WIDTH: f32 = 16.0;

    /// The filter of `kind` at its usual width: 1 px for the box, 3 px for the smooth ones.
    pub fn new(kind: PixelFilterKind) -> Self {
        let width = match kind {
            PixelFilterKind::Box => 1.0,
            PixelFilterKind::Gaussian | PixelFilterKind::BlackmanHarris => 3.0,
        };
        Self { kind, width }
    }

    /// Whether the width is a finite number in (0, [`PixelFilter::MAX_WIDTH`]].
    pub fn is_valid(&self) -> bool {
        self.width.is_finite() && self.width > 0.0 && self.width <= Self::MAX_WIDTH
    }

    /// The 1D profile at `x` in [-1/2, 1/2] (in units of the width); not normalised.
    pub fn profile(&self, x: f32) -> f32 {
        if x.abs() > 0.5 {
            return 0.0;
        }
        match self.kind {
            PixelFilterKind::Box => 1.0,
            // sigma = width / 6: x (in widths) over 1/6.
            PixelFilterKind::Gaussian => (-0.5 * (6.0 * x).powi(2)).exp(),
            PixelFilterKind::BlackmanHarris => {
                let a = std::f32::consts::TAU * (x + 0.5);
                0.35875 - 0.48829 * a.cos() + 0.14128 * (2.0 * a).cos() - 0.01168 * (3.0 * a).cos()
            }
        }
    }

    /// The density of the film offsets [`FilterSampler::offset`] draws (what splatting weighs
    /// by; computed once, share it).
    pub fn density(&self) -> FilterDensity {
        FilterDensity {
            filter: *self,
            scale: 1.0 / (self.width * self.profile_area()),
        }
    }

    /// The integral of [`PixelFilter::profile`] over [-1/2, 1/2] (midpoint rule, 4096 steps:
    /// exact for the box, within 1e-6 for the smooth profiles).
    fn profile_area(&self) -> f32 {
        const STEPS: usize = 4096;
        let sum: f64 = (0..STEPS)
            .map(|i| f64::from(self.profile(((i as f64 + 0.5) / STEPS as f64 - 0.5) as f32)))
            .sum();
        (sum / STEPS as f64) as f32
    }

    /// The sampler for this filter (tabulated once; share it between threads).
    pub fn sampler(&self) -> FilterSampler {
        // The CDF of the profile over [-1/2, 1/2] at CDF_TABLE + 1 points (midpoint rule on 16
        // steps per entry), normalised to end at 1.
        const STEPS: usize = 16;
        let mut cdf = vec![0.0f64; CDF_TABLE + 1];
        for i in 0..CDF_TABLE {
            let mut area = 0.0f64;
            for j in 0..STEPS {
                let x = (i as f64 + (j as f64 + 0.5) / STEPS as f64) / CDF_TABLE as f64 - 0.5;
                area += f64::from(self.profile(x as f32));
            }
            cdf[i + 1] = cdf[i] + area;
        }
        let total = cdf[CDF_TABLE];
        // Its inverse at INVERSE_TABLE + 1 evenly spaced probabilities, so that drawing an
        // offset is one lookup and one interpolation (no search per sample).
        let inverse = (0..=INVERSE_TABLE)
            .map(|k| {
                let u = k as f64 / INVERSE_TABLE as f64 * total;
                let bin = cdf.partition_point(|&c| c <= u).clamp(1, CDF_TABLE) - 1;
                let (lo, hi) = (cdf[bin], cdf[bin + 1]);
                let frac = if hi > lo {
                    ((u - lo) / (hi - lo)).min(1.0)
                } else {
                    0.5
                };
                ((bin as f64 + frac) / CDF_TABLE as f64 - 0.5) as f32 * self.width
            })
            .collect();
        FilterSampler::new(inverse)
    }
}

/// The density (per pixel, along one axis) of a [`PixelFilter`]'s film offsets: its profile
/// normalised to integrate to 1 over the support. A pixel's value is the film's radiance
/// weighted by the product of this in x and y, so light landing on the film at offset
/// (dx, dy) from a pixel's centre counts towards it with `at(dx) * at(dy)`.
#[derive(Debug, Clone, Copy)]
pub struct FilterDensity {
    filter: PixelFilter,
    scale: f32,
}

impl FilterDensity {
    /// The density at offset `d` pixels from the centre (0 beyond half the width).
    #[inline]
    pub fn at(&self, d: f32) -> f32 {
        self.filter.profile(d / self.filter.width) * self.scale
    }

    /// Half the filter's width: the farthest offset that counts.
    pub fn reach(&self) -> f32 {
        0.5 * self.filter.width
    }
}

/// Entries of the tabulated CDF.
const CDF_TABLE: usize = 1024;
/// Entries of the tabulated inverse CDF.
const INVERSE_TABLE: usize = 1024;

/// Cells of [`FilterSampler::density`]'s index over the support.
const DENSITY_CELLS: usize = 4096;

/// Draws sample offsets from a [`PixelFilter`] by its tabulated inverse CDF.
#[derive(Debug, Clone)]
pub struct FilterSampler {
    /// Offsets in pixels at probabilities k / INVERSE_TABLE, k = 0..=INVERSE_TABLE.
    inverse: Vec<f32>,
    /// For each of [`DENSITY_CELLS`] even cells of the support, the interval of `inverse`
    /// that holds the cell's start: where [`FilterSampler::density`] starts looking, a step
    /// or two from the answer (gathering evaluates it ten times a sample).
    cells: Vec<u16>,
    /// Cells per pixel of offset.
    per_px: f32,
}

impl FilterSampler {
    /// The sampler of the inverse CDF table `inverse` (INVERSE_TABLE + 1 sorted offsets).
    fn new(inverse: Vec<f32>) -> Self {
        let (lo, hi) = (inverse[0], inverse[INVERSE_TABLE]);
        let per_px = if hi > lo {
            DENSITY_CELLS as f32 / (hi - lo)
        } else {
            0.0
        };
        let mut k = 0;
        let cells = (0..DENSITY_CELLS)
            .map(|c| {
                let start = lo + c as f32 / per_px;
                while k + 1 < INVERSE_TABLE && inverse[k + 1] <= start {
                    k += 1;
                }
                k as u16
            })
            .collect();
        Self {
            inverse,
            cells,
            per_px,
        }
    }

    /// The offset from the pixel centre, in pixels, for a uniform number `u` in [0, 1): its
    /// density is the filter's 1D profile (to the resolution of a 1024-entry table; exact for
    /// the box).
    #[inline]
    pub fn offset(&self, u: f32) -> f32 {
        let x = u.clamp(0.0, 1.0) * INVERSE_TABLE as f32;
        let i = (x as usize).min(INVERSE_TABLE - 1);
        let (lo, hi) = (self.inverse[i], self.inverse[i + 1]);
        lo + (hi - lo) * (x - i as f32)
    }

    /// The density of [`FilterSampler::offset`]'s draws at offset `d` (pixels): exactly the
    /// table's (each of its intervals holds 1 / INVERSE_TABLE of them, evenly), which a
    /// weight must use to cancel the density it was drawn with; 0 outside the support.
    pub fn density(&self, d: f32) -> f32 {
        let inv = &self.inverse;
        if !(d >= inv[0] && d < inv[INVERSE_TABLE]) {
            return 0.0;
        }
        // The last entry at or below d (at most INVERSE_TABLE - 1, as d < inv[INVERSE_TABLE]),
        // found from its cell's start: exactly what a binary search over the table gives.
        let cell = (((d - inv[0]) * self.per_px) as usize).min(DENSITY_CELLS - 1);
        let mut k = usize::from(self.cells[cell]);
        while k > 0 && inv[k] > d {
            k -= 1;
        }
        while k + 1 < INVERSE_TABLE && inv[k + 1] <= d {
            k += 1;
        }
        let span = inv[k + 1] - inv[k];
        if span > 0.0 {
            1.0 / (INVERSE_TABLE as f32 * span)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Offsets of evenly spread u have the filter's own distribution: their histogram matches
    /// the normalised profile, and they stay within the support.
    /// The density splats weigh by is the offsets' own: it integrates to 1 over the support,
    /// and the mass it gives a bin is the share of offsets that land there.
    #[test]
    fn the_density_is_the_offsets_distribution() {
        for kind in [
            PixelFilterKind::Box,
            PixelFilterKind::Gaussian,
            PixelFilterKind::BlackmanHarris,
        ] {
            let filter = PixelFilter::new(kind);
            let (density, sampler) = (filter.density(), filter.sampler());
            assert_eq!(density.reach(), filter.width / 2.0);
            assert_eq!(density.at(filter.width), 0.0);
            let steps = 3000;
            let dx = filter.width / steps as f32;
            let integral: f32 = (0..steps)
                .map(|i| density.at((i as f32 + 0.5) * dx - filter.width / 2.0) * dx)
                .sum();
            assert!((integral - 1.0).abs() < 1e-3, "{kind:?}: {integral}");
            // Mass within +-width / 6 of the centre, both ways.
            let third: f32 = (0..steps)
                .map(|i| (i as f32 + 0.5) * dx - filter.width / 2.0)
                .filter(|x| x.abs() < filter.width / 6.0)
                .map(|x| density.at(x) * dx)
                .sum();
            let n = 100_000;
            let share = (0..n)
                .filter(|&i| sampler.offset((i as f32 + 0.5) / n as f32).abs() < filter.width / 6.0)
                .count() as f32
                / n as f32;
            assert!((third - share).abs() < 2e-3, "{kind:?}: {third} vs {share}");
        }
    }

    /// The indexed lookup finds the interval a binary search over the table finds, on and
    /// next to every entry and between them.
    #[test]
    fn the_density_lookup_is_the_tables() {
        let searched = |s: &FilterSampler, d: f32| {
            let inv = &s.inverse;
            if !(d >= inv[0] && d < inv[INVERSE_TABLE]) {
                return 0.0;
            }
            let k = inv.partition_point(|&x| x <= d).clamp(1, INVERSE_TABLE) - 1;
            let span = inv[k + 1] - inv[k];
            if span > 0.0 {
                1.0 / (INVERSE_TABLE as f32 * span)
            } else {
                0.0
            }
        };
        for kind in [
            PixelFilterKind::Box,
            PixelFilterKind::Gaussian,
            PixelFilterKind::BlackmanHarris,
        ] {
            for width in [1.0, 2.0, 3.0] {
                let s = PixelFilter { kind, width }.sampler();
                let mut ds: Vec<f32> = Vec::new();
                for &x in &s.inverse {
                    let bits = x.to_bits();
                    ds.extend([x, f32::from_bits(bits.wrapping_add(1))]);
                    ds.push(f32::from_bits(bits.wrapping_sub(1)));
                    ds.extend([-x, x * 0.999_9]);
                }
                ds.extend((0..20_000).map(|i| (i as f32 / 20_000.0 - 0.5) * 1.1 * width));
                for d in ds {
                    let (got, want) = (s.density(d), searched(&s, d));
                    assert_eq!(got.to_bits(), want.to_bits(), "{kind:?} {width} at {d}");
                }
            }
        }
    }

    #[test]
    fn offsets_follow_the_filter_and_stay_in_its_support() {
        for kind in [
            PixelFilterKind::Box,
            PixelFilterKind::Gaussian,
            PixelFilterKind::BlackmanHarris,
        ] {
            let filter = PixelFilter::new(kind);
            let sampler = filter.sampler();
            let n = 200_000;
            let bins = 30;
            let mut hist = vec![0usize; bins];
            for i in 0..n {
                let x = sampler.offset((i as f32 + 0.5) / n as f32);
                assert!(x.abs() <= filter.width / 2.0, "{kind:?}: {x}");
                let b = ((x / filter.width + 0.5) * bins as f32) as usize;
                hist[b.min(bins - 1)] += 1;
            }
            let profile: Vec<f64> = (0..bins)
                .map(|b| f64::from(filter.profile((b as f32 + 0.5) / bins as f32 - 0.5)))
                .collect();
            let total: f64 = profile.iter().sum();
            for b in 0..bins {
                let want = profile[b] / total;
                let got = hist[b] as f64 / n as f64;
                assert!(
                    (got - want).abs() < 0.004 + 0.03 * want,
                    "{kind:?} bin {b}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn smooth_filters_concentrate_near_the_centre_and_are_symmetric() {
        let bh = PixelFilter::default().sampler();
        assert!(bh.offset(0.5).abs() < 1e-3);
        assert!((bh.offset(0.2) + bh.offset(0.8)).abs() < 1e-3);
        // Half the samples of a 3 px Blackman-Harris fall within about +-0.28 px.
        assert!(
            bh.offset(0.75) < 0.35 && bh.offset(0.75) > 0.2,
            "{}",
            bh.offset(0.75)
        );
        let boxf = PixelFilter::new(PixelFilterKind::Box).sampler();
        assert!((boxf.offset(0.25) + 0.25).abs() < 1e-6);
    }
}
