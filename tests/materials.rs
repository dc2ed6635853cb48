//! glTF materials beyond a base colour: alpha MASK and BLEND (holes that camera and shadow
//! rays pass through, stochastic transparency that averages to the blend, deterministic for
//! any thread count and packet width), metallic-roughness textures and normal maps. Scenes are
//! TOML files around small glTF quads written by the tests.

use crate::scene_assets; // for its base64 encoder
use crate::scratch::Scratch;

use dofray::render::Integrator;
use std::io::Cursor;

use dofray::embree::{Device, PacketWidth, Ray};
use dofray::filter::{PixelFilter, PixelFilterKind};
use dofray::render::{Film, Mode, NoProgress, RenderSettings, render};
use dofray::scene::{self, SceneDesc, World};
use glam::{Vec2, Vec3};
use serde_json::json;

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("materials-{name}"))
}

/// A PNG of `w` x `h` RGBA texels from `f(x, y)` (y = 0 is the top row).
fn png(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 4]) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(w, h, |x, y| image::Rgba(f(x, y)));
    let mut out = Vec::new();
    img.write_to(&mut Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

/// A glTF document of one quad spanning [-1, 1]^2 in the plane z = 0, facing -z (towards a
/// camera on the -z side), UVs (0, 0) at the top left to (1, 1) at the bottom right (glTF's v
/// runs down), with `material` and `images` (PNG bytes each; texture i uses image i).
fn quad_gltf(material: serde_json::Value, images: &[Vec<u8>]) -> String {
    let pos: [[f32; 3]; 4] = [[-1., 1., 0.], [1., 1., 0.], [1., -1., 0.], [-1., -1., 0.]];
    let nrm = [[0f32, 0., -1.]; 4];
    let uv: [[f32; 2]; 4] = [[0., 0.], [1., 0.], [1., 1.], [0., 1.]];
    // Counter-clockwise seen from -z: 0, 1, 2 is clockwise there, so 0, 2, 1.
    let idx: [u16; 6] = [0, 2, 1, 0, 3, 2];
    let mut buf = Vec::new();
    pos.iter()
        .flatten()
        .for_each(|v| buf.extend(v.to_le_bytes()));
    nrm.iter()
        .flatten()
        .for_each(|v| buf.extend(v.to_le_bytes()));
    uv.iter()
        .flatten()
        .for_each(|v| buf.extend(v.to_le_bytes()));
    idx.iter().for_each(|v| buf.extend(v.to_le_bytes()));
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
            "indices": 3,
            "material": 0
        }]}],
        "materials": [material],
        "textures": (0..images.len()).map(|i| json!({"source": i})).collect::<Vec<_>>(),
        "images": images.iter().map(|b| json!({
            "uri": format!("data:image/png;base64,{}", scene_assets::base64(b))
        })).collect::<Vec<_>>(),
        "buffers": [{
            "byteLength": buf.len(),
            "uri": format!("data:application/octet-stream;base64,{}", scene_assets::base64(&buf))
        }],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48},
            {"buffer": 0, "byteOffset": 96, "byteLength": 32},
            {"buffer": 0, "byteOffset": 128, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1, -1, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    serde_json::to_string(&doc).unwrap()
}

/// Writes the quad and a scene around it (`scene` is TOML with the quad as `quad.gltf`) and
/// loads it.
fn load(test: &str, gltf: &str, scene: &str) -> SceneDesc {
    let dir = scratch(test);
    std::fs::write(dir.join("quad.gltf"), gltf).unwrap();
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap()
}

fn render_with(desc: &SceneDesc, aa: u32, threads: usize, width: PacketWidth) -> Film {
    let mut world = World::build(desc, &Device::new().unwrap()).unwrap();
    world.scene.set_packet_width(width);
    let camera = desc.camera.build(|_| None).unwrap();
    let settings = RenderSettings {
        integrator: Integrator::Direct,
        mode: Mode::Dense,
        pixel_filter: PixelFilter {
            kind: PixelFilterKind::Box,
            width: 1.0,
        },
        spp: aa,
        aa,
        seed: 5,
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| render(&world, &camera, &settings, &NoProgress).unwrap().0)
}

