//! The equal-error study's picture: PSNR against seconds (log scale) for dense and adaptive,
//! a marker (labelled with its spp) at every rung, and a dashed guide at every PSNR level.
//!
//! Drawn with plotters into an RGB buffer and written as an 8-bit PNG through
//! [`crate::output`]'s atomic writer. Text uses DejaVu Sans, embedded in the binary
//! (`src/bench/fonts/`, with its licence), so nothing is looked up or downloaded at run time.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::equal_error::{EqualErrorReport, Method, Rung};
use super::equal_time::EqualTime;
use crate::error_kind::{ErrorKind, HasKind};
use crate::output::{self, OutputError};

/// The file name of the plot in the bench's `--out` directory.
pub const EQUAL_ERROR_PNG: &str = "equal-error.png";
/// Width and height of the plot in pixels.
pub const PLOT_SIZE: (u32, u32) = (960, 600);
/// The file name of the equal-time picture in the bench's `--out` directory.
pub const EQUAL_TIME_PNG: &str = "equal-time.png";
/// Height of the label strip above each column of the equal-time picture, pixels.
const LABEL: usize = 40;

const FONT: &str = "sans-serif";
static DEJAVU_SANS: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");

/// Why the equal-error plot could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Plotters failed to draw it.
    #[error("cannot draw the plot {}: {message}", path.display())]
    Draw {
        /// The plot's path.
        path: std::path::PathBuf,
        /// Plotters' error, in words.
        message: String,
    },
    /// Writing the PNG failed.
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// Registers the embedded font with plotters (once per process).
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is part of the binary: failing to parse it is a build defect.
        if plotters::style::register_font(FONT, FontStyle::Normal, DEJAVU_SANS).is_err() {
            panic!("the embedded DejaVu Sans font does not parse");
        }
    });
}

/// The curves' colours: dense in a warm red, adaptive in blue (distinct in greyscale too).
fn colour(method: Method) -> RGBColor {
    match method {
        Method::Dense => RGBColor(200, 55, 45),
        Method::Adaptive => RGBColor(30, 90, 190),
    }
}

/// Draws the plot and writes it to `path` as a PNG of [`PLOT_SIZE`].
pub fn write_png(report: &EqualErrorReport, path: &Path) -> Result<(), PlotError> {
    let (w, h) = PLOT_SIZE;
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area();
        draw(report, &root).map_err(|message| PlotError::Draw {
            path: path.to_path_buf(),
            message,
        })?;
    }
    output::write_png_srgb8(path, w as usize, h as usize, &rgb)?;
    Ok(())
}

/// (seconds, PSNR, spp) of a method's rungs that can be drawn (finite PSNR, positive time).
fn drawable(report: &EqualErrorReport, method: Method) -> Vec<(f64, f64, u32)> {
    report
        .rungs(method)
        .iter()
        .filter(|r| r.psnr_vs_reference.is_finite() && r.seconds > 0.0)
        .map(|r| (r.seconds, r.psnr_vs_reference, r.spp))
        .collect()
}

/// The axes' ranges: every drawable rung and every level, with a margin.
fn ranges(report: &EqualErrorReport) -> ((f64, f64), (f64, f64)) {
    let pts: Vec<(f64, f64, u32)> = [Method::Dense, Method::Adaptive]
        .into_iter()
        .flat_map(|m| drawable(report, m))
        .collect();
    let (mut t0, mut t1) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.0), b.max(p.0))
    });
    if !(t0.is_finite() && t1 > 0.0) {
        (t0, t1) = (0.01, 1.0);
    }
    // A fifth of a decade either side (and at least a decade in all).
    let (mut x0, mut x1) = (t0 / 1.6, t1 * 1.6);
    if x1 / x0 < 10.0 {
        let mid = (x0 * x1).sqrt();
        (x0, x1) = (mid / 10f64.sqrt(), mid * 10f64.sqrt());
    }
    let ys = pts
        .iter()
        .map(|p| p.1)
        .chain(report.levels.iter().map(|l| l.psnr_db));
    let (mut y0, mut y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
        (a.min(y), b.max(y))
    });
    if !(y0.is_finite() && y1.is_finite()) {
        (y0, y1) = (20.0, 40.0);
    }
    // Room below the lowest rung for the legend (lower right: slow and poor, usually empty).
    ((x0, x1), ((y0 - 4.5).floor(), (y1 + 1.5).ceil()))
}

