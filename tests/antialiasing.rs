//! Every mode estimates the filtered, lens-integrated radiance: edges are anti-aliased, and
//! nothing smaller than a pixel is lost because the depth pass missed it.

use dofray::camera::{ApertureShape, CameraSpec, Focus, LensSpec};
use dofray::embree::{Device, TriangleMesh};
use dofray::filter::{PixelFilter, PixelFilterKind};
use dofray::render::Integrator;
use dofray::render::{Film, Mode, NoProgress, RenderSettings, render};
use dofray::scene::{Background, MeshMaterials, Object, SceneDesc, World};
use dofray::shade::{Light, Material, Pattern, Texture};
use glam::Vec3;

/// A 20 x 20 wall at z = 10 facing the camera, rotated by `degrees` about the view axis, with
/// UVs over its corners.
fn wall(degrees: f32) -> TriangleMesh {
    let (s, c) = degrees.to_radians().sin_cos();
    let corner = |x: f32, y: f32| [c * x - s * y, s * x + c * y, 10.0];
    TriangleMesh::new(
        vec![
            corner(-10.0, -10.0),
            corner(10.0, -10.0),
            corner(10.0, 10.0),
            corner(-10.0, 10.0),
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap()
    .with_uvs(vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    .unwrap()
}

/// A camera at the origin looking along +z at a wall in focus at z = 10, lit by ambient light
/// alone (every surface's radiance is its albedo).
fn scene(
    size: u32,
    aperture_radius: f32,
    materials: Vec<Material>,
    objects: Vec<Object>,
) -> SceneDesc {
    SceneDesc {
        name: "test".into(),
        camera: CameraSpec {
            eye: Vec3::ZERO,
            look_at: Vec3::Z,
            up: Vec3::Y,
            vfov_deg: 30.0,
            width: size,
            height: size,
            lens: LensSpec::Aperture {
                radius: aperture_radius,
            },
            focus: Focus::Distance(10.0),
            aperture: ApertureShape::default(),
            real_lens: None,
        },
        materials,
        objects,
        lights: vec![],
        ambient: Vec3::ONE,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    }
}

fn render_desc(desc: &SceneDesc, settings: &RenderSettings) -> Film {
    let world = World::build(desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    render(&world, &camera, settings, &NoProgress).unwrap().0
}

/// An in-focus checker wall tilted by 7 degrees: the pixels along its edges take intermediate
/// coverage values, and with a box pixel filter every mode matches a pinhole render at 8 x 8
/// times the resolution averaged down (64 point samples per pixel).
#[test]
fn tilted_checker_edges_are_antialiased_in_every_mode() {
    let checker = Material {
        base_color: Texture::Procedural {
            pattern: Pattern::Checker,
            a: Vec3::ZERO,
            b: Vec3::ONE,
            scale: 20.0,
        },
        ..Material::diffuse(Vec3::ZERO)
    };
    let objects = vec![Object::Mesh {
        mesh: wall(7.0),
        materials: MeshMaterials::One(0),
    }];
    let size = 48usize;
    let desc = scene(size as u32, 0.05, vec![checker.clone()], objects.clone());
    let fine = render_desc(
        &scene(8 * size as u32, 0.05, vec![checker], objects),
        &RenderSettings {
            integrator: Integrator::Direct,
            mode: Mode::Pinhole,
            aa: 1,
            pixel_filter: PixelFilter::new(PixelFilterKind::Box),
            ..Default::default()
        },
    );
    let reference: Vec<f32> = (0..size * size)
        .map(|p| {
            let (x, y) = (p % size, p / size);
            let mut sum = 0.0;
            for j in 0..8 {
                for i in 0..8 {
                    sum += fine.color[(8 * y + j) * 8 * size + 8 * x + i].x;
                }
            }
            sum / 64.0
        })
        .collect();
    let edges = reference.iter().filter(|&&v| v > 0.05 && v < 0.95).count();
    assert!(edges > 150, "{edges} edge pixels in the reference");

    for mode in [Mode::Pinhole, Mode::Dense, Mode::Adaptive] {
        let film = render_desc(
            &desc,
            &RenderSettings {
                integrator: Integrator::Direct,
                mode,
                aa: 64,
                pixel_filter: PixelFilter::new(PixelFilterKind::Box),
                ..Default::default()
            },
        );
        let got: Vec<f32> = film.color.iter().map(|c| c.x).collect();
        let between = got.iter().filter(|&&v| v > 0.05 && v < 0.95).count();
        assert!(
            between * 10 >= edges * 9,
            "{mode:?}: {between} pixels with intermediate values, the reference has {edges}"
        );
        let (mut worst, mut sum) = (0.0f32, 0.0f32);
        for (a, b) in got.iter().zip(&reference) {
            worst = worst.max((a - b).abs());
            sum += (a - b).abs();
        }
        let mean = sum / got.len() as f32;
        eprintln!("{mode:?}: mean |error| {mean:.4}, worst {worst:.3}");
        assert!(
            mean < 0.01 && worst < 0.15,
            "{mode:?}: mean {mean}, worst {worst}"
        );
    }

    // The default filter (Blackman-Harris, 3 px) is smooth: edges are soft, never stepped.
    let film = render_desc(
        &desc,
        &RenderSettings {
            integrator: Integrator::Direct,
            ..Default::default()
        },
    );
    let between = film
        .color
        .iter()
        .filter(|c| c.x > 0.05 && c.x < 0.95)
        .count();
    assert!(between >= edges, "{between} vs {edges}");
}

/// A bright sphere whose pinhole image is 0.6 px across, 8 units in front of an in-focus wall,
/// blurred into a disc of about 24 px. Whether it sits on a pixel centre (where the depth pass
/// sees it) or on a pixel corner (where every depth-pass ray misses it), it adds its own
/// energy to the image: its radiance minus the wall's, times its projected area.
#[test]
fn a_defocused_sphere_smaller_than_a_pixel_adds_its_energy_wherever_it_sits() {
    let size = 40u32;
    let (depth, radius) = (2.0f32, 0.00805f32);
    let (bright, wall_albedo) = (40.0f32, 0.5f32);
    // Pixels per unit at unit distance: the film's half-height over tan(vfov / 2).
    let k = (size as f32 / 2.0) / 15f32.to_radians().tan();
    // The sphere's projected radius in pixels (its angular radius seen from the eye).
    let r_px = k * (radius / depth).asin().tan();
    assert!(r_px * 2.0 < 0.62 && r_px * 2.0 > 0.58, "{r_px}");
    let expected = (bright - wall_albedo) as f64 * std::f64::consts::PI * (r_px as f64).powi(2);
    let wall_energy = wall_albedo as f64 * (size * size) as f64;

    // Half a pixel at the sphere's depth, in scene units.
    let half_pixel = 0.5 * depth / k;
    for (place, offset) in [("corner", 0.0), ("centre", half_pixel)] {
        let desc = scene(
            size,
            0.4,
            vec![
                Material::diffuse(Vec3::splat(wall_albedo)),
                Material::diffuse(Vec3::splat(bright)),
            ],
            vec![
                Object::Mesh {
                    mesh: wall(0.0),
                    materials: MeshMaterials::One(0),
                },
                Object::Sphere {
                    center: Vec3::new(offset, -offset, depth),
                    radius,
                    material: 1,
                },
            ],
        );
        let camera = desc.camera.build(|_| None).unwrap();
        let coc = camera.coc_px(depth);
        assert!(coc > 20.0 && coc < 28.0, "{coc}");
        for (mode, tolerance) in [(Mode::Dense, 0.05), (Mode::Adaptive, 0.10)] {
            let film = render_desc(
                &desc,
                &RenderSettings {
                    integrator: Integrator::Direct,
                    mode,
                    spp: 4096,
                    aa: 4096,
                    ..Default::default()
                },
            );
            let energy: f64 = film.color.iter().map(|c| c.x as f64).sum();
            let added = energy - wall_energy;
            eprintln!("{place}, {mode:?}: added {added:.2}, expected {expected:.2}");
            assert!(
                (added / expected - 1.0).abs() < tolerance,
                "{place}, {mode:?}: the sphere added {added:.2}, expected {expected:.2}"
            );
        }
    }
}

/// A sphere 1.3 px across, lit from behind the camera, between the pixel centres (every
/// depth-pass ray misses it) and blurred into a disc of 10 px, where the depth pass saw only a
/// background blurred eight times as much (nothing, or a dark wall): the background's lattice
/// of sites and cell centres is 16 px apart there and steps over the whole disc. Adaptive mode
/// still adds the sphere's own energy (the closed form: albedo / pi x irradiance x the projected
/// disc's integral of cos, 2/3 pi r^2; in front of the wall less the wall's light it hides),
/// alone on black and in front of the wall, with both integrators.
#[test]
fn an_unseen_defocused_sphere_keeps_its_energy_on_any_background() {
    let size = 64u32;
    // Pixels per unit at unit distance. Focus at 1, the sphere at 8 / 7: its CoC is 1/8 of
    // infinity's (80 px), whose lattice starts at 32 px.
    let k = (size as f32 / 2.0) / 15f32.to_radians().tan();
    let (depth, r_px) = (8.0f32 / 7.0, 0.65f32);
    let radius = r_px * depth / k;
    let aperture = 10.0 / (2.0 * k * 0.125);
    let (albedo, irradiance) = (0.8f32, 20.0f32);
    let (lit, wall_albedo) = ((irradiance / std::f32::consts::PI) as f64, 0.02);
    let disc = std::f64::consts::PI * (r_px as f64).powi(2);
    let dark_wall = Object::Mesh {
        mesh: wall(0.0),
        materials: MeshMaterials::One(0),
    };
    // Pixel corners 8 px from every corner and centre of the 16 px lattice the background starts
    // with: the disc and the pixel filter reach 6.5 px. Both integrators (paths at one place).
    let direct = [(24i32, 16i32), (40, 32), (32, 40)].map(|at| (Integrator::Direct, at));
    for (integrator, (cx, cy)) in direct.into_iter().chain([(Integrator::Path, (24, 16))]) {
        // The film position (cx, cy) seen at the sphere's depth.
        let at = Vec3::new(
            (cx as f32 - size as f32 / 2.0) * depth / k,
            (size as f32 / 2.0 - cy as f32) * depth / k,
            depth,
        );
        for wall in [false, true] {
            let energy = |with_sphere: bool| {
                let mut objects = Vec::new();
                if with_sphere {
                    objects.push(Object::Sphere {
                        center: at,
                        radius,
                        material: 1,
                    });
                }
                if wall {
                    objects.push(dark_wall.clone());
                }
                if objects.is_empty() {
                    return 0.0;
                }
                let mut desc = scene(
                    size,
                    aperture,
                    vec![
                        Material::diffuse(Vec3::splat(wall_albedo as f32)),
                        Material::diffuse(Vec3::splat(albedo)),
                    ],
                    objects,
                );
                desc.camera.focus = Focus::Distance(1.0);
                desc.ambient = Vec3::ZERO;
                desc.lights = vec![Light::Directional {
                    direction: Vec3::Z,
                    irradiance: Vec3::splat(irradiance),
                    angle: 0.0,
                }];
                let camera = desc.camera.build(|_| None).unwrap();
                assert!((camera.coc_px(depth) - 10.0).abs() < 0.01);
                let film = render_desc(
                    &desc,
                    &RenderSettings {
                        integrator,
                        mode: Mode::Adaptive,
                        spp: 4096,
                        ..Default::default()
                    },
                );
                film.color.iter().map(|c| c.x as f64).sum::<f64>()
            };
            let added = energy(true) - energy(false);
            let hidden = if wall { wall_albedo * lit * disc } else { 0.0 };
            let expected = albedo as f64 * lit * 2.0 / 3.0 * disc - hidden;
            let case = format!("{integrator:?} at ({cx}, {cy}), wall {wall}");
            eprintln!("{case}: added {added:.2}, expected {expected:.2}");
            assert!(
                (added / expected - 1.0).abs() < 0.1,
                "{case}: the sphere added {added:.2}, expected {expected:.2}"
            );
        }
    }
}
