//! What the command line prints: bench tables, JSON objects, the version text, errors.

use std::process::ExitCode;

use anyhow::Result;
use dofray::bench::{self, equal_error};
use dofray::embree::Device;
use dofray::render;

/// Seconds for a table cell: "not reached", or "<=" before an upper bound.
pub(crate) fn crossing_cell(c: &equal_error::Crossing) -> String {
    match c.seconds {
        None => "not reached".into(),
        Some(s) if c.at_first_rung => format!("<={s:.4}"),
        Some(s) => format!("{s:.4}"),
    }
}

pub(crate) fn speedup_cell(l: &equal_error::Level) -> String {
    use equal_error::Bound;
    match l.speedup {
        None => "-".into(),
        Some(x) => match l.speedup_bound {
            Bound::Exact => format!("{x:.2}x"),
            Bound::AtMost => format!("<={x:.2}x"),
            Bound::AtLeast => format!(">={x:.2}x"),
            Bound::Unknown => format!("~{x:.2}x?"),
        },
    }
}

pub(crate) fn print_equal_error(r: &equal_error::EqualErrorReport) {
    println!(
        "dofray bench --equal-error: scene {}, {} integrator, {}x{}, median of {} runs, {} threads; reference {} spp{}",
        r.scene,
        r.integrator.name(),
        r.width,
        r.height,
        r.repeat,
        r.threads,
        r.reference_spp,
        if r.reference_cached { " (cached)" } else { "" }
    );
    let aa = match r.aa {
        equal_error::RungAa::Fixed(n) => format!("{n} at every rung"),
        equal_error::RungAa::Ratio(x) => format!("{x} x spp, at least 1"),
    };
    println!(
        "adaptive: error-controlled rule, default tolerance 4/sqrt(spp) code values; aa: {aa}"
    );
    println!(
        "{:>6} {:>5} | {:>9} {:>11} {:>12} {:>8} | {:>9} {:>11} {:>12} {:>8} {:>6}",
        "spp",
        "aa",
        "dense s",
        "rays",
        "samples",
        "PSNR",
        "adapt. s",
        "rays",
        "samples",
        "PSNR",
        "tol."
    );
    for (d, ad) in r.dense.iter().zip(&r.adaptive) {
        println!(
            "{:>6} {:>5} | {:>9.4} {:>11} {:>12} {:>8.2} | {:>9.4} {:>11} {:>12} {:>8.2} {:>6.2}",
            d.spp,
            d.aa,
            d.seconds,
            d.rays,
            d.samples,
            d.psnr_vs_reference,
            ad.seconds,
            ad.rays,
            ad.samples,
            ad.psnr_vs_reference,
            ad.tolerance.unwrap_or(f32::NAN)
        );
    }
    let lending: Vec<String> = r
        .adaptive
        .iter()
        .filter(|a| a.seconds > 0.0)
        .map(|a| format!("{:.0}%", 100.0 * a.reuse_seconds / a.seconds))
        .collect();
    println!(
        "adaptive's time lending samples between sites (reuse), rung by rung: {}",
        lending.join(", ")
    );
    println!("time to reach each PSNR level (seconds, interpolated in log time between rungs):");
    println!(
        "  {:>10} {:>12} {:>12} {:>10}",
        "level", "dense", "adaptive", "speedup"
    );
    let row = |name: String, l: &equal_error::Level| {
        println!(
            "  {:>10} {:>12} {:>12} {:>10}",
            name,
            crossing_cell(&l.dense),
            crossing_cell(&l.adaptive),
            speedup_cell(l)
        );
    };
    for l in &r.levels {
        row(format!("{} dB", l.psnr_db), l);
    }
    match &r.highest_common {
        Some(l) => {
            println!("highest level both reach:");
            row(format!("{:.2} dB", l.psnr_db), l);
        }
        None => println!("highest level both reach: none (no finite PSNR)"),
    }
    println!(
        "PSNR in sRGB against the reference; \"<=\": the cheapest rung already reaches the level \
         (an upper bound)."
    );
    print_error_by_blur(r);
    let measured = r
        .dense
        .iter()
        .chain(&r.adaptive)
        .map(|g| g.psnr_vs_reference);
    let asked = r.levels.iter().map(|l| l.psnr_db);
    print_reference_noise(r.reference_ceiling_db, measured.chain(asked));
    if let Some(plot) = &r.plot {
        println!("plot: {}", plot.display());
    }
    print_equal_time(r);
}

