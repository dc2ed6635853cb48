//! The real-lens camera against optics: the shipped prescriptions' paraxial numbers, focus,
//! the thin-lens limit, vignetting (cat's eye) and focus breathing, and lens files' errors.

use std::path::Path;
use std::sync::Arc;

use dofray::camera::optics::Optics;
use dofray::camera::{Camera, CameraLens, CameraSpec, Focus, Prescription, RealLens, RealLensSpec};

use crate::scratch::Scratch;

fn lens(name: &str) -> Arc<Prescription> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("lenses")
        .join(name);
    Arc::new(Prescription::load(&path).unwrap())
}

fn camera(p: &Arc<Prescription>, f_number: Option<f32>, focus: f32) -> Camera {
    camera_sized(p, f_number, focus, 360)
}

/// A 3:2 camera `width` pixels wide on a 36 mm film.
fn camera_sized(p: &Arc<Prescription>, f_number: Option<f32>, focus: f32, width: u32) -> Camera {
    CameraSpec {
        width,
        height: width * 2 / 3,
        focus: Focus::Distance(focus),
        real_lens: Some(RealLensSpec {
            prescription: p.clone(),
            f_number,
            sensor_width_mm: 36.0,
        }),
        ..CameraSpec::default()
    }
    .build(|_| None)
    .unwrap()
}

fn real(c: &Camera) -> &RealLens {
    match &c.lens {
        CameraLens::Real(l) => l,
        other => panic!("not a real lens: {other:?}"),
    }
}

/// Effective focal length and f-number as the sources publish them (Smith, Modern Lens
/// Design, scaled as the files say), within 1%.
#[test]
fn the_shipped_lenses_have_their_published_focal_lengths_and_f_numbers() {
    for (name, efl, f_number) in [
        ("double-gauss-50mm.dat", 50.0, 2.0),
        ("telephoto-250mm.dat", 250.0, 5.6),
        ("fisheye-10mm.dat", 10.0, 4.0),
        ("wide-22mm.dat", 22.0, 2.8),
    ] {
        let p = lens(name);
        let optics = Optics::new(&p, 0.0, 1.0);
        let para = optics.paraxial().unwrap();
        let n = para.efl / (2.0 * optics.entrance_pupil_radius());
        assert!(
            (para.efl / efl - 1.0).abs() < 0.01,
            "{name}: efl {}",
            para.efl
        );
        assert!((n / f_number - 1.0).abs() < 0.01, "{name}: f/{n}");
        // The camera reports the lens's own numbers (wide open, focused far away).
        let c = camera(&p, None, 1e6);
        let l = real(&c);
        assert!((f64::from(l.focal_length_mm) / efl - 1.0).abs() < 0.01);
        assert!((f64::from(l.f_number) / f_number - 1.0).abs() < 0.01);
        // Stopped down by a stop, it reports that.
        let c = camera(&p, Some(2.0 * f_number as f32), 1e6);
        assert!((f64::from(real(&c).f_number) / (2.0 * f_number) - 1.0).abs() < 0.01);
    }
}

/// The RMS radius on the film of the rays from the axial point `distance` metres in front of
/// the camera (`eye_z` in lens space) through the lens.
fn rms_spot(optics: &Optics, eye_z: f64, distance: f64) -> f64 {
    dofray::camera::optics::rms_spot(optics, eye_z + distance * 1000.0).unwrap()
}

/// Focused at d, the lens images the axial point at d sharpest (smallest RMS spot, found by
/// golden-section search over depth), within 1% of d.
#[test]
fn a_lens_focused_at_d_images_d_sharpest() {
    for (name, f_number) in [("double-gauss-50mm.dat", 4.0), ("telephoto-250mm.dat", 8.0)] {
        let p = lens(name);
        for d in [1.5f32, 4.0] {
            let c = camera(&p, Some(f_number), d);
            let l = real(&c);
            let (optics, eye_z) = (l.optics(), l.eye_z());
            let (mut a, mut b) = (0.7 * f64::from(d), 1.4 * f64::from(d));
            let g = 0.5 * (5f64.sqrt() - 1.0);
            for _ in 0..40 {
                let (x1, x2) = (b - g * (b - a), a + g * (b - a));
                if rms_spot(optics, eye_z, x1) < rms_spot(optics, eye_z, x2) {
                    b = x2;
                } else {
                    a = x1;
                }
            }
            let best = 0.5 * (a + b);
            assert!(
                (best / f64::from(d) - 1.0).abs() < 0.01,
                "{name} at f/{f_number} focused at {d}: sharpest at {best}"
            );
        }
    }
}