/// Tick values for a log axis over `[x0, x1]`: labelled ticks at 1, 2 and 5 times powers of
/// ten, light grid lines at every integer multiple. Each is the double nearest its decimal
/// value, so it prints as written (0.05, not 0.05000000000000001).
fn log_ticks(x0: f64, x1: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut bold, mut light) = (Vec::new(), Vec::new());
    let first = x0.log10().floor() as i32;
    let last = x1.log10().ceil() as i32;
    for e in first..=last {
        for m in 1..10 {
            // Division by an exact power of ten rounds once: 5 / 100 is the double nearest 0.05.
            let v = if e < 0 {
                m as f64 / 10f64.powi(-e)
            } else {
                m as f64 * 10f64.powi(e)
            };
            if v < x0 || v > x1 {
                continue;
            }
            light.push(v);
            if matches!(m, 1 | 2 | 5) {
                bold.push(v);
            }
        }
    }
    (bold, light)
}

/// Guides at the report's PSNR levels, labelled at the left edge.
fn draw_guides<DB: DrawingBackend, X: Ranged<ValueType = f64>, Y: Ranged<ValueType = f64>>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    report: &EqualErrorReport,
    (x0, x1): (f64, f64),
) -> Result<(), String> {
    let guide = RGBColor(110, 110, 110);
    for level in &report.levels {
        let y = level.psnr_db;
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, y), (x1, y)],
                8,
                6,
                guide.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("{y} dB"),
                (x0 * 1.04, y),
                TextStyle::from((FONT, 15).into_font())
                    .color(&guide)
                    .pos(Pos::new(HPos::Left, VPos::Bottom)),
            )))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw(report: &EqualErrorReport, root: &DrawingArea<BitMapBackend, Shift>) -> Result<(), String> {
    register_font();
    let err = |e: &dyn std::fmt::Display| e.to_string();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let ((x0, x1), (y0, y1)) = ranges(report);
    let title = format!(
        "Equal error: {}, {} ({}x{}, reference dense {} spp)",
        report.scene,
        report.integrator.name(),
        report.width,
        report.height,
        report.reference_spp
    );
    let (bold, light) = log_ticks(x0, x1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 26))
        .margin(18)
        .x_label_area_size(56)
        .y_label_area_size(72)
        .build_cartesian_2d(
            (x0..x1)
                .log_scale()
                .with_key_points(bold)
                .with_light_points(light),
            y0..y1,
        )
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("seconds per image (median wall time, log scale)")
        .y_desc("PSNR against the reference (dB, sRGB)")
        .x_label_formatter(&|s| format!("{s}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 16))
        .axis_desc_style((FONT, 18))
        .y_max_light_lines(1)
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(|e| err(&e))?;

    draw_guides(&mut chart, report, (x0, x1))?;

    for method in [Method::Dense, Method::Adaptive] {
        let pts = drawable(report, method);
        let c = colour(method);
        let label = match method {
            Method::Dense => "dense (every pixel a site)".to_string(),
            Method::Adaptive => "adaptive (error rule, default tolerance)".to_string(),
        };
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|p| (p.0, p.1)),
                c.stroke_width(3),
            ))
            .map_err(|e| err(&e))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
        // Curves rise to the right: dense's numbers go below right of its markers, adaptive's
        // above left, clear of both lines.
        let (offset, anchor) = match method {
            Method::Dense => ((7, 3), (HPos::Left, VPos::Top)),
            Method::Adaptive => ((-7, -3), (HPos::Right, VPos::Bottom)),
        };
        let label_style = TextStyle::from((FONT, 14).into_font())
            .color(&c)
            .pos(Pos::new(anchor.0, anchor.1));
        chart
            .draw_series(pts.iter().map(|&(s, p, spp)| {
                EmptyElement::at((s, p))
                    + Circle::new((0, 0), 5, c.filled())
                    + Text::new(format!("{spp}"), offset, label_style.clone())
            }))
            .map_err(|e| err(&e))?;
    }
    // A legend entry explaining the markers' numbers.
    let grey = RGBColor(90, 90, 90);
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        .map_err(|e| err(&e))?
        .label("rung; its number: samples per defocused site")
        .legend(move |(x, y)| Circle::new((x + 12, y), 5, grey.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(160, 160, 160))
        .margin(12)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

impl HasKind for PlotError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Output(e) => e.kind(),
            Self::Draw { .. } => ErrorKind::Io,
        }
    }
}