fn pixel(film: &Film, x: usize, y: usize) -> Vec3 {
    film.color[y * film.width + x]
}

/// Mean colour over pixels [x0, x1) x [y0, y1).
fn mean(film: &Film, x0: usize, x1: usize, y0: usize, y1: usize) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for y in y0..y1 {
        for x in x0..x1 {
            sum += pixel(film, x, y);
        }
    }
    sum / ((x1 - x0) * (y1 - y0)) as f32
}

/// Camera at z = -5 looking at the quad (pinhole, 40 x 40 px: 5 units across at z = 0, so
/// the quad fills pixels 12..28; 8 units across the wall at z = 3).
const VIEW: &str = r#"
ambient = 0

[image]
width = 40
height = 40

[camera]
eye = [0, 0, -5]
look_at = [0, 0, 0]
vfov = 53.130102

[background]
color = 0

[[materials]]
name = "wall"
diffuse = [0.2, 0.9, 0.3]

[[objects]]
type = "quad"
size = [40, 40]
rotate = [-90, 0, 0]
translate = [0, 0, 3]
material = "wall"

[[objects]]
type = "mesh"
file = "quad.gltf"
"#;

/// 4 x 4 alpha checker: 0 in cells where (x + y) is even, 255 elsewhere; white colour.
fn checker_alpha() -> Vec<u8> {
    png(4, 4, |x, y| {
        [255, 255, 255, if (x + y) % 2 == 0 { 0 } else { 255 }]
    })
}

fn mask_material(mode: &str) -> serde_json::Value {
    json!({
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0},
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0
        },
        "alphaMode": mode
    })
}

/// A pixel next to the centre of checker cell (cx, cy) of the quad (cells of 0.5 units, 4 px).
/// Looking along +z with +y up, the image's right is world -x: texel column 0 (u = 0, x = -1)
/// is on the right.
fn cell_pixel(cx: usize, cy: usize) -> (usize, usize) {
    (13 + 4 * (3 - cx), 13 + 4 * cy)
}

#[test]
fn mask_holes_show_the_wall_and_let_light_through() {
    // Lit from the camera: everything the camera sees through a hole is lit, if the shadow
    // rays pass the hole too.
    let scene = format!(
        "{VIEW}\n[[lights]]\ntype = \"point\"\nposition = [0, 0, -5]\nintensity = 201.06\n"
    );
    let desc = load(
        "mask",
        &quad_gltf(mask_material("MASK"), &[checker_alpha()]),
        &scene,
    );
    let m = &desc.materials[desc.materials.len() - 1];
    assert!(
        m.maps.alpha.is_some(),
        "MASK with a holed texture has alpha"
    );
    let film = render_with(&desc, 4, 2, PacketWidth::Auto);
    let white = |c: Vec3| c.x > 1.0 && (c.x - c.y).abs() < 0.01 * c.x;
    let wall = |c: Vec3| c.y > 0.3 && c.x < 0.3 * c.y && c.z < 0.4 * c.y;
    for cy in 0..4 {
        for cx in 0..4 {
            let (x, y) = cell_pixel(cx, cy);
            let c = pixel(&film, x, y);
            if (cx + cy) % 2 == 0 {
                // A hole: the wall, lit (its shadow ray passes the hole it looks through).
                assert!(wall(c), "hole {cx},{cy}: {c}");
            } else {
                assert!(white(c), "cell {cx},{cy}: {c}");
            }
        }
    }
    // Without MASK the quad is opaque: white everywhere.
    let opaque = load(
        "opaque",
        &quad_gltf(mask_material("OPAQUE"), &[checker_alpha()]),
        &scene,
    );
    assert!(opaque.materials.iter().all(|m| m.maps.alpha.is_none()));
    let film = render_with(&opaque, 4, 2, PacketWidth::Auto);
    let (x, y) = cell_pixel(2, 2);
    assert!(white(pixel(&film, x, y)));
}

