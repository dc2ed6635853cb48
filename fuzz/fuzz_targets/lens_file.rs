//! Lens prescription files (`--lens`, `[camera] lens`): any text either is refused with a
//! line number or gives a prescription, and a prescription either is refused as a camera or
//! makes one whose numbers are sane: a finite positive field of view, finite blur bounds at
//! any depth, rays with finite origins, unit directions and weights in [0, a bound], and
//! finite projections and light landings.
//! The first byte picks the focus distance; inputs of more than 32 surfaces are skipped (the
//! camera's pupil tables grow with the surface count, past the fuzzer's time per input).
#![no_main]

use std::sync::Arc;

use dofray::camera::{CameraSpec, Focus, Lens, Prescription, RealLensSpec};
use dofray::glam::Vec2;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&focus, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    dofray_fuzz::run(|| {
        let p = match Prescription::parse(text, "fuzz") {
            Ok(p) => p,
            Err((line, message)) => {
                assert!(line <= text.lines().count() && !message.is_empty());
                return;
            }
        };
        if p.surfaces.len() > 32 {
            return;
        }
        let spec = CameraSpec {
            width: 12,
            height: 8,
            focus: Focus::Distance(0.05 * 1.1f32.powi(i32::from(focus))),
            real_lens: Some(RealLensSpec {
                prescription: Arc::new(p),
                f_number: None,
                sensor_width_mm: 36.0,
            }),
            ..CameraSpec::default()
        };
        let Ok(camera) = spec.build(|_| None) else {
            return;
        };
        assert!(camera.tan_half_vfov.is_finite() && camera.tan_half_vfov > 0.0);
        for depth in [0.01, 0.5, 3.0, 1e4, f32::INFINITY] {
            let coc = camera.coc_px(depth);
            assert!(coc.is_finite() && coc >= 0.0, "coc {coc} at {depth}");
        }
        for (px, py, lx, ly) in [(6.0, 4.0, 0.0, 0.0), (0.5, 0.5, 0.9, -0.9), (11.5, 7.5, -0.3, 0.7)] {
            let (ray, w) = camera.lens_ray_weighted(px, py, Vec2::new(lx, ly));
            assert!(w.is_finite() && w >= 0.0, "weight {w}");
            assert!(ray.origin.is_finite() && ray.dir.is_finite());
            assert!((ray.dir.length() - 1.0).abs() < 1e-3);
            // Where the lens images a point of that ray, and light arriving back along it:
            // finite film positions, a positive measure, a share in [0, 1].
            let p = ray.at(2.0);
            if let Some(film) = camera.project(p) {
                assert!(film.is_finite(), "projected to {film}");
            }
            let entry = camera.lens.entry_point(Vec2::new(0.5 + 0.4 * lx, 0.5 + 0.4 * ly));
            if let Some(l) = camera.film_point(entry, ray.dir) {
                assert!(l.film.is_finite() && l.per_sr.is_finite() && l.per_sr > 0.0);
            }
            let share = camera.lens.entry_yield(&camera, p);
            assert!((0.0..=1.0).contains(&share), "yield {share}");
        }
    });
});
