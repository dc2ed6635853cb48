//! A site's running estimate: the lens-filter-weighted mean of its samples and how uncertain
//! that mean still is. The error-controlled rule ([`super::refine`]) compares the uncertainty
//! with its tolerance to decide whether a site needs more samples and whether a difference
//! between a traced pixel and its interpolation is real or noise.

use glam::{Vec3, Vec4};

/// Weighted sums over the samples of one pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Estimate {
    /// Samples taken.
    pub n: u32,
    sum: Vec3,
    /// Weight of the samples whose camera ray hit geometry (for the coverage).
    hit_w: f32,
    /// Weight of the samples the lens blocked (no light; not part of the coverage).
    blocked_w: f32,
    w: f32,
    w2: f32,
    /// Weighted first and second moments of luminance (f64: 65536 samples of bright
    /// highlights would lose the variance to cancellation in f32).
    wy: f64,
    wy2: f64,
    /// The brightest sample's luminance.
    peak: f32,
    /// The variance of a part of the mean estimated apart ([`Estimate::plus`]), luminance.
    apart: f64,
}

pub use crate::shade::luminance;

/// Linear radiance to 8-bit sRGB code values (0 to 255 for 0 to 1), without clamping above 1:
/// the same power law continues, so differences in highlights still count, scaled the way a
/// display-referred comparison after an exposure change would see them.
pub fn code(v: f32) -> f32 {
    255.0 * crate::metrics::srgb_curve(v.max(0.0))
}

/// A colour in code values, per channel.
pub fn code3(c: Vec3) -> Vec3 {
    Vec3::new(code(c.x), code(c.y), code(c.z))
}

impl Estimate {
    /// Adds one sample of radiance `l` with lens-filter weight `w`; `hit` says whether its
    /// camera ray hit geometry.
    pub fn add(&mut self, l: Vec3, w: f32, hit: bool) {
        self.add_lit(l, f64::from(luminance(l)), w, hit);
    }

    /// [`Estimate::add`] for a sample whose luminance `y` is already known (one sample lent
    /// to many sites is added to each).
    pub fn add_lit(&mut self, l: Vec3, y: f64, w: f32, hit: bool) {
        self.n += 1;
        self.sum += l * w;
        if hit {
            self.hit_w += w;
        }
        self.w += w;
        self.w2 += w * w;
        self.wy += f64::from(w) * y;
        self.wy2 += f64::from(w) * y * y;
        self.peak = self.peak.max(y as f32);
    }

    /// The estimate of this one's samples and `other`'s together, as if each of `other`'s
    /// had been added to this one (up to rounding): a pixel's samples summed in parts.
    /// Neither may have had a part estimated apart ([`Estimate::plus`]) added yet.
    pub fn merge(&mut self, other: &Self) {
        debug_assert!(
            self.apart == 0.0 && other.apart == 0.0,
            "merged before plus"
        );
        self.n += other.n;
        self.sum += other.sum;
        self.hit_w += other.hit_w;
        self.blocked_w += other.blocked_w;
        self.w += other.w;
        self.w2 += other.w2;
        self.wy += other.wy;
        self.wy2 += other.wy2;
        self.peak = self.peak.max(other.peak);
    }

    /// Adds a sample that a real lens blocked (its vignetting), with lens-filter weight `w`:
    /// it brings no light, and the coverage is that of the samples that passed.
    pub fn add_blocked(&mut self, w: f32) {
        self.n += 1;
        self.w += w;
        self.w2 += w * w;
        self.blocked_w += w;
    }

    /// This estimate plus an independent one of mean `mean` whose luminance has variance
    /// `variance` (of that mean): every sample's value moves by `mean`, so the spread of the
    /// samples is unchanged, and the standard error counts `variance` too. Nothing changes
    /// before any weight was added.
    pub fn plus(mut self, mean: Vec3, variance: f64) -> Self {
        if self.w <= 0.0 {
            return self;
        }
        let w = f64::from(self.w);
        let y = f64::from(luminance(mean));
        self.sum += mean * self.w;
        self.wy2 += 2.0 * y * self.wy + y * y * w;
        self.wy += y * w;
        self.peak += y as f32;
        self.apart += variance;
        self
    }

