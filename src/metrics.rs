//! Image-quality metrics for comparing a render against a reference.
//!
//! Images are linear-light RGB, row-major, `width * height` pixels of `[f32; 3]`. Every metric
//! takes the two images, their shared size and the [`Space`] to compare in, and checks its
//! input first: both slices must hold exactly `width * height` pixels
//! ([`MetricsError::SizeMismatch`]), the image must have at least one pixel
//! ([`MetricsError::Empty`]), and every channel of both images must be finite
//! ([`MetricsError::NonFinite`], which names the image, pixel and channel).
//!
//! # Definitions
//!
//! - **Value range.** Each channel is clamped to `[0, 1]` before it is compared, so the peak
//!   value is 1. In [`Space::Srgb`] each clamped channel is then encoded with
//!   [`linear_to_srgb`]: this is what a viewer sees in an 8-bit PNG (without the 8-bit
//!   quantisation) and is the space the renderer reports by default. [`Space::Linear`] compares
//!   the clamped radiance directly.
//! - **PSNR** ([`psnr`]) `= 10 log10(1 / MSE)` dB, where MSE is the mean squared difference over
//!   all pixels and all three channels. Identical images (after clamping and encoding) have
//!   MSE 0 and give `f64::INFINITY`.
//! - **SSIM** ([`ssim`]) follows Wang, Bovik, Sheikh and Simoncelli, "Image Quality
//!   Assessment: From Error Visibility to Structural Similarity" (IEEE TIP 2004), computed on
//!   luma `Y = 0.2126 R + 0.7152 G + 0.0722 B` of the clamped (and, in [`Space::Srgb`],
//!   encoded) channels. Local statistics use an 11x11 Gaussian window with sigma 1.5
//!   (normalised to sum 1), constants `K1 = 0.01`, `K2 = 0.03`, dynamic range `L = 1`
//!   (`C1 = (K1 L)^2`, `C2 = (K2 L)^2`), and per window
//!
//!   ```text
//!   SSIM = (2 mu_a mu_b + C1) (2 sigma_ab + C2)
//!          / ((mu_a^2 + mu_b^2 + C1) (sigma_a^2 + sigma_b^2 + C2))
//!   ```
//!
//!   with population (not sample) variances and covariance. The result is the mean over every
//!   window position lying fully inside the image (the "valid" region, as in Wang's reference
//!   MATLAB code, but without its automatic downsampling of large images). When the image is
//!   narrower or shorter than 11 pixels the window is clipped to the image in that dimension:
//!   it becomes `n` taps wide (`n` the image's size in that dimension), with the Gaussian
//!   weights `exp(-d^2 / (2 sigma^2))` at distances `d` from the centre of those `n` taps,
//!   renormalised, and there is exactly one window position in that dimension. Identical
//!   images give 1; the value lies in `[-1, 1]`. The window is separable, so the five local
//!   statistics (means of `a`, `b`, `a^2`, `b^2`, `ab`) are filtered with two 1-D passes,
//!   `O(pixels * 11 * 2)` work, parallelised over rows with rayon.
//! - **Maximum absolute error** ([`max_abs_error`]) is the largest `|a - b|` over all pixels
//!   and channels.
//! - **Error map** ([`error_map`]) is, per pixel, the mean of `|a - b|` over the three
//!   channels, row-major like the input, for heat maps.

use rayon::prelude::*;

use crate::error_kind::{ErrorKind, HasKind};

/// Which space to compare images in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// Clamped linear radiance, compared directly.
    Linear,
    /// Clamped radiance encoded with the sRGB transfer function ([`linear_to_srgb`]), as a
    /// viewer sees it in a PNG. The default.
    #[default]
    Srgb,
}

/// Why two images could not be compared.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricsError {
    /// An image does not hold `width * height` pixels.
    #[error(
        "size mismatch: image a has {a_len} pixels and image b has {b_len}, \
         but a {width}x{height} image needs {}",
        width.saturating_mul(*height)
    )]
    SizeMismatch {
        /// Pixels in image a.
        a_len: usize,
        /// Pixels in image b.
        b_len: usize,
        /// The width given, pixels.
        width: usize,
        /// The height given, pixels.
        height: usize,
    },
    /// The images have no pixels.
    #[error("the images are empty ({width}x{height})")]
    Empty {
        /// The width given, pixels.
        width: usize,
        /// The height given, pixels.
        height: usize,
    },
    /// A channel is NaN or infinite. `image` is `"a"` or `"b"` (the argument it came from).
    #[error("image {image} has a non-finite value {value} at pixel ({x}, {y}), channel {channel}")]
    NonFinite {
        /// `"a"` or `"b"`.
        image: &'static str,
        /// Pixel column, from 0 at the left.
        x: usize,
        /// Pixel row (pixels are row-major: index `y * width + x`).
        y: usize,
        /// Channel index: 0 red, 1 green, 2 blue.
        channel: usize,
        /// The offending value.
        value: f32,
    },
}