/// A single thin element (a 0.2 mm thick biconvex of 50 mm focal length at f/62, its stop
/// at the element) blurs as the thin lens of the same focal length and aperture does:
/// `CoC = A f / (d_f - f) |d - d_f| / d`, within 1% at 7 depths.
#[test]
fn one_thin_element_is_the_thin_lens() {
    // 1/f = (n - 1) 2/R for a thin biconvex: R = 2 (n - 1) f.
    let (n, f) = (1.5f64, 50.0f64);
    let r = 2.0 * (n - 1.0) * f;
    let text = format!("0 0.01 0 0.8\n{r} 0.2 {n} 20\n{} 0 1 20\n", -r);
    let p = Arc::new(Prescription::parse(&text, "thin").unwrap());
    let focus = 2.0f32;
    // 5 um pixels, so that blur is measured in many of them.
    let c = camera_sized(&p, None, focus, 7200);
    let l = real(&c);
    let efl = f64::from(l.focal_length_mm);
    let pitch = 36.0 / 7200.0;
    let a = 2.0 * f64::from(c.aperture_radius()) * 1000.0;
    // Away from the plane in focus, where the blur is the defocus's, not the residual
    // spherical aberration's.
    for depth in [0.4f32, 0.6, 0.9, 5.0, 10.0, 30.0, 1000.0] {
        let (d, df) = (f64::from(depth) * 1000.0, f64::from(focus) * 1000.0);
        let thin = a * efl / (df - efl) * (d - df).abs() / d / pitch;
        let traced = f64::from(l.blur_px(0.0, depth));
        assert!(
            (traced / thin - 1.0).abs() < 0.01,
            "at {depth} m: traced {traced} px, thin lens {thin} px"
        );
        // The bound the adaptive sampler trusts holds it.
        assert!(f64::from(c.coc_px(depth)) >= traced, "bound at {depth} m");
    }
}

/// Wide open, the double Gauss's corners get less light than its centre (natural and
/// optical vignetting: the cat's eye), falling steadily outwards; stopped down to f/8 the
/// optical part goes and the corners brighten.
#[test]
fn the_corners_vignette_and_stopping_down_brightens_them() {
    let p = lens("double-gauss-50mm.dat");
    let open = camera(&p, None, 3.0);
    let closed = camera(&p, Some(8.0), 3.0);
    let corner = (18.0f32 * 0.95, 12.0f32 * 0.95);
    let mut last = 1.01;
    for s in [0.0f32, 0.25, 0.5, 0.75, 1.0] {
        let e = real(&open).relative_illumination(corner.0 * s, corner.1 * s);
        assert!(
            e <= last && e > 0.0,
            "at {s} of the corner: {e} after {last}"
        );
        last = e;
    }
    assert!((real(&open).relative_illumination(0.0, 0.0) - 1.0).abs() < 1e-3);
    let stopped = real(&closed).relative_illumination(corner.0, corner.1);
    assert!(last < 0.6, "open corner {last}");
    assert!(stopped > last + 0.1, "f/8 corner {stopped} vs open {last}");
}

/// Focusing moves the lens away from the film, so the field of view narrows as focus comes
/// closer (focus breathing), by the ratio of the image distances: the field at focus d is
/// that at infinity times f / v, with 1/v = 1/f - 1/s (s from the front principal plane).
#[test]
fn the_field_of_view_breathes_with_focus() {
    let p = lens("double-gauss-50mm.dat");
    let far = camera(&p, None, 1e6);
    let near = camera(&p, None, 0.6);
    let ratio = near.tan_half_vfov / far.tan_half_vfov;
    assert!(ratio < 0.97, "{ratio}");
    // The thin-lens prediction, object distance measured from the camera (its pupil).
    let f = f64::from(real(&far).focal_length_mm);
    let s = 600.0;
    let v = 1.0 / (1.0 / f - 1.0 / s);
    let want = (f / v) as f32;
    assert!((ratio / want - 1.0).abs() < 0.03, "{ratio} vs {want}");
}

