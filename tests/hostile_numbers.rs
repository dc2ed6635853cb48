//! Extreme numbers never abort the process or produce a silent NaN image: every value that
//! reaches the renderer is checked against a documented range, Embree never sees a ray it
//! cannot take, and focus at infinity is a real setting.

use std::process::Command;

use dofray::camera::{ApertureShape, CameraSpec, Focus, LensSpec};
use dofray::embree::{Device, Ray, RayPacket16, ShadowPacket16, TriangleMesh};
use dofray::render::{Mode, NoProgress, RenderSettings, render};
use dofray::scene::{Background, MeshMaterials, Object, SceneDesc, World, builtin};
use dofray::shade::{Material, Pattern, Texture};
use glam::Vec3;

use crate::scratch::Scratch;

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("hostile-{name}"))
}

/// The flags that used to abort inside Embree (SIGABRT, exit 134): each is now a
/// one-line error naming the aperture, exit 1, and no image.
#[test]
fn huge_derived_apertures_are_refused_by_name() {
    let dir = scratch("aperture");
    let png = dir.join("out.png");
    for flags in [
        &["--aperture-radius", "1e20"][..],
        &["--f-number", "1e-20"],
        &["--sharp-range", "1e-20", "--spread", "100"],
        &["--aperture-radius", "0.1", "--anamorphic", "1e20"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args(["render", "--width", "32", "-o"])
            .arg(&png)
            .args(flags)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        // Lens flags out of range: a usage error.
        assert_eq!(out.status.code(), Some(2), "{flags:?}: {err}");
        assert!(
            err.contains("aperture radius") || err.contains("anamorphic"),
            "{flags:?}: {err}"
        );
        assert!(!png.exists(), "{flags:?}");
    }
}

fn ground_scene() -> SceneDesc {
    let mut desc = builtin::paper();
    desc.camera.width = 48;
    desc.camera.height = 36;
    desc
}

fn render_film(desc: &SceneDesc) -> Vec<Vec3> {
    let world = World::build(desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    let settings = RenderSettings {
        mode: Mode::Adaptive,
        ..Default::default()
    };
    render(&world, &camera, &settings, &NoProgress)
        .unwrap()
        .0
        .color
}

/// `--focus-distance 1e30` used to overflow the lens rays (only sky rendered). A huge focus
/// distance now renders exactly as focus at infinity, which shows the ground.
#[test]
fn focus_at_infinity_and_huge_focus_distances_render_the_scene() {
    let mut desc = ground_scene();
    desc.camera.focus = Focus::Distance(f32::INFINITY);
    let at_infinity = render_film(&desc);
    desc.camera.focus = Focus::Distance(1e30);
    let huge = render_film(&desc);
    assert_eq!(at_infinity, huge);
    assert!(huge.iter().all(|c| c.is_finite()));
    // The bottom row sees the checkered ground, not the sky (which below the horizon is the
    // horizon's (0.375, 0.41, 0.475): blue over red 1.27). Lit and blurred, the ground is
    // brighter and less blue: a converged dense render (2048 spp) gives the row a mean of
    // (0.653, 0.683, 0.755), blue over red 1.16. (The check this replaces asked one pixel of
    // the row for blue under red + 0.05, which not even that render has: noise decided it.)
    let bottom = &huge[35 * 48..];
    let mean = bottom.iter().copied().sum::<Vec3>() / bottom.len() as f32;
    let blue_over_red = bottom.iter().map(|c| c.z / c.x).sum::<f32>() / bottom.len() as f32;
    assert!(
        blue_over_red < 1.22 && mean.x > 1.3 * 0.375,
        "mean {mean}, blue over red {blue_over_red}: {:?}",
        &bottom[..4]
    );
    // The CoC at infinity is 0 when focused there.
    desc.camera.focus = Focus::Distance(f32::INFINITY);
    let camera = desc.camera.build(|_| None).unwrap();
    assert_eq!(camera.coc_px(f32::INFINITY), 0.0);
    assert!(camera.coc_px(10.0) > 0.0);
}

fn wall_scene(z: f32, material: Material) -> SceneDesc {
    let quad = TriangleMesh::new(
        vec![
            [-1.0, -1.0, z],
            [1.0, -1.0, z],
            [1.0, 1.0, z],
            [-1.0, 1.0, z],
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap();
    SceneDesc {
        name: "wall".into(),
        camera: CameraSpec {
            eye: Vec3::ZERO,
            look_at: Vec3::Z,
            up: Vec3::Y,
            vfov_deg: 30.0,
            width: 16,
            height: 16,
            lens: LensSpec::Aperture { radius: 0.01 },
            focus: Focus::Distance(5.0),
            aperture: ApertureShape::default(),
            real_lens: None,
        },
        materials: vec![material],
        objects: vec![Object::Mesh {
            mesh: quad,
            materials: MeshMaterials::One(0),
        }],
        lights: vec![],
        ambient: Vec3::ONE,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    }
}

/// A triangle at z = 1e16 used to give a 100% NaN image; a pattern scale or specular of 3e38
/// gave NaN or infinite pixels. Each is now refused by name before rendering.
#[test]
fn out_of_range_geometry_and_materials_are_refused_by_name() {
    let device = Device::new().unwrap();
    let refused = |desc: SceneDesc, names: &[&str]| {
        let err = World::build(&desc, &device)
            .err()
            .expect("refused")
            .to_string();
        for n in names {
            assert!(err.contains(n), "{err} lacks {n}");
        }
    };
    refused(
        wall_scene(1e16, Material::diffuse(Vec3::ONE)),
        &["object 0", "1e15"],
    );
    refused(
        wall_scene(
            5.0,
            Material {
                base_color: Texture::Procedural {
                    pattern: Pattern::Checker,
                    a: Vec3::ZERO,
                    b: Vec3::ONE,
                    scale: 3e38,
                },
                ..Material::diffuse(Vec3::ONE)
            },
        ),
        &["material 0", "scale"],
    );
    refused(
        wall_scene(
            5.0,
            Material {
                roughness: 3e38,
                ..Material::diffuse(Vec3::ONE)
            },
        ),
        &["material 0", "roughness"],
    );
    // The eye too far out (Embree takes origins up to about 1.8e19; the docs allow 1e15).
    let mut desc = wall_scene(5.0, Material::diffuse(Vec3::ONE));
    desc.camera.eye = Vec3::new(0.0, 0.0, -2e18);
    let err = desc.camera.build(|_| None).unwrap_err().to_string();
    assert!(err.contains("eye") && err.contains("1e15"), "{err}");
}

/// A mirror 1e13 away (within range): the reflection rays start there and the image is finite.
#[test]
fn a_far_mirror_renders_a_finite_image() {
    let mut desc = wall_scene(
        1e13,
        Material {
            metallic: 1.0,
            roughness: 0.0,
            ..Material::diffuse(Vec3::splat(0.5))
        },
    );
    // Scale the quad so it fills the view at that distance.
    if let Object::Mesh { mesh, .. } = &mut desc.objects[0] {
        let p = mesh
            .positions()
            .iter()
            .map(|p| [p[0] * 1e13, p[1] * 1e13, p[2]])
            .collect();
        *mesh = TriangleMesh::new(p, mesh.indices().to_vec()).unwrap();
    }
    desc.camera.focus = Focus::Distance(1e13);
    let film = render_film(&desc);
    assert!(film.iter().all(|c| c.is_finite()));
}

/// The last guard, in the Embree layer itself: a ray Embree cannot take (NaN, infinite, or
/// beyond its 1.8e19 range) never reaches it, whatever a caller builds.
#[test]
fn rays_embree_cannot_take_never_reach_it() {
    let bad = [
        Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Z),
        Ray::new(Vec3::new(0.0, 0.0, 1e19), Vec3::Z),
        Ray::new(Vec3::ZERO, Vec3::new(0.0, f32::INFINITY, 1.0)),
        Ray::segment(Vec3::ZERO, Vec3::Z, f32::NAN, 1.0),
    ];
    let good = Ray::new(Vec3::ZERO, Vec3::Z);
    let scene = World::build(
        &wall_scene(5.0, Material::diffuse(Vec3::ONE)),
        &Device::new().unwrap(),
    )
    .unwrap()
    .scene;
    let mut packet = RayPacket16::new();
    let mut shadow = ShadowPacket16::new();
    for (lane, ray) in bad.iter().enumerate() {
        assert!(!ray.is_traceable());
        assert!(!packet.set(lane, ray) && !packet.is_active(lane));
        assert!(!shadow.set(lane, ray) && !shadow.is_active(lane));
        assert_eq!(scene.intersect1(ray), None);
        assert!(!scene.occluded1(ray));
    }
    assert!(packet.set(5, &good) && shadow.set(5, &good));
    scene.intersect16(&mut packet, dofray::embree::RayHint::Coherent);
    scene.occluded16(&mut shadow, dofray::embree::RayHint::Coherent);
    assert!(packet.hit(5).is_some() && shadow.occluded(5));
    // Bulk fills drop such lanes too.
    let mut origin = [[0.0f32; 16]; 3];
    let mut dir = [[0.0f32; 16]; 3];
    dir[2] = [1.0; 16];
    origin[0][3] = f32::NAN;
    origin[1][7] = 1e30;
    packet.set_lanes(16, &origin, &dir);
    assert_eq!(packet.active_count(), 14);
    scene.intersect16(&mut packet, dofray::embree::RayHint::Incoherent);
    assert!(packet.hit(0).is_some() && packet.hit(3).is_none() && packet.hit(7).is_none());
}

/// An autofocus pixel that sees no surface is reported as the scene file gives it, with the
/// pixel it became at the size the command line asked for.
#[test]
fn a_missed_autofocus_pixel_is_named_as_the_file_gives_it() {
    let dir = scratch("autofocus");
    let scene = dir.join("sky.toml");
    std::fs::write(
        &scene,
        "[image]\nwidth = 100\nheight = 100\n[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, 1]\n\
         focus_pixel = [50, 2]\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 5]\nradius = 1\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args(["render", "--width", "40", "-o"])
        .arg(dir.join("out.png"))
        .arg(&scene)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    // The scene file's autofocus pixel: a bad input.
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("(50, 2) of its 100x100 image") && err.contains("(20, 1) at 40x40"),
        "{err}"
    );
}

/// Values every key accepts alone but the renderer cannot use are refused where they were
/// written: the file, the line and the key (or the table), as a bad input (exit 3).
#[test]
fn values_refused_after_parsing_point_at_the_file_line_and_key() {
    let dir = scratch("located");
    let sphere = "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n";
    for (table, expect) in [
        (
            "[camera]\neye = [0, 0, 5]\nfocal_length_mm = 3e38\nf_number = 2\n",
            "scene.toml:3:19: `camera.focal_length_mm`: focal_length_mm must be",
        ),
        (
            "[camera]\neye = [0, 0, 5]\naperture_radius = 3e38\n",
            "scene.toml:3:19: `camera.aperture_radius`",
        ),
        (
            "[camera]\neye = [0, 0, 5]\nf_number = 1e-30\n",
            "scene.toml:3:12: `camera.f_number`",
        ),
        (
            "[camera]\neye = [0, 0, 5]\naperture_radius = 0.1\nanamorphic = 1e30\n",
            "scene.toml:4:14: `camera.anamorphic`",
        ),
        (
            "[[lights]]\ntype = \"point\"\nposition = [3e38, 0, 0]\n",
            "scene.toml:1:1: `lights[0]`: light 0's position",
        ),
        (
            "[[materials]]\nname = \"m\"\ndiffuse = [1e38, 0.5, 0.5]\n",
            "scene.toml:2:8: `materials[0]`: material 0's colour",
        ),
        (
            "[[textures]]\nname = \"t\"\npattern = \"checker\"\nscale = 1e38\n\
             [[materials]]\nname = \"m\"\ntexture = \"t\"\n",
            "scene.toml:6:8: `materials[0]`: material 0's pattern scale",
        ),
    ] {
        let scene = dir.join("scene.toml");
        std::fs::write(&scene, format!("{table}\n{sphere}")).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args(["render", "--width", "16", "-o"])
            .arg(dir.join("out.png"))
            .arg(&scene)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{table}: {err}");
        assert!(err.contains(expect), "{table}: {err}");
    }
    dir.close().unwrap();
}
