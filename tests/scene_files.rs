//! Scenes from files: the TOML format, OBJ and glTF loading, transforms, and a clear error (file,
//! line or key, what was expected) for every kind of bad input, never a panic.

use crate::scene_assets;
use crate::scratch::Scratch;

use std::path::{Path, PathBuf};

use dofray::camera::{CameraLens, Focus, LensSpec};
use dofray::embree::Device;
use dofray::limits::{
    BYTES_PER_PIXEL, MemoryLimit, check_image_memory, check_image_memory_against,
};
use dofray::render::{Film, Mode, NoProgress, RenderSettings, RulePatch, render};
use dofray::scene::{self, LoadError, MeshMaterials, Object, SceneDesc, World, builtin};
use dofray::shade::{Light, Texture};
use glam::{Vec2, Vec3};
use proptest::prelude::*;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn assets() -> PathBuf {
    repo().join("scenes/assets")
}

fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    scene::load(path.to_str().unwrap())
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("scenes-{name}"))
}

/// Writes `files` into a scratch directory and loads its `scene.toml`.
fn load_files(test: &str, files: &[(&str, &[u8])]) -> Result<SceneDesc, LoadError> {
    let dir = scratch(test);
    for (name, bytes) in files {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
    load(&dir.join("scene.toml"))
}

/// Loads a scene text that must fail, and returns the message.
fn error_of(test: &str, toml: &str) -> String {
    match load_files(test, &[("scene.toml", toml.as_bytes())]) {
        Ok(_) => panic!("{test}: expected an error for\n{toml}"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that `message` names `file`, and contains each of `parts`.
fn assert_names(message: &str, file: &str, parts: &[&str]) {
    assert!(
        message.contains(file),
        "message does not name {file}: {message}"
    );
    for p in parts {
        assert!(message.contains(p), "message lacks {p:?}: {message}");
    }
}

/// A minimal valid scene, for variations.
const SPHERE: &str = "[[objects]]\ntype = \"sphere\"\nradius = 1\n";

fn world(desc: &SceneDesc) -> World {
    World::build(desc, &Device::new().unwrap()).unwrap()
}

fn dense(desc: &SceneDesc, width: u32, height: u32) -> Film {
    let mut desc = desc.clone();
    if let Focus::Pixel { x, y } = &mut desc.camera.focus {
        *x = (*x as u64 * width as u64 / desc.camera.width as u64) as u32;
        *y = (*y as u64 * height as u64 / desc.camera.height as u64) as u32;
    }
    desc.camera.width = width;
    desc.camera.height = height;
    let world = world(&desc);
    let camera = desc
        .camera
        .build(|ray| {
            let hit = world.scene.intersect1(ray)?;
            let forward = (desc.camera.look_at - desc.camera.eye).normalize();
            Some((ray.at(hit.t) - ray.origin).dot(forward))
        })
        .unwrap();
    let settings = RenderSettings {
        mode: Mode::Dense,
        spp: 4,
        seed: 7,
        ..Default::default()
    };
    render(&world, &camera, &settings, &NoProgress).unwrap().0
}

fn bits(f: &Film) -> Vec<u32> {
    f.color
        .iter()
        .flat_map(|c| c.to_array().map(f32::to_bits))
        .collect()
}

fn meshes(desc: &SceneDesc) -> Vec<(&dofray::embree::TriangleMesh, usize)> {
    desc.objects
        .iter()
        .filter_map(|o| match o {
            Object::Mesh {
                mesh,
                materials: MeshMaterials::One(m),
            } => Some((mesh, *m)),
            _ => None,
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// The scenes in the repository.

#[test]
fn paper_toml_renders_identically_to_the_builtin() {
    let file = load(&repo().join("scenes/paper.toml")).unwrap();
    let built = builtin::paper();
    assert_eq!(file.name, "paper");
    assert_eq!((file.camera.width, file.camera.height), (640, 480));
    // The focus is given as a point rather than a distance: the cameras must still agree.
    assert_eq!(
        file.camera.build(|_| None).unwrap(),
        built.camera.build(|_| None).unwrap()
    );
    assert_eq!(file.lights, built.lights);
    assert_eq!(file.ambient, built.ambient);
    assert_eq!(file.background, built.background);
    assert_eq!(
        format!("{:?}", file.objects),
        format!("{:?}", built.objects)
    );
    assert_eq!(
        format!("{:?}", file.materials),
        format!("{:?}", built.materials)
    );
    let a = dense(&file, 64, 48);
    let b = dense(&built, 64, 48);
    assert!(a.color.iter().any(|c| *c != a.color[0]), "a blank image");
    assert_eq!(
        bits(&a),
        bits(&b),
        "paper.toml and the built-in paper scene differ"
    );
}

#[test]
fn every_scene_file_loads_builds_and_renders() {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(repo().join("scenes")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let desc = load(&path).unwrap_or_else(|e| panic!("{e}"));
            let film = dense(&desc, 32, 24);
            assert!(film.color.iter().all(|c| c.is_finite()));
            names.push(desc.name);
        }
    }
    names.sort();
    assert_eq!(
        names,
        [
            "bokeh",
            "focus_pull",
            "gallery",
            "interior",
            "night",
            "paper",
            "vase"
        ]
    );
}

/// The packet-wide surface points the renderer shades equal `World::surface_point` of each
/// lane bit for bit, on spheres, meshes with and without normals and UVs, and misses.
#[test]
fn packet_surface_points_equal_single_ones() {
    use dofray::embree::{LANES, RayHint, RayPacket16};
    use dofray::shade::SurfacePoints16;
    for name in ["paper", "gallery", "vase", "bokeh"] {
        let desc = load(&repo().join(format!("scenes/{name}.toml"))).unwrap();
        let world = world(&desc);
        let camera = desc.camera.build(|_| Some(1.0)).unwrap();
        let mut packet = RayPacket16::new();
        let mut points = SurfacePoints16::default();
        let mut hit_lanes = 0;
        for block in 0..200u32 {
            packet.clear();
            for lane in 0..LANES as u32 {
                let i = block * LANES as u32 + lane;
                let px = (i * 37 % camera.width) as f32 + 0.25;
                let py = (i * 53 % camera.height) as f32 + 0.75;
                // Inactive lanes mixed in: every fifth lane stays off.
                if i % 5 != 3 {
                    packet.set(lane as usize, &camera.pinhole_ray(px, py));
                }
            }
            world.scene.intersect16(&mut packet, RayHint::Incoherent);
            let hits = packet.hit_mask();
            world.surface_points16(&packet, hits, &mut points);
            for lane in 0..LANES {
                let expected = packet.hit(lane).map(|hit| {
                    let sp = world.surface_point(&packet.ray(lane), &hit);
                    (sp.position, sp.normal, sp.uv)
                });
                assert_eq!(hits & (1 << lane) != 0, expected.is_some());
                if let Some((p, n, uv)) = expected {
                    let got = points.get(lane);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&got.position.to_array()),
                        bits(&p.to_array()),
                        "{name}"
                    );
                    assert_eq!(bits(&got.normal.to_array()), bits(&n.to_array()), "{name}");
                    assert_eq!(bits(&got.uv.to_array()), bits(&uv.to_array()), "{name}");
                    hit_lanes += 1;
                }
            }
        }
        assert!(hit_lanes > 1000, "{name}: {hit_lanes}");
    }
}

#[test]
fn the_mesh_scenes_use_meshes_and_image_textures() {
    for name in ["gallery", "vase"] {
        let desc = load(&repo().join(format!("scenes/{name}.toml"))).unwrap();
        let ms = meshes(&desc);
        assert!(
            ms.iter()
                .any(|(m, _)| m.triangle_count() > 1000 && m.uvs().is_some()),
            "{name}: no textured mesh"
        );
        assert!(
            desc.materials
                .iter()
                .any(|m| matches!(m.base_color, Texture::Image { .. })),
            "{name}: no image texture"
        );
    }
}

#[test]
fn committed_assets_match_their_generator() {
    for (name, bytes) in scene_assets::generate() {
        let committed = std::fs::read(assets().join(name)).unwrap();
        match name.rsplit('.').next().unwrap() {
            // Text, and binary glTF built from exact float data.
            "obj" | "mtl" | "gltf" | "glb" => {
                assert!(
                    committed == bytes,
                    "scenes/assets/{name} differs from its generator"
                )
            }
            // Images: compare decoded pixels (encoders may change their byte streams).
            _ => {
                let a = image::load_from_memory(&committed).unwrap().to_rgb8();
                let b = image::load_from_memory(&bytes).unwrap().to_rgb8();
                assert_eq!(a.dimensions(), b.dimensions(), "{name}");
                let diff: u64 = a
                    .as_raw()
                    .iter()
                    .zip(b.as_raw())
                    .map(|(x, y)| x.abs_diff(*y) as u64)
                    .sum();
                assert!(diff as f64 / (a.as_raw().len() as f64) < 2.0, "{name}");
            }
        }
        assert!(
            committed.len() < 200_000,
            "{name} is {} bytes",
            committed.len()
        );
    }
}

#[test]
#[ignore = "writes scenes/assets; run on purpose to regenerate them"]
fn regenerate_scene_assets() {
    scene_assets::write_all(&assets());
}

// ---------------------------------------------------------------------------------------------
// Model loading.

#[test]
fn obj_loads_with_mtl_materials_and_textures() {
    let desc = load(&assets().join("torus.obj")).unwrap();
    let ms = meshes(&desc);
    assert_eq!(ms.len(), 1);
    let (torus, m) = ms[0];
    let (s, r) = (scene_assets::TORUS_SEGMENTS, scene_assets::TORUS_RINGS);
    assert_eq!(torus.triangle_count(), s * r * 2);
    assert_eq!(torus.vertex_count(), (s + 1) * (r + 1));
    assert!(torus.normals().is_some());
    let uvs = torus.uvs().expect("UVs");
    assert!(uvs.iter().any(|uv| uv[0] > 1.5), "tiled u up to 2");
    match &desc.materials[m].base_color {
        Texture::Image { image, tint } => {
            assert_eq!((image.width, image.height), (128, 32));
            assert_eq!(*tint, Vec3::ONE);
            // sRGB 220 -> linear 0.716 (the first band is red).
            assert!(
                (image.texels[0].x - 0.716).abs() < 0.03,
                "{}",
                image.texels[0]
            );
        }
        other => panic!("expected the map_Kd texture, got {other:?}"),
    }
    // Ns 64 is the GGX roughness of the same highlight width: sqrt(sqrt(2 / 66)).
    let r = desc.materials[m].roughness;
    assert!((r - (2.0f32 / 66.0).sqrt().sqrt()).abs() < 1e-6, "{r}");

    let desc = load(&assets().join("pedestal.obj")).unwrap();
    let ms = meshes(&desc);
    assert_eq!(
        ms.iter().map(|(m, _)| m.triangle_count()).sum::<usize>(),
        12
    );
    let slate = &desc.materials[ms[0].1];
    assert!(matches!(slate.base_color, Texture::Constant(c) if c == Vec3::new(0.22, 0.24, 0.28)));
    let top = &desc.materials[ms[1].1];
    assert_eq!(
        top.metallic, 0.3,
        "illum 3 makes a metal of strength max(Ks)"
    );
    assert!(ms[0].0.normals().is_none() && ms[0].0.uvs().is_none());
}

#[test]
fn gltf_and_glb_load_nodes_materials_uvs_and_camera() {
    let gltf = load(&assets().join("vase.gltf")).unwrap();
    let glb = load(&assets().join("vase.glb")).unwrap();
    let tris = scene_assets::VASE_SEGMENTS * scene_assets::VASE_ROWS * 2;
    for desc in [&gltf, &glb] {
        let ms = meshes(desc);
        assert_eq!(ms.len(), 1);
        let (vase, m) = ms[0];
        assert_eq!(vase.triangle_count(), tris);
        assert!(vase.normals().is_some());
        let uvs = vase.uvs().expect("UVs");
        // glTF's v is flipped: the bottom row (t = 0) has our v = 0.
        assert!(
            uvs.iter()
                .all(|uv| (0.0..=3.0).contains(&uv[0]) && (0.0..=1.0).contains(&uv[1]))
        );
        match &desc.materials[m].base_color {
            Texture::Image { image, tint } => {
                assert_eq!((image.width, image.height), (64, 64));
                assert_eq!(*tint, Vec3::new(1.0, 0.9, 0.8), "base-colour factor");
            }
            other => panic!("expected the base-colour texture, got {other:?}"),
        }
        // Node transforms: the child is stretched 1.25x in y and the parent lifts it 0.02.
        let top = vase
            .positions()
            .iter()
            .map(|p| p[1])
            .fold(f32::MIN, f32::max);
        let bottom = vase
            .positions()
            .iter()
            .map(|p| p[1])
            .fold(f32::MAX, f32::min);
        assert!((top - (0.02 + 0.9 * 1.25)).abs() < 1e-4, "{top}");
        assert!((bottom - 0.02).abs() < 1e-6, "{bottom}");
        // The camera comes from the file: its node's translation, yfov 0.7 rad, aspect 1.5.
        assert_eq!(desc.camera.eye, Vec3::new(0.0, 0.9, 2.6));
        assert!((desc.camera.vfov_deg - 0.7f32.to_degrees()).abs() < 1e-4);
        assert_eq!((desc.camera.width, desc.camera.height), (640, 427));
        // glTF cameras carry no depth of field: sharp, not an invented aperture.
        assert_eq!(desc.camera.lens, LensSpec::Pinhole);
        assert_eq!(desc.lights.len(), 1, "a default light");
    }
    assert_eq!(
        meshes(&gltf)[0].0.positions(),
        meshes(&glb)[0].0.positions()
    );
}

#[test]
fn the_world_shares_mesh_buffers_with_the_description() {
    // No copy of a (possibly huge) mesh when the world is built: Embree reads the very buffers
    // the loader filled.
    let desc = load(&assets().join("vase.glb")).unwrap();
    let world = world(&desc);
    let mesh = meshes(&desc)[0].0;
    match world.scene.geometry(dofray::embree::GeometryId(0)) {
        dofray::embree::Geometry::Mesh(m) => {
            assert_eq!(m.positions().as_ptr(), mesh.positions().as_ptr());
            assert_eq!(m.indices().as_ptr(), mesh.indices().as_ptr());
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_bare_obj_gets_a_camera_that_frames_it() {
    let desc = load(&assets().join("torus.obj")).unwrap();
    let cam = desc.camera.build(|_| None).unwrap();
    let (lo, hi) = (Vec3::new(-0.82, -0.22, -0.82), Vec3::new(0.82, 0.22, 0.82));
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let p = cam.project(corner).expect("in front");
        assert!(
            p.x >= 0.0 && p.y >= 0.0 && p.x <= 640.0 && p.y <= 480.0,
            "{corner} projects to {p}"
        );
    }
    match desc.camera.focus {
        Focus::Point(p) => assert!(p.length() < 1e-3, "focus on the bounds' centre, got {p}"),
        f => panic!("{f:?}"),
    }
    assert!(matches!(desc.lights[0], Light::Directional { .. }));
    // It renders, and the model is in the picture.
    let film = dense(&desc, 40, 30);
    let centre = film.color[film.index(20, 22)];
    let corner = film.color[0];
    assert_ne!(centre, corner);
}

#[test]
fn coordinates_beyond_what_a_camera_can_frame_name_the_object() {
    let m = error_of(
        "huge-sphere",
        "[[objects]]\ntype = \"sphere\"\nradius = 1e38\n",
    );
    assert_names(
        &m,
        "scene.toml:1:1",
        &[
            "`objects[0]`",
            "too large to frame",
            "give `eye` and `look_at`",
        ],
    );
    // The farthest-reaching object is named, not the first.
    let m = error_of(
        "huge-second",
        &format!("{SPHERE}[[objects]]\ntype = \"sphere\"\ncenter = [0, 3e38, 0]\nradius = 1\n"),
    );
    assert_names(
        &m,
        "scene.toml:4:1",
        &["`objects[1]`", "too large to frame"],
    );
    let m = error_of(
        "huge-eye",
        &format!(
            "[camera]\nlook_at = [0, 0, 0]\n{SPHERE}[[objects]]\ntype = \"sphere\"\nradius = 1e30\n"
        ),
    );
    assert_names(&m, "scene.toml:", &["`objects[1]`", "too large to frame"]);
    // With a camera given, the same scene loads, but is beyond the range every ray must stay
    // in: the renderer refuses it by name instead of letting Embree abort.
    let d = load_files(
        "huge-camera",
        &[(
            "scene.toml",
            b"[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\ntype = \"sphere\"\nradius = 1e38\n",
        )],
    )
    .unwrap();
    let err = World::build(&d, &Device::new().unwrap())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("object 0") && err.contains("1e15"), "{err}");
    d.camera.build(|_| None).unwrap();
    let m = error_of(
        "far-apart",
        &format!("[camera]\neye = [1e20, 0, 0]\nlook_at = [-1e20, 0, 0]\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:3:11", &["camera.look_at", "too far apart"]);
    // A bare model file.
    let dir = scratch("huge-obj");
    std::fs::write(
        dir.join("big.obj"),
        "v 3e38 0 0\nv -3e38 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let m = load(&dir.join("big.obj")).unwrap_err().to_string();
    assert_names(
        &m,
        "big.obj",
        &["too large to frame", "scale the model down"],
    );
    // No "inf" in the message, its path left out (the scratch directory's random name could
    // spell it).
    assert!(!m.replace(dir.to_str().unwrap(), "").contains("inf"), "{m}");
}

#[test]
fn the_camera_error_points_at_the_camera() {
    let m = error_of(
        "same",
        &format!("[camera]\neye = [0, 1, 5]\nlook_at = [0, 1, 5]\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:3:11",
        &["camera.look_at", "must differ from `eye`"],
    );
    // An eye at the framed look-at point (the bounds' centre) names the eye.
    let m = error_of("same-eye", &format!("[camera]\neye = [0, 0, 0]\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:7", &["camera.eye", "must differ"]);
}

#[test]
fn scales_out_of_range_say_so() {
    let m = error_of("scale-big", &format!("{SPHERE}scale = 1e30\n"));
    assert_names(
        &m,
        "scene.toml:4:",
        &["objects[0].scale", "too large", "overflows"],
    );
    assert!(!m.contains("singular"), "{m}");
    let m = error_of("scale-small", &format!("{SPHERE}scale = 1e-20\n"));
    assert_names(&m, "scene.toml:4:", &["objects[0].scale", "too small"]);
}

#[test]
fn loaded_meshes_hold_no_spare_capacity() {
    // tobj grows its buffers by doubling: the mesh keeps none of that slack (only Embree's
    // one element of padding).
    let d = load(&assets().join("torus.obj")).unwrap();
    for (m, _) in meshes(&d) {
        let (v, t) = (m.vertex_count(), m.triangle_count());
        let attributes = m.normals().map_or(0, |_| v * 12) + m.uvs().map_or(0, |_| v * 8);
        assert!(m.normals().is_some() && m.uvs().is_some());
        assert_eq!(m.heap_bytes(), (v + 1) * 12 + (t + 1) * 12 + attributes);
    }
    // And a transformed copy (transformed in tobj's buffers) matches the plain one.
    let toml = format!(
        "[[objects]]\ntype = \"mesh\"\nfile = \"{}\"\nscale = [3, 2, 1]\nrotate = [0, 90, 0]\n\
         translate = [0, 1, 0]\n",
        assets().join("torus.obj").display()
    );
    let t = load_files("moved-obj", &[("scene.toml", toml.as_bytes())]).unwrap();
    let (plain, turned) = (meshes(&d)[0].0, meshes(&t)[0].0);
    let m = glam::Mat3::from_rotation_y(90f32.to_radians())
        * glam::Mat3::from_diagonal(Vec3::new(3.0, 2.0, 1.0));
    let normal_matrix = m.inverse().transpose();
    for i in (0..plain.vertex_count()).step_by(13) {
        let p = m * Vec3::from(plain.positions()[i]) + Vec3::Y;
        assert!((p - Vec3::from(turned.positions()[i])).length() < 1e-5);
        let n = (normal_matrix * Vec3::from(plain.normals().unwrap()[i])).normalize();
        assert!((n - Vec3::from(turned.normals().unwrap()[i])).length() < 1e-5);
    }
    assert_eq!(plain.indices(), turned.indices());
    assert_eq!(plain.uvs(), turned.uvs());
}

// ---------------------------------------------------------------------------------------------
// Transforms.

#[test]
fn transforms_scale_rotate_then_translate() {
    let toml = format!(
        "{SPHERE}center = [1, 0, 0]\nscale = 2\nrotate = [0, 0, 90]\ntranslate = [0, 0, 5]\n\
         [[objects]]\ntype = \"quad\"\nsize = [2, 4]\nrotate = [-90, 0, 0]\ntranslate = [0, 2, 3]\n\
         [[objects]]\ntype = \"mesh\"\nfile = \"{}\"\nrotate_axis = [0, 1, 0]\nrotate_angle = 90\nscale = [1, 2, 1]\n",
        assets().join("vase.gltf").display()
    );
    let desc = load_files("transforms", &[("scene.toml", toml.as_bytes())]).unwrap();
    match desc.objects[0] {
        Object::Sphere { center, radius, .. } => {
            // (1, 0, 0) scaled to (2, 0, 0), turned 90 degrees about z to (0, 2, 0), moved by z 5.
            assert!(
                (center - Vec3::new(0.0, 2.0, 5.0)).length() < 1e-5,
                "{center}"
            );
            assert_eq!(radius, 2.0);
        }
        ref o => panic!("{o:?}"),
    }
    let ms = meshes(&desc);
    // The quad stands up as a wall at z = 3 from y = 0 to 4, keeping its UVs.
    let wall = ms[0].0;
    for p in wall.positions() {
        assert!(
            (p[2] - 3.0).abs() < 1e-5 && p[1] > -1e-5 && p[1] < 4.0 + 1e-5,
            "{p:?}"
        );
    }
    assert_eq!(wall.uvs().unwrap()[0], [-1.0, -2.0]);
    let n = wall.face_normal(0).normalize();
    assert!((n.z.abs() - 1.0).abs() < 1e-5, "{n}");

    // The vase: node transforms, then ours; normals follow the inverse transpose.
    let plain = load(&assets().join("vase.gltf")).unwrap();
    let plain = meshes(&plain)[0].0;
    let turned = ms[1].0;
    let rot = glam::Mat3::from_rotation_y(90f32.to_radians());
    let m = rot * glam::Mat3::from_diagonal(Vec3::new(1.0, 2.0, 1.0));
    let normal_matrix = m.inverse().transpose();
    for i in (0..plain.vertex_count()).step_by(97) {
        let p = m * Vec3::from(plain.positions()[i]);
        assert!((p - Vec3::from(turned.positions()[i])).length() < 1e-4);
        let n = (normal_matrix * Vec3::from(plain.normals().unwrap()[i])).normalize();
        assert!((n - Vec3::from(turned.normals().unwrap()[i])).length() < 1e-4);
        // Still perpendicular to the surface: check against a transformed tangent.
    }
    assert_eq!(turned.uvs(), plain.uvs());
}

#[test]
fn normals_transform_by_the_inverse_transpose() {
    // Under a non-uniform scale, a normal must stay perpendicular to the transformed surface:
    // for an edge e, n'.(M e) must equal n.e scaled by 1 / |M^-T n|, which only the inverse
    // transpose achieves (M n would tilt normals towards the stretched axis).
    let toml = format!(
        "[[objects]]\ntype = \"mesh\"\nfile = \"{}\"\nscale = [3, 0.5, 1]\nrotate = [20, 40, 60]\n",
        assets().join("torus.obj").display()
    );
    let desc = load_files("normals", &[("scene.toml", toml.as_bytes())]).unwrap();
    let torus = meshes(&desc)[0].0;
    let plain = load(&assets().join("torus.obj")).unwrap();
    let plain = meshes(&plain)[0].0;
    let m = glam::Mat3::from_rotation_z(60f32.to_radians())
        * glam::Mat3::from_rotation_y(40f32.to_radians())
        * glam::Mat3::from_rotation_x(20f32.to_radians())
        * glam::Mat3::from_diagonal(Vec3::new(3.0, 0.5, 1.0));
    let inv_t = m.inverse().transpose();
    let (n0, n1) = (plain.normals().unwrap(), torus.normals().unwrap());
    let mut naive_error = 0.0f32;
    for tri in plain.indices() {
        for k in 0..3 {
            let (i, j) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
            let e = Vec3::from(plain.positions()[j]) - Vec3::from(plain.positions()[i]);
            let e1 = Vec3::from(torus.positions()[j]) - Vec3::from(torus.positions()[i]);
            assert!((m * e - e1).length() < 1e-4);
            let n = Vec3::from(n0[i]);
            let expected = n.dot(e) / (inv_t * n).length();
            let got = Vec3::from(n1[i]).dot(e1);
            assert!((got - expected).abs() < 1e-4, "{got} vs {expected}");
            naive_error = naive_error.max(((m * n).normalize().dot(e1) - expected).abs());
        }
    }
    assert!(
        naive_error > 0.01,
        "the test cannot tell the naive transform apart"
    );
}

#[test]
fn defaults_fill_what_the_file_leaves_out() {
    let desc = load_files("defaults", &[("scene.toml", SPHERE.as_bytes())]).unwrap();
    assert_eq!(desc.name, "scene");
    assert_eq!((desc.camera.width, desc.camera.height), (640, 480));
    assert_eq!(desc.camera.vfov_deg, 40.0);
    assert_eq!(desc.camera.lens, LensSpec::Pinhole);
    assert_eq!(desc.camera.focus, Focus::Point(Vec3::ZERO));
    assert_eq!(desc.lights.len(), 1, "a default light");
    assert_eq!(desc.settings.spp, None);
    assert_eq!(desc.materials.len(), 1, "the default material");
    let cam = desc.camera.build(|_| None).unwrap();
    let p = cam.project(Vec3::ZERO).unwrap();
    assert!((p - Vec2::new(320.0, 240.0)).length() < 1.0, "{p}");
}

#[test]
fn every_camera_key_is_read() {
    let base = "[image]\nwidth = 100\nheight = 50\n[render]\nspp = 8\ninterval_factor = 0.2\n";
    let cam = |keys: &str| {
        let toml = format!(
            "{base}[camera]\neye = [0, 0, -5]\nlook_at = [0, 0, 0]\nup = [0, 1, 0]\n{keys}\n{SPHERE}"
        );
        load_files("camera", &[("scene.toml", toml.as_bytes())]).unwrap()
    };
    let d = cam(
        "vfov = 30\naperture_radius = 0.1\nfocus_distance = 4\nblades = 6\nblade_rotation = 10\nanamorphic = 1.5",
    );
    assert_eq!(
        (
            d.camera.width,
            d.camera.height,
            d.settings.spp,
            d.settings.rule
        ),
        (
            100,
            50,
            Some(8),
            Some(RulePatch::Seed {
                interval_factor: Some(0.2),
                paper_exact: false
            })
        )
    );
    assert_eq!(d.camera.vfov_deg, 30.0);
    assert_eq!(d.camera.lens, LensSpec::Aperture { radius: 0.1 });
    assert_eq!(d.camera.focus, Focus::Distance(4.0));
    assert_eq!(
        (
            d.camera.aperture.blades,
            d.camera.aperture.rotation_deg,
            d.camera.aperture.anamorphic
        ),
        (6, 10.0, 1.5)
    );
    let d = cam("f_number = 2.8\nfocal_length_mm = 85\nfocus_point = [0, 0, -1]");
    assert_eq!(
        d.camera.lens,
        LensSpec::Photographic {
            focal_length_mm: 85.0,
            f_number: 2.8,
            sensor_width_mm: 36.0
        }
    );
    assert_eq!(d.camera.focus, Focus::Point(Vec3::new(0.0, 0.0, -1.0)));
    let d = cam("sharp_range = 0.5\nspread = 4\nfocus_pixel = [50, 25]");
    assert_eq!(
        d.camera.lens,
        LensSpec::Seed {
            sharp_range: 0.5,
            spread: 4.0
        }
    );
    assert_eq!(d.camera.focus, Focus::Pixel { x: 50, y: 25 });
    let d = cam("aperture_radius = 0");
    assert_eq!(d.camera.lens, LensSpec::Pinhole);
    let d = load_files("bg", &[("scene.toml", format!("ambient = [0.1, 0.2, 0.3]\n[background]\ncolor = 0.5\n[[lights]]\ntype = \"directional\"\ndirection = [0, -1, 0]\nirradiance = [1, 2, 3]\n{SPHERE}").as_bytes())]).unwrap();
    assert_eq!(d.ambient, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(d.background.horizon, Vec3::splat(0.5));
    assert_eq!(
        d.lights,
        vec![Light::Directional {
            direction: Vec3::NEG_Y,
            irradiance: Vec3::new(1.0, 2.0, 3.0),
            angle: 0.0,
        }]
    );
    let d = load_files(
        "nolights",
        &[("scene.toml", format!("lights = []\n{SPHERE}").as_bytes())],
    )
    .unwrap();
    assert!(
        d.lights.is_empty(),
        "an explicit empty list means no lights"
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input: each names the file and the line or key, and says what was expected.

#[test]
fn toml_syntax_errors_name_the_line_and_column() {
    let m = error_of("syntax", "[camera\neye = [0, 0, 0]\n");
    assert_names(&m, "scene.toml:1:", &[]);
    let m = error_of("syntax2", "name = \"x\"\n[image]\nwidth = = 3\n");
    assert_names(&m, "scene.toml:3:", &[]);
    let m = error_of(
        "syntax3",
        "[[objects]]\ntype = \"sphere\"\nradius = 1\ncenter = [0, 0,\n",
    );
    assert_names(&m, "scene.toml:", &[]);
}

#[test]
fn unknown_keys_are_rejected() {
    let m = error_of("unknown", "[[objects]]\ntype = \"sphere\"\nradis = 1\n");
    assert_names(
        &m,
        "scene.toml:3:1",
        &["`objects[0].radis`", "unknown field `radis`", "radius"],
    );
    let m = error_of(
        "unknown2",
        &format!("[camera]\nfocus_distnce = 3\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:2:1",
        &["camera.focus_distnce", "unknown field"],
    );
    let m = error_of("unknown3", &format!("colour = 1\n{SPHERE}"));
    assert_names(&m, "scene.toml:1:1", &["colour", "unknown field"]);
    let m = error_of("unknown4", "[[objects]]\ntype = \"cube\"\nradius = 1\n");
    assert_names(
        &m,
        "scene.toml:2:",
        &["objects[0].type", "unknown variant `cube`", "sphere"],
    );
}

#[test]
fn wrong_types_are_rejected() {
    let m = error_of("type", "[[objects]]\ntype = \"sphere\"\nradius = \"big\"\n");
    assert_names(
        &m,
        "scene.toml:3:10",
        &[
            "objects[0].radius",
            "invalid type: string",
            "a finite number > 0",
        ],
    );
    let m = error_of("type2", &format!("[image]\nwidth = 640.5\n{SPHERE}"));
    assert_names(
        &m,
        "scene.toml:2:",
        &["image.width", "whole number of pixels"],
    );
    let m = error_of("type3", &format!("[camera]\neye = [0, 0]\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:", &["camera.eye", "invalid length 2"]);
    let m = error_of(
        "type4",
        &format!("[[materials]]\nname = \"m\"\ndiffuse = [1, 0]\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:3:", &["materials[0].diffuse", "colour"]);
    let m = error_of("type5", "objects = 3\n");
    assert_names(&m, "scene.toml:1:", &["objects", "invalid type"]);
}

#[test]
fn nan_and_infinity_are_rejected_with_the_key() {
    let m = error_of(
        "nan",
        "[[objects]]\ntype = \"sphere\"\nradius = 1\ncenter = [0, nan, 0]\n",
    );
    assert_names(
        &m,
        "scene.toml:4:14",
        &["objects[0].center", "NaN", "finite"],
    );
    let m = error_of("inf", &format!("ambient = inf\n{SPHERE}"));
    assert_names(&m, "scene.toml:1:11", &["ambient", "inf"]);
    let m = error_of(
        "inf2",
        &format!("[camera]\neye = [\n  0,\n  -inf,\n  1]\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:4:3", &["camera.eye", "finite"]);
    // A number beyond f32 is refused where it must be finite (a focus distance takes it as
    // infinity: see focus_distance_may_be_infinite).
    let m = error_of(
        "huge",
        &format!("[camera]\naperture_radius = 1e300\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:2:", &["camera.aperture_radius", "finite"]);
    let m = error_of(
        "naninarray",
        &format!(
            "[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = [1, nan, 1]\n{SPHERE}"
        ),
    );
    assert_names(&m, "scene.toml:4:", &["lights[0].intensity", "NaN"]);
}

#[test]
fn negative_or_zero_sizes_and_radii_are_rejected() {
    let m = error_of("radius", "[[objects]]\ntype = \"sphere\"\nradius = -1\n");
    assert_names(&m, "scene.toml:3:10", &["objects[0].radius", "-1", "> 0"]);
    let m = error_of("radius0", "[[objects]]\ntype = \"sphere\"\nradius = 0\n");
    assert_names(&m, "scene.toml:3:10", &["objects[0].radius", "> 0"]);
    let m = error_of("width", &format!("[image]\nwidth = 0\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:9", &["image.width", ">= 1"]);
    let m = error_of("height", &format!("[image]\nheight = -480\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:", &["image.height", "-480"]);
    let m = error_of("quad", "[[objects]]\ntype = \"quad\"\nsize = [10, -2]\n");
    assert_names(&m, "scene.toml:3:", &["objects[0].size", "> 0"]);
    let m = error_of("scale", &format!("{SPHERE}scale = 0\n"));
    assert_names(&m, "scene.toml:4:", &["objects[0].scale", "> 0"]);
    let m = error_of(
        "aperture",
        &format!("[camera]\naperture_radius = -0.1\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:2:", &["camera.aperture_radius", ">= 0"]);
    let m = error_of("spp", &format!("[render]\nspp = 0\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:", &["render.spp", ">= 1"]);
    let m = error_of("fov", &format!("[camera]\nvfov = 180\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:", &["camera.vfov", "between 0 and 180"]);
}

#[test]
fn inconsistent_scenes_are_rejected_by_key() {
    let m = error_of("nomat", &format!("{SPHERE}material = \"gold\"\n"));
    assert_names(
        &m,
        "scene.toml:4:",
        &["objects[0].material", "no material named \"gold\""],
    );
    let m = error_of(
        "notex",
        &format!("[[materials]]\nname = \"m\"\ntexture = \"wood\"\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:3:",
        &["materials[0].texture", "no texture named \"wood\""],
    );
    let m = error_of(
        "dup",
        &format!("[[materials]]\nname = \"m\"\n[[materials]]\nname = \"m\"\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:4:", &["materials[1].name", "defined twice"]);
    let m = error_of(
        "twolens",
        &format!("[camera]\naperture_radius = 0.1\nf_number = 2\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:3:",
        &["camera.f_number", "both set the lens"],
    );
    let m = error_of(
        "twofocus",
        &format!("[camera]\nfocus_distance = 2\nfocus_point = [0, 0, 0]\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:3:",
        &["camera.focus_point", "both set the focus"],
    );
    let m = error_of(
        "pixel",
        &format!("[image]\nwidth = 10\nheight = 10\n[camera]\nfocus_pixel = [10, 3]\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:5:",
        &["camera.focus_pixel", "outside the 10x10 image"],
    );
    let m = error_of("spread", &format!("[camera]\nsharp_range = 1\n{SPHERE}"));
    assert_names(&m, "scene.toml:2:", &["camera.sharp_range", "needs both"]);
    let m = error_of("sphere-size", &format!("{SPHERE}size = [1, 1]\n"));
    assert_names(
        &m,
        "scene.toml:",
        &["objects[0].size", "does not apply to a sphere"],
    );
    let m = error_of("sphere-noradius", "[[objects]]\ntype = \"sphere\"\n");
    assert_names(&m, "scene.toml:", &["objects[0]", "needs `radius`"]);
    let m = error_of("squash", &format!("{SPHERE}scale = [1, 2, 1]\n"));
    assert_names(&m, "scene.toml:4:", &["objects[0].scale", "uniformly"]);
    let m = error_of("light", &format!("[[lights]]\ntype = \"point\"\n{SPHERE}"));
    assert_names(&m, "scene.toml:", &["lights[0]", "needs `position`"]);
    let m = error_of(
        "up",
        &format!("[camera]\neye = [0, 5, 0]\nlook_at = [0, 0, 0]\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:", &["camera.up", "parallel"]);
    let m = error_of(
        "texture-both",
        &format!("[[textures]]\nname = \"t\"\nimage = \"a.png\"\npattern = \"dots\"\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:", &["textures[0]", "not both"]);
    let m = error_of(
        "mesh-ext",
        "[[objects]]\ntype = \"mesh\"\nfile = \"model.stl\"\n",
    );
    assert_names(
        &m,
        "scene.toml:3:",
        &[
            "objects[0].file",
            "unsupported mesh file",
            ".obj, .gltf or .glb",
        ],
    );
}

#[test]
fn a_scene_with_no_objects_is_rejected() {
    let m = error_of("empty", "[camera]\neye = [0, 0, -5]\nlook_at = [0, 0, 0]\n");
    assert_names(&m, "scene.toml", &["no objects"]);
    let m = error_of("empty2", "");
    assert_names(&m, "scene.toml", &["no objects"]);
}

#[test]
fn missing_files_name_the_scene_line_and_the_missing_file() {
    let m = error_of(
        "nomesh",
        "[[objects]]\ntype = \"mesh\"\nfile = \"models/nope.obj\"\n",
    );
    assert_names(
        &m,
        "scene.toml:3:8",
        &["objects[0].file", "models/nope.obj", "cannot read"],
    );
    let m = error_of(
        "notexfile",
        &format!("[[textures]]\nname = \"t\"\nimage = \"wood.png\"\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:3:9",
        &["textures[0].image", "wood.png", "cannot read"],
    );
    // An OBJ whose MTL library is missing, and an MTL whose texture is missing.
    let obj = "mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let m = load_files(
        "nomtl",
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.obj\"\n",
            ),
            ("m.obj", obj.as_bytes()),
        ],
    )
    .unwrap_err()
    .to_string();
    assert_names(
        &m,
        "scene.toml:3:8",
        &["m.obj:1", "material library", "missing.mtl", "cannot read"],
    );
    let obj = "mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let m = load_files(
        "nomaptex",
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.obj\"\n",
            ),
            ("m.obj", obj.as_bytes()),
            ("m.mtl", b"newmtl a\nKd 1 1 1\nmap_Kd gone.png\n"),
        ],
    )
    .unwrap_err()
    .to_string();
    assert_names(&m, "m.mtl", &["a.map_Kd", "gone.png", "cannot read"]);
    // A glTF with an external buffer that is not there.
    let gltf = r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":12,"uri":"geometry.bin"}]}"#;
    let m = load_files(
        "nobin",
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.gltf\"\n",
            ),
            ("m.gltf", gltf.as_bytes()),
        ],
    )
    .unwrap_err()
    .to_string();
    assert_names(
        &m,
        "scene.toml:3:8",
        &["m.gltf", "geometry.bin", "cannot read"],
    );
    // A directory where a file should be.
    let m = load_files(
        "dir",
        &[(
            "scene.toml",
            b"[[objects]]\ntype = \"mesh\"\nfile = \".\"\n",
        )],
    )
    .unwrap_err()
    .to_string();
    assert_names(&m, "scene.toml:3:", &["objects[0].file"]);
    let dir = scratch("dirobj");
    std::fs::create_dir_all(dir.join("d.obj")).unwrap();
    let m = load(&dir.join("d.obj")).unwrap_err().to_string();
    assert_names(&m, "d.obj", &["cannot read"]);
    // The scene file itself.
    let m = scene::load("/nonexistent/scene.toml")
        .unwrap_err()
        .to_string();
    assert_names(&m, "/nonexistent/scene.toml", &["cannot read"]);
    let m = scene::load("no-such-scene").unwrap_err().to_string();
    assert_names(&m, "no-such-scene", &["unknown scene", "paper"]);
}

fn obj_scene(test: &str, obj: &str) -> String {
    load_files(
        test,
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.obj\"\n",
            ),
            ("m.obj", obj.as_bytes()),
        ],
    )
    .unwrap_err()
    .to_string()
}

#[test]
fn malformed_and_truncated_obj_files_name_the_line() {
    let m = obj_scene("objtrunc", "v 0 0 0\nv 1 0 0\nv 0 1\n");
    assert_names(
        &m,
        "m.obj:3",
        &["scene.toml:3:8", "malformed vertex position"],
    );
    // The last line without its newline is still named as itself.
    let m = obj_scene("objnonl", "v 0 0 0\nv 1 0 0\nv 0 1");
    assert_names(&m, "m.obj:3", &["malformed vertex position"]);
    let m = obj_scene("objnonl2", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 x");
    assert_names(&m, "m.obj:5", &["malformed face"]);
    // A face cut short: tobj drops faces of fewer than 3 corners silently.
    let m = obj_scene(
        "objshort",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\nf 1 2 3\n",
    );
    assert_names(
        &m,
        "m.obj:5",
        &["scene.toml:3:8", "face with 2 corners", "at least 3"],
    );
    let m = obj_scene("objshort1", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1");
    assert_names(&m, "m.obj:5", &["face with 1 corner:"]);
    let m = obj_scene("objshort0", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf\nf 1 2 3\n");
    assert_names(&m, "m.obj:4", &["face with 0 corners"]);
    // The earlier of two problems is the one named.
    let m = obj_scene("objfirst", "v 0 0 0\nv 1 0 0\nf 1 2\nv 0 1 0\nf 1 2 9\n");
    assert_names(&m, "m.obj:3", &["face with 2 corners"]);
    let m = obj_scene("objface", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
    assert_names(&m, "m.obj:4", &["malformed face"]);
    let m = obj_scene("objempty", "# nothing\n");
    assert_names(&m, "m.obj", &["no triangles"]);
    let m = obj_scene("objbinary", "v 0 0 0\n\u{0}\u{1}\u{2}\n");
    assert_names(&m, "m.obj", &[]);
    let mut bad = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n".to_vec();
    bad.extend([0xff, 0xfe, b'\n']);
    let dir = scratch("objutf8");
    std::fs::write(dir.join("m.obj"), &bad).unwrap();
    let m = load(&dir.join("m.obj")).unwrap_err().to_string();
    assert_names(&m, "m.obj:4", &["UTF-8"]);
    // tobj would panic on a colour with two components; that must be an error naming the line.
    let dir = scratch("mtlshort");
    std::fs::write(
        dir.join("m.obj"),
        "mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(dir.join("m.mtl"), "newmtl a\nKd 0.5 0.5\n").unwrap();
    let m = load(&dir.join("m.obj")).unwrap_err().to_string();
    assert_names(
        &m,
        "m.mtl:2",
        &["m.obj:1", "material library", "`Kd` has 2 values"],
    );
    let m = load_files(
        "mtlbad",
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.obj\"\n",
            ),
            (
                "m.obj",
                b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            ),
            ("m.mtl", b"newmtl a\nNs lots\n"),
        ],
    )
    .unwrap_err()
    .to_string();
    assert_names(
        &m,
        "m.mtl:2",
        &["scene.toml:3:8", "m.obj:1", "malformed material"],
    );
    // One grey value is allowed.
    std::fs::write(dir.join("m.mtl"), "newmtl a\nKd 0.5\n").unwrap();
    let d = load(&dir.join("m.obj")).unwrap();
    let (_, m) = meshes(&d)[0];
    assert!(matches!(d.materials[m].base_color, Texture::Constant(c) if c == Vec3::splat(0.5)));
}

#[test]
fn face_indices_out_of_range_are_rejected() {
    let m = obj_scene("objrange", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
    assert_names(
        &m,
        "m.obj:5",
        &["scene.toml:3:8", "index 9 is out of range", "3 vertices"],
    );
    let m = obj_scene("objneg", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n");
    assert_names(&m, "m.obj:3", &["index -3 is out of range"]);
    let m = obj_scene(
        "objvt",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n",
    );
    assert_names(&m, "m.obj:5", &["texture coordinate index 2"]);
    // Texture and normal indices in a file that has none (tobj ignores them unchecked).
    let m = obj_scene("objvt0", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1/5 2 3\n");
    assert_names(
        &m,
        "m.obj:5",
        &[
            "scene.toml:3:8",
            "texture coordinate index 5 is out of range",
            "0 texture coordinates",
        ],
    );
    let m = obj_scene("objvn0", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//7 2//7 3//7\n");
    assert_names(
        &m,
        "m.obj:4",
        &["normal index 7 is out of range", "0 normals"],
    );
    let m = obj_scene(
        "objvn1",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1/2 2/1 3/1\n",
    );
    assert_names(&m, "m.obj:5", &["normal index 2 is out of range"]);
    // In range they load (and a face without them beside one with them is fine).
    let dir = scratch("objvtok");
    std::fs::write(
        dir.join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\n",
    )
    .unwrap();
    let d = load(&dir.join("m.obj")).unwrap();
    assert_eq!(meshes(&d)[0].0.triangle_count(), 1);
    // glTF indices beyond the vertices.
    let (doc, bin) = tiny_gltf(&[0, 1, 7]);
    let m = load_files(
        "gltfrange",
        &[
            (
                "scene.toml",
                b"[[objects]]\ntype = \"mesh\"\nfile = \"m.glb\"\n",
            ),
            ("m.glb", &scene_assets::glb(&doc, &bin)),
        ],
    )
    .unwrap_err()
    .to_string();
    assert_names(
        &m,
        "m.glb",
        &["scene.toml:3:8", "out of range", "3 vertices"],
    );
}

/// A one-triangle glTF document with the given u16 indices; returns (JSON, binary buffer).
fn tiny_gltf(indices: &[u16]) -> (serde_json::Value, Vec<u8>) {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend(v.to_le_bytes());
    }
    for i in indices {
        bin.extend(i.to_le_bytes());
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": indices.len() * 2}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}
        ]
    });
    (doc, bin)
}

#[test]
fn gltf_strips_fans_and_unindexed_triangles_load() {
    let dir = scratch("gltfmodes");
    let (doc, bin) = tiny_gltf(&[0, 1, 2]);
    for (mode, indexed, tris) in [(4, false, 1), (5, true, 1), (6, true, 1), (0, true, 0)] {
        let mut d = doc.clone();
        d["meshes"][0]["primitives"][0]["mode"] = serde_json::json!(mode);
        if !indexed {
            d["meshes"][0]["primitives"][0]
                .as_object_mut()
                .unwrap()
                .remove("indices");
        }
        let path = dir.join(format!("mode{mode}.glb"));
        std::fs::write(&path, scene_assets::glb(&d, &bin)).unwrap();
        match load(&path) {
            Ok(desc) => assert_eq!(meshes(&desc)[0].0.triangle_count(), tris, "mode {mode}"),
            Err(e) => {
                assert_eq!(tris, 0, "mode {mode}: {e}");
                assert_names(&e.to_string(), "mode0.glb", &["no triangle meshes"]);
            }
        }
    }
}

#[test]
fn malformed_and_truncated_gltf_files_are_rejected() {
    let dir = scratch("gltfbad");
    let gltf = std::fs::read(assets().join("vase.gltf")).unwrap();
    let glb = std::fs::read(assets().join("vase.glb")).unwrap();
    let half_glb = format!(
        "truncated GLB file: its header declares {} bytes, but the file has {}",
        glb.len(),
        glb.len() / 2
    );
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "half.gltf",
            gltf[..gltf.len() / 2].to_vec(),
            "not a valid glTF",
        ),
        ("half.glb", glb[..glb.len() / 2].to_vec(), &half_glb),
        (
            "header.glb",
            glb[..10].to_vec(),
            "truncated GLB file: it has 10 bytes, less than the 12-byte GLB header",
        ),
        ("empty.gltf", Vec::new(), "not a valid glTF"),
        (
            "nomesh.gltf",
            br#"{"asset":{"version":"2.0"}}"#.to_vec(),
            "no triangle meshes",
        ),
        (
            "v1.gltf",
            br#"{"asset":{"version":"1.0"},"meshes":{}}"#.to_vec(),
            "not a valid glTF",
        ),
    ];
    for (name, bytes, expect) in cases {
        std::fs::write(dir.join(name), bytes).unwrap();
        let m = load(&dir.join(name)).unwrap_err().to_string();
        assert_names(&m, name, &[expect]);
    }
    // A buffer shorter than it claims.
    let (doc, bin) = tiny_gltf(&[0, 1, 2]);
    let mut short = doc.clone();
    short["buffers"][0]["byteLength"] = serde_json::json!(bin.len() + 64);
    std::fs::write(dir.join("short.glb"), scene_assets::glb(&short, &bin)).unwrap();
    let m = load(&dir.join("short.glb")).unwrap_err().to_string();
    assert_names(&m, "short.glb", &["truncated"]);
    // An accessor reaching past its buffer view, and one of the wrong type.
    let mut past = doc.clone();
    past["accessors"][0]["count"] = serde_json::json!(30);
    std::fs::write(dir.join("past.glb"), scene_assets::glb(&past, &bin)).unwrap();
    let m = load(&dir.join("past.glb")).unwrap_err().to_string();
    assert_names(&m, "past.glb", &["accessor 0", "POSITION"]);
    let mut vec2 = doc.clone();
    vec2["accessors"][0]["type"] = serde_json::json!("VEC2");
    std::fs::write(dir.join("vec2.glb"), scene_assets::glb(&vec2, &bin)).unwrap();
    let m = load(&dir.join("vec2.glb")).unwrap_err().to_string();
    assert_names(&m, "vec2.glb", &["POSITION", "Vec3"]);
    // NaN coordinates.
    let mut nan_bin = bin.clone();
    nan_bin[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(dir.join("nan.glb"), scene_assets::glb(&doc, &nan_bin)).unwrap();
    let m = load(&dir.join("nan.glb")).unwrap_err().to_string();
    assert_names(&m, "nan.glb", &["non-finite"]);
    // The valid tiny model loads.
    std::fs::write(dir.join("ok.glb"), scene_assets::glb(&doc, &bin)).unwrap();
    let d = load(&dir.join("ok.glb")).unwrap();
    assert_eq!(meshes(&d)[0].0.triangle_count(), 1);
}

#[test]
fn unreadable_and_truncated_images_are_rejected() {
    let png = std::fs::read(assets().join("tiles.png")).unwrap();
    let jpg = std::fs::read(assets().join("bands.jpg")).unwrap();
    let scene = format!(
        "[[textures]]\nname = \"t\"\nimage = \"t.png\"\n[[materials]]\nname = \"m\"\ntexture = \"t\"\n{SPHERE}material = \"m\"\n"
    );
    for (case, bytes) in [
        ("pnghalf", &png[..png.len() / 2]),
        ("pnghead", &png[..20]),
        ("jpghalf", &jpg[..jpg.len() / 3]),
        ("jpg90", &jpg[..jpg.len() * 9 / 10]),
        ("jpgnoend", &jpg[..jpg.len() - 2]),
        ("notimage", b"GIF89a not really".as_slice()),
        ("emptyimg", b"".as_slice()),
    ] {
        let m = load_files(case, &[("scene.toml", scene.as_bytes()), ("t.png", bytes)])
            .unwrap_err()
            .to_string();
        assert_names(&m, "scene.toml:3:9", &["textures[0].image", "t.png"]);
        if case.starts_with("jpg") {
            // A decoder fills a cut JPEG with grey: the cut must be caught before it.
            assert_names(&m, "t.png", &["truncated JPEG", "end-of-image marker"]);
        }
    }
    // And a good one loads, sRGB-decoded.
    let d = load_files(
        "pngok",
        &[("scene.toml", scene.as_bytes()), ("t.png", &png)],
    )
    .unwrap();
    assert!(
        matches!(&d.materials[0].base_color, Texture::Image { image, .. } if image.width == 64)
    );
}

#[test]
fn invalid_utf8_in_a_scene_names_the_line() {
    let mut bytes = format!("{SPHERE}name = \"").into_bytes();
    bytes.extend([0xc3, 0x28, b'"', b'\n']);
    let m = load_files("utf8", &[("scene.toml", &bytes)])
        .unwrap_err()
        .to_string();
    assert_names(&m, "scene.toml:4:", &["UTF-8"]);
}

#[test]
fn image_sizes_beyond_memory_are_refused_with_the_need() {
    assert!(check_image_memory(640, 480).is_ok());
    let e = check_image_memory(200_000, 200_000).unwrap_err();
    assert_eq!(e.needed(), 200_000u128 * 200_000 * BYTES_PER_PIXEL as u128);
    let m = e.to_string();
    assert!(m.contains("200000x200000") && m.contains("TiB"), "{m}");
    let limit = MemoryLimit::Available {
        available: 100 << 20,
    };
    let e = check_image_memory_against(4000, 3000, &limit).unwrap_err();
    assert!(e.to_string().contains("1.4 GiB"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Random input never panics.

fn try_load(dir: &Path, name: &str, bytes: &[u8]) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    // Ok or Err; a panic fails the property.
    let _ = load(&path);
}

/// Flips, drops or inserts bytes of a valid file.
fn mutate(base: &[u8], edits: &[(usize, u8, u8)]) -> Vec<u8> {
    let mut v = base.to_vec();
    for &(pos, kind, byte) in edits {
        if v.is_empty() {
            v.push(byte);
            continue;
        }
        let i = pos % v.len();
        match kind % 4 {
            0 => v[i] = byte,
            1 => {
                v.remove(i);
            }
            2 => v.insert(i, byte),
            _ => v.truncate(i),
        }
    }
    v
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let dir = scratch("fuzz");
        for name in ["s.toml", "m.obj", "m.gltf", "m.glb"] {
            try_load(&dir, name, &bytes);
        }
        let mut glb = b"glTF\x02\x00\x00\x00".to_vec();
        glb.extend(&bytes);
        try_load(&dir, "g.glb", &glb);
    }

    #[test]
    fn mutated_files_never_panic(edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..6)) {
        let dir = scratch("mutate");
        for asset in ["tiles.png", "bands.jpg", "pedestal.obj", "gallery.mtl", "vase.glb"] {
            std::fs::copy(assets().join(asset), dir.join(asset)).unwrap();
        }
        let scene = std::fs::read(repo().join("scenes/gallery.toml")).unwrap();
        let scene = String::from_utf8(scene).unwrap().replace("assets/", "");
        try_load(&dir, "gallery.toml", &mutate(scene.as_bytes(), &edits));
        let obj = std::fs::read(assets().join("pedestal.obj")).unwrap();
        try_load(&dir, "p.obj", &mutate(&obj, &edits));
        let mtl = std::fs::read(assets().join("gallery.mtl")).unwrap();
        std::fs::write(dir.join("gallery.mtl"), mutate(&mtl, &edits)).unwrap();
        let _ = load(&dir.join("pedestal.obj"));
        let (doc, bin) = tiny_gltf(&[0, 1, 2]);
        let json = serde_json::to_vec(&doc).unwrap();
        try_load(&dir, "t.glb", &mutate(&scene_assets::glb(&doc, &bin), &edits));
        try_load(&dir, "t.gltf", &mutate(&json, &edits));
        let png = std::fs::read(assets().join("tiles.png")).unwrap();
        std::fs::write(dir.join("tiles.png"), mutate(&png, &edits)).unwrap();
        try_load(&dir, "tex.toml", format!("[[textures]]\nname = \"t\"\nimage = \"tiles.png\"\n{SPHERE}").as_bytes());
    }
}

/// `[render]` sets the samples and the pixel filter; a bad width names its key.
#[test]
fn render_table_sets_samples_and_the_pixel_filter() {
    use dofray::filter::{PixelFilter, PixelFilterKind};
    let d = load_files(
        "render-table",
        &[(
            "scene.toml",
            format!("[render]\nspp = 8\naa = 2\npixel_filter = \"gaussian\"\n{SPHERE}").as_bytes(),
        )],
    )
    .unwrap();
    assert_eq!((d.settings.spp, d.settings.aa), (Some(8), Some(2)));
    assert_eq!(
        d.settings.resolve().unwrap().pixel_filter,
        PixelFilter::new(PixelFilterKind::Gaussian)
    );
    let d = load_files(
        "render-box",
        &[(
            "scene.toml",
            format!("[render]\npixel_filter = \"box\"\npixel_filter_width = 2\n{SPHERE}")
                .as_bytes(),
        )],
    )
    .unwrap();
    let f = d.settings.resolve().unwrap().pixel_filter;
    assert_eq!((f.kind, f.width), (PixelFilterKind::Box, 2.0));
    let m = error_of(
        "render-wide",
        &format!("[render]\npixel_filter_width = 100\n{SPHERE}"),
    );
    assert_names(
        &m,
        "scene.toml:2:",
        &["render.pixel_filter_width must be a number in (0, 16], got 100"],
    );
    // Checked as the render checks it, named by its key.
    let m = error_of("render-spp", &format!("[render]\nspp = 100000\n{SPHERE}"));
    assert_names(
        &m,
        "scene.toml:2:",
        &["render.spp must be 1 to 65536, got 100000"],
    );
    let m = error_of(
        "render-kind",
        &format!("[render]\npixel_filter = \"mitchell\"\n{SPHERE}"),
    );
    assert_names(&m, "scene.toml:2:", &["pixel_filter"]);
}

/// `focus_distance = inf` focuses at infinity; NaN and negative infinity are still refused.
#[test]
fn focus_distance_may_be_infinite() {
    let d = load_files(
        "focus-inf",
        &[(
            "scene.toml",
            format!("[camera]\neye = [0, 0, -5]\nlook_at = [0, 0, 0]\nfocus_distance = inf\naperture_radius = 0.1\n{SPHERE}").as_bytes(),
        )],
    )
    .unwrap();
    let camera = d.camera.build(|_| None).unwrap();
    let CameraLens::Thin(lens) = &camera.lens else {
        panic!("a thin lens")
    };
    assert_eq!(lens.inv_focus_distance, 0.0);
    assert_eq!(camera.coc_px(f32::INFINITY), 0.0);
    for bad in ["-inf", "nan", "0"] {
        let m = error_of(
            "focus-bad",
            &format!("[camera]\nfocus_distance = {bad}\n{SPHERE}"),
        );
        assert_names(&m, "scene.toml:2:", &["camera.focus_distance", "or inf"]);
    }
}