const SCENE: &str = "[camera]\neye = [0, 1, 4]\nlook_at = [0, 0.5, 0]\nfocus_distance = 4\n";
const OBJECT: &str = "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0.5, 0]\nradius = 0.5\n";

/// A scene file's `lens` is read relative to it, with `f_number` and `sensor_width_mm`;
/// its errors name the scene's line and key and the lens file's line; the thin lens's keys
/// and animated lens keys are refused beside it.
#[test]
fn scene_files_take_a_lens_and_point_at_its_faults() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses");
    let scene_path = dir.join("scene.toml");
    let parse = |extra: &str| {
        let src = format!("{SCENE}{extra}{OBJECT}");
        dofray::scene::file::parse(&src, &scene_path)
    };
    let desc = parse("lens = \"double-gauss-50mm.dat\"\nf_number = 4\n").unwrap();
    let real = desc.camera.real_lens.as_ref().unwrap();
    assert_eq!(real.f_number, Some(4.0));
    assert!(real.prescription.name.starts_with("Double Gauss"));
    let camera = desc.camera.build(|_| None).unwrap();
    assert!((camera.aperture_radius() * 1000.0 * 2.0 * 4.0 / 50.4 - 1.0).abs() < 0.02);

    let e = parse("lens = \"missing.dat\"\n").unwrap_err().to_string();
    assert!(
        e.contains("scene.toml:5") && e.contains("camera.lens") && e.contains("missing.dat"),
        "{e}"
    );
    let bad_dir = Scratch::new("bad-lens");
    let bad = bad_dir.join("bad-lens.dat");
    std::fs::write(&bad, "# bad\n10 2 1.5 10\n0 1 0 8\n-10 0 1.5 10 x\n").unwrap();
    let e = parse(&format!("lens = {:?}\n", bad.to_str().unwrap()))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&format!("{}:4: abbe", bad.display())), "{e}");
    bad_dir.close().unwrap();
    let e = parse("lens = \"double-gauss-50mm.dat\"\nvfov = 30\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scene.toml:6") && e.contains("camera.vfov"),
        "{e}"
    );
    let e = parse("lens = \"double-gauss-50mm.dat\"\nf_number = 1.2\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera.f_number") && e.contains("opens to f/2.0"),
        "{e}"
    );
    let e = parse(
        "lens = \"double-gauss-50mm.dat\"\n[animation]\n[[animation.key]]\nframe = 1\nf_number = 4\n",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("animation.key[0].f_number") && e.contains("real lens"),
        "{e}"
    );
}

