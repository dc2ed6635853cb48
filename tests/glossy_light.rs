//! Lamps seen in glossy surfaces, traced from the light too (`render::glossy_light`): a
//! polished ball's highlight of a point light, an emissive ball or a softbox, out of focus,
//! keeps its energy (light tracing on or off agree),
//! comes out far less noisy, and regions and thread counts get the same splats; a scene with
//! nothing glossy renders exactly as without it.

use std::path::Path;

use dofray::render::{self, Film, Mode, NoProgress, Region, RenderSettings, SettingsPatch};
use dofray::scene::{SceneDesc, World};

const WIDTH: u32 = 96;
const HEIGHT: u32 = 72;

/// An 85 mm f/1.4 lens focused at 4 m looking down +z from the origin at a ball of `roughness`
/// (metal) 1.2 m away, blurred to a disc about 8 px across, lit by a point light above and
/// beside the camera; black around it, a grey floor far below.
fn scene(roughness: f32, metallic: f32) -> SceneDesc {
    with_lamp(roughness, metallic, POINT_LAMP)
}

/// The point light of [`scene`].
const POINT_LAMP: &str = r#"
[[lights]]
type = "point"
position = [0.4, 0.5, 0.3]
intensity = 20
"#;

/// [`scene`]'s lamp as an emissive ball `diameter` cm across instead (out of view, as bright
/// in all): its glossy reflection is traced from the emitter's surface.
fn emissive_lamp(diameter: f32) -> String {
    let emission = 20.0 / (std::f32::consts::PI * (diameter / 200.0).powi(2));
    format!(
        r#"
[[materials]]
name = "lamp"
diffuse = 0
emission = {emission}

[[objects]]
type = "sphere"
center = [0.4, 0.5, 0.3]
radius = {}
material = "lamp"
"#,
        diameter / 200.0
    )
}

/// The scene-file head every scene here shares: scene `name`, `lights` (`""` or `"lights =
/// []"`), the frame, an 85 mm f/1.4 lens at the origin looking down +z focused at 4 m, and a
/// black world.
fn frame(name: &str, lights: &str) -> String {
    format!(
        r#"
name = "{name}"
ambient = 0
{lights}

[image]
width = {WIDTH}
height = {HEIGHT}

[camera]
eye = [0, 0, 0]
look_at = [0, 0, 1]
f_number = 1.4
focal_length_mm = 85
sensor_width_mm = 36
focus_distance = 4

[background]
horizon = 0
zenith = 0
"#
    )
}

/// [`scene`] lit by `lamp` (scene-file tables) alone.
fn with_lamp(roughness: f32, metallic: f32, lamp: &str) -> SceneDesc {
    // Without `[[lights]]` a scene file gets a default key light.
    let no_lights = if lamp.contains("[[lights]]") {
        ""
    } else {
        "lights = []"
    };
    let src = format!(
        r#"{}
{lamp}

[[materials]]
name = "ball"
diffuse = 0.9
metallic = {metallic}
roughness = {roughness}

[[materials]]
name = "floor"
diffuse = 0.5

[[objects]]
type = "sphere"
center = [0, 0, 1.2]
radius = 0.12
material = "ball"

[[objects]]
type = "quad"
size = [20, 20]
translate = [0, -1, 2]
material = "floor"
"#,
        frame("ball", no_lights)
    );
    dofray::scene::file::parse(&src, Path::new("ball.toml")).unwrap()
}

/// Settings of `mode` at `spp` with light tracing on or off and `seed` (shared with
/// `caustics.rs`).
pub(crate) fn settings(mode: Mode, spp: u32, light_tracing: bool, seed: u64) -> RenderSettings {
    SettingsPatch {
        mode: Some(mode),
        spp: Some(spp),
        light_tracing: Some(light_tracing),
        seed: Some(seed),
        ..Default::default()
    }
    .resolve()
    .unwrap()
}

/// `desc` rendered with `settings` (shared with `caustics.rs`).
pub(crate) fn render(desc: &SceneDesc, settings: &RenderSettings) -> Film {
    let device = dofray::embree::Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    render::render(&world, &camera, settings, &NoProgress)
        .unwrap()
        .0
}

/// The summed colour (mean of the channels) of the pixels where `mask` holds.
fn total(film: &Film, mask: impl Fn(usize) -> bool) -> f64 {
    (film.color.iter().enumerate())
        .filter(|&(i, _)| mask(i))
        .map(|(_, c)| f64::from(c.x + c.y + c.z) / 3.0)
        .sum()
}