/// Writes the report's plot as `equal-error.png` in `dir`, and its equal-time picture as
/// `equal-time.png` ([`super::equal_time`]), and records their paths in the report.
pub fn write_plot(report: &mut EqualErrorReport, dir: &Path) -> Result<(), PlotError> {
    let path = dir.join(EQUAL_ERROR_PNG);
    write_png(report, &path)?;
    report.plot = Some(path);
    let path = dir.join(EQUAL_TIME_PNG);
    if let Some(chosen) = &report.equal_time {
        write_equal_time_png(report, chosen, &path)?;
    }
    if let Some(chosen) = &mut report.equal_time {
        chosen.picture = Some(path);
    }
    Ok(())
}

/// Draws the equal-time picture ([`super::equal_time`]) to `path`: three labelled columns (the
/// reference, dense and adaptive), each whole above with the window outlined, and the window
/// below, enlarged by the largest whole factor that fits the frame's size.
fn write_equal_time_png(
    report: &EqualErrorReport,
    chosen: &EqualTime,
    path: &Path,
) -> Result<(), PlotError> {
    let (w, h) = (report.width, report.height);
    let (cols, rows) = (3 * w, LABEL + 2 * h);
    let mut rgb = vec![255u8; cols * rows * 3];
    let [cx, cy, cw, ch] = chosen.crop;
    let zoom = (w / cw).min(h / ch).max(1);
    let (ox, oy) = ((w - (cw * zoom).min(w)) / 2, (h - (ch * zoom).min(h)) / 2);
    for (col, picture) in chosen.pictures.iter().enumerate() {
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
    let [cx, cy, cw, ch] = crop;
    for (col, label) in labels.iter().enumerate() {
        // 18 px text, smaller where a narrow column would make labels overlap (a glyph is
        // about 0.6 of the size wide).
        let size = (w as f64 / (0.6 * label.chars().count().max(1) as f64)).clamp(8.0, 18.0);
        let style = TextStyle::from((FONT, size).into_font())
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center));
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
    use super::super::equal_error::{self, Rung};
    use super::*;

    fn report(dense: Vec<Rung>, adaptive: Vec<Rung>) -> EqualErrorReport {
        equal_error::tests::report(dense, adaptive, &[30.0, 35.0])
    }

    #[test]
    fn the_plot_is_a_png_of_the_documented_size() {
        let scratch = tempfile::Builder::new()
            .prefix("dofray-plot-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let cases = [
            report(
                vec![
                    rung(4, 0.02, 27.0),
                    rung(8, 0.04, 30.5),
                    rung(16, 0.08, 33.0),
                ],
                vec![
                    rung(4, 0.005, 29.0),
                    rung(8, 0.01, 32.0),
                    rung(16, 0.02, 36.0),
                ],
            ),
            // Degenerate: one rung, an image identical to the reference, a zero time.
            report(vec![rung(4, 0.0, 30.0)], vec![rung(4, 0.01, f64::INFINITY)]),
            report(Vec::new(), Vec::new()),
        ];
        for (i, mut r) in cases.into_iter().enumerate() {
            let path = dir.join(format!("plot-{i}.png"));
            write_png(&r, &path).unwrap();
            let img = image::open(&path).unwrap();
            assert_eq!((img.width(), img.height()), PLOT_SIZE, "case {i}");
            // Something was drawn: not a blank white picture.
            let rgb = img.to_rgb8();
            assert!(rgb.pixels().any(|p| p.0 != [255, 255, 255]), "case {i}");
            // write_plot names the file and records it.
            write_plot(&mut r, dir).unwrap();
            assert_eq!(r.plot.as_deref(), Some(dir.join(EQUAL_ERROR_PNG).as_path()));
        }
        scratch.close().unwrap();
    }

    #[test]
    fn log_ticks_are_one_two_five_with_light_lines_between() {
        let (bold, light) = log_ticks(0.015, 0.6);
        assert_eq!(bold, [0.02, 0.05, 0.1, 0.2, 0.5]);
        // 0.02 to 0.09, then 0.1 to 0.6.
        assert_eq!(light.len(), 8 + 6, "{light:?}");
        assert!(light.iter().all(|&v| (0.015..=0.6).contains(&v)));
        let (bold, _) = log_ticks(3.0, 250.0);
        assert_eq!(bold, [5.0, 10.0, 20.0, 50.0, 100.0, 200.0]);
    }
}
