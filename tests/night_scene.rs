//! The night street, `scenes/night.toml`: it is exactly what its generator
//! (`examples/make_night_street.rs`, included here) writes, its far bulbs are small lights
//! defocused to discs many times their size, and adaptive rendering keeps their light.

#[allow(dead_code)]
#[path = "../examples/make_night_street.rs"]
mod make_night_street;

use crate::scene_assets;

use std::path::PathBuf;

use dofray::embree::Device;
use dofray::render::{Mode, NoProgress, RenderSettings, render};
use dofray::scene::{self, Object, SceneDesc, World};
use glam::Vec3;

fn load() -> SceneDesc {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/night.toml");
    scene::load(path.to_str().unwrap()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_committed_scene_is_what_the_generator_writes() {
    scene_assets::assert_generated(
        "night.toml",
        "make_night_street",
        &make_night_street::generate(),
    );
}

#[test]
fn its_far_bulbs_are_small_lights_blurred_to_large_discs() {
    let desc = load();
    let camera = desc.camera.build(|_| None).unwrap();
    let bulb = |m: usize| desc.materials[m].emission.max_element() > 100.0;
    let mut far = 0;
    for o in &desc.objects {
        let Object::Sphere {
            center,
            radius,
            material,
        } = o
        else {
            continue;
        };
        if !bulb(*material) {
            continue;
        }
        let depth = (*center - camera.eye).dot(camera.forward);
        let size = 2.0 * radius * camera.pixels_per_unit() / depth;
        if depth > 3.5 * camera.focus_distance() {
            far += 1;
            assert!(size < 2.6, "a bulb {size} px across at depth {depth}");
            assert!(camera.coc_px(depth) > 5.0 * size, "{depth}: {size} px");
        }
    }
    assert!(far >= 24, "{far} far bulbs");
}

/// The light of the upper third of a small render (the bulbs and the walls they light).
fn upper_light(desc: &SceneDesc, mode: Mode) -> f64 {
    let world = World::build(desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    let settings = RenderSettings {
        mode,
        spp: 16,
        seed: 3,
        ..Default::default()
    };
    let film = render(&world, &camera, &settings, &NoProgress).unwrap().0;
    assert!(film.color.iter().all(|c| c.is_finite()));
    let rows = desc.camera.height as usize / 3;
    let width = desc.camera.width as usize;
    let sum: Vec3 = film.color[..rows * width].iter().sum();
    f64::from(sum.element_sum())
}

#[test]
fn adaptive_keeps_the_small_bulbs_light() {
    let mut desc = load();
    (desc.camera.width, desc.camera.height) = (192, 108);
    let dense = upper_light(&desc, Mode::Dense);
    let adaptive = upper_light(&desc, Mode::Adaptive);
    let ratio = adaptive / dense;
    assert!((ratio - 1.0).abs() < 0.03, "adaptive / dense {ratio}");
}