/// The standard piecewise sRGB transfer function (IEC 61966-2-1), linear to encoded, with the
/// input clamped to `[0, 1]`: `12.92 v` for `v <= 0.0031308`, else `1.055 v^(1/2.4) - 0.055`.
pub fn linear_to_srgb(v: f32) -> f32 {
    srgb_encode(f64::from(v)) as f32
}

/// The sRGB curve of a linear value >= 0 without the clamp at 1 (the same power law continues
/// above 1): `12.92 v` for `v <= 0.0031308`, else `1.055 v^(1/2.4) - 0.055`.
pub fn srgb_curve(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// [`linear_to_srgb`] in double precision (the metrics compute in f64).
fn srgb_encode(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        // (1055 p - 55) / 1000, not 1.055 p - 0.055, so that 1 encodes to exactly 1 in f64.
        ((1055.0 * v.powf(1.0 / 2.4) - 55.0) / 1000.0).clamp(0.0, 1.0)
    }
}

/// Checks sizes and values; returns the pixel count.
fn validate(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: usize,
    height: usize,
) -> Result<usize, MetricsError> {
    let n = width.checked_mul(height);
    if n != Some(a.len()) || n != Some(b.len()) {
        return Err(MetricsError::SizeMismatch {
            a_len: a.len(),
            b_len: b.len(),
            width,
            height,
        });
    }
    let n = a.len();
    if n == 0 {
        return Err(MetricsError::Empty { width, height });
    }
    for (image, pixels) in [("a", a), ("b", b)] {
        for (i, p) in pixels.iter().enumerate() {
            if let Some(channel) = p.iter().position(|c| !c.is_finite()) {
                return Err(MetricsError::NonFinite {
                    image,
                    x: i % width,
                    y: i / width,
                    channel,
                    value: p[channel],
                });
            }
        }
    }
    Ok(n)
}

/// One pixel clamped to `[0, 1]` and, in sRGB space, encoded.
fn encode(p: [f32; 3], space: Space) -> [f64; 3] {
    p.map(|c| {
        let c = f64::from(c).clamp(0.0, 1.0);
        match space {
            Space::Linear => c,
            Space::Srgb => srgb_encode(c),
        }
    })
}

/// Per-channel differences `a - b` of each pixel pair, in the comparison space.
fn diffs<'a>(
    a: &'a [[f32; 3]],
    b: &'a [[f32; 3]],
    space: Space,
) -> impl Iterator<Item = [f64; 3]> + 'a {
    a.iter().zip(b).map(move |(&pa, &pb)| {
        let (ea, eb) = (encode(pa, space), encode(pb, space));
        [ea[0] - eb[0], ea[1] - eb[1], ea[2] - eb[2]]
    })
}

/// Peak signal-to-noise ratio in dB, `10 log10(1 / MSE)` over all pixels and channels with
/// peak 1; `f64::INFINITY` when the images are identical after clamping (and encoding).
pub fn psnr(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: usize,
    height: usize,
    space: Space,
) -> Result<f64, MetricsError> {
    let n = validate(a, b, width, height)?;
    let sum_sq: f64 = diffs(a, b, space)
        .map(|d| d.iter().map(|e| e * e).sum::<f64>())
        .sum();
    let mse = sum_sq / (3 * n) as f64;
    Ok(if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    })
}

/// The squared error of one band of pixels: what [`error_by_band`] reports.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct BandError {
    /// The band holds the pixels whose key is at least `lo` (`None`: no lower bound)...
    pub lo: Option<f32>,
    /// ...and below `hi` (`None`: no upper bound).
    pub hi: Option<f32>,
    /// Its share of the image's pixels (0 to 1).
    pub pixels: f64,
    /// Its share of the image's squared error (0 to 1; 0 everywhere when the images agree).
    pub error: f64,
    /// PSNR over its pixels alone (dB, as [`psnr`]); `None` when it has no pixels or they
    /// agree.
    pub psnr_db: Option<f64>,
}

