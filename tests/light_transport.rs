//! The path tracer against closed forms: furnaces, a Lambertian plane under a sun, a point
//! light and a sphere light. Small images, many samples per pixel, means over many pixels.

use std::f32::consts::PI;

use dofray::camera::{CameraSpec, Focus, LensSpec};
use dofray::embree::{Device, TriangleMesh};
use dofray::render::{
    Film, Integrator, Mode, NoProgress, PathLimits, RenderSettings, Strategy, render,
};
use dofray::scene::{Background, MeshMaterials, Object, SceneDesc, World};
use dofray::shade::{Light, Material};
use glam::Vec3;

use crate::scratch::Scratch;

/// A pinhole camera at `eye` looking at `look_at`, 16 x 16 pixels over `vfov` degrees.
fn camera(eye: Vec3, look_at: Vec3, vfov: f32) -> CameraSpec {
    CameraSpec {
        eye,
        look_at,
        up: if (look_at - eye).normalize().y.abs() > 0.99 {
            Vec3::Z
        } else {
            Vec3::Y
        },
        vfov_deg: vfov,
        width: 16,
        height: 16,
        lens: LensSpec::Pinhole,
        focus: Focus::Distance(1.0),
        ..Default::default()
    }
}

/// Renders `desc` with `settings`.
fn render_with(desc: &SceneDesc, settings: &RenderSettings) -> Film {
    let device = Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    render(&world, &camera, settings, &NoProgress).unwrap().0
}

/// Renders `desc` with the path tracer, `spp` samples per pixel, paths up to `bounces` long.
fn render_path(desc: &SceneDesc, spp: u32, bounces: u32) -> Film {
    let settings = RenderSettings {
        mode: Mode::Pinhole,
        aa: spp,
        integrator: Integrator::Path,
        path: PathLimits {
            total: bounces,
            diffuse: bounces,
            glossy: bounces,
            transmission: bounces,
            ..Default::default()
        },
        ..Default::default()
    };
    render_with(desc, &settings)
}

fn mean(film: &Film) -> Vec3 {
    film.color.iter().copied().sum::<Vec3>() / film.color.len() as f32
}

