//! glTF as Blender exports it: KHR_lights_punctual lights (types, placement, photometric to
//! radiometric conversion), required and unsupported extensions, the one warning per file,
//! orthographic cameras, a TOML scene taking its camera from a glTF, and spot-light falloff.
//! The assets in `tests/scene_assets/blender/` were written by Blender 4.2's own exporter
//! (`scripts/make_blender_assets.py`).

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use dofray::camera::{Focus, LensSpec};
use dofray::embree::Device;
use dofray::render::{Mode, NoProgress, RenderSettings, render};
use dofray::scene::{self, LoadError, SceneDesc, World};
use dofray::shade::{LUMENS_PER_WATT, Light, spot_falloff};
use glam::Vec3;

use crate::scratch::{Scratch, ScratchFile};

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/scene_assets/blender")
        .join(name)
}

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("lights-{name}"))
}

fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    scene::load(path.to_str().unwrap())
}

fn toml_scene(test: &str, toml: &str) -> Result<SceneDesc, LoadError> {
    let dir = scratch(test);
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    load(&path)
}

/// ortho.gltf's JSON, edited by `edit`, written next to a copy of its buffer in a scratch
/// directory, which lives as long as the returned path.
fn edited_ortho(test: &str, edit: impl FnOnce(&mut serde_json::Value)) -> ScratchFile {
    let dir = scratch(test);
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(asset("ortho.gltf")).unwrap()).unwrap();
    edit(&mut json);
    std::fs::copy(asset("ortho.bin"), dir.join("ortho.bin")).unwrap();
    let path = dir.join("edited.gltf");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    ScratchFile::new(dir, path)
}

fn near(a: Vec3, b: Vec3, eps: f32) -> bool {
    (a - b).abs().max_element() <= eps
}

fn lights_by_kind(desc: &SceneDesc) -> (Vec<Light>, Vec<Light>, Vec<Light>) {
    let (mut p, mut s, mut d) = (Vec::new(), Vec::new(), Vec::new());
    for l in &desc.lights {
        match l {
            Light::Point { .. } => p.push(*l),
            Light::Spot { .. } => s.push(*l),
            Light::Directional { .. } => d.push(*l),
        }
    }
    (p, s, d)
}

/// The lights Blender wrote (see the script): a 1000 W point light of colour (1, 0.85, 0.7) at
/// Blender (-1, 2, 2.5), a 2000 W spot (spot_size 40 degrees, blend 0.25) at (3, -3, 4) aimed at
/// (0, 0, 0.75), a strength-2 sun rotated (40, 0, 30) degrees; Blender's z-up becomes glTF's y-up
/// as (x, z, -y).
fn check_blender_lights(desc: &SceneDesc) {
    assert_eq!(desc.lights.len(), 3, "{:?}", desc.lights);
    let (points, spots, suns) = lights_by_kind(desc);
    let Light::Point {
        position,
        intensity,
    } = points[0]
    else {
        unreachable!()
    };
    assert!(
        near(position, Vec3::new(-1.0, 2.5, -2.0), 1e-5),
        "{position}"
    );
    // Blender: P / (4 pi) * 683 cd; dofray: / 683 -> P / (4 pi) W/sr, times the colour.
    let w_sr = 1000.0 / (4.0 * PI);
    assert!(
        near(intensity, Vec3::new(1.0, 0.85, 0.7) * w_sr, 1e-3 * w_sr),
        "{intensity}"
    );
    let Light::Spot {
        position,
        direction,
        intensity,
        inner_angle,
        outer_angle,
        ..
    } = spots[0]
    else {
        unreachable!()
    };
    assert!(near(position, Vec3::new(3.0, 4.0, 3.0), 1e-5), "{position}");
    let aim = (Vec3::new(0.0, 0.75, 0.0) - position).normalize();
    assert!(near(direction, aim, 1e-4), "{direction} vs {aim}");
    let w_sr = 2000.0 / (4.0 * PI);
    assert!(
        near(intensity, Vec3::splat(w_sr), 1e-3 * w_sr),
        "{intensity}"
    );
    assert!(
        (outer_angle.to_degrees() - 20.0).abs() < 1e-3,
        "{outer_angle}"
    );
    assert!(
        (inner_angle.to_degrees() - 15.0).abs() < 1e-3,
        "{inner_angle}"
    );
    let Light::Directional {
        direction,
        irradiance,
        ..
    } = suns[0]
    else {
        unreachable!()
    };
    assert!(near(irradiance, Vec3::splat(2.0), 1e-5), "{irradiance}");
    let (s40, c40) = (40f32.to_radians().sin(), 40f32.to_radians().cos());
    let (s30, c30) = (0.5f32, 30f32.to_radians().cos());
    let blender = Vec3::new(-s30 * s40, c30 * s40, -c40);
    let expected = Vec3::new(blender.x, blender.z, -blender.y);
    assert!(near(direction, expected, 1e-4), "{direction} vs {expected}");
}