/// Where the top rung's error is, by blur band, both methods side by side.
fn print_error_by_blur(r: &equal_error::EqualErrorReport) {
    let (Some(d), Some(a)) = (r.dense.last(), r.adaptive.last()) else {
        return;
    };
    println!(
        "where the error is at {} spp, by the CoC (diameter) the depth pass saw: the band's \
         share of the squared error and its own PSNR:",
        d.spp
    );
    println!(
        "  {:>9} {:>7} | {:>7} {:>7} | {:>7} {:>7}",
        "CoC px", "pixels", "dense", "dB", "adapt.", "dB"
    );
    let db = |p: Option<f64>| p.map_or("-".to_string(), |p| format!("{p:.2}"));
    for (bd, ba) in d.error_by_blur.iter().zip(&a.error_by_blur) {
        if bd.pixels == 0.0 {
            continue;
        }
        let band = match (bd.lo, bd.hi) {
            (None, Some(hi)) => format!("< {hi}"),
            (Some(lo), Some(hi)) => format!("{lo}-{hi}"),
            (Some(lo), None) => format!(">= {lo}"),
            (None, None) => "all".to_string(),
        };
        println!(
            "  {:>9} {:>6.1}% | {:>6.1}% {:>7} | {:>6.1}% {:>7}",
            band,
            100.0 * bd.pixels,
            100.0 * bd.error,
            db(bd.psnr_db),
            100.0 * ba.error,
            db(ba.psnr_db)
        );
    }
}

/// The equal-time pair of the side-by-side picture, and where the picture is.
fn print_equal_time(r: &equal_error::EqualErrorReport) {
    if let Some(t) = &r.equal_time {
        let (d, a) = (&r.dense[t.dense_rung], &r.adaptive[t.adaptive_rung]);
        let [x, y, w, h] = t.crop;
        println!(
            "at about equal time: dense {} spp {:.3} s {:.2} dB, adaptive {} spp {:.3} s {:.2} dB; \
             hardest {w}x{h} window at {x},{y}",
            d.spp, d.seconds, d.psnr_vs_reference, a.spp, a.seconds, a.psnr_vs_reference
        );
        if let Some(picture) = &t.picture {
            println!(
                "side by side (reference, dense, adaptive; whole and the window enlarged): {}",
                picture.display()
            );
        }
    }
}