#[test]
fn mask_shadows_have_holes() {
    // Shadow rays straight through the quad to a light on the camera side, from the wall:
    // blocked behind opaque cells, free behind holes.
    let desc = load(
        "shadow",
        &quad_gltf(mask_material("MASK"), &[checker_alpha()]),
        VIEW,
    );
    let world = World::build(&desc, &Device::new().unwrap()).unwrap();
    for cy in 0..4 {
        for cx in 0..4 {
            let p = Vec3::new(-0.75 + 0.5 * cx as f32, 0.75 - 0.5 * cy as f32, 2.999);
            let ray = Ray::segment(p, Vec3::NEG_Z, 0.0, 10.0);
            let hole = (cx + cy) % 2 == 0;
            assert_eq!(world.scene.occluded1(&ray), !hole, "cell {cx},{cy}");
        }
    }
    // In a render: a light from the side throws the checker onto the wall beside the quad.
    let scene = format!(
        "{VIEW}\n[[lights]]\ntype = \"directional\"\ndirection = [-1, 0, 1]\nirradiance = 3.1416\n"
    );
    let lit = |mode: &str| {
        let desc = load(
            &format!("shadow{mode}"),
            &quad_gltf(mask_material(mode), &[checker_alpha()]),
            &scene,
        );
        let film = render_with(&desc, 4, 2, PacketWidth::Auto);
        // The wall at z = 3, x in [-4, -2] (the shadow), seen at pixels 30..40 (8 units over
        // 40 px; world -x is on the right), y in [-1, 1] at pixels 15..25.
        let mut lit = 0;
        for y in 16..24 {
            for x in 31..39 {
                if pixel(&film, x, y).y > 0.3 {
                    lit += 1;
                }
            }
        }
        lit
    };
    assert_eq!(lit("OPAQUE"), 0, "an opaque quad's shadow is whole");
    let holes = lit("MASK");
    assert!(
        (16..=48).contains(&holes),
        "{holes} of 64 lit through the holes"
    );
}

fn blend_scene(test: &str, plane: f32, wall: f32) -> SceneDesc {
    let material = json!({
        "pbrMetallicRoughness": {
            "baseColorFactor": [plane, plane, plane, 0.25],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0
        },
        "alphaMode": "BLEND"
    });
    let scene = VIEW
        .replace("ambient = 0", "ambient = 1\nlights = []")
        .replace("diffuse = [0.2, 0.9, 0.3]", &format!("diffuse = {wall}"));
    load(test, &quad_gltf(material, &[]), &scene)
}

#[test]
fn blend_averages_to_the_mix_and_is_deterministic() {
    // A white quad of alpha 0.25 over a black wall, and a black one over a white wall.
    for (plane, wall, expected) in [(1.0, 0.0, 0.25), (0.0, 1.0, 0.75)] {
        let desc = blend_scene(&format!("blend{plane}"), plane, wall);
        let film = render_with(&desc, 64, 2, PacketWidth::Auto);
        let m = mean(&film, 13, 27, 13, 27).x;
        assert!(
            (m - expected).abs() < 0.02,
            "plane {plane} over wall {wall}: {m}, expected {expected}"
        );
        // Outside the quad: the wall alone.
        assert!((pixel(&film, 2, 2).x - wall).abs() < 1e-4);
    }
    // Bit-identical for any thread count and packet width.
    let desc = blend_scene("blenddet", 1.0, 0.0);
    let a = render_with(&desc, 16, 1, PacketWidth::Auto);
    for (threads, width) in [
        (3, PacketWidth::X16),
        (2, PacketWidth::X8),
        (1, PacketWidth::X4),
    ] {
        let b = render_with(&desc, 16, threads, width);
        assert!(
            a.color == b.color,
            "{threads} threads, {width:?}: the image changed"
        );
    }
}