#[test]
fn blender_glb_lights_camera_and_required_extension_load() {
    // Blender marks KHR_lights_punctual required; it loads.
    let desc = load(&asset("lights.glb")).unwrap();
    check_blender_lights(&desc);
    // Only the camera's missing depth of field is worth a warning: it renders sharp.
    assert_eq!(desc.warnings.len(), 1, "{:?}", desc.warnings);
    assert!(desc.warnings[0].contains("no depth of field"));
    assert_eq!(desc.camera.lens, LensSpec::Pinhole);
    // Its camera, not a framing one: Blender (0, -8, 4) is glTF (0, 4, 8); aspect 4:3.
    assert!(near(desc.camera.eye, Vec3::new(0.0, 4.0, 8.0), 1e-5));
    assert!((desc.camera.vfov_deg - 0.5274237f32.to_degrees()).abs() < 1e-3);
    assert_eq!((desc.camera.width, desc.camera.height), (640, 480));
    // The glTF's lights replace the key light and it gets Blender's default world.
    assert_eq!(desc.ambient, Vec3::splat(0.05));
    assert_eq!(desc.background.zenith, Vec3::splat(0.05));
}

#[test]
fn blender_gltf_with_a_separate_buffer_loads_the_same() {
    let desc = load(&asset("lights.gltf")).unwrap();
    check_blender_lights(&desc);
}

