//! Shadow and mirror rays leave surfaces at an offset that fits the geometry: no acne on a
//! radius-1000 ground sphere (Embree's sphere test is only as precise as the sphere is large),
//! and no light leaking under small or nearby occluders (the offset must not be needlessly
//! large either).

use dofray::camera::{ApertureShape, Camera, CameraSpec, Focus, LensSpec};
use dofray::embree::{Device, TriangleMesh};
use dofray::render::Integrator;
use dofray::render::{Film, Mode, NoProgress, RenderSettings, render};
use dofray::scene::{Background, MeshMaterials, Object, SceneDesc, World};
use dofray::shade::{Light, Material};
use glam::Vec3;

fn setup(desc: &SceneDesc) -> (World, Camera) {
    let device = Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    (world, camera)
}

fn camera(eye: Vec3, look_at: Vec3, vfov_deg: f32, width: u32, height: u32) -> CameraSpec {
    CameraSpec {
        eye,
        look_at,
        up: Vec3::Y,
        vfov_deg,
        width,
        height,
        lens: LensSpec::Pinhole,
        focus: Focus::Point(look_at),
        aperture: ApertureShape::default(),
        real_lens: None,
    }
}

fn scene(camera: CameraSpec, objects: Vec<Object>, light: Vec3, intensity: f32) -> SceneDesc {
    SceneDesc {
        name: "shadows".into(),
        camera,
        materials: vec![Material::diffuse(Vec3::splat(0.5))],
        objects,
        // Times pi: the direct integrator's Lambert term has its 1 / pi.
        lights: vec![Light::Point {
            position: light,
            intensity: Vec3::splat(intensity * std::f32::consts::PI),
        }],
        ambient: Vec3::splat(0.1),
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    }
}

fn sphere(center: Vec3, radius: f32) -> Object {
    Object::Sphere {
        center,
        radius,
        material: 0,
    }
}