/// `dofray render --lens` renders through the lens (finite, the centre as bright as through
/// a thin lens, the corners darker), and a bad lens file is bad input (exit 3) naming it.
#[test]
fn the_command_line_renders_through_a_lens() {
    let dir = Scratch::new("real-lens");
    let lens = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses/double-gauss-50mm.dat");
    let render = |extra: &[&str], out: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args([
                "render", "--width", "96", "--height", "64", "--spp", "8", "--mode", "dense",
            ])
            .args(extra)
            .arg("-o")
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    let real = render(&["--lens", lens.to_str().unwrap(), "--json"], "real.png");
    assert!(
        real.status.success(),
        "{}",
        String::from_utf8_lossy(&real.stderr)
    );
    // --json names the lens and its own numbers as focused.
    let json: serde_json::Value = serde_json::from_slice(&real.stdout).unwrap();
    let l = &json["lens"];
    assert!(l["name"].as_str().unwrap().contains("Gauss"), "{l}");
    let focal = l["focal_length_mm"].as_f64().unwrap();
    assert!((45.0..56.0).contains(&focal), "{l}");
    assert!((l["f_number"].as_f64().unwrap() - 2.0).abs() < 0.2, "{l}");
    assert!(l["vfov_deg"].as_f64().unwrap() > 20.0, "{l}");
    let thin = render(
        &["--f-number", "2", "--focal-length", "50", "--json"],
        "thin.png",
    );
    assert!(thin.status.success());
    let json: serde_json::Value = serde_json::from_slice(&thin.stdout).unwrap();
    assert!(json["lens"].is_null());
    let luma = |name: &str| {
        let img = image::open(dir.join(name)).unwrap().to_luma32f();
        let mean = |x0: u32, y0: u32| {
            let mut s = 0.0;
            for y in y0..y0 + 8 {
                for x in x0..x0 + 8 {
                    s += img.get_pixel(x, y).0[0];
                }
            }
            s / 64.0
        };
        (mean(44, 28), mean(0, 56))
    };
    let ((real_centre, real_corner), (thin_centre, _)) = (luma("real.png"), luma("thin.png"));
    assert!(real_centre > 0.0 && real_corner.is_finite());
    assert!(
        (real_centre / thin_centre - 1.0).abs() < 0.15,
        "{real_centre} vs {thin_centre}"
    );
    let bad = dir.join("bad.dat");
    std::fs::write(&bad, "# x\n10 2 1.5\n").unwrap();
    let out = render(&["--lens", bad.to_str().unwrap()], "bad.png");
    assert_eq!(out.status.code(), Some(3));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.dat:2:"), "{stderr}");
    let out = render(
        &["--lens", lens.to_str().unwrap(), "--blades", "6"],
        "x.png",
    );
    assert_eq!(out.status.code(), Some(2));
    dir.close().unwrap();
}