#[test]
fn photometric_units_convert_with_683_lumens_per_watt() {
    assert_eq!(LUMENS_PER_WATT, 683.0);
    let path = edited_ortho("photometric", |j| {
        j["extensions"]["KHR_lights_punctual"]["lights"] = serde_json::json!([
            {"type": "point", "intensity": 683.0, "color": [1.0, 0.5, 0.25]},
            {"type": "directional", "intensity": 1366.0},
            {"type": "spot", "intensity": 6830.0, "spot": {"outerConeAngle": 0.5}}
        ]);
        let nodes = j["nodes"].as_array_mut().unwrap();
        nodes.push(serde_json::json!({"extensions": {"KHR_lights_punctual": {"light": 1}}}));
        nodes.push(
            serde_json::json!({"extensions": {"KHR_lights_punctual": {"light": 2}},
            "translation": [0.0, 3.0, 0.0]}),
        );
        let n = nodes.len();
        j["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .extend([serde_json::json!(n - 2), serde_json::json!(n - 1)]);
        // Perspective camera, so the bare model loads.
        j["cameras"][0] = serde_json::json!({"type": "perspective",
            "perspective": {"yfov": 0.6, "znear": 0.1}});
    });
    let desc = load(&path).unwrap();
    let (points, spots, suns) = lights_by_kind(&desc);
    assert!(matches!(points[0], Light::Point { intensity, .. }
        if near(intensity, Vec3::new(1.0, 0.5, 0.25), 1e-6)));
    assert!(
        matches!(suns[0], Light::Directional { irradiance, direction, .. }
        if near(irradiance, Vec3::splat(2.0), 1e-6) && near(direction, Vec3::NEG_Z, 1e-6))
    );
    // Spot defaults: inner 0; shining down the node's -Z.
    assert!(
        matches!(spots[0], Light::Spot { intensity, inner_angle, outer_angle, position, .. }
        if near(intensity, Vec3::splat(10.0), 1e-5) && inner_angle == 0.0 && outer_angle == 0.5
            && near(position, Vec3::new(0.0, 3.0, 0.0), 1e-6))
    );
}

#[test]
fn an_unsupported_required_extension_is_an_error_naming_it_and_the_file() {
    let path = edited_ortho("required", |j| {
        j["extensionsRequired"] =
            serde_json::json!(["KHR_lights_punctual", "KHR_draco_mesh_compression"]);
        j["extensionsUsed"] =
            serde_json::json!(["KHR_lights_punctual", "KHR_draco_mesh_compression"]);
    });
    let e = load(&path).unwrap_err().to_string();
    for part in [
        "edited.gltf",
        "KHR_draco_mesh_compression",
        "extensionsRequired",
        "KHR_lights_punctual",
    ] {
        assert!(e.contains(part), "{part:?} not in {e}");
    }
}

#[test]
fn an_orthographic_only_camera_is_refused_for_a_bare_model() {
    let e = load(&asset("ortho.gltf")).unwrap_err().to_string();
    for part in ["ortho.gltf", "orthographic", "\"Ortho\"", "perspective"] {
        assert!(e.contains(part), "{part:?} not in {e}");
    }
}

#[test]
fn ignored_features_are_named_in_one_warning_per_file() {
    let path = edited_ortho("warning", |j| {
        j["extensionsUsed"] = serde_json::json!([
            "KHR_lights_punctual",
            "KHR_materials_clearcoat",
            "EXT_mesh_gpu_instancing"
        ]);
        // A perspective camera beside the orthographic one: used, and the other skipped.
        j["cameras"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({"type": "perspective",
            "perspective": {"yfov": 0.6, "znear": 0.1}}));
        let nodes = j["nodes"].as_array_mut().unwrap();
        nodes.push(serde_json::json!({"camera": 1, "translation": [0.0, 1.0, 5.0]}));
        let n = nodes.len();
        j["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!(n - 1));
    });
    let desc = load(&path).unwrap();
    // The ignored features' line, and the camera's missing depth of field.
    assert_eq!(desc.warnings.len(), 2, "{:?}", desc.warnings);
    let w = &desc.warnings[0];
    for part in [
        "edited.gltf",
        "KHR_materials_clearcoat",
        "EXT_mesh_gpu_instancing",
        "range 5",
        "\"Ranged\"",
        "orthographic",
        "\"Ortho\"",
    ] {
        assert!(w.contains(part), "{part:?} not in {w}");
    }
    assert!(!w.contains('\n'), "{w}");
    assert!(near(desc.camera.eye, Vec3::new(0.0, 1.0, 5.0), 1e-6));
}

#[test]
fn a_toml_scene_adds_the_models_lights_and_its_warning() {
    let ortho = asset("ortho.gltf");
    let desc = toml_scene(
        "toml-lights",
        &format!(
            "[[objects]]\ntype = \"mesh\"\nfile = {:?}\ntranslate = [0, 1, 0]\n",
            ortho
        ),
    )
    .unwrap();
    // The model's light replaces the default key light, moved with the object.
    assert_eq!(desc.lights.len(), 1);
    assert!(matches!(desc.lights[0], Light::Point { position, .. }
        if near(position, Vec3::new(1.0, 3.0, 1.0), 1e-5)));
    assert_eq!(desc.warnings.len(), 1);
    assert!(desc.warnings[0].contains("range 5"), "{:?}", desc.warnings);
    // `lights = false`: the default key light instead; the file's [[lights]] and the model's
    // add up.
    let desc = toml_scene(
        "toml-nolights",
        &format!(
            "[[objects]]\ntype = \"mesh\"\nfile = {:?}\nlights = false\n",
            ortho
        ),
    )
    .unwrap();
    assert!(matches!(desc.lights[..], [Light::Directional { .. }]));
    let desc = toml_scene(
        "toml-both",
        &format!(
            "[[lights]]\ntype = \"spot\"\nposition = [0, 4, 0]\ndirection = [0, -1, 0]\n\
             outer_angle = 30\ninner_angle = 20\n\n[[objects]]\ntype = \"mesh\"\nfile = {:?}\n",
            ortho
        ),
    )
    .unwrap();
    assert_eq!(desc.lights.len(), 2);
    assert!(
        matches!(desc.lights[0], Light::Spot { inner_angle, outer_angle, intensity, .. }
        if (inner_angle.to_degrees() - 20.0).abs() < 1e-4
            && (outer_angle.to_degrees() - 30.0).abs() < 1e-4
            && intensity == Vec3::splat(100.0))
    );
}

#[test]
fn toml_spot_lights_are_checked() {
    let cases = [
        (
            "type = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\ninner_angle = 40\nouter_angle = 30",
            "lights[0].inner_angle",
        ),
        (
            "type = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nouter_angle = 95",
            "lights[0].outer_angle",
        ),
        ("type = \"spot\"\nposition = [0, 1, 0]", "needs `direction`"),
        (
            "type = \"point\"\nposition = [0, 1, 0]\nouter_angle = 30",
            "belongs to spot lights",
        ),
        (
            "type = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, 0, 0]",
            "must not be zero",
        ),
    ];
    for (i, (light, expected)) in cases.iter().enumerate() {
        let toml = format!("[[lights]]\n{light}\n\n[[objects]]\ntype = \"sphere\"\nradius = 1\n");
        let e = toml_scene(&format!("spot{i}"), &toml)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(expected) && e.contains("scene.toml"),
            "{expected:?} not in {e}"
        );
    }
}

#[test]
fn a_toml_scene_takes_its_camera_from_a_gltf_and_its_lens_on_top() {
    let glb = asset("lights.glb");
    let desc = toml_scene(
        "camera",
        &format!(
            "[camera]\nf_number = 2.8\nfocus_distance = 6\n\n[[objects]]\ntype = \"mesh\"\n\
             file = {glb:?}\ncamera = true\n"
        ),
    )
    .unwrap();
    let c = &desc.camera;
    assert!(near(c.eye, Vec3::new(0.0, 4.0, 8.0), 1e-5), "{}", c.eye);
    assert_eq!((c.width, c.height), (640, 480));
    assert_eq!(c.focus, Focus::Distance(6.0));
    // Blender's 50 mm lens on a 36 mm sensor: the focal length that keeps the glTF's yfov.
    let LensSpec::Photographic {
        focal_length_mm,
        f_number,
        ..
    } = c.lens
    else {
        panic!("{:?}", c.lens)
    };
    assert!((focal_length_mm - 50.0).abs() < 0.05, "{focal_length_mm}");
    assert_eq!(f_number, 2.8);
    assert!((c.effective_vfov_deg() - 0.5274237f32.to_degrees()).abs() < 1e-2);
    check_blender_lights(&desc);

    // No perspective camera, a second camera, and view keys are errors.
    let ortho = asset("ortho.gltf");
    let e = toml_scene(
        "camera-ortho",
        &format!("[[objects]]\ntype = \"mesh\"\nfile = {ortho:?}\ncamera = true\n"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("objects[0].camera") && e.contains("orthographic"),
        "{e}"
    );
    let e = toml_scene(
        "camera-eye",
        &format!("[camera]\neye = [0, 1, 5]\n\n[[objects]]\ntype = \"mesh\"\nfile = {glb:?}\ncamera = true\n"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("camera.eye") && e.contains("camera = true"),
        "{e}"
    );
    let e = toml_scene(
        "camera-sphere",
        "[[objects]]\ntype = \"sphere\"\nradius = 1\ncamera = true\n",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("objects[0].camera"), "{e}");
}

#[test]
fn spot_falloff_is_full_inside_zero_outside_and_smooth_between() {
    let (inner, outer) = (20f32.to_radians(), 30f32.to_radians());
    let spot = Light::Spot {
        position: Vec3::new(0.0, 2.0, 0.0),
        direction: Vec3::NEG_Y,
        intensity: Vec3::splat(8.0),
        inner_angle: inner,
        outer_angle: outer,
        radius: 0.0,
    };
    // A point on the ground at angle `deg` from the axis.
    let at = |deg: f32| Vec3::new(2.0 * deg.to_radians().tan(), 0.0, 0.0);
    let lit = |deg: f32| {
        let p = at(deg);
        spot.sample(p).irradiance.x * (Vec3::new(0.0, 2.0, 0.0) - p).length_squared()
    };
    assert!((lit(0.0) - 8.0).abs() < 1e-4);
    assert!((lit(10.0) - 8.0).abs() < 1e-4);
    assert_eq!(lit(31.0), 0.0);
    assert_eq!(lit(60.0), 0.0);
    let mut last = 8.0;
    for deg in [25.0, 26.0, 28.0, 29.5] {
        let v = lit(deg);
        assert!(v > 0.0 && v < last, "{deg}: {v} after {last}");
        last = v;
    }
    // Blender's blend (1 - inner / outer = 1/3) and smoothstep.
    let x = (26f32.to_radians().cos() - outer.cos()) / ((1.0 - outer.cos()) / 3.0);
    assert!((lit(26.0) - 8.0 * x * x * (3.0 - 2.0 * x)).abs() < 1e-3);
    // No blend: a hard edge.
    assert_eq!(spot_falloff(0.95, 0.9, 0.0), 1.0);
    assert_eq!(spot_falloff(0.85, 0.9, 0.0), 0.0);
}

#[test]
fn a_blender_scene_renders_lit_by_its_lights() {
    let mut desc = load(&asset("lights.glb")).unwrap();
    desc.camera.width = 80;
    desc.camera.height = 60;
    desc.camera.lens = LensSpec::Pinhole;
    let device = Device::new().unwrap();
    let settings = RenderSettings {
        mode: Mode::Dense,
        spp: 1,
        aa: 1,
        seed: 1,
        ..Default::default()
    };
    let sum = |desc: &SceneDesc| -> f32 {
        let world = World::build(desc, &device).unwrap();
        let camera = desc.camera.build(|_| None).unwrap();
        let film = render(&world, &camera, &settings, &NoProgress).unwrap().0;
        assert!(film.color.iter().all(|c| c.is_finite()));
        film.color.iter().map(|c| c.x + c.y + c.z).sum()
    };
    let all = sum(&desc);
    let without = |keep: fn(&Light) -> bool| {
        let mut d = desc.clone();
        d.lights.retain(keep);
        sum(&d)
    };
    let no_spot = without(|l| !matches!(l, Light::Spot { .. }));
    let no_point = without(|l| !matches!(l, Light::Point { .. }));
    let none = without(|_| false);
    assert!(none > 0.0, "ambient and sky alone are not black");
    assert!(all > 1.5 * none, "{all} vs {none}");
    assert!(
        all > no_spot * 1.02,
        "the spot lights something: {all} vs {no_spot}"
    );
    assert!(
        all > no_point * 1.02,
        "the point light lights something: {all} vs {no_point}"
    );
}

/// ortho.gltf with a perspective camera 5 units in front of the model (yfov 0.6 rad), whose
/// camera and node get `camera_extras` and `node_extras` (null: none).
fn perspective(
    test: &str,
    camera_extras: serde_json::Value,
    node_extras: serde_json::Value,
) -> ScratchFile {
    edited_ortho(test, |j| {
        let mut camera = serde_json::json!({"type": "perspective",
            "perspective": {"yfov": 0.6, "znear": 0.1}});
        if !camera_extras.is_null() {
            camera["extras"] = camera_extras;
        }
        j["cameras"] = serde_json::json!([camera]);
        // The node of the orthographic camera, which it replaces.
        let mut node = serde_json::json!({"camera": 0, "translation": [0.0, 0.0, 5.0]});
        if !node_extras.is_null() {
            node["extras"] = node_extras;
        }
        j["nodes"][2] = node;
    })
}

#[test]
fn a_gltf_camera_without_depth_of_field_renders_sharp_and_says_how_to_blur() {
    use dofray::overrides::Overrides;
    use dofray::renderer::Renderer;
    let path = perspective("no-dof", serde_json::Value::Null, serde_json::Value::Null);
    let desc = load(&path).unwrap();
    // No invented lens: a pinhole, and one warning naming the file and the flags.
    assert_eq!(desc.camera.lens, LensSpec::Pinhole);
    let w = desc.lens_guessed.clone().expect("the lens warning");
    assert!(desc.warnings.contains(&w), "{:?}", desc.warnings);
    for part in [
        "edited.gltf",
        "no depth of field",
        "--f-number",
        "--focus-distance",
        "add-on",
    ] {
        assert!(w.contains(part), "{part:?} not in {w}");
    }
    let vfov = desc.camera.effective_vfov_deg();
    assert!((vfov - 0.6f32.to_degrees()).abs() < 1e-4, "{vfov}");
    // --f-number gives the blur and keeps the camera's framing; the warning goes.
    let device = Device::new().unwrap();
    let overrides = Overrides {
        f_number: Some(2.0),
        focus_distance: Some(5.0),
        ..Default::default()
    };
    let r = Renderer::with_overrides(desc, overrides, &device).unwrap();
    assert!(r.desc().lens_guessed.is_none());
    assert!(!r.desc().warnings.contains(&w), "{:?}", r.desc().warnings);
    let kept = r.desc().camera.effective_vfov_deg();
    assert!(
        (kept - vfov).abs() < 1e-3,
        "field of view {vfov} became {kept}"
    );
    let camera = r.camera(None).unwrap();
    use dofray::camera::Lens;
    // 36 mm sensor, the focal length of that field of view at 640 x 480, f/2.
    let focal_mm = 18.0 * 480.0 / 640.0 / (0.3f32).tan();
    let radius = focal_mm / 1000.0 / 4.0;
    assert!(
        (camera.lens.aperture_radius() - radius).abs() < 1e-3 * radius,
        "{} against {radius}",
        camera.lens.aperture_radius()
    );
}

#[test]
fn depth_of_field_from_a_gltf_cameras_custom_properties() {
    // Camera data's properties, with the node's (Blender's object) over them.
    let path = perspective(
        "dof-extras",
        serde_json::json!({"dofray_f_number": 2.8, "dofray_focus_distance": 4.0,
            "dofray_blades": 6, "other": "ignored"}),
        serde_json::json!({"dofray_f_number": 1.4, "dofray_anamorphic": 1.33}),
    );
    let desc = load(&path).unwrap();
    assert!(desc.lens_guessed.is_none(), "{:?}", desc.warnings);
    assert!(
        desc.warnings.iter().all(|w| !w.contains("depth of field")),
        "{:?}",
        desc.warnings
    );
    match desc.camera.lens {
        LensSpec::Photographic { f_number, .. } => assert_eq!(f_number, 1.4),
        other => panic!("{other:?}"),
    }
    assert_eq!(desc.camera.focus, Focus::Distance(4.0));
    assert_eq!(desc.camera.aperture.blades, 6);
    assert_eq!(desc.camera.aperture.anamorphic, 1.33);
    // The glTF field of view is kept.
    let vfov = desc.camera.effective_vfov_deg();
    assert!((vfov - 0.6f32.to_degrees()).abs() < 1e-3, "{vfov}");

    // A property of the wrong type or range: an error naming the file and the property.
    for (extras, key) in [
        (
            serde_json::json!({"dofray_f_number": "two"}),
            "cameras[0].extras.dofray_f_number",
        ),
        (
            serde_json::json!({"dofray_focus_distance": -1.0}),
            "cameras[0].extras.dofray_focus_distance",
        ),
        (
            serde_json::json!({"dofray_blades": 2}),
            "cameras[0].extras.dofray_blades",
        ),
    ] {
        let path = perspective("dof-bad", extras, serde_json::Value::Null);
        let e = load(&path).unwrap_err().to_string();
        for part in ["edited.gltf", key] {
            assert!(e.contains(part), "{part:?} not in {e}");
        }
    }
}

#[test]
fn a_model_without_a_camera_states_the_lens_it_was_given() {
    use dofray::overrides::Overrides;
    use dofray::renderer::Renderer;
    let path = edited_ortho("no-camera", |j| {
        j.as_object_mut().unwrap().remove("cameras");
        for node in j["nodes"].as_array_mut().unwrap() {
            node.as_object_mut().unwrap().remove("camera");
        }
    });
    let desc = load(&path).unwrap();
    let w = desc
        .lens_guessed
        .clone()
        .expect("the guessed lens is stated");
    for part in ["edited.gltf", "no camera", "aperture radius", "--f-number"] {
        assert!(w.contains(part), "{part:?} not in {w}");
    }
    assert!(matches!(desc.camera.lens, LensSpec::Aperture { radius } if radius > 0.0));
    let device = Device::new().unwrap();
    let overrides = Overrides {
        aperture_radius: Some(0.01),
        ..Default::default()
    };
    let r = Renderer::with_overrides(desc, overrides, &device).unwrap();
    assert!(!r.desc().warnings.contains(&w));
}

#[test]
fn the_command_line_warns_about_a_sharp_gltf_camera_until_a_lens_is_given() {
    let dir = scratch("cli-warning");
    let png = dir.join("x.png");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "render".to_owned(),
            asset("lights.glb").to_str().unwrap().to_owned(),
        ];
        args.extend(
            [
                "-o",
                png.to_str().unwrap(),
                "--width",
                "32",
                "--spp",
                "1",
                "-q",
            ]
            .map(String::from),
        );
        args.extend(extra.iter().map(|s| s.to_string()));
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args(&args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert!(run(&[]).contains("no depth of field"));
    assert!(!run(&["--f-number", "2"]).contains("no depth of field"));
}