    /// This estimate's mean weighted by `alpha` (within 0 and 1) and `other`'s by `1 -
    /// alpha`: the estimate of a pixel whose share `alpha` one estimator covers and the rest
    /// another (colour and coverage alike). Its standard error is that of the mixture of
    /// both sets of samples, an approximation. `other` alone when this one has no weight.
    pub fn blend(self, alpha: f32, other: Self) -> Self {
        if self.w <= 0.0 {
            return other;
        }
        let alpha = alpha.clamp(0.0, 1.0);
        let (a, b) = (
            alpha / self.w,
            if other.w > 0.0 {
                (1.0 - alpha) / other.w
            } else {
                0.0
            },
        );
        let (a64, b64) = (f64::from(a), f64::from(b));
        Self {
            n: self.n + other.n,
            sum: self.sum * a + other.sum * b,
            hit_w: self.hit_w * a + other.hit_w * b,
            blocked_w: self.blocked_w * a + other.blocked_w * b,
            w: self.w * a + other.w * b,
            w2: self.w2 * a * a + other.w2 * b * b,
            wy: self.wy * a64 + other.wy * b64,
            wy2: self.wy2 * a64 + other.wy2 * b64,
            peak: self.peak.max(other.peak),
            apart: self.apart * f64::from(alpha * alpha)
                + other.apart * f64::from((1.0 - alpha) * (1.0 - alpha)),
        }
    }

    /// The sum of the weights of the samples added (their weighted count).
    pub fn weight(&self) -> f32 {
        self.w
    }

    /// The brightest sample's luminance (0 before any sample).
    pub fn peak(&self) -> f32 {
        self.peak
    }

    /// What a rare bright event could still hide, in code values: had the next sample seen
    /// luminance `brighter` (the brightest sample nearby), the mean would move by
    /// `(brighter - mean) / n`. Samples that all agree have no variance, yet a small
    /// highlight behind the blur may simply not have been hit; this is how far that could be
    /// off.
    pub fn unseen_code(&self, brighter: f32) -> f32 {
        if self.n == 0 {
            return f32::INFINITY;
        }
        let y = luminance(self.mean()).max(0.0);
        code(y + (brighter - y).max(0.0) / self.n as f32) - code(y)
    }

    /// The weighted mean (black when nothing was added or every weight was zero).
    pub fn mean(&self) -> Vec3 {
        if self.w > 0.0 {
            self.sum / self.w
        } else {
            Vec3::ZERO
        }
    }

    /// How many equally weighted samples the weighted mean is worth: (sum w)^2 / sum w^2
    /// (0 before any sample).
    pub fn effective_samples(&self) -> f32 {
        if self.w2 > 0.0 {
            self.w * self.w / self.w2
        } else {
            0.0
        }
    }

    /// The weighted fraction of samples that hit geometry (0 when nothing was added).
    pub fn coverage(&self) -> f32 {
        let seen = self.w - self.blocked_w;
        if seen > 0.0 {
            (self.hit_w / seen).min(1.0)
        } else {
            0.0
        }
    }

    /// The mean colour with the coverage as its fourth component.
    pub fn mean_rgba(&self) -> Vec4 {
        self.mean().extend(self.coverage())
    }

    /// Standard error of the coverage, in code values of alpha (255 = opaque): hits are
    /// Bernoulli trials, so their variance is a (1 - a). Infinite with fewer than two
    /// samples.
    pub fn coverage_error_code(&self) -> f32 {
        if self.n < 2 || self.w <= 0.0 {
            return f32::INFINITY;
        }
        let a = f64::from(self.coverage());
        (255.0 * self.error_of_mean(a * (1.0 - a))) as f32
    }

    /// The standard error of the weighted mean of samples whose variance (uncorrected) is
    /// `var`; needs two samples or more.
    fn error_of_mean(&self, var: f64) -> f64 {
        let (w, w2) = (f64::from(self.w), f64::from(self.w2));
        let n = f64::from(self.n);
        // Bessel-corrected, then the variance of a weighted mean.
        let var = var * n / (n - 1.0);
        (var * w2 / (w * w)).sqrt()
    }

    /// Standard error of the mean's luminance, linear units; infinite with fewer than two
    /// samples (nothing is known yet).
    pub fn std_error(&self) -> f32 {
        if self.n < 2 || self.w <= 0.0 {
            return f32::INFINITY;
        }
        let w = f64::from(self.w);
        let mean = self.wy / w;
        let spread = self.error_of_mean((self.wy2 / w - mean * mean).max(0.0));
        if self.apart > 0.0 {
            (spread * spread + self.apart).sqrt() as f32
        } else {
            spread as f32
        }
    }