/// A square of side `2 h` in the plane y = 0, facing +y.
fn ground(h: f32) -> TriangleMesh {
    TriangleMesh::new(
        vec![[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap()
}

fn assert_close(got: f32, want: f32, rel: f32, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{what}: got {got}, want {want} (within {:.2}%)",
        rel * 100.0
    );
}

/// White furnace: a white Lambertian sphere in a uniform world of radiance 1 cannot be told
/// from it; a perfect mirror neither.
#[test]
fn a_white_sphere_vanishes_in_a_uniform_world() {
    for material in [
        Material::diffuse(Vec3::ONE),
        Material {
            metallic: 1.0,
            roughness: 0.0,
            ..Material::diffuse(Vec3::ONE)
        },
    ] {
        let desc = SceneDesc {
            camera: camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 25.0),
            materials: vec![material],
            objects: vec![Object::Sphere {
                center: Vec3::ZERO,
                radius: 1.0,
                material: 0,
            }],
            lights: vec![],
            ambient: Vec3::ZERO,
            background: Background::uniform(Vec3::ONE),
            ..Default::default()
        };
        let film = render_path(&desc, 64, 8);
        let m = mean(&film);
        for c in m.to_array() {
            assert_close(c, 1.0, 0.01, "furnace mean");
        }
        // Every pixel, not just the mean, is close: nothing is lost or gained anywhere.
        for px in &film.color {
            assert!((px.x - 1.0).abs() < 0.1, "{px}");
        }
    }
}

/// Inside a closed sphere of albedo 0.8 that emits 0.2, every point sees 0.2 of emission plus
/// 0.8 of what arrives: radiance 0.2 / (1 - 0.8) = 1 once paths are long enough (0.8^200 is
/// nothing). Exercises emission, bounces, Russian roulette and MIS of an emitter sampled
/// from inside.
#[test]
fn a_closed_furnace_converges_to_emission_over_one_minus_albedo() {
    let desc = SceneDesc {
        camera: camera(Vec3::new(0.3, -0.2, 0.1), Vec3::new(1.0, 0.5, -2.0), 60.0),
        materials: vec![Material {
            emission: Vec3::splat(0.2),
            ..Material::diffuse(Vec3::splat(0.8))
        }],
        objects: vec![Object::Sphere {
            center: Vec3::ZERO,
            radius: 3.0,
            material: 0,
        }],
        lights: vec![],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    let m = mean(&render_path(&desc, 256, 200));
    for c in m.to_array() {
        assert_close(c, 1.0, 0.01, "closed furnace");
    }
}

/// A Lambertian plane of albedo `rho` under a sun of irradiance E at angle theta:
/// L = rho E cos(theta) / pi, exactly (one light sample per pixel, no noise).
#[test]
fn a_lambertian_plane_under_a_sun_has_the_closed_form_radiance() {
    let rho = 0.6;
    let theta = 30.0f32.to_radians();
    let e = 3.0;
    let desc = SceneDesc {
        camera: camera(Vec3::new(0.0, 2.0, 0.0), Vec3::ZERO, 20.0),
        materials: vec![Material::diffuse(Vec3::splat(rho))],
        objects: vec![Object::Mesh {
            mesh: ground(50.0),
            materials: MeshMaterials::One(0),
        }],
        lights: vec![Light::Directional {
            direction: Vec3::new(theta.sin(), -theta.cos(), 0.0),
            irradiance: Vec3::splat(e),
            angle: 0.0,
        }],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    let m = mean(&render_path(&desc, 16, 4));
    assert_close(m.x, rho * e * theta.cos() / PI, 0.005, "sun on a plane");
}

/// A point light of intensity I at height h over a Lambertian plane: at the foot of the light,
/// L = rho I / (pi h^2) (the camera looks at a patch small enough for the falloff to be
/// negligible: 0.3 degrees wide).
#[test]
fn a_lambertian_plane_under_a_point_light_has_the_closed_form_radiance() {
    let (rho, intensity, h) = (0.5, 40.0, 2.0);
    let desc = SceneDesc {
        camera: camera(Vec3::new(0.0, 1.0, 0.0), Vec3::ZERO, 0.3),
        materials: vec![Material::diffuse(Vec3::splat(rho))],
        objects: vec![Object::Mesh {
            mesh: ground(50.0),
            materials: MeshMaterials::One(0),
        }],
        lights: vec![Light::Point {
            position: Vec3::new(0.0, h, 0.0),
            intensity: Vec3::splat(intensity),
        }],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    let m = mean(&render_path(&desc, 16, 4));
    assert_close(
        m.x,
        rho * intensity / (PI * h * h),
        0.005,
        "point light on a plane",
    );
}

/// A sphere light (an emissive sphere of radius r and radiance Le, centre at height h) gives
/// the plane below it irradiance pi Le (r / h)^2 at its foot, so L = rho Le (r / h)^2. Both
/// the light sample (a cone towards the sphere) and the BSDF sample (which can hit it) carry
/// it, weighted by MIS. The second sphere is a 4 mm lamp 4 m up: its cone's 1 - cos (5e-7) is
/// within a few ulps of 1 in f32, which the light sample must not round (it was 6% off).
#[test]
fn a_sphere_light_lights_a_plane_as_the_closed_form_says() {
    for (rho, le, r, h) in [(0.7, 5.0, 0.5, 2.0), (0.7, 1e6, 0.004, 4.0)] {
        let desc = SceneDesc {
            // Looking down past the sphere's side at the foot point, from below the sphere.
            camera: camera(Vec3::new(0.0, 0.6, 0.0), Vec3::ZERO, 0.3),
            materials: vec![
                Material::diffuse(Vec3::splat(rho)),
                Material {
                    emission: Vec3::splat(le),
                    ..Material::diffuse(Vec3::ZERO)
                },
            ],
            objects: vec![
                Object::Mesh {
                    mesh: ground(50.0),
                    materials: MeshMaterials::One(0),
                },
                Object::Sphere {
                    center: Vec3::new(0.0, h, 0.0),
                    radius: r,
                    material: 1,
                },
            ],
            lights: vec![],
            ambient: Vec3::ZERO,
            background: Background::uniform(Vec3::ZERO),
            ..Default::default()
        };
        let m = mean(&render_path(&desc, 1024, 1));
        assert_close(
            m.x,
            rho * le * (r / h) * (r / h),
            0.01,
            "sphere light on a plane",
        );
    }
}

/// A street of 40 small sphere lamps, 3 m up in two rows 8 m apart, one every 3 m along
/// each: a point of the ground beneath one of them takes most of its light from the few
/// nearest, which the light sample must pick most (by power alone it picked each one draw in
/// 40, and the ground at 16 samples was noise: a relative spread of 0.52 between pixels, now
/// 0.047). The
/// radiance is the closed form's, rho L sum (r / d)^2 cos, and the pixels agree.
#[test]
fn a_street_of_lamps_lights_the_ground_from_the_lamps_near_each_point() {
    let (rho, le, r) = (0.7, 200.0, 0.05);
    let lamps: Vec<Vec3> = (0..40)
        .map(|k| {
            Vec3::new(
                if k % 2 == 0 { -4.0 } else { 4.0 },
                3.0,
                3.0 * (k / 2) as f32,
            )
        })
        .collect();
    let at = Vec3::new(-4.0, 0.0, 30.0);
    let mut objects = vec![Object::Mesh {
        mesh: ground(200.0),
        materials: MeshMaterials::One(0),
    }];
    objects.extend(lamps.iter().map(|&center| Object::Sphere {
        center,
        radius: r,
        material: 1,
    }));
    let desc = SceneDesc {
        camera: camera(at + Vec3::new(0.3, 1.0, 0.0), at, 0.3),
        materials: vec![
            Material::diffuse(Vec3::splat(rho)),
            Material {
                emission: Vec3::splat(le),
                ..Material::diffuse(Vec3::ZERO)
            },
        ],
        objects,
        lights: vec![],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    let want: f32 = (lamps.iter())
        .map(|&c| {
            let v = c - at;
            rho * le * r * r / v.length_squared() * (v.y / v.length())
        })
        .sum();
    let film = render_path(&desc, 16, 1);
    assert_close(mean(&film).x, want, 0.02, "the street's ground");
    let n = film.color.len() as f32;
    let spread = (film.color.iter())
        .map(|c| (c.x - want) * (c.x - want))
        .sum::<f32>()
        / n;
    let relative = spread.sqrt() / want;
    assert!(relative < 0.1, "relative spread between pixels {relative}");
}

/// Writes a `w` x `h` Radiance .hdr file of radiance `texel(x, y)` (row 0 at the top) into a
/// fresh folder and returns the folder (removed when it is dropped).
fn hdr_map(test: &str, w: u32, h: u32, texel: impl Fn(u32, u32) -> [f32; 3]) -> Scratch {
    let dir = Scratch::new(&format!("env-{test}"));
    let img = image::Rgb32FImage::from_fn(w, h, |x, y| image::Rgb(texel(x, y)));
    image::DynamicImage::ImageRgb32F(img)
        .save_with_format(dir.join("sky.hdr"), image::ImageFormat::Hdr)
        .unwrap();
    dir
}

/// A scene file around a world map, with one object: `objects` (TOML).
fn world_scene(dir: &std::path::Path, objects: &str, camera: &str) -> SceneDesc {
    let toml = format!(
        "lights = []\n[image]\nwidth = 16\nheight = 16\n{camera}\n[world]\nmap = \"sky.hdr\"\n\
         strength = 1\nrotation = 30\n[[materials]]\nname = \"white\"\ndiffuse = 1\nior = 1\n\
         {objects}"
    );
    std::fs::write(dir.join("scene.toml"), toml).unwrap();
    dofray::scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap()
}

/// White furnace with an environment map of radiance 1 everywhere: the sphere vanishes.
#[test]
fn a_white_sphere_vanishes_in_a_uniform_environment_map() {
    let dir = hdr_map("furnace", 32, 16, |_, _| [1.0; 3]);
    let desc = world_scene(
        &dir,
        "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"white\"\n",
        "[camera]\neye = [0, 0, 4]\nlook_at = [0, 0, 0]\nvfov = 25",
    );
    let m = mean(&render_path(&desc, 64, 8));
    for c in m.to_array() {
        assert_close(c, 1.0, 0.01, "map furnace");
    }
}

/// An upward white Lambertian plane under a map with a small, very bright sun and a dim sky:
/// its radiance is the map's cosine-weighted integral over the upper hemisphere over pi.
/// The sun is found by importance-sampling the map (uniform sampling would need far more
/// samples for 1%), and the sky by both strategies, weighted by MIS.
#[test]
fn an_environment_map_lights_a_plane_as_its_integral_says() {
    let (w, h) = (64u32, 32u32);
    let texel = |x: u32, y: u32| {
        if (x, y) == (40, 9) {
            [2000.0, 1800.0, 1500.0]
        } else {
            let up = 1.0 - y as f32 / h as f32;
            [0.2 * up, 0.3 * up, 0.5 * up]
        }
    };
    let dir = hdr_map("plane", w, h, texel);
    let desc = world_scene(
        &dir,
        "[[objects]]\ntype = \"quad\"\ncenter = [0, 0, 0]\nsize = [200, 200]\n\
         material = \"white\"\n",
        "[camera]\neye = [0, 0.5, 0]\nlook_at = [0, 0, 0]\nup = [0, 0, -1]\nvfov = 0.5",
    );
    // The irradiance on the plane, integrated over the map as the renderer loaded it.
    let map = desc.background.map.clone().expect("a map");
    let n = 1200;
    let mut e = [0.0f64; 3];
    for i in 0..n {
        let cos = (i as f32 + 0.5) / n as f32; // uniform in cos theta over the upper hemisphere
        for j in 0..2 * n {
            let phi = 2.0 * PI * (j as f32 + 0.5) / (2 * n) as f32;
            let s = (1.0 - cos * cos).sqrt();
            let d = Vec3::new(s * phi.cos(), cos, s * phi.sin());
            let l = map.radiance(d) * cos;
            for k in 0..3 {
                e[k] += l[k] as f64;
            }
        }
    }
    // Summed in f64: 2.9 million terms would lose percents in f32.
    let e = Vec3::from_array(e.map(|v| v as f32)) * (2.0 * PI / (2 * n * n) as f32);
    let m = mean(&render_path(&desc, 256, 1));
    for (got, want) in m.to_array().into_iter().zip((e / PI).to_array()) {
        assert_close(got, want, 0.02, "map on a plane");
    }
}

/// A world map that is missing is an error naming it.
#[test]
fn a_missing_world_map_is_an_error_naming_it() {
    let dir = Scratch::new("env-missing");
    std::fs::write(
        dir.join("scene.toml"),
        "[world]\nmap = \"nowhere.hdr\"\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n",
    )
    .unwrap();
    let e = dofray::scene::load(dir.join("scene.toml").to_str().unwrap())
        .unwrap_err()
        .to_string();
    assert!(e.contains("nowhere.hdr"), "{e}");
}

/// A small rect light of power P facing down at height h over a white Lambertian plane: its
/// radiance is P / (pi A), so the plane's radiance at its foot is about P / (pi^2 h^2) (within
/// 0.1% for a light a twentieth of h across). Written as a scene file, with Blender's watts.
#[test]
fn a_rect_light_in_watts_lights_a_plane_as_cycles_would() {
    let dir = Scratch::new("rect");
    let (p, h) = (50.0f32, 2.0f32);
    let toml = format!(
        "[image]\nwidth = 16\nheight = 16\n[camera]\neye = [0, 0.5, 0]\nlook_at = [0, 0, 0]\n\
         up = [0, 0, -1]\nvfov = 0.5\n[world]\ncolor = 0\n[[lights]]\ntype = \"rect\"\n\
         position = [0, {h}, 0]\ndirection = [0, -1, 0]\nsize = 0.1\npower = {p}\n\
         [[materials]]\nname = \"white\"\ndiffuse = 1\nior = 1\n[[objects]]\ntype = \"quad\"\n\
         size = [100, 100]\nmaterial = \"white\"\n"
    );
    std::fs::write(dir.join("scene.toml"), toml).unwrap();
    let desc = dofray::scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
    let m = mean(&render_path(&desc, 256, 1));
    assert_close(m.x, p / (PI * PI * h * h), 0.01, "rect light on a plane");
    // Turned to face up, it sends the plane nothing: it emits from its front only.
    let up = std::fs::read_to_string(dir.join("scene.toml"))
        .unwrap()
        .replace("direction = [0, -1, 0]", "direction = [0, 1, 0]");
    std::fs::write(dir.join("scene.toml"), up).unwrap();
    let desc = dofray::scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
    assert_eq!(mean(&render_path(&desc, 16, 1)).x, 0.0);
}

/// Area lights are lights as Cycles has them, not walls: a 1 m square light between a sunlit
/// white plane and a camera looking straight down casts no shadow, camera rays pass through it
/// when it hides from the camera (as Blender's lights do by default) and through its back
/// always, and the camera sees its radiance P / (pi A) when it is visible.
#[test]
fn area_lights_cast_no_shadow_and_hide_as_blender_lights_do() {
    let dir = Scratch::new("light-object");
    let (e, p) = (2.0f32, 30.0f32);
    let render_light = |facing: &str, p: f32, extra: &str| {
        let toml = format!(
            "[image]\nwidth = 16\nheight = 16\n[camera]\neye = [0, 3, 0]\nlook_at = [0, 0, 0]\n\
             up = [0, 0, -1]\nvfov = 5\n[world]\ncolor = 0\n[[lights]]\ntype = \"directional\"\n\
             direction = [0, -1, 0]\nirradiance = {e}\n[[lights]]\ntype = \"rect\"\n\
             position = [0, 1, 0]\ndirection = {facing}\nsize = 1\npower = {p}\n{extra}\n\
             [[materials]]\nname = \"white\"\ndiffuse = 1\nior = 1\n[[objects]]\ntype = \"quad\"\n\
             size = [100, 100]\nmaterial = \"white\"\n"
        );
        std::fs::write(dir.join("scene.toml"), toml).unwrap();
        let desc = dofray::scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
        mean(&render_path(&desc, 16, 1)).x
    };
    // Facing the camera, hidden from it: the sunlit plane, unshadowed (the light faces away
    // from it).
    let hidden = render_light("[0, 1, 0]", p, "visible_to_camera = false");
    assert_close(hidden, e / PI, 1e-3, "a hidden light's plane");
    // Visible: its own radiance.
    let seen = render_light("[0, 1, 0]", p, "");
    assert_close(seen, p / PI, 1e-3, "a visible light's radiance");
    // Its back, dark (power 0): the camera sees through it to the sunlit plane.
    let back = render_light("[0, -1, 0]", 0.0, "");
    assert_close(back, e / PI, 1e-3, "seen through a light's back");
    // A dark sphere light hidden from the camera: neither seen nor casting a shadow.
    let sphere = render_sphere_light(&dir, e);
    assert_close(sphere, e / PI, 1e-3, "through a hidden sphere light");
}

/// The mean of the plane of `area_lights_cast_no_shadow_and_hide_as_blender_lights_do` under a
/// dark sphere light hidden from the camera.
fn render_sphere_light(dir: &std::path::Path, e: f32) -> f32 {
    let toml = format!(
        "[image]\nwidth = 16\nheight = 16\n[camera]\neye = [0, 3, 0]\nlook_at = [0, 0, 0]\n\
         up = [0, 0, -1]\nvfov = 5\n[world]\ncolor = 0\n[[lights]]\ntype = \"directional\"\n\
         direction = [0, -1, 0]\nirradiance = {e}\n[[lights]]\ntype = \"sphere\"\n\
         position = [0, 1, 0]\nradius = 0.5\npower = 0\nvisible_to_camera = false\n\
         [[materials]]\nname = \"white\"\ndiffuse = 1\nior = 1\n[[objects]]\ntype = \"quad\"\n\
         size = [100, 100]\nmaterial = \"white\"\n"
    );
    std::fs::write(dir.join("sphere.toml"), toml).unwrap();
    let desc = dofray::scene::load(dir.join("sphere.toml").to_str().unwrap()).unwrap();
    mean(&render_path(&desc, 16, 1)).x
}

/// Renders a 16 x 16 px view straight down at the foot of a white Lambertian plane (a tiny
/// field of view), lit by the scene file's `lights` (its `[[lights]]` tables) with `objects`
/// added, and returns the mean red radiance.
fn plane_under(test: &str, lights: &str, objects: &str) -> f32 {
    let dir = Scratch::new(test);
    let toml = format!(
        "[image]\nwidth = 16\nheight = 16\n[camera]\neye = [0, 0.5, 0]\nlook_at = [0, 0, 0]\n\
         up = [0, 0, -1]\nvfov = 0.5\n[world]\ncolor = 0\n{lights}\n\
         [[materials]]\nname = \"white\"\ndiffuse = 1\nior = 1\n[[objects]]\ntype = \"quad\"\n\
         size = [100, 100]\nmaterial = \"white\"\n{objects}\n"
    );
    std::fs::write(dir.join("scene.toml"), toml).unwrap();
    let desc = dofray::scene::load(dir.join("scene.toml").to_str().unwrap()).unwrap();
    mean(&render_path(&desc, 256, 1)).x
}

/// A spot light with a radius shines from a disc facing each point it lights, as Cycles' spot
/// with its default Soft Falloff: a point at distance h on its axis receives I / (h^2 + r^2)
/// (I / h^2 from a point); a sun with an angle gives a facing plane its irradiance E and casts
/// a soft shadow: a square 0.2 m across 1 m over the plane hides 5.03% of a 60-degree sun's
/// cosine-weighted cone from the point below it (a differential-area-to-rectangle form factor),
/// where a parallel sun leaves it black.
#[test]
fn soft_spots_and_suns_have_the_closed_form_light() {
    let spot = |radius: &str| {
        format!(
            "[[lights]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\n\
             intensity = 10\nouter_angle = 90\ninner_angle = 90\n{radius}"
        )
    };
    let point = plane_under("spot0", &spot(""), "");
    assert_close(point, 10.0 / PI, 1e-3, "a spot light without a radius");
    let disc = plane_under("spot1", &spot("radius = 0.5"), "");
    assert_close(disc, 10.0 / 1.25 / PI, 0.005, "a spot light with a radius");

    let sun = |angle: &str| {
        format!(
            "[[lights]]\ntype = \"directional\"\ndirection = [0, -1, 0]\nirradiance = 2\n\
             {angle}"
        )
    };
    let blocker = "[[objects]]\ntype = \"quad\"\ncenter = [0, 1, 0]\nsize = [0.2, 0.2]\n\
                   material = \"white\"";
    let open = plane_under("sun0", &sun("angle = 60"), "");
    assert_close(
        open,
        2.0 / PI,
        1e-3,
        "a sun with an angle on a facing plane",
    );
    let hard = plane_under("sun1", &sun(""), blocker);
    assert_eq!(hard, 0.0, "a parallel sun's shadow is black");
    // Projected solid angle of the square: 4 corner rectangles of X = Y = a / h = 0.1, each
    // (X / sqrt(1 + X^2)) atan(X / sqrt(1 + X^2)) x 2 / 2; over the cone's pi sin^2(30 deg).
    let x = 0.1f32 / (1.01f32).sqrt();
    let blocked = 4.0 * x * x.atan() / (PI * 0.25);
    let soft = plane_under("sun2", &sun("angle = 60"), blocker);
    assert_close(
        soft,
        2.0 / PI * (1.0 - blocked),
        0.005,
        "a soft sun's shadow",
    );
}

/// A sun with an angle is a disc in the sky that reflected and refracted rays find, as in
/// Cycles: a mirror facing it shows the disc at E / (pi sin^2(angle / 2)), the camera does not
/// see it directly (Blender's lights are hidden from camera rays), and on a rough glossy and a
/// diffuse surface its light samples, BSDF samples that find the disc, and both weighed by the
/// power heuristic agree.
#[test]
fn a_suns_disc_shows_in_mirrors_and_its_samples_agree_with_bsdf_samples() {
    let (e, angle) = (3.0f32, 20f32.to_radians());
    // Travelling down and towards +z: its disc is 45 degrees up, towards -z.
    let sun = Light::Directional {
        direction: Vec3::new(0.0, -1.0, 1.0),
        irradiance: Vec3::splat(e),
        angle,
    };
    let mirror = Material {
        metallic: 1.0,
        roughness: 0.0,
        ..Material::diffuse(Vec3::ONE)
    };
    let scene = |eye: Vec3, look_at: Vec3, floor: Material| SceneDesc {
        camera: camera(eye, look_at, 8.0),
        materials: vec![floor],
        objects: vec![Object::Mesh {
            mesh: ground(50.0),
            materials: MeshMaterials::One(0),
        }],
        lights: vec![sun],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    // Every pixel's reflection lies within 6 degrees of the disc's centre (radius 10).
    let seen = render_path(
        &scene(Vec3::Y, Vec3::new(0.0, 0.0, -1.0), mirror.clone()),
        4,
        2,
    );
    let disc = e / (PI * (0.5 * angle).sin().powi(2));
    for c in &seen.color {
        assert_close(c.x, disc, 1e-3, "the sun's disc in a mirror");
    }
    // Looking straight at the disc: nothing (a parallel sun shows nothing either way).
    let sky = render_path(&scene(Vec3::Y, Vec3::new(0.0, 2.0, -1.0), mirror), 4, 2);
    assert_eq!(mean(&sky), Vec3::ZERO, "the camera does not see the sun");

    let surface = |roughness: f32, metallic: f32| Material {
        roughness,
        metallic,
        ..Material::diffuse(Vec3::new(0.8, 0.6, 0.4))
    };
    for (name, floor) in [
        ("glossy", surface(0.3, 1.0)),
        ("diffuse", surface(1.0, 0.0)),
    ] {
        let desc = scene(Vec3::new(0.0, 1.0, 0.2), Vec3::new(0.0, 0.0, -0.8), floor);
        let mis = assert_strategies_agree(&desc, 1, name);
        assert!(mis.x > 0.0, "{name}: lit");
    }
}

/// Renders `desc` (paths up to `bounces` long, 1024 samples per pixel) with light samples
/// alone, BSDF samples alone and both weighed by the power heuristic, checks that the three
/// agree within 2% in every channel, and returns the last's mean.
fn assert_strategies_agree(desc: &SceneDesc, bounces: u32, what: &str) -> Vec3 {
    let with = |strategy| {
        let settings = RenderSettings {
            mode: Mode::Pinhole,
            aa: 1024,
            path: PathLimits {
                strategy,
                total: bounces,
                ..Default::default()
            },
            ..Default::default()
        };
        mean(&render_with(desc, &settings))
    };
    let mis = with(Strategy::Mis);
    for (how, other) in [
        ("light only", with(Strategy::LightOnly)),
        ("BSDF only", with(Strategy::BsdfOnly)),
    ] {
        for (a, b) in other.to_array().into_iter().zip(mis.to_array()) {
            assert_close(a, b, 0.02, &format!("{what}, {how}"));
        }
    }
    mis
}

/// Multiple importance sampling is unbiased: light samples alone, BSDF samples alone and both
/// weighted by the power heuristic agree (within their noise) on a glossy and a diffuse
/// surface lit by a sphere light, an emissive quad and a sky.
#[test]
fn light_bsdf_and_mis_estimates_agree() {
    let quad = TriangleMesh::new(
        vec![
            [-1.5, 1.0, -0.5],
            [-0.5, 1.0, -0.5],
            [-0.5, 1.5, -0.5],
            [-1.5, 1.5, -0.5],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap();
    let desc = SceneDesc {
        camera: camera(Vec3::new(0.0, 1.5, 3.0), Vec3::ZERO, 40.0),
        materials: vec![
            Material {
                metallic: 0.5,
                roughness: 0.4,
                ior: 1.5,
                ..Material::diffuse(Vec3::new(0.7, 0.6, 0.5))
            },
            Material {
                emission: Vec3::new(6.0, 5.0, 4.0),
                ..Material::diffuse(Vec3::ZERO)
            },
            Material {
                emission: Vec3::new(2.0, 3.0, 4.0),
                ..Material::diffuse(Vec3::ZERO)
            },
        ],
        objects: vec![
            Object::Mesh {
                mesh: ground(20.0),
                materials: MeshMaterials::One(0),
            },
            Object::Sphere {
                center: Vec3::new(0.8, 1.2, 0.0),
                radius: 0.4,
                material: 1,
            },
            Object::Mesh {
                mesh: quad,
                materials: MeshMaterials::One(2),
            },
        ],
        lights: vec![],
        ambient: Vec3::ZERO,
        background: Background {
            horizon: Vec3::new(0.3, 0.3, 0.35),
            zenith: Vec3::new(0.1, 0.2, 0.5),
            map: None,
        },
        ..Default::default()
    };
    assert_strategies_agree(
        &desc,
        PathLimits::default().total,
        "a glossy and a diffuse floor",
    );
}

/// A near-mirror ball (GGX alpha 0.0025) over a grey floor under a point light: the floor
/// around it holds the lamp's caustic, which camera paths find only by a diffuse bounce that
/// happens to hit the ball where it reflects the lamp (fireflies).
fn caustic_scene(floor: Material, ball: Material) -> SceneDesc {
    SceneDesc {
        camera: camera(Vec3::new(0.0, 4.0, 2.5), Vec3::new(0.0, 0.0, 0.0), 50.0),
        materials: vec![floor, ball],
        objects: vec![
            Object::Mesh {
                mesh: ground(20.0),
                materials: MeshMaterials::One(0),
            },
            Object::Sphere {
                center: Vec3::new(0.0, 0.6, 0.0),
                radius: 0.5,
                material: 1,
            },
        ],
        lights: vec![Light::Point {
            position: Vec3::new(1.5, 3.0, 0.0),
            intensity: Vec3::splat(100.0),
        }],
        ambient: Vec3::ZERO,
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    }
}

/// Renders `desc` with the path tracer through a pinhole at `spp`, seed `seed`, with Cycles'
/// Filter Glossy at `filter`.
fn render_filtered(desc: &SceneDesc, spp: u32, seed: u64, filter: f32) -> Film {
    let settings = RenderSettings {
        mode: Mode::Pinhole,
        aa: spp,
        seed,
        path: PathLimits {
            filter_glossy: filter,
            ..Default::default()
        },
        ..Default::default()
    };
    render_with(desc, &settings)
}

/// Mean squared difference of two renders' pixels in `mask` (their noise, when only the seed
/// differs).
fn mean_square_difference(a: &Film, b: &Film, mask: &[bool]) -> f32 {
    let sum: f32 = (0..a.color.len())
        .filter(|&p| mask[p])
        .map(|p| (a.color[p] - b.color[p]).length_squared())
        .sum();
    sum / mask.iter().filter(|&&m| m).count() as f32
}

/// Mean of the pixels in `mask`.
fn masked_mean(film: &Film, mask: &[bool]) -> Vec3 {
    let sum: Vec3 = (0..film.color.len())
        .filter(|&p| mask[p])
        .map(|p| film.color[p])
        .sum();
    sum / mask.iter().filter(|&&m| m).count() as f32
}

/// The pixels of `with` that see only what `without` sees, at least 2 px (the pixel filter's
/// reach) from any pixel whose depth differs.
fn unchanged_pixels(with: &Film, without: &Film) -> Vec<bool> {
    let (w, h) = (with.width as i64, with.height as i64);
    let differs = |x: i64, y: i64| {
        let p = (y * w + x) as usize;
        (with.depth[p] - without.depth[p]).abs() > 1e-3
    };
    (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            !(-2..=2).any(|dy: i64| {
                (-2..=2).any(|dx: i64| {
                    let (u, v) = (x + dx, y + dy);
                    (0..w).contains(&u) && (0..h).contains(&v) && differs(u, v)
                })
            })
        })
        .collect()
}

/// Cycles' Filter Glossy: the caustic's fireflies go (renders with different seeds agree far
/// better on the floor around the ball), the floor's light stays, and a scene of fully rough
/// surfaces, which the filter cannot make rougher, renders bit for bit as without it.
#[test]
fn the_glossy_filter_smooths_a_caustic_and_keeps_its_light() {
    let floor = Material {
        roughness: 1.0,
        ..Material::diffuse(Vec3::splat(0.5))
    };
    let glossy = Material {
        metallic: 1.0,
        roughness: 0.2,
        ..Material::diffuse(Vec3::splat(0.9))
    };
    let desc = caustic_scene(floor.clone(), glossy);
    // The floor around the ball, not the ball itself: its own highlight is a tiny lamp seen
    // directly, which the filter leaves alone (so does Cycles').
    let mut bare = desc.clone();
    bare.objects.truncate(1);
    let mask = unchanged_pixels(
        &render_filtered(&desc, 1, 1, 0.0),
        &render_filtered(&bare, 1, 1, 0.0),
    );
    assert!(mask.iter().filter(|&&m| m).count() > 150);
    let (mut noise, mut light) = ([0.0f32; 2], [0.0f32; 2]);
    for (i, filter) in [0.0, 1.0].into_iter().enumerate() {
        for seeds in [(1, 2), (3, 4), (5, 6)] {
            let a = render_filtered(&desc, 64, seeds.0, filter);
            let b = render_filtered(&desc, 64, seeds.1, filter);
            noise[i] += mean_square_difference(&a, &b, &mask);
            light[i] += (masked_mean(&a, &mask).x + masked_mean(&b, &mask).x) / 6.0;
        }
    }
    assert!(
        noise[1] < 0.1 * noise[0],
        "renders with different seeds differ by {} with the filter, {} without",
        noise[1],
        noise[0]
    );
    assert_close(
        light[1],
        light[0],
        0.02,
        "the floor's light with the filter",
    );

    let rough = Material {
        metallic: 1.0,
        roughness: 1.0,
        ..Material::diffuse(Vec3::splat(0.9))
    };
    let desc = caustic_scene(floor, rough);
    let (off, on) = (
        render_filtered(&desc, 4, 1, 0.0),
        render_filtered(&desc, 4, 1, 1.0),
    );
    assert!(
        off.color == on.color,
        "fully rough surfaces changed under the filter"
    );
}