/// Where `a` errs against `b`: the squared error split by a per-pixel `key` (for example the
/// blur diameter) into bands below `edges[0]`, between consecutive edges (ascending) and from
/// the last edge up. A key that is not a number counts in the first band.
pub fn error_by_band(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    (width, height): (usize, usize),
    space: Space,
    (key, edges): (&[f32], &[f32]),
) -> Result<Vec<BandError>, MetricsError> {
    let n = validate(a, b, width, height)?;
    if key.len() != n {
        return Err(MetricsError::SizeMismatch {
            a_len: key.len(),
            b_len: n,
            width,
            height,
        });
    }
    let mut sums = vec![(0usize, 0.0f64); edges.len() + 1];
    for (d, &k) in diffs(a, b, space).zip(key) {
        let band = &mut sums[edges.iter().take_while(|&&e| k >= e).count()];
        band.0 += 1;
        band.1 += d.iter().map(|e| e * e).sum::<f64>();
    }
    let total: f64 = sums.iter().map(|s| s.1).sum();
    Ok(sums
        .iter()
        .enumerate()
        .map(|(i, &(count, sum_sq))| BandError {
            lo: i.checked_sub(1).map(|j| edges[j]),
            hi: edges.get(i).copied(),
            pixels: count as f64 / n as f64,
            error: if total > 0.0 { sum_sq / total } else { 0.0 },
            psnr_db: (count > 0 && sum_sq > 0.0)
                .then(|| -10.0 * (sum_sq / (3 * count) as f64).log10()),
        })
        .collect())
}

/// The largest per-pixel, per-channel absolute error `|a - b|` (in `[0, 1]`).
pub fn max_abs_error(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: usize,
    height: usize,
    space: Space,
) -> Result<f64, MetricsError> {
    validate(a, b, width, height)?;
    Ok(diffs(a, b, space)
        .flatten()
        .map(f64::abs)
        .fold(0.0, f64::max))
}

/// Per pixel, the mean absolute error over the three channels, row-major (`width * height`
/// values in `[0, 1]`), for heat maps.
pub fn error_map(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: usize,
    height: usize,
    space: Space,
) -> Result<Vec<f32>, MetricsError> {
    validate(a, b, width, height)?;
    Ok(diffs(a, b, space)
        .map(|d| ((d[0].abs() + d[1].abs() + d[2].abs()) / 3.0) as f32)
        .collect())
}