/// Defocused lamps through the double Gauss wide open: towards the corner their bokeh shrinks
/// into a cat's eye (narrower along the radius than across it), and its energy falls as the
/// lens's traced relative illumination says.
#[test]
fn bokeh_becomes_a_cats_eye_towards_the_corners() {
    let dir = Scratch::new("cats-eye");
    let (w, h) = (240u32, 160u32);
    // Two lamps of 0.1 m radius 10 m away (5 px images), seen at the centre and at (0.8,
    // 0.8) of the half frame, with the lens focused at 0.7 m: discs of about 14 px.
    let lens_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses/double-gauss-50mm.dat");
    let p = Arc::new(Prescription::load(&lens_path).unwrap());
    let spec = |focus: Focus| CameraSpec {
        eye: glam::Vec3::ZERO,
        look_at: -glam::Vec3::Z,
        width: w,
        height: h,
        focus,
        real_lens: Some(RealLensSpec {
            prescription: p.clone(),
            f_number: None,
            sensor_width_mm: 36.0,
        }),
        ..CameraSpec::default()
    };
    let camera = spec(Focus::Distance(0.7)).build(|_| None).unwrap();
    let corner_px = (0.5 * w as f32 * 1.8 - 0.5, 0.5 * h as f32 * 0.2);
    let at_10m = |px: f32, py: f32| {
        let ray = camera.pinhole_ray(px, py);
        ray.origin
            + ray.dir * ((10.0 - ray.origin.dot(camera.forward)) / ray.dir.dot(camera.forward))
    };
    let lamps = [
        at_10m(0.5 * w as f32, 0.5 * h as f32),
        at_10m(corner_px.0, corner_px.1),
    ];
    let mut scene = String::from(
        "[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, -1]\nfocus_distance = 0.7\nlens = \"LENS\"\n[world]\ncolor = [0, 0, 0]\n[[materials]]\nname = \"lamp\"\ndiffuse = [0, 0, 0]\nemission = [2, 2, 2]\n",
    )
    .replace("LENS", lens_path.to_str().unwrap());
    for c in lamps {
        scene += &format!(
            "[[objects]]\ntype = \"sphere\"\ncenter = [{}, {}, {}]\nradius = 0.1\nmaterial = \"lamp\"\n",
            c.x, c.y, c.z
        );
    }
    let scene_path = dir.join("lamps.toml");
    std::fs::write(&scene_path, scene).unwrap();
    let out = dir.join("lamps.exr");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args([
            "render",
            "--mode",
            "dense",
            "--spp",
            "64",
            "--width",
            &w.to_string(),
            "--height",
            &h.to_string(),
        ])
        .arg(&scene_path)
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    // The combined pass's green, linear, row by row.
    let layers = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    let green: Vec<f32> = layers.layer_data[0]
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "ViewLayer.Combined.G")
        .expect("a combined green channel")
        .sample_data
        .values_as_f32()
        .collect();
    let pixel = |x: u32, y: u32| green[(y * w + x) as usize];
    // Each disc's energy and its spread along and across the radius (second moments about
    // its centroid): robust to the noise of a few hundred samples.
    let disc = |cx: f32, cy: f32| {
        let radial =
            glam::Vec2::new(cx - 0.5 * w as f32, cy - 0.5 * h as f32).normalize_or(glam::Vec2::X);
        let mut sum = (0.0f32, glam::Vec2::ZERO);
        let near = |x: u32, y: u32| {
            glam::Vec2::new(x as f32 + 0.5 - cx, y as f32 + 0.5 - cy).length() <= 30.0
        };
        for y in 0..h {
            for x in 0..w {
                if near(x, y) {
                    let v = pixel(x, y);
                    sum.0 += v;
                    sum.1 += v * glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                }
            }
        }
        let centroid = sum.1 / sum.0;
        let (mut along, mut across) = (0.0f32, 0.0f32);
        for y in 0..h {
            for x in 0..w {
                if near(x, y) {
                    let d = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - centroid;
                    along += pixel(x, y) * d.dot(radial).powi(2);
                    across += pixel(x, y) * d.perp_dot(radial).powi(2);
                }
            }
        }
        (sum.0, (along / sum.0).sqrt(), (across / sum.0).sqrt())
    };
    let (c_energy, c_along, c_across) = disc(0.5 * w as f32, 0.5 * h as f32);
    let (k_energy, k_along, k_across) = disc(corner_px.0, corner_px.1);
    // The centre disc is round; the corner's is squeezed along the radius: a cat's eye.
    assert!(
        (c_along / c_across - 1.0).abs() < 0.1,
        "centre {c_along} x {c_across}"
    );
    assert!(
        k_along < 0.85 * k_across,
        "corner {k_along} along the radius, {k_across} across"
    );
    assert!(
        k_along * k_across < 0.8 * c_along * c_across,
        "corner disc not smaller"
    );
    let pitch = 36.0 / w as f32;
    let film = (
        (corner_px.0 - 0.5 * w as f32) * pitch,
        (corner_px.1 - 0.5 * h as f32) * pitch,
    );
    let predicted = real(&camera).relative_illumination(film.0, film.1);
    let ratio = k_energy / c_energy;
    assert!(
        (ratio / predicted - 1.0).abs() < 0.1,
        "energy ratio {ratio}, traced {predicted}"
    );
    dir.close().unwrap();
}

/// The blur bound stays a bound beyond its table, nearer than any lens focuses: it grows as
/// depth shrinks and never goes negative (the fuzzer found a lens whose last chord fell, so
/// extrapolating along it gave -767 px at 1 cm).
#[test]
fn the_blur_bound_holds_nearer_than_its_table() {
    let mut text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses/double-gauss-50mm.dat"),
    )
    .unwrap();
    text = text.replace("437.065", "874.065");
    let p = Arc::new(Prescription::parse(&text, "fuzzed").unwrap());
    let c = camera_sized(&p, None, 0.336, 12);
    let mut last = 0.0;
    // The table ends 5 cm in front of the front element, about 7 cm from the camera.
    for depth in [0.03f32, 0.02, 0.01, 0.001] {
        let coc = c.coc_px(depth);
        assert!(
            coc.is_finite() && coc >= last,
            "{coc} px at {depth} m after {last}"
        );
        last = coc;
    }
}