    /// [`Estimate::std_error`] in code values: how far one standard error above the mean
    /// moves its code (a finite difference, so dark pixels, where the code is steep, and
    /// bright ones are both measured as a viewer would see them).
    pub fn std_error_code(&self) -> f32 {
        let se = self.std_error();
        if !se.is_finite() {
            return f32::INFINITY;
        }
        let y = luminance(self.mean()).max(0.0);
        code(y + se) - code(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples summed in two parts and merged give what summing them all in one gives:
    /// count, mean, coverage, standard error and peak.
    #[test]
    fn parts_merged_are_the_whole() {
        let samples: Vec<(Vec3, f32, bool)> = (0..40)
            .map(|i| {
                let v = (i * 37 % 11) as f32 / 7.0;
                (
                    Vec3::new(v, 0.5 * v, 2.0 - v),
                    0.1 + (i % 5) as f32,
                    i % 3 != 0,
                )
            })
            .collect();
        let add = |e: &mut Estimate, s: &[(Vec3, f32, bool)]| {
            for &(l, w, hit) in s {
                e.add_lit(l, f64::from(luminance(l)), w, hit);
            }
        };
        let mut whole = Estimate::default();
        add(&mut whole, &samples);
        let (mut first, mut second) = (Estimate::default(), Estimate::default());
        add(&mut first, &samples[..13]);
        add(&mut second, &samples[13..]);
        first.merge(&second);
        assert_eq!(first.n, whole.n);
        assert!((first.mean() - whole.mean()).length() < 1e-5);
        assert!((first.coverage() - whole.coverage()).abs() < 1e-6);
        assert!((first.std_error() - whole.std_error()).abs() < 1e-5);
        assert_eq!(first.peak(), whole.peak());
        assert!((first.weight() - whole.weight()).abs() < 1e-4);
    }

    #[test]
    fn mean_and_standard_error_of_known_samples() {
        let mut e = Estimate::default();
        assert!(e.std_error().is_infinite());
        for v in [0.0f32, 1.0, 0.0, 1.0] {
            e.add(Vec3::splat(v), 1.0, true);
        }
        assert!((e.mean() - Vec3::splat(0.5)).length() < 1e-6);
        // Sample variance 1/3, standard error sqrt(1/3 / 4).
        let want = (1.0f32 / 12.0).sqrt();
        assert!((e.std_error() - want).abs() < 1e-5, "{}", e.std_error());
        let mut constant = Estimate::default();
        for _ in 0..8 {
            constant.add(Vec3::new(0.3, 0.2, 0.1), 0.5, true);
        }
        assert_eq!(constant.std_error(), 0.0);
        assert_eq!(constant.std_error_code(), 0.0);
    }

    /// Samples a real lens blocked darken the mean (vignetting) but leave the coverage to
    /// the samples that passed.
    #[test]
    fn blocked_samples_darken_but_do_not_uncover() {
        let mut e = Estimate::default();
        for k in 0..8 {
            e.add(Vec3::ONE, 1.0, k % 2 == 0);
            e.add_blocked(1.0);
        }
        assert_eq!(e.n, 16);
        assert!((e.mean() - Vec3::splat(0.5)).length() < 1e-6);
        assert!((e.coverage() - 0.5).abs() < 1e-6);
        let mut all = Estimate::default();
        all.add_blocked(1.0);
        assert_eq!((all.mean(), all.coverage()), (Vec3::ZERO, 0.0));
    }

    #[test]
    fn agreeing_samples_still_doubt_a_brighter_neighbour() {
        let mut e = Estimate::default();
        for _ in 0..16 {
            e.add(Vec3::splat(0.2), 1.0, true);
        }
        assert_eq!(e.std_error_code(), 0.0);
        assert_eq!(e.peak(), 0.2);
        // Nothing brighter nearby: nothing unseen.
        assert_eq!(e.unseen_code(0.2), 0.0);
        // A highlight of 400 seen nearby could move this mean by 400 / 16: far beyond a code.
        assert!(e.unseen_code(400.0) > 100.0);
        // With 4x the samples, a quarter of that in linear terms.
        let mut more = e;
        for _ in 0..48 {
            more.add(Vec3::splat(0.2), 1.0, true);
        }
        assert!(more.unseen_code(400.0) < e.unseen_code(400.0));
    }

    #[test]
    fn coverage_is_the_weighted_fraction_of_hits() {
        let mut e = Estimate::default();
        assert_eq!(e.coverage(), 0.0);
        e.add(Vec3::ONE, 3.0, true);
        e.add(Vec3::ZERO, 1.0, false);
        assert!((e.coverage() - 0.75).abs() < 1e-6);
        assert_eq!(e.mean_rgba().w, e.coverage());
        // Bernoulli: sqrt(a (1 - a) n / (n - 1) * sum w^2) / sum w, times 255.
        let want = 255.0 * (0.1875f32 * 2.0 * 10.0).sqrt() / 4.0;
        assert!((e.coverage_error_code() - want).abs() < 1e-3);
        let mut all = Estimate::default();
        for _ in 0..4 {
            all.add(Vec3::ONE, 1.0, true);
        }
        assert_eq!((all.coverage(), all.coverage_error_code()), (1.0, 0.0));
    }

    #[test]
    fn code_values_match_srgb_and_continue_above_one() {
        assert_eq!(code(0.0), 0.0);
        assert!((code(1.0) - 255.0).abs() < 1e-3);
        assert!((code(0.5) - 255.0 * crate::metrics::linear_to_srgb(0.5)).abs() < 1e-3);
        assert!(code(4.0) > code(2.0) && code(2.0) > 255.0);
        assert_eq!(code(-1.0), 0.0);
    }
}
