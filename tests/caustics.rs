//! Caustics traced from the lamp (`render::glossy_light`'s caustic paths, part of
//! `--light-tracing on`): a polished plate throws a lamp's light onto a floor that nothing
//! else lights. The floor keeps the light the camera alone finds (light tracing on or off
//! agree), and it comes out far less noisy.

use std::path::Path;

use dofray::render::{Film, Mode, RenderSettings};
use dofray::scene::SceneDesc;

use crate::glossy_light::render;

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;

/// A 35 mm f/2.8 lens at (0, 0.5, 0) looking down at a grey floor 3.5 m away; a metal plate of
/// `roughness`, tilted 45 degrees, hangs above it and reflects `lamp` (beside it, shaded from
/// the floor by a black board) straight down: the floor's only light is the plate's caustic.
fn scene(roughness: f32, lamp: &str) -> SceneDesc {
    plate_scene(roughness, 1.0, lamp)
}

/// [`scene`] with a plate of `metallic` (0: a glossy plastic, whose diffuse layer lights the
/// floor too).
fn plate_scene(roughness: f32, metallic: f32, lamp: &str) -> SceneDesc {
    // Without `[[lights]]` a scene file gets a default key light.
    let no_lights = if lamp.contains("[[lights]]") {
        ""
    } else {
        "lights = []"
    };
    let src = format!(
        r#"
name = "caustic"
ambient = 0
{no_lights}

[image]
width = {WIDTH}
height = {HEIGHT}

[camera]
eye = [0, 0.5, 0]
look_at = [0, -0.5, 3.5]
f_number = 2.8
focal_length_mm = 35
sensor_width_mm = 36
focus_distance = 3.5

[background]
horizon = 0
zenith = 0

{lamp}

[[materials]]
name = "plate"
diffuse = 0.9
metallic = {metallic}
roughness = {roughness}

[[materials]]
name = "floor"
diffuse = 0.8

[[materials]]
name = "shade"
diffuse = 0

[[objects]]
type = "quad"
size = [0.6, 0.6]
rotate = [0, 0, 135]
translate = [0, 0.4, 3.5]
material = "plate"

[[objects]]
type = "quad"
size = [6, 6]
translate = [0, -0.5, 3.5]
material = "floor"

[[objects]]
type = "quad"
size = [2.2, 2]
translate = [-1.5, 0.25, 3.5]
material = "shade"
"#
    );
    dofray::scene::file::parse(&src, Path::new("caustic.toml")).unwrap()
}

/// A 20 cm emissive ball beside the plate.
const BALL_LAMP: &str = r#"
[[materials]]
name = "lamp"
diffuse = 0
emission = 40

[[objects]]
type = "sphere"
center = [-1.5, 0.4, 3.5]
radius = 0.1
material = "lamp"
"#;

/// A narrow spot light in the same place, aimed at the plate.
const SPOT_LAMP: &str = r#"
[[lights]]
type = "spot"
position = [-1.5, 0.4, 3.5]
direction = [1, 0, 0]
intensity = 40
outer_angle = 8
inner_angle = 6
"#;

/// A parallel sun shining level along +x: it lights the plate and, grazing, not the floor.
const SUN_LAMP: &str = r#"
[[lights]]
type = "directional"
direction = [1, 0, 0]
irradiance = 3
"#;

/// Dense settings at `spp` with light tracing on or off and `seed`.
fn settings(spp: u32, light_tracing: bool, seed: u64) -> RenderSettings {
    crate::glossy_light::settings(Mode::Dense, spp, light_tracing, seed)
}

/// The floor below the plate: the lower 30 rows of the frame.
fn on_floor(i: usize) -> bool {
    i / WIDTH as usize >= 18
}

/// The summed colour (mean of the channels) of the floor.
fn floor_light(film: &Film) -> f64 {
    (film.color.iter().enumerate())
        .filter(|&(i, _)| on_floor(i))
        .map(|(_, c)| f64::from(c.x + c.y + c.z) / 3.0)
        .sum()
}

/// The mean floor light over `seeds` at `spp`, with light tracing `on` or off.
fn mean_floor(desc: &SceneDesc, spp: u32, on: bool, seeds: std::ops::RangeInclusive<u64>) -> f64 {
    let n = seeds.clone().count() as f64;
    seeds
        .map(|s| floor_light(&render(desc, &settings(spp, on, s))))
        .sum::<f64>()
        / n
}

/// Root mean square difference of two renders over the floor.
fn floor_rms(a: &Film, b: &Film) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, (p, q)) in a.color.iter().zip(&b.color).enumerate() {
        if on_floor(i) {
            sum += f64::from((*p - *q).length_squared());
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

#[test]
fn a_plates_caustic_of_an_emissive_ball_keeps_its_light_and_loses_its_speckle() {
    let desc = scene(0.3, BALL_LAMP);
    // The camera alone, with many samples: it finds the ball in the plate rarely.
    let off = mean_floor(&desc, 1024, false, 1..=3);
    let on = mean_floor(&desc, 64, true, 1..=2);
    eprintln!("light on the floor: camera alone {off:.3}, with light paths {on:.3}");
    assert!(off > 1.0, "the caustic is there: {off}");
    // Dropping the camera's caustic paths without tracing them from the lamp would leave the
    // floor black; counting them on both sides would double it. (The camera alone is the
    // noisier: its three seeds spread by about 2%.)
    assert!(
        (on / off - 1.0).abs() < 0.06,
        "light on the floor: camera alone {off:.3}, with light paths {on:.3}"
    );
    let pair = |on: bool| {
        let (a, b) = (
            render(&desc, &settings(32, on, 11)),
            render(&desc, &settings(32, on, 12)),
        );
        floor_rms(&a, &b)
    };
    let (noise_off, noise_on) = (pair(false), pair(true));
    eprintln!("seed-to-seed difference: {noise_off:.4} camera alone, {noise_on:.4} light paths");
    assert!(
        noise_on * 3.0 < noise_off,
        "seed-to-seed difference on the floor: {noise_off:.4} camera alone, {noise_on:.4} with light paths"
    );
}

#[test]
fn a_plates_caustic_of_a_spot_light_or_a_sun_keeps_its_light() {
    // Lamps the camera finds only by its light samples from the plate: a spot, and a sun
    // (whose light paths start across its beam); and a plastic plate under the spot, whose
    // diffuse layer's light stays with the camera while its coat's goes to the light paths.
    for (metallic, lamp) in [(1.0, SPOT_LAMP), (1.0, SUN_LAMP), (0.0, SPOT_LAMP)] {
        caustic_keeps_its_light(&plate_scene(0.3, metallic, lamp));
    }
}

/// The floor's light in `desc` is the same from the camera alone as with light paths.
fn caustic_keeps_its_light(desc: &SceneDesc) {
    let off = mean_floor(desc, 1024, false, 1..=4);
    let on = mean_floor(desc, 64, true, 1..=2);
    eprintln!("light on the floor: camera alone {off:.3}, with light paths {on:.3}");
    assert!(off > 1.0, "the caustic is there: {off}");
    assert!(
        (on / off - 1.0).abs() < 0.06,
        "light on the floor: camera alone {off:.3}, with light paths {on:.3}"
    );
}