/// Small defocused lamps, light-traced through the double Gauss's front element, carry the
/// same light to each disc as the camera's own rays find (16 light-traced spp against 256
/// camera-only spp, dense): the two estimators of the real lens meet, vignetting included.
#[test]
fn light_traced_lamps_through_a_real_lens_match_the_camera() {
    let dir = Scratch::new("lens-light");
    let (w, h) = (150u32, 100u32);
    let lens_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses/double-gauss-50mm.dat");
    // Lamps 0.16 m across 10 m away (3.3 px sharp), focused at 0.7 m: discs of about 9 px,
    // at the centre, half way out and near the corner (tan of half the field of view
    // of a 50 mm lens on a 36 x 24 mm film: 0.36 x 0.24).
    let mut scene = String::from(
        "[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, -1]\nfocus_distance = 0.7\nlens = \"LENS\"\n[world]\ncolor = [0, 0, 0]\n[[materials]]\nname = \"lamp\"\ndiffuse = [0, 0, 0]\nemission = [2, 2, 2]\n",
    )
    .replace("LENS", lens_path.to_str().unwrap());
    let spots = [(0.0f32, 0.0f32), (0.45, 0.4), (0.8, -0.75)];
    for (x, y) in spots {
        scene += &format!(
            "[[objects]]\ntype = \"sphere\"\ncenter = [{}, {}, -10]\nradius = 0.08\nmaterial = \"lamp\"\n",
            x * 3.6,
            y * 2.4
        );
    }
    let scene_path = dir.join("lamps.toml");
    std::fs::write(&scene_path, scene).unwrap();
    let render = |light: &str, spp: &str| -> Vec<f32> {
        let out = dir.join(format!("lamps-{light}.exr"));
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args(["render", "--mode", "dense", "--light-tracing", light])
            .args([
                "--spp",
                spp,
                "--width",
                &w.to_string(),
                "--height",
                &h.to_string(),
            ])
            .arg(&scene_path)
            .arg("-o")
            .arg(&out)
            .status()
            .unwrap();
        assert!(status.success());
        let layers = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
        layers.layer_data[0]
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == "ViewLayer.Combined.G")
            .expect("a combined green channel")
            .sample_data
            .values_as_f32()
            .collect()
    };
    let traced = render("on", "16");
    let camera_only = render("off", "256");
    // Each lamp's light: the sum over a window around where its disc lands (the image is
    // inverted by neither: +x is right, +y is up).
    let energy = |img: &[f32], (x, y): (f32, f32)| {
        let cx = (0.5 + 0.5 * x) * w as f32;
        let cy = (0.5 - 0.5 * y) * h as f32;
        let mut sum = 0.0f64;
        for py in 0..h {
            for px in 0..w {
                let d = glam::Vec2::new(px as f32 + 0.5 - cx, py as f32 + 0.5 - cy);
                if d.length() < 14.0 {
                    sum += f64::from(img[(py * w + px) as usize]);
                }
            }
        }
        sum
    };
    for spot in spots {
        let (a, b) = (energy(&traced, spot), energy(&camera_only, spot));
        assert!(b > 0.0, "no light near {spot:?}");
        eprintln!("lamp at {spot:?}: light-traced / camera {:.4}", a / b);
        assert!(
            (a / b - 1.0).abs() < 0.05,
            "lamp at {spot:?}: light-traced {a}, camera {b}"
        );
    }
    let total = |img: &[f32]| img.iter().map(|&v| f64::from(v)).sum::<f64>();
    let ratio = total(&traced) / total(&camera_only);
    assert!((ratio - 1.0).abs() < 0.03, "whole image {ratio}");
    dir.close().unwrap();
}