#[test]
fn metallic_roughness_texture_varies_per_hit() {
    // Blue (metallic) 255 on the left half, 0 on the right; green (roughness) 255.
    let mr = png(4, 1, |x, _| [0, 255, if x < 2 { 255 } else { 0 }, 255]);
    let material = json!({
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.6, 0.4, 1.0],
            "metallicFactor": 1.0,
            "roughnessFactor": 0.5,
            "metallicRoughnessTexture": {"index": 0}
        }
    });
    let desc = load("mr", &quad_gltf(material, &[mr]), VIEW);
    let m = desc.materials.last().unwrap();
    let base = Vec3::new(0.8, 0.6, 0.4);
    let metal = m.surface(Vec2::new(0.2, 0.5));
    let dielectric = m.surface(Vec2::new(0.8, 0.5));
    // Metal: no diffuse, base-coloured highlight, some mirror (roughness 0.5 x 1).
    assert!(metal.albedo.max_element() < 1e-6, "{metal:?}");
    assert!((metal.specular - base * 0.5).abs().max_element() < 1e-5);
    assert!((metal.mirror - 0.25).abs() < 1e-5);
    // Dielectric: the base colour is the diffuse colour, a faint white highlight, no mirror.
    assert!((dielectric.albedo - base).abs().max_element() < 1e-5);
    assert!(
        (dielectric.specular - Vec3::splat(0.02))
            .abs()
            .max_element()
            < 1e-5
    );
    assert_eq!(dielectric.mirror, 0.0);
    // Both have roughness 0.5: exponent 2 / 0.25^2 - 2 = 30.
    assert!((metal.shininess - 30.0).abs() < 1e-3);
}

