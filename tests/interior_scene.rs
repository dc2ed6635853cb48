//! The interior scene, `scenes/interior.toml`: it is exactly what its generator
//! (`examples/make_interior.rs`, included here) writes, it has the lights, materials and lens it
//! is meant to have, and it renders as a room lit largely by bounced light.

#[allow(dead_code)]
#[path = "../examples/make_interior.rs"]
mod make_interior;

use crate::scene_assets;

use std::path::PathBuf;

use dofray::camera::Camera;
use dofray::embree::Device;
use dofray::render::{Film, Mode, NoProgress, SettingsPatch, render};
use dofray::scene::{self, Object, SceneDesc, World};
use dofray::shade::Light;
use glam::Vec3;

fn path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/interior.toml")
}

fn load() -> SceneDesc {
    scene::load(path().to_str().unwrap()).unwrap_or_else(|e| panic!("{e}"))
}

fn camera(desc: &SceneDesc) -> Camera {
    desc.camera.build(|_| None).unwrap()
}

#[test]
fn the_committed_scene_is_what_the_generator_writes() {
    scene_assets::assert_generated("interior.toml", "make_interior", &make_interior::generate());
}

/// The emissive spheres: (centre, radius).
fn lamps(desc: &SceneDesc) -> Vec<(Vec3, f32)> {
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
        .collect()
}

#[test]
fn the_room_has_its_lights_materials_and_lens() {
    let desc = load();
    assert_eq!(desc.name, "interior");
    assert_eq!((desc.camera.width, desc.camera.height), (640, 480));
    assert!(desc.warnings.is_empty(), "{:?}", desc.warnings);

    // A sun of 3 to 5 W/m^2 and a uniform sky.
    let suns: Vec<f32> = desc
        .lights
        .iter()
        .filter_map(|l| match l {
            Light::Directional { irradiance, .. } => Some(irradiance.max_element()),
            _ => None,
        })
        .collect();
    assert!(
        suns.len() == 1 && (3.0..=5.0).contains(&suns[0]),
        "suns: {suns:?}"
    );
    assert_eq!(desc.background.horizon, desc.background.zenith);
    assert!(desc.background.map.is_none());
    // The ceiling panel (an area light: a one-sided emitter) and the two lamp spheres.
    assert!(
        desc.materials
            .iter()
            .any(|m| m.one_sided && m.emission.max_element() > 0.0),
        "no area light"
    );
    let lamps = lamps(&desc);
    assert_eq!(lamps.len(), 2, "{lamps:?}");
    // Glass and a metal.
    assert!(
        desc.materials
            .iter()
            .any(|m| m.transmission == 1.0 && m.roughness == 0.0 && m.ior == 1.5)
    );
    assert!(desc.materials.iter().any(|m| m.metallic == 1.0));

    // The eye is inside the room (x within 2.5, z within 2, y under the 2.7 m ceiling); the
    // focus is at mid distance; one lamp is near the lens, defocused in front of the focus,
    // the other far behind it; points at infinity (the sky) are blurred most.
    let camera = camera(&desc);
    let eye = camera.eye;
    assert!(eye.x.abs() < 2.5 && eye.z.abs() < 2.0 && eye.y > 0.0 && eye.y < 2.7);
    let focus = camera.focus_distance();
    assert!((1.2..2.5).contains(&focus), "focus at {focus} m");
    let depths: Vec<f32> = lamps
        .iter()
        .map(|(c, _)| (*c - eye).dot(camera.forward))
        .collect();
    assert!(
        depths.iter().any(|&d| d < 1.0 && camera.coc_px(d) > 12.0),
        "no lamp defocused in front: {depths:?}"
    );
    assert!(
        depths.iter().any(|&d| d > 3.0 && camera.coc_px(d) > 5.0),
        "no lamp defocused behind: {depths:?}"
    );
    assert!(camera.coc_px(f32::INFINITY) > 10.0);
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

fn mean(film: &Film) -> f32 {
    film.color.iter().map(|&c| luminance(c)).sum::<f32>() / film.color.len() as f32
}

/// The mean colour of the film's pixels in the rectangle [x0, x1) x [y0, y1) of fractions of
/// its width and height.
fn region(film: &Film, x: [f32; 2], y: [f32; 2]) -> Vec3 {
    let (w, h) = (film.width as f32, film.height as f32);
    let (x0, x1) = ((x[0] * w) as usize, (x[1] * w) as usize);
    let (y0, y1) = ((y[0] * h) as usize, (y[1] * h) as usize);
    let mut sum = Vec3::ZERO;
    for row in y0..y1 {
        for col in x0..x1 {
            sum += film.color[row * film.width + col];
        }
    }
    sum / ((x1 - x0) * (y1 - y0)) as f32
}

#[test]
fn the_room_renders_lit_largely_by_bounced_light() {
    let mut desc = load();
    desc.camera.width = 80;
    desc.camera.height = 60;
    let world = World::build(&desc, &Device::new().unwrap()).unwrap();
    let camera = camera(&desc);
    let render_with = |diffuse_bounces: Option<u32>| {
        let flags = SettingsPatch {
            mode: Some(Mode::Dense),
            spp: Some(16),
            seed: Some(1),
            diffuse_bounces,
            ..Default::default()
        };
        let settings = flags.over(&desc.settings).resolve().unwrap();
        render(&world, &camera, &settings, &NoProgress).unwrap().0
    };
    let film = render_with(None);
    assert!(
        film.color
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0)
    );
    // Exposed for viewing as it is: not black, not blown out (mean radiance of a mid grey
    // in sRGB is about 0.2).
    let lit = mean(&film);
    assert!((0.1..0.6).contains(&lit), "mean luminance {lit}");
    let blown = film.color.iter().filter(|c| c.max_element() > 1.0).count();
    // Only the lamps and glints exceed 1 (about 2% of the pixels).
    assert!(blown * 20 < film.color.len(), "{blown} pixels above 1");

    // The sky seen through the window (upper left) is blue and bright; the terracotta far
    // wall (upper right) is red.
    let window = region(&film, [0.0, 0.15], [0.1, 0.4]);
    assert!(
        window.z > window.x && window.z > 0.5,
        "window region {window}"
    );
    let wall = region(&film, [0.55, 0.75], [0.35, 0.5]);
    assert!(wall.x > 1.5 * wall.z, "far wall region {wall}");

    // Without diffuse bounces (direct light, mirrors and glass only) the room is much darker:
    // most of its surfaces are lit by light the walls, floor and ceiling reflect.
    let direct = mean(&render_with(Some(0)));
    assert!(
        lit > 1.4 * direct,
        "mean luminance {lit} with bounces, {direct} without"
    );
}