/// Root mean square difference of two films over the pixels where `mask` holds.
fn rms_difference(a: &Film, b: &Film, mask: impl Fn(usize) -> bool) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, (p, q)) in a.color.iter().zip(&b.color).enumerate() {
        if mask(i) {
            sum += f64::from((*p - *q).length_squared());
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// How much two seeds' renders of `desc` differ on the ball at 32 spp (rms), with the camera
/// alone and with light paths.
fn seed_noise(desc: &SceneDesc) -> (f64, f64) {
    let pair = |lt: bool| {
        let a = render(desc, &settings(Mode::Dense, 32, lt, 11));
        let b = render(desc, &settings(Mode::Dense, 32, lt, 12));
        rms_difference(&a, &b, on_ball)
    };
    let (off, on) = (pair(false), pair(true));
    eprintln!("seed-to-seed difference: {off:.4} camera alone, {on:.4} with light paths");
    (off, on)
}

/// The ball's blurred image: the upper middle of the frame (the floor is lower down).
fn on_ball(i: usize) -> bool {
    let (x, y) = (i % WIDTH as usize, i / WIDTH as usize);
    (28..68).contains(&x) && (10..56).contains(&y)
}

#[test]
fn a_polished_balls_highlight_keeps_its_light_and_loses_its_speckle() {
    let ball = scene(0.08, 1.0);
    // Energy: the ball's light with the camera alone (many samples: it finds the highlight
    // rarely) against the camera and the lamp's paths together, at a quarter of the samples.
    let seeds = [1u64, 2, 3];
    let off: f64 = (seeds.iter())
        .map(|&s| {
            total(
                &render(&ball, &settings(Mode::Dense, 256, false, s)),
                on_ball,
            )
        })
        .sum::<f64>()
        / seeds.len() as f64;
    let on: f64 = (seeds.iter())
        .map(|&s| total(&render(&ball, &settings(Mode::Dense, 64, true, s)), on_ball))
        .sum::<f64>()
        / seeds.len() as f64;
    eprintln!("light on the ball: camera alone {off:.3}, with light paths {on:.3}");
    assert!(off > 10.0, "the highlight is there: {off}");
    assert!(
        (on / off - 1.0).abs() < 0.03,
        "light on the ball: camera alone {off:.2}, with light paths {on:.2}"
    );
    // Noise: two seeds differ far less with light paths.
    let (noise_off, noise_on) = seed_noise(&ball);
    assert!(
        noise_on * 4.0 < noise_off,
        "seed-to-seed difference on the ball: {noise_off:.4} camera alone, {noise_on:.4} with light paths"
    );
}

#[test]
fn an_emissive_balls_reflection_keeps_its_light_and_loses_its_speckle() {
    // Energy, where the camera alone is precise enough to check it: a 10 cm lamp on a ball
    // of roughness 0.15.
    let ball = with_lamp(0.15, 1.0, &emissive_lamp(10.0));
    let mean = |spp: u32, lt: bool, seeds: std::ops::RangeInclusive<u64>| {
        let n = seeds.clone().count() as f64;
        (seeds.map(|s| total(&render(&ball, &settings(Mode::Dense, spp, lt, s)), on_ball)))
            .sum::<f64>()
            / n
    };
    let (off, on) = (mean(256, false, 1..=3), mean(64, true, 1..=6));
    eprintln!("light on the ball: camera alone {off:.3}, with light paths {on:.3}");
    assert!(off > 100.0, "the highlight is there: {off}");
    assert!(
        (on / off - 1.0).abs() < 0.04,
        "light on the ball: camera alone {off:.2}, with light paths {on:.2}"
    );
    // Noise, where the camera finds the lamp rarely: a 4 cm lamp on a ball of roughness 0.08.
    let ball = with_lamp(0.08, 1.0, &emissive_lamp(4.0));
    let (noise_off, noise_on) = seed_noise(&ball);
    assert!(
        noise_on * 3.0 < noise_off,
        "seed-to-seed difference on the ball: {noise_off:.4} camera alone, {noise_on:.4} with light paths"
    );
}

/// A small polished ball of `roughness` 0.6 m in front of an 85 mm f/1.4 lens focused at 4 m
/// (a disc about 40 px across in a 96 px frame, the ball itself about 7 px), lit only by a
/// 1 x 1 m softbox (an emissive quad, two triangles) beside and behind the camera: the ball's
/// blurred reflection of the panel is the whole image.
fn softbox(roughness: f32) -> SceneDesc {
    let src = format!(
        r#"{}
[[materials]]
name = "panel"
diffuse = 0
emission = 20

[[materials]]
name = "ball"
diffuse = 0.9
metallic = 1.0
roughness = {roughness}

[[objects]]
type = "quad"
size = [1, 1]
rotate = [90, 0, 0]
translate = [0.6, 0.6, -1.5]
material = "panel"

[[objects]]
type = "sphere"
center = [0, 0, 0.6]
radius = 0.02
material = "ball"
"#,
        frame("softbox", "lights = []")
    );
    dofray::scene::file::parse(&src, Path::new("softbox.toml")).unwrap()
}

#[test]
fn a_softboxs_reflection_in_a_small_ball_keeps_its_light_and_loses_its_speckle() {
    // A panel's light paths leave from a point of it towards the ball (`Aim::FromPoint`):
    // from the panel's centre, cones holding the ball as seen from all of the panel found it
    // in 1 of tens of thousands of directions, and the camera kept the reflection, speckled.
    let ball = softbox(0.15);
    let all = |_: usize| true;
    let mean = |spp: u32, lt: bool, seeds: std::ops::RangeInclusive<u64>| {
        let n = seeds.clone().count() as f64;
        (seeds.map(|s| total(&render(&ball, &settings(Mode::Dense, spp, lt, s)), all))).sum::<f64>()
            / n
    };
    let (off, on) = (mean(256, false, 1..=3), mean(64, true, 1..=3));
    eprintln!("light in the frame: camera alone {off:.3}, with light paths {on:.3}");
    assert!(off > 1.0, "the reflection is there: {off}");
    assert!(
        (on / off - 1.0).abs() < 0.03,
        "light in the frame: camera alone {off:.3}, with light paths {on:.3}"
    );
    let pair = |lt: bool| {
        let a = render(&ball, &settings(Mode::Dense, 32, lt, 11));
        let b = render(&ball, &settings(Mode::Dense, 32, lt, 12));
        rms_difference(&a, &b, all)
    };
    let (noise_off, noise_on) = (pair(false), pair(true));
    eprintln!(
        "seed-to-seed difference: {noise_off:.5} camera alone, {noise_on:.5} with light paths"
    );
    assert!(
        noise_on * 4.0 < noise_off,
        "seed-to-seed difference: {noise_off:.5} camera alone, {noise_on:.5} with light paths"
    );
}

#[test]
fn adaptive_mode_keeps_the_highlights_light() {
    // A point light's highlight (on the ball), and a softbox's reflection (the whole frame).
    let all = |_: usize| true;
    let cases: [(SceneDesc, &dyn Fn(usize) -> bool); 2] =
        [(scene(0.08, 1.0), &on_ball), (softbox(0.15), &all)];
    for (ball, mask) in cases {
        let dense = total(&render(&ball, &settings(Mode::Dense, 64, true, 5)), mask);
        let adaptive = total(&render(&ball, &settings(Mode::Adaptive, 64, true, 5)), mask);
        eprintln!("light on the ball: dense {dense:.3}, adaptive {adaptive:.3}");
        assert!(
            (adaptive / dense - 1.0).abs() < 0.05,
            "light on the ball: dense {dense:.2}, adaptive {adaptive:.2}"
        );
    }
}

#[test]
fn a_rough_ball_renders_as_without_light_paths() {
    // Roughness 0.6: nothing is glossy enough to trace from the lamp, so nothing changes.
    let ball = scene(0.6, 1.0);
    let on = render(&ball, &settings(Mode::Adaptive, 16, true, 1));
    let off = render(&ball, &settings(Mode::Adaptive, 16, false, 1));
    assert_eq!(on.color, off.color);
}

#[test]
fn regions_and_thread_counts_get_the_same_glossy_splats() {
    // A point light's paths, and a panel's (aimed from the points they leave).
    for ball in [scene(0.1, 0.5), softbox(0.15)] {
        let s = settings(Mode::Adaptive, 16, true, 1);
        let region = Region {
            x0: 40,
            y0: 20,
            x1: 70,
            y1: 40,
        };
        crate::light_tracing::same_in_a_region_and_on_one_thread(&ball, &s, &region);
    }
}
