//! Alpha as coverage (`--transparent`, `[render] transparent`): the filtered, lens-weighted
//! fraction of camera samples that hit geometry. Checked against geometry (a sphere's
//! projected area, in focus and blurred), against the opaque render (the background is the
//! only difference), and through adaptive interpolation.

use std::path::PathBuf;

use dofray::embree::Device;
use dofray::render::{Film, Mode, NoProgress, RenderSettings, SamplingRule, render};
use dofray::scene::{self, SceneDesc, World};
use glam::Vec3;

use crate::scratch::Scratch;

const SIZE: u32 = 96;
const VFOV_DEG: f32 = 30.0;
const RADIUS: f32 = 0.5;
const DISTANCE: f32 = 5.0;
const BACKGROUND: [f32; 3] = [0.2, 0.4, 0.9];

/// A grey sphere of radius 0.5 at the origin seen from 5 units away, on a uniform background,
/// lit only by ambient light; `lens` adds camera keys.
fn sphere_scene(test: &str, lens: &str) -> SceneDesc {
    let dir = Scratch::new(&format!("coverage-{test}"));
    let [r, g, b] = BACKGROUND;
    let toml = format!(
        r#"
ambient = 1
lights = []

[image]
width = {SIZE}
height = {SIZE}

[camera]
eye = [0, 0, {DISTANCE}]
look_at = [0, 0, 0]
vfov = {VFOV_DEG}
{lens}

[background]
color = [{r}, {g}, {b}]

[[materials]]
name = "grey"
diffuse = 0.5

[[objects]]
type = "sphere"
radius = {RADIUS}
material = "grey"
"#
    );
    let path: PathBuf = dir.join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    scene::load(path.to_str().unwrap()).unwrap()
}