/// Gives the quad of `gltf` a TANGENT attribute of `t` at every vertex, in a buffer of its own.
fn with_tangents(gltf: &str, t: [f32; 4]) -> String {
    let mut doc: serde_json::Value = serde_json::from_str(gltf).unwrap();
    let bytes: Vec<u8> = (0..4).flat_map(|_| t).flat_map(f32::to_le_bytes).collect();
    doc["buffers"].as_array_mut().unwrap().push(json!({
        "byteLength": bytes.len(),
        "uri": format!("data:application/octet-stream;base64,{}", scene_assets::base64(&bytes))
    }));
    doc["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({"buffer": 1, "byteOffset": 0, "byteLength": 64}));
    doc["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({"bufferView": 4, "componentType": 5126, "count": 4, "type": "VEC4"}));
    doc["meshes"][0]["primitives"][0]["attributes"]["TANGENT"] = json!(4);
    serde_json::to_string(&doc).unwrap()
}

/// A normal map tilting every normal by 45 degrees towards +u (`towards_v`: +v, up in the
/// image), lit along the tilted normal: brighter than the flat quad by 1 / cos 45.
fn tilted(test: &str, towards_v: bool, light: [f32; 3]) -> f32 {
    tilted_with(test, towards_v, light, None)
}

/// [`tilted`], with a TANGENT attribute when `tangent` is given.
fn tilted_with(test: &str, towards_v: bool, light: [f32; 3], tangent: Option<[f32; 4]>) -> f32 {
    let s = (0.5 + 0.5 * std::f32::consts::FRAC_1_SQRT_2) * 255.0;
    let texel = if towards_v {
        [128, s.round() as u8, s.round() as u8, 255]
    } else {
        [s.round() as u8, 128, s.round() as u8, 255]
    };
    let map = png(2, 2, |_, _| texel);
    let material = json!({
        "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
        "normalTexture": {"index": 0}
    });
    let scene = format!(
        "{VIEW}\n[[lights]]\ntype = \"directional\"\ndirection = {light:?}\nirradiance = 3.1416\n"
    );
    let mut gltf = quad_gltf(material, &[map]);
    if let Some(t) = tangent {
        gltf = with_tangents(&gltf, t);
    }
    let desc = load(test, &gltf, &scene);
    let film = render_with(&desc, 1, 2, PacketWidth::Auto);
    pixel(&film, 20, 20).x
}

#[test]
fn normal_maps_tilt_the_shading_normal_in_tangent_space() {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    // The quad faces -z; +u is +x, +v (image up) is +y. Light travelling along -n'.
    let u = tilted("nu", false, [-h, 0.0, h]);
    assert!(
        (u - 1.0).abs() < 0.02,
        "tilted towards +u, lit along it: {u}"
    );
    let u_other = tilted("nu2", false, [h, 0.0, h]);
    assert!(u_other < 0.02, "lit from the other side: {u_other}");
    let v = tilted("nv", true, [0.0, -h, h]);
    assert!(
        (v - 1.0).abs() < 0.02,
        "tilted towards +v, lit along it: {v}"
    );
    let v_other = tilted("nv2", true, [0.0, h, h]);
    assert!(v_other < 0.02, "lit from below: {v_other}");
    // TANGENT agreeing with the UVs (bitangent = cross(normal, tangent) * w = +y): the same.
    let t = tilted_with("nt", false, [-h, 0.0, h], Some([1.0, 0.0, 0.0, -1.0]));
    assert!((t - 1.0).abs() < 0.02, "with TANGENT: {t}");
    // A TANGENT along +y is used as given: tilting towards +u now tilts towards +y.
    let t = tilted_with("nty", false, [0.0, -h, h], Some([0.0, 1.0, 0.0, 1.0]));
    assert!((t - 1.0).abs() < 0.02, "TANGENT along +y: {t}");
}

#[test]
fn scene_files_have_alpha_too() {
    // A white quad of alpha 0.25 (blended by default) in front of the black wall.
    let scene = VIEW
        .replace("ambient = 0", "ambient = 1\nlights = []")
        .replace("diffuse = [0.2, 0.9, 0.3]", "diffuse = 0")
        .replace(
            "[[objects]]\ntype = \"mesh\"\nfile = \"quad.gltf\"",
            "[[materials]]\nname = \"veil\"\ndiffuse = 1\nalpha = 0.25\n\n\
             [[objects]]\ntype = \"quad\"\nsize = [2, 2]\nrotate = [-90, 0, 0]\nmaterial = \"veil\"",
        );
    let desc = load("toml-blend", "{}", &scene);
    assert!(desc.materials[1].maps.alpha.is_some());
    let film = render_with(&desc, 64, 2, PacketWidth::Auto);
    let m = mean(&film, 13, 27, 13, 27).x;
    assert!((m - 0.25).abs() < 0.02, "{m}");

    // A mask from an image texture's alpha: the checker's holes show the black wall.
    let dir = scratch("toml-mask");
    std::fs::write(dir.join("alpha.png"), checker_alpha()).unwrap();
    let scene = scene
        .replace("alpha = 0.25", "texture = \"holes\"\nalpha_mode = \"mask\"")
        .replace(
            "[[materials]]\nname = \"veil\"",
            "[[textures]]\nname = \"holes\"\nimage = \"alpha.png\"\n\n[[materials]]\nname = \"veil\"",
        );
    std::fs::write(dir.join("scene.toml"), &scene).unwrap();
    let desc = scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
    let film = render_with(&desc, 4, 2, PacketWidth::Auto);
    let m = mean(&film, 12, 28, 12, 28).x;
    assert!((m - 0.5).abs() < 0.05, "half the quad is holes: {m}");
    // Opaque without alpha keys.
    let scene = scene.replace("alpha_mode = \"mask\"", "");
    std::fs::write(dir.join("scene.toml"), &scene).unwrap();
    let desc = scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
    assert!(desc.materials.iter().all(|m| m.maps.alpha.is_none()));
}
