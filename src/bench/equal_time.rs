//! The equal-error study's picture to judge at a glance: the reference, dense and adaptive at
//! (about) equal time, whole and as an enlarged crop of the window where they differ most from
//! the reference.
//!
//! The adaptive rung shown is the one nearest in PSNR to the highest level both methods reach
//! (else the middle rung); the dense rung is the one whose median time is nearest to it (in
//! ratio). The crop is the window a third of the frame's shorter side across where the two
//! renders' squared sRGB errors add up to the most: the hardest part of the shot (bokeh,
//! blurred texture, noise), not a chosen one. [`super::plot`] draws the picture.

/// 8-bit sRGB pictures of one render (row-major RGB bytes).
pub type Picture = Vec<u8>;

/// The pair the picture shows: which rung of each method, and where the crop is.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EqualTime {
    /// Dense's rung shown (index into [`super::equal_error::EqualErrorReport::dense`]).
    pub dense_rung: usize,
    /// Adaptive's rung shown (index into [`super::equal_error::EqualErrorReport::adaptive`]).
    pub adaptive_rung: usize,
    /// The crop window: x, y, width, height in pixels.
    pub crop: [usize; 4],
    /// Where the picture was written, if it was.
    pub picture: Option<std::path::PathBuf>,
    /// The reference's, dense's and adaptive's pictures (not serialised).
    #[serde(skip)]
    pub pictures: Box<[Picture; 3]>,
}

/// The rungs to show, from each method's rungs' (seconds, PSNR): adaptive's nearest in PSNR to
/// `level` (else the middle one), and dense's nearest to it in time. `None` without rungs.
pub fn choose_rungs(
    dense: &[(f64, f64)],
    adaptive: &[(f64, f64)],
    level: Option<f64>,
) -> Option<(usize, usize)> {
    if dense.is_empty() || adaptive.is_empty() {
        return None;
    }
    let a = match level {
        Some(level) => (0..adaptive.len())
            .filter(|&i| adaptive[i].1.is_finite())
            .min_by(|&i, &j| {
                let off = |r: (f64, f64)| (r.1 - level).abs();
                off(adaptive[i]).total_cmp(&off(adaptive[j]))
            })
            .unwrap_or(adaptive.len() / 2),
        None => adaptive.len() / 2,
    };
    let t = adaptive[a].0.max(1e-9);
    let d = (0..dense.len()).min_by(|&i, &j| {
        let off = |r: (f64, f64)| (r.0.max(1e-9) / t).ln().abs();
        off(dense[i]).total_cmp(&off(dense[j]))
    })?;
    Some((d, a))
}

/// The window (x, y, size, size) a third of the shorter side across (at least 8 px, at most
/// the frame) where the squared differences of `a` and `b` from `reference` sum to the most;
/// the first such window in row-major order of a 4-pixel grid.
pub fn hardest_window(
    reference: &[u8],
    a: &[u8],
    b: &[u8],
    width: usize,
    height: usize,
) -> [usize; 4] {
    let size = (width.min(height) / 3).max(8).min(width).min(height);
    // Summed-area table of the per-pixel error, one row and column of zeros in front.
    let mut sat = vec![0f64; (width + 1) * (height + 1)];
    for y in 0..height {
        let mut row = 0f64;
        for x in 0..width {
            let p = 3 * (y * width + x);
            let err = |img: &[u8]| -> f64 {
                (0..3)
                    .map(|c| (f64::from(img[p + c]) - f64::from(reference[p + c])).powi(2))
                    .sum()
            };
            row += err(a) + err(b);
            sat[(y + 1) * (width + 1) + x + 1] = sat[y * (width + 1) + x + 1] + row;
        }
    }
    let sum = |x: usize, y: usize| {
        let at = |x: usize, y: usize| sat[y * (width + 1) + x];
        at(x + size, y + size) - at(x, y + size) - at(x + size, y) + at(x, y)
    };
    let mut best = (f64::NEG_INFINITY, 0, 0);
    for y in (0..=height - size).step_by(4) {
        for x in (0..=width - size).step_by(4) {
            let s = sum(x, y);
            if s > best.0 {
                best = (s, x, y);
            }
        }
    }
    [best.1, best.2, size, size]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pair_is_adaptive_near_the_level_and_dense_near_its_time() {
        let dense = [(1.0, 25.0), (3.0, 31.0), (16.0, 37.0)];
        let adaptive = [(0.5, 28.0), (2.0, 34.0), (8.0, 40.0)];
        assert_eq!(choose_rungs(&dense, &adaptive, Some(34.5)), Some((1, 1)));
        assert_eq!(choose_rungs(&dense, &adaptive, Some(39.0)), Some((2, 2)));
        assert_eq!(choose_rungs(&dense, &adaptive, None), Some((1, 1)));
        assert_eq!(choose_rungs(&[], &adaptive, None), None);
    }

    #[test]
    fn the_window_is_where_the_errors_are() {
        let (w, h) = (60, 30);
        let reference = vec![100u8; w * h * 3];
        let mut a = reference.clone();
        // A bright blot at (40..46, 20..26).
        for y in 20..26 {
            for x in 40..46 {
                a[3 * (y * w + x)] = 255;
            }
        }
        let [x, y, cw, ch] = hardest_window(&reference, &a, &reference, w, h);
        assert_eq!((cw, ch), (10, 10));
        assert!(
            x <= 40 && x + cw >= 46 && y <= 20 && y + ch >= 26,
            "{x} {y}"
        );
    }
}