/// A square facing +y (both faces occlude: Embree's triangles are two-sided), `size` wide,
/// centred on `center`.
fn card(center: Vec3, size: f32) -> Object {
    let h = size / 2.0;
    let corner = |dx: f32, dz: f32| (center + Vec3::new(dx, 0.0, dz)).to_array();
    let mesh = TriangleMesh::new(
        vec![corner(-h, -h), corner(h, -h), corner(h, h), corner(-h, h)],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap();
    Object::Mesh {
        mesh,
        materials: MeshMaterials::One(0),
    }
}

fn render_film(desc: &SceneDesc, mode: Mode) -> Film {
    let (world, camera) = setup(desc);
    let settings = RenderSettings {
        integrator: Integrator::Direct,
        mode,
        seed: 5,
        ..Default::default()
    };
    render(&world, &camera, &settings, &NoProgress).unwrap().0
}

/// The ground pixel's radiance from ambient light alone: albedo 0.5 times ambient 0.1.
const AMBIENT: f32 = 0.05;

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// The acceptance test of the shadow-acne issue: a radius-1000 ground sphere under a point
/// light, filling the view around the origin, where an offset scaled by the hit point's
/// magnitude alone (1e-4 there) is below Embree's error for a ray leaving that sphere (up to
/// 3e-4): isolated shadow rays found the ground itself and their samples went dark. The ground
/// is lit smoothly, so no pixel may be darker than the median of its eight neighbours by more
/// than a little (one lost sample of the four or sixteen in a pixel costs 6 to 25 %).
#[test]
fn radius_1000_ground_sphere_has_no_shadow_acne_in_any_mode() {
    let (w, h) = (64u32, 48u32);
    let mut cam = camera(Vec3::new(0.0, 2.5, -1.5), Vec3::ZERO, 50.0, w, h);
    cam.lens = LensSpec::Aperture { radius: 0.15 };
    let desc = scene(
        cam,
        vec![sphere(Vec3::new(0.0, -1000.0, 0.0), 1000.0)],
        Vec3::new(1.0, 6.0, -2.0),
        60.0,
    );
    let mut failures = Vec::new();
    for mode in [Mode::Pinhole, Mode::Dense, Mode::Adaptive] {
        let film = render_film(&desc, mode);
        let lum: Vec<f32> = film.color.iter().map(|&c| luminance(c)).collect();
        let (w, h) = (w as usize, h as usize);
        let mut dark = Vec::new();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let here = lum[y * w + x];
                assert!(
                    here > 4.0 * AMBIENT,
                    "{mode:?} ({x}, {y}) is not lit ground"
                );
                let mut around: Vec<f32> = (0..9)
                    .filter(|&i| i != 4)
                    .map(|i| lum[(y + i / 3 - 1) * w + x + i % 3 - 1])
                    .collect();
                around.sort_by(f32::total_cmp);
                let median = 0.5 * (around[3] + around[4]);
                if here < median * (1.0 - 0.02) {
                    dark.push(format!("({x}, {y}) {:.1} %", 100.0 * (1.0 - here / median)));
                }
            }
        }
        if !dark.is_empty() {
            failures.push(format!(
                "{mode:?}: {} dark pixels: {}",
                dark.len(),
                dark.join(", ")
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The luminance of a 1x1 pinhole image: a narrow view of the camera's `look_at` (its samples
/// spread over a small patch around it, which must be uniformly lit or shadowed).
fn look(desc: &SceneDesc) -> f32 {
    luminance(render_film(desc, Mode::Pinhole).color[0])
}

/// A card hovering just above the ground shadows the ground under it, at any scale: the offset
/// must stay below the gap. At scale 1 the ground is a radius-1000 sphere, whose offset is
/// largest (2^-19 x 1000 = 1.9e-3 under a card 8e-3 above it). At scale 0.01 everything is 100
/// times smaller (a radius-10 ground sphere, a card 8e-5 above it), where the old offset's
/// absolute floor of 1e-4 put the shadow rays' origins above the card and let light through.
/// The camera looks under the card at a shallow angle; the light is straight above.
#[test]
fn a_card_just_above_the_ground_shadows_it_at_any_scale() {
    for scale in [1.0f32, 0.01] {
        let gap = 8e-3 * scale;
        let size = 0.2 * scale;
        // 1.1 degrees above the ground: under the card's edge 0.1 away with room to spare.
        let eye = Vec3::new(1.0, 0.02, 0.3) * scale;
        let objects = vec![
            sphere(Vec3::new(0.0, -1000.0 * scale, 0.0), 1000.0 * scale),
            card(Vec3::new(0.0, gap, 0.0), size),
        ];
        let light = Vec3::new(0.0, 3.0, 0.0) * scale;
        let lit_desc = scene(
            camera(eye, Vec3::ZERO, 0.02, 1, 1),
            vec![objects[0].clone()],
            light,
            30.0 * scale * scale,
        );
        let desc = SceneDesc {
            objects,
            ..lit_desc.clone()
        };
        let (lit, shadowed) = (look(&lit_desc), look(&desc));
        assert!(
            lit > 10.0 * AMBIENT,
            "scale {scale}: without the card {lit}"
        );
        assert!(
            (shadowed - AMBIENT).abs() < 1e-5,
            "scale {scale}: under the card {shadowed}, ambient alone is {AMBIENT}"
        );
    }
}

/// A ball of radius 0.05 resting on the radius-1000 ground keeps its contact shadow right
/// next to the point where it touches (a too-large offset would start the shadow rays above
/// the ball), and a tiny sphere (radius 0.01, at the origin, alone) is lit on the side facing
/// the light and unlit on its far side.
#[test]
fn small_spheres_keep_contact_shadows_and_dark_far_sides() {
    // The ground point 0.012 beside the contact point, seen from the side away from the light
    // at 15 degrees (under the ball's overhang); the light is up and to the other side, so
    // the ball is between them.
    let target = Vec3::new(0.012, 0.0, 0.0);
    let eye = target + 0.5 * Vec3::new(15f32.to_radians().cos(), 15f32.to_radians().sin(), 0.0);
    let ground = sphere(Vec3::new(0.0, -1000.0, 0.0), 1000.0);
    let ball = sphere(Vec3::new(0.0, 0.05, 0.0), 0.05);
    let light = Vec3::new(-3.0, 5.0, 0.0);
    let bare = scene(
        camera(eye, target, 0.05, 1, 1),
        vec![ground.clone()],
        light,
        30.0,
    );
    let with_ball = SceneDesc {
        objects: vec![ground, ball],
        ..bare.clone()
    };
    let (lit, shadowed) = (look(&bare), look(&with_ball));
    assert!(lit > 4.0 * AMBIENT, "without the ball {lit}");
    assert!(
        (shadowed - AMBIENT).abs() < 1e-5,
        "beside the contact point {shadowed}, ambient alone is {AMBIENT}"
    );

    // A tiny sphere lit from straight above, filling the view from the side. On the lit half
    // the cosine, so the radiance, grows smoothly towards the top (a sample whose shadow ray
    // found the sphere itself would break that); the far half gets ambient light alone.
    let n = 16usize;
    let tiny = scene(
        camera(
            Vec3::new(0.0, 0.0, -0.1),
            Vec3::ZERO,
            6.0,
            n as u32,
            n as u32,
        ),
        vec![sphere(Vec3::ZERO, 0.01)],
        Vec3::new(0.0, 1.0, 0.0),
        1.0,
    );
    let film = render_film(&tiny, Mode::Pinhole);
    let lum = |x: usize, y: usize| luminance(film.color[y * n + x]);
    for x in 0..n {
        for y in 0..n / 2 - 2 {
            assert!(
                lum(x, y) > lum(x, y + 1) && lum(x, y + 1) > AMBIENT,
                "lit half, column {x}: row {y} {} vs row {} {}",
                lum(x, y),
                y + 1,
                lum(x, y + 1)
            );
        }
        for y in n / 2 + 2..n {
            assert!(
                (lum(x, y) - AMBIENT).abs() < 1e-5,
                "far half ({x}, {y}): {}",
                lum(x, y)
            );
        }
    }
}

/// A coarse sphere mesh (10 x 5 facets) with smooth vertex normals, lit from the side: where
/// the interpolated normal faces the light, the surface is lit, even near the terminator where
/// the flat facets (and their neighbours) face away from it. Rays leaving such a point start on
/// the smooth surface the normals describe, not on the facet; an offset alone (the old one,
/// 2e-4 here, or the new one, 8e-6) lets the facets shadow themselves in steps along the
/// terminator (the "shadow terminator" problem: about 20 pixels here).
#[test]
fn low_poly_smooth_sphere_has_no_faceted_terminator() {
    let (lon, lat) = (10usize, 5usize);
    let mut positions = vec![[0.0, 1.0, 0.0]];
    for i in 1..lat {
        let theta = std::f32::consts::PI * i as f32 / lat as f32;
        for j in 0..lon {
            let phi = std::f32::consts::TAU * (j as f32 + 0.5 * (i % 2) as f32) / lon as f32;
            positions.push([
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ]);
        }
    }
    positions.push([0.0, -1.0, 0.0]);
    let ring = |i: usize, j: usize| (1 + (i - 1) * lon + j % lon) as u32;
    let south = positions.len() as u32 - 1;
    let mut indices = Vec::new();
    for j in 0..lon {
        indices.push([0, ring(1, j + 1), ring(1, j)]);
        indices.push([south, ring(lat - 1, j), ring(lat - 1, j + 1)]);
        for i in 1..lat - 1 {
            indices.push([ring(i, j), ring(i, j + 1), ring(i + 1, j)]);
            indices.push([ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)]);
        }
    }
    let normals = positions.clone();
    let mesh = TriangleMesh::new(positions, indices)
        .unwrap()
        .with_normals(normals)
        .unwrap();
    let n = 48usize;
    let view = |objects| {
        let mut desc = scene(
            camera(
                Vec3::new(0.0, 0.3, -20.0),
                Vec3::ZERO,
                7.0,
                n as u32,
                n as u32,
            ),
            objects,
            Vec3::ZERO,
            0.0,
        );
        // Light from the right, a little from the front, so the terminator crosses facets.
        desc.lights = vec![Light::Directional {
            direction: Vec3::new(-1.0, 0.2, 0.3).normalize(),
            irradiance: Vec3::ONE,
            angle: 0.0,
        }];
        render_film(&desc, Mode::Pinhole)
    };
    let smooth = view(vec![sphere(Vec3::ZERO, 1.0)]);
    let faceted = view(vec![Object::Mesh {
        mesh,
        materials: MeshMaterials::One(0),
    }]);
    // Wherever the true sphere gets a fair share of direct light (cosine above 0.15: away from
    // the terminator by more than the facets' deviation from the sphere), so must the mesh,
    // away from the silhouettes (which differ): every sample of the pixel and its neighbours
    // on the mesh gets at least the ambient light; the background is black.
    let lum = |film: &Film, x: usize, y: usize| luminance(film.color[y * n + x]);
    let mut dark = Vec::new();
    for y in 1..n - 1 {
        for x in 1..n - 1 {
            let inside =
                (0..9).all(|i| lum(&faceted, x + i % 3 - 1, y + i / 3 - 1) > 0.999 * AMBIENT);
            let (s, f) = (lum(&smooth, x, y), lum(&faceted, x, y));
            if inside && s > AMBIENT + 0.5 * 0.15 && f < AMBIENT + 0.5 * 0.05 {
                dark.push(format!("({x}, {y}) {f} (sphere {s})"));
            }
        }
    }
    assert!(
        dark.is_empty(),
        "{} pixels self-shadowed: {}",
        dark.len(),
        dark.join(", ")
    );
}
