//! The equal-error study's picture to judge at a glance: the reference, dense and adaptive at
//! (about) equal time, whole and as an enlarged crop of the window where they differ most from
//! the reference.
//!
//! The adaptive rung shown is the one nearest in PSNR to the highest level both methods reach
//! (else the middle rung); the dense rung is the one whose median time is nearest to it (in
//! ratio). The crop is the window a third of the frame's shorter side across where the two
//! renders' squared sRGB errors add up to the most: the hardest part of the shot (bokeh,
//! blurred texture, noise), not a chosen one.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::equal_error::{EqualErrorReport, Rung};
use super::plot::{FONT, PlotError, register_font};
use crate::output;

/// The file name of the picture in the bench's `--out` directory.
pub const EQUAL_TIME_PNG: &str = "equal-time.png";
/// Height of the label strip above each column, pixels.
const LABEL: usize = 40;

/// 8-bit sRGB pictures of one render (row-major RGB bytes).
pub type Picture = Vec<u8>;

/// The pair the picture shows: which rung of each method, and where the crop is.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EqualTime {
    /// Dense's rung shown (index into [`EqualErrorReport::dense`]).
    pub dense_rung: usize,
    /// Adaptive's rung shown (index into [`EqualErrorReport::adaptive`]).
    pub adaptive_rung: usize,
    /// The crop window: x, y, width, height in pixels.
    pub crop: [usize; 4],
    /// Where the picture was written, if it was.
    pub picture: Option<std::path::PathBuf>,
}

/// The rungs to show: adaptive's nearest in PSNR to `level` (else the middle one), and dense's
/// nearest to it in time. `None` without rungs.
pub fn choose_rungs(
    dense: &[Rung],
    adaptive: &[Rung],
    level: Option<f64>,
) -> Option<(usize, usize)> {
    if dense.is_empty() || adaptive.is_empty() {
        return None;
    }
    let a = match level {
        Some(level) => (0..adaptive.len())
            .filter(|&i| adaptive[i].psnr_vs_reference.is_finite())
            .min_by(|&i, &j| {
                let off = |r: &Rung| (r.psnr_vs_reference - level).abs();
                off(&adaptive[i]).total_cmp(&off(&adaptive[j]))
            })
            .unwrap_or(adaptive.len() / 2),
        None => adaptive.len() / 2,
    };
    let t = adaptive[a].seconds.max(1e-9);
    let d = (0..dense.len()).min_by(|&i, &j| {
        let off = |r: &Rung| (r.seconds.max(1e-9) / t).ln().abs();
        off(&dense[i]).total_cmp(&off(&dense[j]))
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

/// Draws the picture: three columns (reference, dense, adaptive), each labelled, the whole
/// frame above (the crop outlined) and the crop below, enlarged by the largest whole factor
/// that fits the frame's size. `pictures` are the reference, dense and adaptive renders.
pub fn write_png(
    report: &EqualErrorReport,
    chosen: &EqualTime,
    pictures: [&[u8]; 3],
    path: &Path,
) -> Result<(), PlotError> {
    let (w, h) = (report.width, report.height);
    let (cols, rows) = (3 * w, LABEL + 2 * h);
    let mut rgb = vec![255u8; cols * rows * 3];
    let [cx, cy, cw, ch] = chosen.crop;
    let zoom = (w / cw).min(h / ch).max(1);
    let (ox, oy) = ((w - (cw * zoom).min(w)) / 2, (h - (ch * zoom).min(h)) / 2);
    for (col, picture) in pictures.iter().enumerate() {
        for y in 0..h {
            let src = &picture[3 * y * w..3 * (y + 1) * w];
            let at = 3 * ((LABEL + y) * cols + col * w);
            rgb[at..at + 3 * w].copy_from_slice(src);
        }
        for y in 0..(ch * zoom).min(h) {
            for x in 0..(cw * zoom).min(w) {
                let s = 3 * ((cy + y / zoom) * w + cx + x / zoom);
                let d = 3 * ((LABEL + h + oy + y) * cols + col * w + ox + x);
                rgb[d..d + 3].copy_from_slice(&picture[s..s + 3]);
            }
        }
    }
    let labels = labels(report, chosen);
    {
        let size = (cols as u32, rows as u32);
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        draw_labels(&root, &labels, w, chosen.crop).map_err(|message| PlotError::Draw {
            path: path.to_path_buf(),
            message,
        })?;
    }
    output::write_png_srgb8(path, cols, rows, &rgb)?;
    Ok(())
}

/// Each column's label: what it is, its samples, time and PSNR.
fn labels(report: &EqualErrorReport, chosen: &EqualTime) -> [String; 3] {
    let rung = |name: &str, r: &Rung| {
        format!(
            "{name} {} spp: {:.2} s, {:.1} dB",
            r.spp, r.seconds, r.psnr_vs_reference
        )
    };
    [
        format!("reference (dense {} spp)", report.reference_spp),
        rung("dense", &report.dense[chosen.dense_rung]),
        rung("adaptive", &report.adaptive[chosen.adaptive_rung]),
    ]
}

fn draw_labels(
    root: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    labels: &[String; 3],
    w: usize,
    crop: [usize; 4],
) -> Result<(), String> {
    register_font();
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let style = TextStyle::from((FONT, 18).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let [cx, cy, cw, ch] = crop;
    for (col, label) in labels.iter().enumerate() {
        let x = (col * w + w / 2) as i32;
        root.draw(&Text::new(label.as_str(), (x, (LABEL / 2) as i32), &style))
            .map_err(|e| err(&e))?;
        let x0 = (col * w + cx) as i32;
        let y0 = (LABEL + cy) as i32;
        let outline = [(x0, y0), (x0 + cw as i32 - 1, y0 + ch as i32 - 1)];
        root.draw(&Rectangle::new(
            outline,
            RGBColor(255, 210, 0).stroke_width(1),
        ))
        .map_err(|e| err(&e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::equal_error::tests::rung;
    use super::*;

    #[test]
    fn the_pair_is_adaptive_near_the_level_and_dense_near_its_time() {
        let dense = vec![
            rung(4, 1.0, 25.0),
            rung(16, 3.0, 31.0),
            rung(64, 16.0, 37.0),
        ];
        let adaptive = vec![rung(4, 0.5, 28.0), rung(16, 2.0, 34.0), rung(64, 8.0, 40.0)];
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