/// SSIM window size (taps per dimension) and Gaussian sigma.
const WINDOW: usize = 11;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// Normalised Gaussian weights for a window of `taps` samples (`taps <= WINDOW`), centred on
/// the middle of the taps.
fn gaussian_weights(taps: usize) -> Vec<f64> {
    let centre = (taps as f64 - 1.0) / 2.0;
    let w: Vec<f64> = (0..taps)
        .map(|i| {
            let d = i as f64 - centre;
            (-d * d / (2.0 * SIGMA * SIGMA)).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|v| v / sum).collect()
}

/// Luma of one pixel in the comparison space.
fn luma(p: [f32; 3], space: Space) -> f64 {
    let [r, g, b] = encode(p, space);
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

/// SSIM of one window from its weighted statistics `[mu_a, mu_b, E[a^2], E[b^2], E[ab]]`.
fn ssim_from_stats(s: [f64; 5]) -> f64 {
    let [mu_a, mu_b, aa, bb, ab] = s;
    let var_a = aa - mu_a * mu_a;
    let var_b = bb - mu_b * mu_b;
    let cov = ab - mu_a * mu_b;
    ((2.0 * mu_a * mu_b + C1) * (2.0 * cov + C2))
        / ((mu_a * mu_a + mu_b * mu_b + C1) * (var_a + var_b + C2))
}

/// Mean structural similarity (Wang et al. 2004) of the luma of `a` and `b`: 11x11 Gaussian
/// window (sigma 1.5), K1 = 0.01, K2 = 0.03, L = 1, averaged over the window positions fully
/// inside the image (window clipped to the image when the image is smaller; see the module
/// documentation). 1 for identical images.
pub fn ssim(
    a: &[[f32; 3]],
    b: &[[f32; 3]],
    width: usize,
    height: usize,
    space: Space,
) -> Result<f64, MetricsError> {
    validate(a, b, width, height)?;
    let ya: Vec<f64> = a.par_iter().map(|&p| luma(p, space)).collect();
    let yb: Vec<f64> = b.par_iter().map(|&p| luma(p, space)).collect();

    let (kx, ky) = (WINDOW.min(width), WINDOW.min(height));
    let (wx, wy) = (gaussian_weights(kx), gaussian_weights(ky));
    let (ow, oh) = (width - kx + 1, height - ky + 1);

    // Horizontal pass: every row, filtered to the `ow` valid columns.
    let mut horiz = vec![[0.0f64; 5]; height * ow];
    horiz.par_chunks_mut(ow).enumerate().for_each(|(y, out)| {
        let (ra, rb) = (
            &ya[y * width..(y + 1) * width],
            &yb[y * width..(y + 1) * width],
        );
        for (x, o) in out.iter_mut().enumerate() {
            let mut s = [0.0f64; 5];
            for (k, &w) in wx.iter().enumerate() {
                let (pa, pb) = (ra[x + k], rb[x + k]);
                s[0] += w * pa;
                s[1] += w * pb;
                s[2] += w * pa * pa;
                s[3] += w * pb * pb;
                s[4] += w * pa * pb;
            }
            *o = s;
        }
    });

    // Vertical pass: each valid output row, summed to one value per row so the total is
    // accumulated in a fixed order (deterministic regardless of thread count).
    let row_sums: Vec<f64> = (0..oh)
        .into_par_iter()
        .map(|oy| {
            let mut stats = vec![[0.0f64; 5]; ow];
            for (k, &w) in wy.iter().enumerate() {
                let src = &horiz[(oy + k) * ow..(oy + k + 1) * ow];
                for (acc, h) in stats.iter_mut().zip(src) {
                    for (a, &v) in acc.iter_mut().zip(h) {
                        *a += w * v;
                    }
                }
            }
            stats.into_iter().map(ssim_from_stats).sum::<f64>()
        })
        .collect();
    Ok(row_sums.iter().sum::<f64>() / (ow * oh) as f64)
}

impl HasKind for MetricsError {
    /// The images compared are dofray's own renders: a mismatch is a bug.
    fn kind(&self) -> ErrorKind {
        ErrorKind::Internal
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(w: usize, h: usize, v: [f32; 3]) -> Vec<[f32; 3]> {
        vec![v; w * h]
    }

    /// A deterministic uniform sequence in [0, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// A smooth, textured test image with values in roughly [0.1, 0.9].
    fn textured(w: usize, h: usize) -> Vec<[f32; 3]> {
        let mut rng = Lcg(7);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let base = 0.5 + 0.25 * (x * 0.3).sin() * (y * 0.2).cos();
                let n = 0.15 * (rng.next() - 0.5);
                [base + n, 0.8 * base + 0.1, 0.9 - 0.6 * base + n]
            })
            .collect()
    }

    fn add_noise(img: &[[f32; 3]], noise: &[[f32; 3]], amp: f32) -> Vec<[f32; 3]> {
        img.iter()
            .zip(noise)
            .map(|(p, n)| [p[0] + amp * n[0], p[1] + amp * n[1], p[2] + amp * n[2]])
            .collect()
    }

    fn noise_field(len: usize, seed: u64) -> Vec<[f32; 3]> {
        let mut rng = Lcg(seed);
        (0..len)
            .map(|_| {
                [
                    2.0 * rng.next() - 1.0,
                    2.0 * rng.next() - 1.0,
                    2.0 * rng.next() - 1.0,
                ]
            })
            .collect()
    }

    /// Direct (non-separable) SSIM for checking the separable implementation.
    fn ssim_brute(
        a: &[[f32; 3]],
        b: &[[f32; 3]],
        width: usize,
        height: usize,
        space: Space,
    ) -> f64 {
        let (kx, ky) = (WINDOW.min(width), WINDOW.min(height));
        let (wx, wy) = (gaussian_weights(kx), gaussian_weights(ky));
        let mut total = 0.0;
        let mut count = 0;
        for oy in 0..=height - ky {
            for ox in 0..=width - kx {
                let mut s = [0.0; 5];
                for (j, &wj) in wy.iter().enumerate() {
                    for (i, &wi) in wx.iter().enumerate() {
                        let idx = (oy + j) * width + ox + i;
                        let (pa, pb) = (luma(a[idx], space), luma(b[idx], space));
                        let w = wi * wj;
                        s[0] += w * pa;
                        s[1] += w * pb;
                        s[2] += w * pa * pa;
                        s[3] += w * pb * pb;
                        s[4] += w * pa * pb;
                    }
                }
                total += ssim_from_stats(s);
                count += 1;
            }
        }
        total / count as f64
    }

    fn constant_ssim(mu_a: f64, mu_b: f64) -> f64 {
        (2.0 * mu_a * mu_b + C1) / (mu_a * mu_a + mu_b * mu_b + C1)
    }

    // ---- linear_to_srgb ----

    #[test]
    fn the_error_splits_by_band_and_adds_up_to_the_whole() {
        // Keys 0.5 and NaN in the first band, 2 and 3 in the middle one, 9 in the last.
        let (w, h) = (5, 1);
        let b = constant(w, h, [0.5; 3]);
        let mut a = b.clone();
        a[0] = [0.6; 3]; // error 0.1 in band 0
        a[2] = [0.8; 3]; // error 0.3 in band 1
        a[3] = [0.5; 3]; // exact, band 2
        let key = [0.5, 2.0, 3.0, 9.0, f32::NAN];
        let bands = error_by_band(&a, &b, (w, h), Space::Linear, (&key, &[1.0, 4.0])).unwrap();
        assert_eq!(bands.len(), 3);
        assert_eq!((bands[0].lo, bands[0].hi), (None, Some(1.0)));
        assert_eq!((bands[2].lo, bands[2].hi), (Some(4.0), None));
        let pixels: Vec<f64> = bands.iter().map(|b| b.pixels).collect();
        assert_eq!(pixels, [0.4, 0.4, 0.2]);
        let err: Vec<f64> = bands.iter().map(|b| b.error).collect();
        assert!((err[0] - 0.1 / 1.0).abs() < 1e-6, "{err:?}");
        assert!((err[1] - 0.9).abs() < 1e-6, "{err:?}");
        assert_eq!(err[2], 0.0);
        assert_eq!(bands[2].psnr_db, None);
        // Each band's PSNR is over its own pixels: band 1 has one error of 0.3 in two pixels.
        let expect = -10.0 * (0.09f64 / 2.0).log10();
        assert!((bands[1].psnr_db.unwrap() - expect).abs() < 1e-4);
        // The bands' squared errors add up to the image's.
        let whole = psnr(&a, &b, w, h, Space::Linear).unwrap();
        let sum: f64 = bands
            .iter()
            .filter_map(|b| b.psnr_db.map(|p| 10f64.powf(-p / 10.0) * b.pixels))
            .sum();
        assert!((-10.0 * sum.log10() - whole).abs() < 1e-4);
        let short = error_by_band(&a, &b, (w, h), Space::Linear, (&key[..4], &[1.0]));
        assert!(matches!(short, Err(MetricsError::SizeMismatch { .. })));
    }

    #[test]
    fn srgb_transfer_known_values() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert_eq!(linear_to_srgb(1.0), 1.0);
        assert!((linear_to_srgb(0.003_130_8) - 0.040_45).abs() < 1e-5);
        assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-5);
        // Linear segment below the knee.
        assert!((linear_to_srgb(0.001) - 0.012_92).abs() < 1e-7);
        // 18% grey encodes to about 0.4614 (sRGB 118/255).
        assert!((linear_to_srgb(0.18) - 0.461_356).abs() < 1e-5);
    }

    #[test]
    fn srgb_transfer_clamps_and_is_monotonic() {
        assert_eq!(linear_to_srgb(-0.5), 0.0);
        assert_eq!(linear_to_srgb(7.0), 1.0);
        let mut prev = -1.0;
        for i in 0..=1000 {
            let v = linear_to_srgb(i as f32 / 1000.0);
            assert!(v >= prev, "not monotonic at {i}");
            assert!((0.0..=1.0).contains(&v));
            prev = v;
        }
    }

    // ---- validation ----

    #[test]
    fn size_mismatch_is_an_error_naming_both_sizes() {
        let a = constant(4, 3, [0.5; 3]);
        let b = constant(3, 3, [0.5; 3]);
        let err = psnr(&a, &b, 4, 3, Space::Linear).unwrap_err();
        assert_eq!(
            err,
            MetricsError::SizeMismatch {
                a_len: 12,
                b_len: 9,
                width: 4,
                height: 3
            }
        );
        let msg = err.to_string();
        assert!(
            msg.contains("12") && msg.contains('9') && msg.contains("4x3"),
            "{msg}"
        );
        // Both slices agree with each other but not with the stated size.
        assert!(matches!(
            ssim(&a, &a, 5, 3, Space::Srgb),
            Err(MetricsError::SizeMismatch { .. })
        ));
        assert!(matches!(
            max_abs_error(&a, &b, 4, 3, Space::Srgb),
            Err(MetricsError::SizeMismatch { .. })
        ));
        assert!(matches!(
            error_map(&b, &a, 4, 3, Space::Srgb),
            Err(MetricsError::SizeMismatch { .. })
        ));
        // Overflowing sizes do not panic.
        assert!(matches!(
            psnr(&a, &a, usize::MAX, 2, Space::Linear),
            Err(MetricsError::SizeMismatch { .. })
        ));
    }

    #[test]
    fn empty_images_are_an_error() {
        let e: Vec<[f32; 3]> = Vec::new();
        for (w, h) in [(0, 0), (0, 5), (5, 0)] {
            assert_eq!(
                psnr(&e, &e, w, h, Space::Linear).unwrap_err(),
                MetricsError::Empty {
                    width: w,
                    height: h
                }
            );
            assert!(matches!(
                ssim(&e, &e, w, h, Space::Srgb),
                Err(MetricsError::Empty { .. })
            ));
            assert!(matches!(
                max_abs_error(&e, &e, w, h, Space::Srgb),
                Err(MetricsError::Empty { .. })
            ));
            assert!(matches!(
                error_map(&e, &e, w, h, Space::Srgb),
                Err(MetricsError::Empty { .. })
            ));
        }
    }

    #[test]
    fn nan_is_an_error_naming_the_pixel() {
        let a = constant(4, 3, [0.5; 3]);
        let mut b = a.clone();
        b[2 * 4 + 1][2] = f32::NAN; // pixel (1, 2), blue
        let err = psnr(&a, &b, 4, 3, Space::Linear).unwrap_err();
        match err {
            MetricsError::NonFinite {
                image,
                x,
                y,
                channel,
                value,
            } => {
                assert_eq!((image, x, y, channel), ("b", 1, 2, 2));
                assert!(value.is_nan());
            }
            other => panic!("unexpected error {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("(1, 2)") && msg.contains("image b") && msg.contains("channel 2"),
            "{msg}"
        );

        // Infinity in image a, and every metric checks.
        let mut a2 = a.clone();
        a2[3][0] = f32::INFINITY; // pixel (3, 0), red
        let expect = |r: Result<(), MetricsError>| match r.unwrap_err() {
            MetricsError::NonFinite {
                image,
                x,
                y,
                channel,
                ..
            } => {
                assert_eq!((image, x, y, channel), ("a", 3, 0, 0))
            }
            other => panic!("unexpected error {other:?}"),
        };
        expect(psnr(&a2, &a, 4, 3, Space::Srgb).map(drop));
        expect(ssim(&a2, &a, 4, 3, Space::Srgb).map(drop));
        expect(max_abs_error(&a2, &a, 4, 3, Space::Srgb).map(drop));
        expect(error_map(&a2, &a, 4, 3, Space::Srgb).map(drop));
    }

    // ---- PSNR ----

    #[test]
    fn psnr_of_known_mse() {
        // 0.5 vs 0.6: MSE 0.01 -> 20 dB, up to 0.6's f32 representation error.
        let a = constant(8, 5, [0.5; 3]);
        let b = constant(8, 5, [0.6; 3]);
        let p = psnr(&a, &b, 8, 5, Space::Linear).unwrap();
        assert!((p - 20.0).abs() < 1e-5, "{p}");
        let d = f64::from(0.6f32) - 0.5;
        assert!((p - -10.0 * (d * d).log10()).abs() < 1e-9, "{p}");

        // Exactly representable: 0.5 vs 0.625, MSE 1/64 -> 10 log10(64) dB.
        let c = constant(8, 5, [0.625; 3]);
        let p = psnr(&a, &c, 8, 5, Space::Linear).unwrap();
        assert!((p - 10.0 * 64f64.log10()).abs() < 1e-9, "{p}");
        assert_eq!(p, psnr(&c, &a, 8, 5, Space::Linear).unwrap());

        // One channel of one pixel of four off by 0.25: MSE = 0.0625 / 12.
        let d = constant(2, 2, [0.25; 3]);
        let mut e = d.clone();
        e[3][1] = 0.5;
        let p = psnr(&d, &e, 2, 2, Space::Linear).unwrap();
        assert!((p - 10.0 * (12.0f64 / 0.0625).log10()).abs() < 1e-9, "{p}");
    }

    #[test]
    fn psnr_identical_is_infinite() {
        let a = textured(13, 9);
        assert_eq!(psnr(&a, &a, 13, 9, Space::Linear).unwrap(), f64::INFINITY);
        assert_eq!(psnr(&a, &a, 13, 9, Space::Srgb).unwrap(), f64::INFINITY);
        // Identical after clamping to [0, 1].
        let hot = constant(3, 2, [2.0, 1.0, -1.0]);
        let clamped = constant(3, 2, [1.0, 5.0, 0.0]);
        assert_eq!(
            psnr(&hot, &clamped, 3, 2, Space::Linear).unwrap(),
            f64::INFINITY
        );
    }

    #[test]
    fn psnr_in_srgb_encodes_first() {
        let a = constant(4, 4, [0.5; 3]);
        let b = constant(4, 4, [0.6; 3]);
        let d = srgb_encode(f64::from(0.6f32)) - srgb_encode(0.5);
        let p = psnr(&a, &b, 4, 4, Space::Srgb).unwrap();
        assert!((p - -10.0 * (d * d).log10()).abs() < 1e-9, "{p}");
        // sRGB compresses highlights: the same linear step is a smaller encoded step here.
        assert!(p > psnr(&a, &b, 4, 4, Space::Linear).unwrap());
        // ...and expands shadows.
        let s = constant(4, 4, [0.01; 3]);
        let t = constant(4, 4, [0.02; 3]);
        assert!(
            psnr(&s, &t, 4, 4, Space::Srgb).unwrap() < psnr(&s, &t, 4, 4, Space::Linear).unwrap()
        );
    }

    // ---- SSIM ----

    #[test]
    fn gaussian_window_is_normalised_and_standard() {
        let w = gaussian_weights(11);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(
            w.iter()
                .zip(w.iter().rev())
                .all(|(l, r)| (l - r).abs() < 1e-15)
        );
        // Centre tap of the 1-D sigma 1.5 window: 1 / sum_{d=-5..5} exp(-d^2 / 4.5).
        assert!((w[5] - 0.266_011).abs() < 1e-5, "{}", w[5]);
        let w4 = gaussian_weights(4);
        assert!((w4.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((w4[0] - w4[3]).abs() < 1e-15 && (w4[1] - w4[2]).abs() < 1e-15);
        assert_eq!(gaussian_weights(1), vec![1.0]);
    }

    #[test]
    fn ssim_identical_is_one() {
        let a = textured(40, 30);
        for space in [Space::Linear, Space::Srgb] {
            let s = ssim(&a, &a, 40, 30, space).unwrap();
            assert!((s - 1.0).abs() < 1e-9, "{s}");
        }
        // Also for images smaller than the window, and constant images.
        let small = textured(5, 3);
        assert!((ssim(&small, &small, 5, 3, Space::Srgb).unwrap() - 1.0).abs() < 1e-9);
        let c = constant(12, 12, [0.3; 3]);
        assert!((ssim(&c, &c, 12, 12, Space::Linear).unwrap() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn ssim_is_symmetric() {
        let a = textured(37, 23);
        let b = add_noise(&a, &noise_field(37 * 23, 3), 0.1);
        for space in [Space::Linear, Space::Srgb] {
            let ab = ssim(&a, &b, 37, 23, space).unwrap();
            let ba = ssim(&b, &a, 37, 23, space).unwrap();
            assert!((ab - ba).abs() < 1e-12, "{ab} vs {ba}");
            assert!(ab < 0.99, "{ab}");
        }
    }

    #[test]
    fn ssim_falls_monotonically_with_noise() {
        let (w, h) = (48, 32);
        let a = textured(w, h);
        let noise = noise_field(w * h, 11);
        let mut prev = ssim(&a, &a, w, h, Space::Srgb).unwrap();
        for amp in [0.005, 0.02, 0.05, 0.1, 0.2, 0.4] {
            let b = add_noise(&a, &noise, amp);
            let s = ssim(&a, &b, w, h, Space::Srgb).unwrap();
            assert!(s < prev, "amp {amp}: {s} !< {prev}");
            assert!(s > -1.0);
            prev = s;
        }
        assert!(prev < 0.5, "heavy noise should score low: {prev}");
    }

    #[test]
    fn ssim_of_constant_images_matches_the_luminance_term() {
        // Contrast/structure term is 1 (variances and covariance 0), so SSIM reduces to
        // (2 mu_a mu_b + C1) / (mu_a^2 + mu_b^2 + C1).
        let a = constant(20, 15, [0.3; 3]);
        let b = constant(20, 15, [0.6; 3]);
        let s = ssim(&a, &b, 20, 15, Space::Linear).unwrap();
        let expect = constant_ssim(f64::from(0.3f32), f64::from(0.6f32));
        assert!((s - expect).abs() < 1e-6, "{s} vs {expect}");
        assert!(expect < 0.9); // the test would notice a wrong formula

        // Coloured pixels: the means are the lumas.
        let (pa, pb) = ([0.9f32, 0.1, 0.2], [0.05f32, 0.4, 0.7]);
        let a = constant(16, 11, pa);
        let b = constant(16, 11, pb);
        let s = ssim(&a, &b, 16, 11, Space::Linear).unwrap();
        let expect = constant_ssim(luma(pa, Space::Linear), luma(pb, Space::Linear));
        assert!((s - expect).abs() < 1e-6, "{s} vs {expect}");

        // In sRGB the means are the encoded values; also with a window clipped to a 6x4 image.
        let a = constant(6, 4, [0.2; 3]);
        let b = constant(6, 4, [0.05; 3]);
        let s = ssim(&a, &b, 6, 4, Space::Srgb).unwrap();
        let expect = constant_ssim(
            srgb_encode(f64::from(0.2f32)),
            srgb_encode(f64::from(0.05f32)),
        );
        assert!((s - expect).abs() < 1e-6, "{s} vs {expect}");
    }

    #[test]
    fn ssim_separable_matches_direct_window() {
        for (w, h) in [
            (20, 17),
            (11, 11),
            (12, 30),
            (7, 19),
            (25, 4),
            (3, 2),
            (1, 1),
        ] {
            let a = textured(w, h);
            let b = add_noise(&a, &noise_field(w * h, 5), 0.15);
            for space in [Space::Linear, Space::Srgb] {
                let fast = ssim(&a, &b, w, h, space).unwrap();
                let slow = ssim_brute(&a, &b, w, h, space);
                assert!(
                    (fast - slow).abs() < 1e-10,
                    "{w}x{h} {space:?}: {fast} vs {slow}"
                );
            }
        }
    }

    #[test]
    fn ssim_weighs_pixels_by_window_coverage() {
        // A corner pixel lies in only one valid window position (at its low-weight edge), a
        // central pixel in many, so changing the corner lowers SSIM less.
        let (w, h) = (20, 20);
        let a = textured(w, h);
        let mut corner = a.clone();
        corner[0] = [0.0; 3];
        let mut centre = a.clone();
        centre[10 * w + 10] = [0.0; 3];
        let s_corner = ssim(&a, &corner, w, h, Space::Linear).unwrap();
        let s_centre = ssim(&a, &centre, w, h, Space::Linear).unwrap();
        assert!(s_corner < 1.0);
        assert!(s_centre < s_corner, "{s_centre} !< {s_corner}");
    }

    #[test]
    fn ssim_runs_on_640x480() {
        let (w, h) = (640, 480);
        let a = textured(w, h);
        let b = add_noise(&a, &noise_field(w * h, 9), 0.05);
        let t = std::time::Instant::now();
        let s = ssim(&a, &b, w, h, Space::Srgb).unwrap();
        eprintln!("ssim 640x480: {s} in {:?}", t.elapsed());
        assert!(s > 0.0 && s < 1.0, "{s}");
    }

    // ---- max_abs_error and error_map ----

    #[test]
    fn max_abs_error_on_hand_made_images() {
        let a = [[0.1, 0.2, 0.3], [0.5, 0.5, 0.5], [1.0, 0.0, 0.25]];
        let b = [[0.1, 0.25, 0.3], [0.5, 0.2, 0.5], [1.5, 0.0, 0.5]];
        // Channel errors: 0.05, 0.3, 0.25 (1.5 clamps to 1.0, so red of pixel 2 is 0).
        let m = max_abs_error(&a, &b, 3, 1, Space::Linear).unwrap();
        assert!((m - 0.3).abs() < 1e-6, "{m}");
        assert_eq!(m, max_abs_error(&b, &a, 3, 1, Space::Linear).unwrap());
        let m = max_abs_error(&a, &b, 1, 3, Space::Srgb).unwrap();
        let expect = srgb_encode(0.5) - srgb_encode(f64::from(0.2f32));
        assert!((m - expect).abs() < 1e-9, "{m} vs {expect}");
        assert_eq!(max_abs_error(&a, &a, 3, 1, Space::Srgb).unwrap(), 0.0);
        // Full-range error.
        let black = [[0.0f32; 3]; 2];
        let white = [[1.0f32; 3], [0.0; 3]];
        assert_eq!(
            max_abs_error(&black, &white, 2, 1, Space::Srgb).unwrap(),
            1.0
        );
    }

    #[test]
    fn error_map_on_hand_made_images() {
        // 2x2, row-major.
        let a = [
            [0.0, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [0.25, 0.5, 0.75],
            [1.0, 1.0, 1.0],
        ];
        let b = [
            [0.3, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [0.75, 0.5, 0.25],
            [2.0, 0.0, 1.0],
        ];
        let m = error_map(&a, &b, 2, 2, Space::Linear).unwrap();
        assert_eq!(m.len(), 4);
        let expect = [0.1f32, 0.0, 1.0 / 3.0, 1.0 / 3.0];
        for (i, (&got, &want)) in m.iter().zip(&expect).enumerate() {
            assert!((got - want).abs() < 1e-6, "pixel {i}: {got} vs {want}");
        }
        // sRGB: pixel 0 is |srgb(0.3) - 0| / 3.
        let m = error_map(&a, &b, 2, 2, Space::Srgb).unwrap();
        assert!((m[0] - linear_to_srgb(0.3) / 3.0).abs() < 1e-6, "{}", m[0]);
        assert_eq!(m[1], 0.0);
        // Identical images map to zero everywhere.
        assert!(
            error_map(&a, &a, 2, 2, Space::Srgb)
                .unwrap()
                .iter()
                .all(|&e| e == 0.0)
        );
        // The map's maximum never exceeds the max channel error.
        let me = max_abs_error(&a, &b, 2, 2, Space::Srgb).unwrap();
        assert!(m.iter().all(|&e| f64::from(e) <= me + 1e-7));
    }

    #[test]
    fn space_serialises_lowercase_and_defaults_to_srgb() {
        assert_eq!(Space::default(), Space::Srgb);
        assert_eq!(serde_json::to_string(&Space::Srgb).unwrap(), "\"srgb\"");
        assert_eq!(serde_json::to_string(&Space::Linear).unwrap(), "\"linear\"");
    }
}
