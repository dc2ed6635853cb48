//! The hard depth-of-field scene, `scenes/bokeh.toml`: it is exactly what its generator
//! (`examples/make_hard_scene.rs`, included here) writes, and it has what it is meant to test:
//! small lamps defocused in front of and behind the focus, with discs much larger than the lamps.

#[allow(dead_code)]
#[path = "../examples/make_hard_scene.rs"]
mod make_hard_scene;

use crate::scene_assets;

use std::path::PathBuf;

use dofray::camera::Camera;
use dofray::embree::Device;
use dofray::render::{Mode, NoProgress, RenderSettings, render};
use dofray::scene::{self, Object, SceneDesc, World};
use glam::Vec3;

fn path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/bokeh.toml")
}

fn load() -> SceneDesc {
    scene::load(path().to_str().unwrap()).unwrap_or_else(|e| panic!("{e}"))
}

fn camera(desc: &SceneDesc) -> Camera {
    desc.camera.build(|_| None).unwrap()
}

#[test]
fn the_committed_scene_is_what_the_generator_writes() {
    scene_assets::assert_generated(
        "bokeh.toml",
        "make_hard_scene",
        &make_hard_scene::generate(),
    );
}

/// The lamps (emissive spheres) in view: (pinhole diameter, CoC diameter, depth), in pixels
/// and scene units.
fn lamps(desc: &SceneDesc, camera: &Camera) -> Vec<(f32, f32, f32)> {
    desc.objects
        .iter()
        .filter_map(|o| match o {
            Object::Sphere {
                center,
                radius,
                material,
            } if desc.materials[*material].emission != Vec3::ZERO => Some((*center, *radius)),
            _ => None,
        })
        .filter_map(|(c, r)| {
            let p = camera.project(c)?;
            let inside = p.x >= 0.0
                && p.y >= 0.0
                && p.x <= camera.width as f32
                && p.y <= camera.height as f32;
            let depth = (c - camera.eye).dot(camera.forward);
            inside.then(|| {
                (
                    2.0 * r * camera.pixels_per_unit() / depth,
                    camera.coc_px(depth),
                    depth,
                )
            })
        })
        .collect()
}

#[test]
fn small_lamps_are_defocused_in_front_of_and_behind_the_focus() {
    let desc = load();
    assert_eq!(desc.name, "bokeh");
    assert_eq!((desc.camera.width, desc.camera.height), (640, 480));
    let camera = camera(&desc);
    let lamps = lamps(&desc, &camera);
    let front: Vec<_> = lamps
        .iter()
        .filter(|l| l.2 < camera.focus_distance())
        .collect();
    let behind: Vec<_> = lamps
        .iter()
        .filter(|l| l.2 > camera.focus_distance())
        .collect();
    assert!(front.len() >= 10, "{} lamps in front", front.len());
    assert!(behind.len() >= 25, "{} lamps behind", behind.len());
    // Discs of 30 px and more in front, 15 px and more behind, each at least 4 times the
    // lamp's own size (so its rim is hard).
    for &&(_, coc, depth) in &front {
        assert!(coc >= 30.0, "a lamp at depth {depth} has a CoC of {coc} px");
    }
    for &&(_, coc, depth) in &behind {
        assert!(coc >= 15.0, "a lamp at depth {depth} has a CoC of {coc} px");
    }
    for &(size, coc, _) in &lamps {
        assert!(size <= coc / 4.0, "lamp of {size} px, CoC {coc} px");
    }
    // The background at infinity is blurred strongly.
    assert!(camera.coc_px(f32::INFINITY) > 40.0);
}

#[test]
fn the_hard_scene_renders_at_a_small_size() {
    let mut desc = load();
    desc.camera.width = 80;
    desc.camera.height = 60;
    let world = World::build(&desc, &Device::new().unwrap()).unwrap();
    let camera = camera(&desc);
    let settings = RenderSettings {
        mode: Mode::Dense,
        spp: 16,
        seed: 1,
        ..Default::default()
    };
    let film = render(&world, &camera, &settings, &NoProgress).unwrap().0;
    assert!(film.color.iter().all(|c| c.is_finite()));
    // Bokeh: some pixels are bright, and the night is dark elsewhere. Converged (1024 spp
    // dense, camera rays only) 3373 of the 4800 pixels are bright and 720 dark; noisier
    // renders, whose lamps' discs are speckled, have more of both extremes.
    let bright = film.color.iter().filter(|c| c.max_element() > 0.3).count();
    let dark = film.color.iter().filter(|c| c.max_element() < 0.1).count();
    assert!(
        bright > 200 && dark > 500,
        "{bright} bright, {dark} dark pixels"
    );
}
