//! Emissive materials: `emission` in scene files, `Ke` in MTL files, `emissiveFactor` (with
//! `KHR_materials_emissive_strength` and `emissiveTexture`) in glTF; range errors that name the
//! file and key; and renders in which an emissive surface shows its emitted radiance, directly
//! and in a mirror, without lighting anything else under the direct integrator (the path tracer
//! samples emitters as lights: tests/light_transport.rs).

use crate::scene_assets;
use crate::scratch::Scratch;

use dofray::render::Integrator;
use std::path::Path;

use dofray::embree::Device;
use dofray::render::{Film, Mode, NoProgress, RenderSettings, render};
use dofray::scene::{self, LoadError, SceneDesc, World};
use glam::Vec3;

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("emission-{name}"))
}

/// Writes `files` into a scratch directory and loads the first one.
fn load_files(test: &str, files: &[(&str, &[u8])]) -> Result<SceneDesc, LoadError> {
    let dir = scratch(test);
    for (name, bytes) in files {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
    scene::load(dir.join(files[0].0).to_str().unwrap())
}

fn load_toml(test: &str, toml: &str) -> Result<SceneDesc, LoadError> {
    load_files(test, &[("scene.toml", toml.as_bytes())])
}

fn error_of(test: &str, toml: &str) -> String {
    match load_toml(test, toml) {
        Ok(_) => panic!("{test}: expected an error for\n{toml}"),
        Err(e) => e.to_string(),
    }
}

/// Dense render of a description at its own size, 16 samples per pixel.
fn dense(desc: &SceneDesc) -> Film {
    let world = World::build(desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    let settings = RenderSettings {
        integrator: Integrator::Direct,
        mode: Mode::Dense,
        spp: 16,
        aa: 16,
        seed: 3,
        ..Default::default()
    };
    render(&world, &camera, &settings, &NoProgress).unwrap().0
}

fn pixel(film: &Film, x: usize, y: usize) -> Vec3 {
    film.color[y * film.width + x]
}

fn close(a: Vec3, b: Vec3, rel: f32) -> bool {
    (a - b).abs().max_element() <= rel * b.max_element()
}

// ---------------------------------------------------------------------------------------------
// Scene files.

const EMITTER: &str = r#"
[[materials]]
name = "lamp"
diffuse = 0
emission = [2, 1, 0.5]

[[objects]]
type = "sphere"
radius = 1
material = "lamp"
"#;

#[test]
fn scene_files_read_emission_and_default_to_none() {
    let desc = load_toml("parse", EMITTER).unwrap();
    assert_eq!(desc.materials[0].emission, Vec3::new(2.0, 1.0, 0.5));
    assert!(desc.materials[0].emission_texture.is_none());
    let grey = load_toml(
        "grey",
        &EMITTER.replace("emission = [2, 1, 0.5]", "emission = 3"),
    )
    .unwrap();
    assert_eq!(grey.materials[0].emission, Vec3::splat(3.0));
    let none = load_toml(
        "none",
        &EMITTER.replace("emission = [2, 1, 0.5]\n", "roughness = 0.5\n"),
    )
    .unwrap();
    assert_eq!(none.materials[0].emission, Vec3::ZERO);
    // Every repository scene keeps emission 0 where it does not ask for it.
    let paper = scene::load("paper").unwrap();
    assert!(paper.materials.iter().all(|m| m.emission == Vec3::ZERO));
}

#[test]
fn bad_emission_values_name_the_file_line_and_key() {
    let cases = [
        ("emission = -1", "expected a colour"),
        ("emission = [1, -0.5, 0]", "expected a finite number >= 0"),
        ("emission = nan", "NaN"),
        ("emission = [1, 2]", "invalid length 2"),
        ("emission = \"bright\"", "expected a colour"),
        ("emission = 2e6", "out of range"),
        ("emission = [0, 0, 1e7]", "from 0 to 1e6"),
    ];
    for (i, (line, expected)) in cases.iter().enumerate() {
        let toml = EMITTER.replace("emission = [2, 1, 0.5]", line);
        let e = error_of(&format!("bad{i}"), &toml);
        assert!(e.contains("scene.toml:5:"), "{line}: {e}");
        assert!(e.contains("materials[0].emission"), "{line}: {e}");
        assert!(e.contains(expected), "{line}: {e} lacks {expected:?}");
    }
    // The renderer's own range check (for descriptions built in code) names the material.
    let mut desc = load_toml("range", EMITTER).unwrap();
    desc.materials[0].emission = Vec3::new(0.0, f32::INFINITY, 0.0);
    let e = World::build(&desc, &Device::new().unwrap())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("material 0's emission") && e.contains("1e6"),
        "{e}"
    );
}

/// An emissive sphere in focus, alone in the dark: the pixels it covers hold its emission, and
/// it lights nothing (a white wall beside it stays black).
#[test]
fn an_emissive_sphere_in_focus_shows_its_emission_and_lights_nothing() {
    let toml = format!(
        r#"
lights = []
ambient = 0

[image]
width = 48
height = 32

[camera]
eye = [0, 0, -6]
look_at = [0, 0, 0]
vfov = 30
aperture_radius = 0.05
focus_point = [0, 0, -1]

[background]
color = 0

[[materials]]
name = "wall"
diffuse = 1
roughness = 0.5

{EMITTER}

[[objects]]
type = "quad"
center = [0, 0, 0]
size = [40, 40]
rotate = [-90, 0, 0]
translate = [0, 0, 3]
material = "wall"
"#
    );
    let desc = load_toml("render", &toml).unwrap();
    let film = dense(&desc);
    let centre = pixel(&film, 24, 16);
    assert!(
        close(centre, Vec3::new(2.0, 1.0, 0.5), 0.01),
        "centre {centre}"
    );
    // The wall around the sphere: neither emission nor light reaches it.
    assert_eq!(pixel(&film, 1, 1), Vec3::ZERO);
    assert_eq!(pixel(&film, 46, 30), Vec3::ZERO);
}

/// A mirror floor seen from above reflects an emissive sphere above the camera: the mirror
/// shows the emission.
#[test]
fn mirrors_reflect_emission() {
    let toml = r#"
lights = []
ambient = 0

[image]
width = 16
height = 16

[camera]
eye = [0, 1, 0]
look_at = [0, 0, 0]
up = [0, 0, 1]
vfov = 10

[background]
color = 0

[[materials]]
name = "mirror"
diffuse = 1
metallic = 1
roughness = 0

[[materials]]
name = "lamp"
diffuse = 0
emission = [0.25, 4, 1]

[[objects]]
type = "quad"
size = [100, 100]
material = "mirror"

[[objects]]
type = "sphere"
center = [0, 10, 0]
radius = 3
material = "lamp"
"#;
    let desc = load_toml("mirror", toml).unwrap();
    let film = dense(&desc);
    let c = pixel(&film, 8, 8);
    assert!(
        close(c, Vec3::new(0.25, 4.0, 1.0), 0.01),
        "mirror shows {c}"
    );
}

// ---------------------------------------------------------------------------------------------
// OBJ / MTL.

const TRIANGLE_OBJ: &str = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glow\nf 1 2 3\n";

#[test]
fn mtl_ke_is_emission() {
    let desc = load_files(
        "ke",
        &[
            ("t.obj", TRIANGLE_OBJ.as_bytes()),
            ("m.mtl", b"newmtl glow\nKd 0 0 0\nKe 1 0.5 0.25\n"),
        ],
    )
    .unwrap();
    let glow = desc
        .materials
        .iter()
        .find(|m| m.emission != Vec3::ZERO)
        .expect("an emissive material");
    assert_eq!(glow.emission, Vec3::new(1.0, 0.5, 0.25));
    // One value means grey, as for Kd.
    let desc = load_files(
        "ke1",
        &[
            ("t.obj", TRIANGLE_OBJ.as_bytes()),
            ("m.mtl", b"newmtl glow\nKe 2\n"),
        ],
    )
    .unwrap();
    assert!(
        desc.materials
            .iter()
            .any(|m| m.emission == Vec3::splat(2.0))
    );
    let e = load_files(
        "kebig",
        &[
            ("t.obj", TRIANGLE_OBJ.as_bytes()),
            ("m.mtl", b"newmtl glow\nKe 1 5e6 0\n"),
        ],
    )
    .expect_err("refused")
    .to_string();
    assert!(
        e.contains("m.mtl") && e.contains("glow.Ke") && e.contains("at most 1e6"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// glTF.

/// The repository's vase document with its material made emissive by `edit`.
fn emissive_vase(
    test: &str,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Result<SceneDesc, LoadError> {
    let mut doc: serde_json::Value = serde_json::from_str(&scene_assets::vase_gltf()).unwrap();
    edit(&mut doc["materials"][0]);
    let text = serde_json::to_string(&doc).unwrap();
    load_files(test, &[("vase.gltf", text.as_bytes())])
}

#[test]
fn gltf_emissive_factor_strength_and_texture() {
    let desc = emissive_vase("gltf", |m| {
        m["emissiveFactor"] = serde_json::json!([1.0, 0.5, 0.25]);
        m["emissiveTexture"] = serde_json::json!({"index": 0});
        m["extensions"] = serde_json::json!({
            "KHR_materials_emissive_strength": {"emissiveStrength": 8.0}
        });
    })
    .unwrap();
    let m = &desc.materials[0];
    assert_eq!(m.emission, Vec3::new(8.0, 4.0, 2.0));
    let texture = m.emission_texture.as_ref().expect("the emissive texture");
    assert_eq!((texture.width, texture.height), (64, 64));
    // The emitted radiance is the factor times the texel (sRGB decoded).
    let uv = glam::Vec2::new(0.3, 0.6);
    assert_eq!(m.emitted(uv), m.emission * texture.sample(uv));

    // Without the extension the factor alone; a texture on another UV set is ignored.
    let desc = emissive_vase("gltf1", |m| {
        m["emissiveFactor"] = serde_json::json!([0.5, 0.5, 0.5]);
        m["emissiveTexture"] = serde_json::json!({"index": 0, "texCoord": 1});
    })
    .unwrap();
    assert_eq!(desc.materials[0].emission, Vec3::splat(0.5));
    assert!(desc.materials[0].emission_texture.is_none());

    // The unchanged vase emits nothing.
    let plain = scene::load(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes/assets/vase.glb")
            .to_str()
            .unwrap(),
    )
    .unwrap();
    assert!(plain.materials.iter().all(|m| m.emission == Vec3::ZERO));

    let e = emissive_vase("gltfbig", |m| {
        m["emissiveFactor"] = serde_json::json!([1.0, 1.0, 1.0]);
        m["extensions"] = serde_json::json!({
            "KHR_materials_emissive_strength": {"emissiveStrength": 1e7}
        });
    })
    .expect_err("refused")
    .to_string();
    assert!(
        e.contains("vase.gltf") && e.contains("materials[0]") && e.contains("at most 1e6"),
        "{e}"
    );
}