/// Says how far the reference's own noise lets a PSNR against it go, and warns when the
/// `psnrs` measured or asked for come within 3 dB of that.
fn print_reference_noise(ceiling_db: Option<f64>, psnrs: impl Iterator<Item = f64>) {
    let Some(ceiling) = ceiling_db else {
        return;
    };
    let top = psnrs
        .filter(|p| p.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let limited = if top >= ceiling - 3.0 {
        "; PSNRs within 3 dB of it measure the reference's noise as much as the render's \
         (raise --reference-spp)"
    } else {
        ""
    };
    println!(
        "reference noise (from its two independent halves): a noise-free render would measure \
         {ceiling:.2} dB against it{limited}"
    );
}

pub(crate) fn print_table(r: &bench::BenchReport) {
    println!(
        "dofray bench: scene {}, {} integrator, {}x{}, {} spp, {} aa, median of {} runs, {} threads; reference {} spp{}",
        r.scene,
        r.integrator.name(),
        r.width,
        r.height,
        r.spp,
        r.aa,
        r.repeat,
        r.threads,
        r.reference_spp,
        if r.reference_cached { " (cached)" } else { "" }
    );
    println!(
        "{:<20} {:>8} {:>11} {:>8} {:>9} {:>8} {:>8} {:>9} {:>9} {:>8} {:>8}",
        "mode",
        "seconds",
        "rays",
        "Mrays/s",
        "sites",
        "x pinh.",
        "speedup",
        "PSNR dns",
        "PSNR ref",
        "SSIM ref",
        "max err"
    );
    for row in &r.rows {
        println!(
            "{:<20} {:>8.3} {:>11} {:>8.2} {:>9} {:>8.2} {:>8.2} {:>9.2} {:>9.2} {:>8.4} {:>8.3}",
            row.label,
            row.seconds,
            row.rays,
            row.mrays_per_s,
            row.sample_sites,
            row.time_vs_pinhole,
            row.speedup_vs_dense,
            row.psnr_vs_dense,
            row.psnr_vs_reference,
            row.ssim_vs_reference,
            row.max_error_vs_reference
        );
    }
    println!(
        "intersect-only replay of dense's rays: {:.2} Mrays/s; dense runs at {:.0}% of it",
        r.intersect_only_mrays_per_s,
        100.0 * r.dense_vs_intersect_only
    );
    println!(
        "where the time goes (ms): depth pass + maps + sample sites (of which lending samples \
         between them) + interpolation"
    );
    for row in r
        .rows
        .iter()
        .filter(|row| row.mode != render::Mode::Pinhole)
    {
        println!(
            "  {:<20} {:>7.1} + {:>5.1} + {:>7.1} ({:>6.1}) + {:>5.1}",
            row.label,
            row.pinhole_seconds * 1e3,
            row.maps_seconds * 1e3,
            row.sites_seconds * 1e3,
            row.reuse_seconds * 1e3,
            row.interpolate_seconds * 1e3
        );
    }
    println!("PSNR/SSIM in sRGB (what a viewer sees); \"inf\" = identical images.");
    let measured = r.rows.iter().map(|row| row.psnr_vs_reference);
    print_reference_noise(r.reference_ceiling_db, measured);
}

/// A bench report (or any serialisable object) with `schema_version`, `dofray_version` and
/// `git_commit` added at the top level.
pub(crate) fn versioned_json(report: &impl serde::Serialize) -> Result<String> {
    let mut value = serde_json::to_value(report)?;
    if let Some(map) = value.as_object_mut() {
        map.insert("schema_version".into(), dofray::exit::SCHEMA_VERSION.into());
        map.insert("dofray_version".into(), dofray::VERSION.into());
        map.insert("git_commit".into(), dofray::GIT_COMMIT.into());
    }
    Ok(serde_json::to_string(&value)?)
}

/// What `dofray --version` prints: dofray's version and commit, and the Embree it runs on.
pub(crate) fn version_text() -> String {
    let mut text = format!(
        "dofray {}\ncommit: {}\n",
        dofray::VERSION,
        dofray::GIT_COMMIT
    );
    match Device::new() {
        Ok(device) => {
            let width = device.native_packet_width();
            text += &format!(
                "embree: {}\nembree isa: {} (native packet width {width})\nembree config: {:?}\n",
                device.embree_version(),
                dofray::batch::summary::isa_family(width),
                device.config()
            );
        }
        Err(e) => text += &format!("embree: unavailable ({e})\n"),
    }
    text
}

/// Prints a failure: the plain message on stderr and, with `--json`, the error object on stdout.
pub(crate) fn report_error(kind: dofray::exit::ErrorKind, message: &str, json: bool) -> ExitCode {
    eprintln!("error: {message}");
    if json {
        println!("{}", dofray::exit::json_error(kind, message));
    }
    ExitCode::from(kind.exit_code())
}