fn render_with(desc: &SceneDesc, settings: &RenderSettings) -> Film {
    let world = World::build(desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    render(&world, &camera, settings, &NoProgress).unwrap().0
}

fn settings(mode: Mode, transparent: bool) -> RenderSettings {
    RenderSettings {
        mode,
        spp: 64,
        aa: 16,
        seed: 5,
        transparent,
        ..Default::default()
    }
}

/// The sphere's silhouette area in pixels: seen on axis it is a disc of angular radius
/// asin(r / d), i.e. radius f tan(asin(r / d)) = f r / sqrt(d^2 - r^2) on the image plane.
fn projected_area() -> f32 {
    let f = SIZE as f32 / 2.0 / (VFOV_DEG.to_radians() / 2.0).tan();
    let radius = f * RADIUS / (DISTANCE * DISTANCE - RADIUS * RADIUS).sqrt();
    std::f32::consts::PI * radius * radius
}

fn total_alpha(film: &Film) -> f32 {
    film.alpha.iter().sum()
}

#[test]
fn coverage_integrates_to_the_silhouette_in_focus_and_blurred() {
    let want = projected_area();
    let sharp = sphere_scene("sharp", "");
    // Focused far behind the sphere: its silhouette is spread over a CoC of several pixels,
    // but blur moves coverage around without creating or destroying it.
    let blurred = sphere_scene("blurred", "aperture_radius = 0.25\nfocus_distance = 9");
    for (name, desc, mode) in [
        ("pinhole", &sharp, Mode::Pinhole),
        ("dense, in focus", &sharp, Mode::Dense),
        ("dense, blurred", &blurred, Mode::Dense),
        ("adaptive, blurred", &blurred, Mode::Adaptive),
    ] {
        let film = render_with(desc, &settings(mode, true));
        let got = total_alpha(&film);
        assert!(
            (got - want).abs() < 0.01 * want,
            "{name}: total coverage {got} px, silhouette {want} px"
        );
        assert!(film.alpha.iter().all(|a| (0.0..=1.0).contains(a)));
        // Far corners see only background: transparent black.
        assert_eq!(film.alpha[0], 0.0, "{name}");
        assert_eq!(film.color[0], Vec3::ZERO, "{name}");
        // The centre sees only the sphere.
        let centre = (SIZE / 2 * SIZE + SIZE / 2) as usize;
        assert_eq!(film.alpha[centre], 1.0, "{name}");
        // Partial coverage exists along the rim (anti-aliased or blurred edges).
        let partial = film.alpha.iter().filter(|&&a| a > 0.05 && a < 0.95).count();
        assert!(partial > 20, "{name}: only {partial} partly covered pixels");
    }
    // The blurred edge is wider than the sharp one.
    let partial = |film: &Film| film.alpha.iter().filter(|&&a| a > 0.05 && a < 0.95).count();
    let sharp_edge = partial(&render_with(&sharp, &settings(Mode::Dense, true)));
    let blurred_edge = partial(&render_with(&blurred, &settings(Mode::Dense, true)));
    assert!(
        blurred_edge > 2 * sharp_edge,
        "blurred edge {blurred_edge} px, sharp {sharp_edge} px"
    );
}

#[test]
fn transparent_colour_is_the_opaque_colour_without_the_background() {
    let desc = sphere_scene("over", "aperture_radius = 0.25\nfocus_distance = 9");
    let opaque = render_with(&desc, &settings(Mode::Dense, false));
    let clear = render_with(&desc, &settings(Mode::Dense, true));
    assert!(opaque.alpha.iter().all(|&a| a == 1.0));
    let background = Vec3::from(BACKGROUND);
    // Same samples: composing the transparent render over the background gives the opaque
    // render (the "over" operation a compositor performs with a plate).
    for p in 0..opaque.color.len() {
        let over = clear.color[p] + (1.0 - clear.alpha[p]) * background;
        assert!(
            (over - opaque.color[p]).abs().max_element() < 1e-4,
            "pixel {p}: {over} over vs {} opaque",
            opaque.color[p]
        );
    }
}

#[test]
fn adaptive_checks_coverage_where_colour_cannot_tell() {
    // A black sphere on nothing: colour is 0 everywhere in a transparent render, so only the
    // coverage shows the edge. Its interpolated rim must still follow the silhouette.
    let mut desc = sphere_scene("black", "aperture_radius = 0.25\nfocus_distance = 9");
    desc.materials.iter_mut().for_each(|m| {
        m.base_color = dofray::shade::Texture::Constant(Vec3::ZERO);
    });
    let reference = render_with(
        &desc,
        &RenderSettings {
            spp: 512,
            seed: 99,
            ..settings(Mode::Dense, true)
        },
    );
    let dense = render_with(&desc, &settings(Mode::Dense, true));
    let adaptive = render_with(
        &desc,
        &RenderSettings {
            rule: SamplingRule::ErrorControlled { tolerance: None },
            ..settings(Mode::Adaptive, true)
        },
    );
    let rms = |film: &Film| {
        let sum: f32 = (film.alpha.iter().zip(&reference.alpha))
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        (sum / film.alpha.len() as f32).sqrt()
    };
    let (d, a) = (rms(&dense), rms(&adaptive));
    eprintln!("alpha RMS error vs 512 spp: dense {d}, adaptive {a}");
    assert!(
        a < 1.5 * d + 0.002,
        "alpha RMS error vs a 512-spp reference: adaptive {a}, dense {d}"
    );
    let interpolated = adaptive.samples.iter().filter(|&&n| n == 0).count();
    assert!(interpolated > 0, "nothing was interpolated");
}

#[test]
fn exposure_scales_radiance_by_powers_of_two() {
    let desc = sphere_scene("exposure", "aperture_radius = 0.25\nfocus_distance = 9");
    let base = render_with(&desc, &settings(Mode::Dense, false));
    let brighter = render_with(
        &desc,
        &RenderSettings {
            exposure: 2.0,
            ..settings(Mode::Dense, false)
        },
    );
    // Same samples, each scaled by 4 (exact in binary floating point).
    for (a, b) in base.color.iter().zip(&brighter.color) {
        assert_eq!(*a * 4.0, *b);
    }
    assert_eq!(base.alpha, brighter.alpha);
    for bad in [f32::NAN, f32::INFINITY, 65.0, -65.0] {
        let s = RenderSettings {
            exposure: bad,
            ..Default::default()
        };
        assert!(s.validate().is_err(), "exposure {bad} accepted");
    }
}