/// A real lens projects a point where its chief ray images it, distortion included: the
/// fisheye's barrel distortion (far from the pinhole projection) and the double Gauss's
/// near-rectilinear image, at near and far depths.
#[test]
fn points_project_along_the_chief_rays() {
    for (name, sensor, focus) in [
        ("double-gauss-50mm.dat", 36.0, 2.0),
        ("fisheye-10mm.dat", 24.0, 1.0),
    ] {
        let camera = CameraSpec {
            width: 240,
            height: 160,
            focus: Focus::Distance(focus),
            real_lens: Some(RealLensSpec {
                prescription: lens(name),
                f_number: None,
                sensor_width_mm: sensor,
            }),
            ..CameraSpec::default()
        }
        .build(|_| None)
        .unwrap();
        let mut off_pinhole = 0.0f32;
        for (px, py) in [
            (120.0, 80.0),
            (30.5, 20.5),
            (200.0, 150.0),
            (5.0, 80.0),
            (235.0, 3.0),
        ] {
            // Beyond the fisheye's image circle the lens passes no chief ray.
            let (ray, weight) = camera.lens_ray_weighted(px, py, glam::Vec2::ZERO);
            if weight == 0.0 {
                continue;
            }
            for depth in [0.5f32, 3.0, 100.0] {
                let t = (depth - (ray.origin - camera.eye).dot(camera.forward))
                    / ray.dir.dot(camera.forward);
                // The fisheye's far corners look more than 90 degrees off the axis: no point
                // in front of the lens lies on those rays.
                if t.is_nan() || t <= 0.0 {
                    continue;
                }
                let p = ray.at(t);
                let got = camera.project(p).unwrap();
                assert!(
                    (got - glam::Vec2::new(px, py)).length() < 0.25,
                    "{name}: ({px}, {py}) at {depth} m projects to {got}"
                );
                if let Some(pin) = camera.pinhole_project(p) {
                    off_pinhole = off_pinhole.max((pin - got).length());
                }
            }
        }
        eprintln!("{name}: the pinhole projection is up to {off_pinhole:.1} px off");
        if name.starts_with("fisheye") {
            assert!(off_pinhole > 10.0, "{off_pinhole}");
        }
        // Behind the lens: no image.
        assert!(camera.project(camera.eye - camera.forward).is_none());
    }
}

/// The blur bound near a film position ([`Camera::coc_px_at`], what the blur map reads per
/// pixel) holds the spot traced there, between the table's radii as on them, wide open and
/// stopped down, and never exceeds the whole film's bound; the telephoto wide open, whose
/// corners are soft where its centre is sharp, is far sharper by it in the middle of the
/// frame than the whole film's bound says.
#[test]
fn the_blur_bound_near_a_film_position_holds_the_spot_there() {
    let half_diagonal = 0.5 * 36.0f32.hypot(24.0);
    for (name, f_number) in [
        ("double-gauss-50mm.dat", None),
        ("double-gauss-50mm.dat", Some(5.6)),
        ("telephoto-250mm.dat", None),
        ("wide-22mm.dat", None),
        ("fisheye-10mm.dat", None),
    ] {
        let p = lens(name);
        let focus = 4.0f32;
        let c = camera(&p, f_number, focus);
        let l = real(&c);
        let pitch = 36.0 / c.width as f32;
        for s in [0.0f32, 0.06, 0.19, 0.33, 0.47, 0.58, 0.71, 0.86, 0.93, 0.97] {
            let r = s * half_diagonal;
            // Film x runs opposite to the image's (the image is inverted on the film).
            let (px, py) = (0.5 * c.width as f32 - r / pitch, 0.5 * c.height as f32);
            for depth in [0.6f32, 1.5, 3.0, 3.9, focus, 4.1, 6.0, 20.0, 1e4] {
                let traced = l.blur_px(r, depth);
                let near = c.coc_px_at(depth, px, py);
                assert!(
                    near >= traced,
                    "{name} f/{f_number:?}: {near} px bound at {s} of the half diagonal, \
                     {depth} m, where the spot is {traced} px"
                );
                assert!(
                    near <= c.coc_px(depth),
                    "{name}: above the whole film's bound"
                );
            }
        }
    }
    let p = lens("telephoto-250mm.dat");
    let c = camera(&p, None, 4.0);
    let (centre, whole) = (c.coc_px_at(4.0, 180.0, 120.0), c.coc_px(4.0));
    assert!(
        centre < 0.5 * whole,
        "in focus: {centre} px at the centre against {whole} px over the film"
    );
}
