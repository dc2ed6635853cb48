//! Light tracing of small emitters (`render::light_trace`): a sub-pixel lamp defocused to a
//! 24 px disc keeps the energy a closed form gives it, alone on black and in front of a wall, in
//! adaptive mode as in dense; the light-traced disc is where and as large as the camera's own
//! rays find it; regions and thread counts change nothing.

use std::path::Path;

use dofray::camera::LensFilter;
use dofray::render::{
    self, Film, Mode, NoProgress, Region, RenderSettings, RenderStats, SettingsPatch,
};
use dofray::scene::{SceneDesc, World};
use glam::Vec3;

const WIDTH: u32 = 192;
const HEIGHT: u32 = 144;
/// The lamp's radiance.
const LAMP: f32 = 400.0;
/// The lamp's distance along the view axis; the lens is focused at 4 m, so its CoC is ~24 px.
const LAMP_DEPTH: f32 = 0.9;

/// An 85 mm f/1.4 lens focused at 4 m looking down +z from the origin, a lamp of radius
/// `radius` (metres) at 0.9 m, on black or in front of a dim emissive wall in focus.
fn scene(radius: f32, wall: bool) -> SceneDesc {
    scene_with(
        &format!("type = \"sphere\"\ncenter = [0.01, 0.005, {LAMP_DEPTH}]\nradius = {radius}"),
        wall,
    )
}

/// [`scene`] with the lamp object given by `lamp` (its `[[objects]]` keys but the material).
fn scene_with(lamp: &str, wall: bool) -> SceneDesc {
    let wall = if wall {
        r#"
[[materials]]
name = "wall"
diffuse = 0
emission = 0.2

[[objects]]
type = "quad"
size = [8, 8]
rotate = [-90, 0, 0]
translate = [0, 0, 4]
material = "wall"
"#
    } else {
        ""
    };
    let src = format!(
        r#"
name = "lamp"
ambient = 0

[image]
width = {WIDTH}
height = {HEIGHT}

[camera]
eye = [0, 0, 0]
look_at = [0, 0, 1]
f_number = 1.4
focal_length_mm = 85
sensor_width_mm = 36
focus_distance = 4

[background]
horizon = 0
zenith = 0

[[materials]]
name = "lamp"
diffuse = 0
emission = {LAMP}

[[objects]]
{lamp}
material = "lamp"
{wall}"#
    );
    dofray::scene::file::parse(&src, Path::new("lamp.toml")).unwrap()
}

fn settings(mode: Mode, spp: u32, light_tracing: bool) -> RenderSettings {
    SettingsPatch {
        mode: Some(mode),
        spp: Some(spp),
        light_tracing: Some(light_tracing),
        ..Default::default()
    }
    .resolve()
    .unwrap()
}

fn render(desc: &SceneDesc, settings: &RenderSettings) -> (Film, RenderStats) {
    let device = dofray::embree::Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    render::render(&world, &camera, settings, &NoProgress).unwrap()
}

/// The image's summed colour (mean of the channels): the energy on the film.
fn total(film: &Film) -> f64 {
    film.color
        .iter()
        .map(|c| f64::from(c.x + c.y + c.z) / 3.0)
        .sum()
}

/// The lamp's energy on the film: its radiance times its solid angle times the pixels per
/// steradian (k^2 near the axis, k = pixels per unit at unit distance), whatever the blur.
fn expected(desc: &SceneDesc, radius: f32) -> f64 {
    let camera = desc.camera.build(|_| None).unwrap();
    let k = f64::from(camera.pixels_per_unit());
    let d = Vec3::new(0.01, 0.005, LAMP_DEPTH).length() as f64;
    let r = f64::from(radius);
    let solid_angle = 2.0 * std::f64::consts::PI * (1.0 - (1.0 - r * r / (d * d)).sqrt());
    f64::from(LAMP) * solid_angle * k * k
}

#[test]
fn a_sub_pixel_lamp_keeps_its_energy_alone_on_black_and_in_front_of_a_wall() {
    // 0.5 mm at 0.9 m: half a pixel across, blurred to a disc of about 24 px.
    let radius = 0.0005;
    let lamp = scene(radius, false);
    let camera = lamp.camera.build(|_| None).unwrap();
    let coc = camera.coc_px(LAMP_DEPTH);
    assert!((20.0..28.0).contains(&coc), "CoC {coc} px");
    let want = expected(&lamp, radius);
    let dense = total(&render(&lamp, &settings(Mode::Dense, 16, true)).0);
    let (film, stats) = render(&lamp, &settings(Mode::Adaptive, 16, true));
    let adaptive = total(&film);
    assert!(stats.light_paths > 0);
    for (name, got) in [("dense", dense), ("adaptive", adaptive)] {
        assert!(
            (got / want - 1.0).abs() < 0.03,
            "{name} on black: {got} of {want} expected"
        );
    }
    // In front of a wall in focus: the lamp's share is the difference with the wall alone
    // (less the bit of wall it hides, 0.05% of its own energy here).
    let wall = render(&scene(radius, true), &settings(Mode::Adaptive, 16, true)).0;
    let bare = {
        let mut d = scene(radius, true);
        d.objects
            .retain(|o| !matches!(o, dofray::scene::Object::Sphere { .. }));
        total(&render(&d, &settings(Mode::Adaptive, 16, true)).0)
    };
    let share = total(&wall) - bare;
    assert!(
        (share / want - 1.0).abs() < 0.05,
        "adaptive before a wall: {share} of {want} expected"
    );
}

/// The centroid (x, y) and RMS radius of the film's energy.
fn moments(film: &Film) -> (f64, f64, f64) {
    let mut sum = [0.0f64; 4];
    for (i, c) in film.color.iter().enumerate() {
        let e = f64::from(c.x + c.y + c.z);
        let (x, y) = ((i % film.width) as f64 + 0.5, (i / film.width) as f64 + 0.5);
        sum[0] += e;
        sum[1] += e * x;
        sum[2] += e * y;
        sum[3] += e * (x * x + y * y);
    }
    let (cx, cy) = (sum[1] / sum[0], sum[2] / sum[0]);
    (cx, cy, (sum[3] / sum[0] - cx * cx - cy * cy).sqrt())
}

#[test]
fn the_light_traced_disc_is_the_one_camera_rays_find() {
    // 6 mm at 0.9 m: about 6 px sharp, blurred by 24 px: light-traced, and big enough for
    // camera rays to find at 64 samples. A sphere, and a square of two triangles facing the
    // camera (a mesh lamp, as glTF brings them).
    let sphere = scene(0.006, false);
    let square = scene_with(
        &format!(
            "type = \"quad\"\nsize = [0.01, 0.01]\nrotate = [-90, 0, 0]\ntranslate = [0.01, 0.005, {LAMP_DEPTH}]"
        ),
        false,
    );
    for (lamp, filter) in [
        (&sphere, LensFilter::Box),
        (&sphere, LensFilter::Gaussian),
        (&square, LensFilter::Box),
    ] {
        let with = |light_tracing| {
            let s = RenderSettings {
                filter,
                ..settings(Mode::Dense, 64, light_tracing)
            };
            render(lamp, &s)
        };
        let (traced, stats) = with(true);
        assert!(
            stats.light_paths > 0,
            "{filter:?}: the lamp is light-traced"
        );
        let (camera_only, stats) = with(false);
        assert_eq!(stats.light_paths, 0);
        let (a, b) = (total(&traced), total(&camera_only));
        assert!((a / b - 1.0).abs() < 0.05, "{filter:?}: energy {a} vs {b}");
        let (ma, mb) = (moments(&traced), moments(&camera_only));
        assert!(
            (ma.0 - mb.0).abs() < 0.5 && (ma.1 - mb.1).abs() < 0.5,
            "{filter:?}: centroid {ma:?} vs {mb:?}"
        );
        assert!(
            (ma.2 / mb.2 - 1.0).abs() < 0.05,
            "{filter:?}: disc radius {ma:?} vs {mb:?}"
        );
    }
}

#[test]
fn an_emitter_large_and_sharp_on_screen_stays_with_the_camera() {
    // The wall is in focus and fills the frame: light tracing would only add noise.
    let mut d = scene(0.0005, true);
    d.objects
        .retain(|o| !matches!(o, dofray::scene::Object::Sphere { .. }));
    let (_, stats) = render(&d, &settings(Mode::Dense, 16, true));
    assert_eq!(stats.light_paths, 0);
}

#[test]
fn regions_and_thread_counts_get_the_same_splats() {
    // A region through the middle of the disc.
    let region = Region {
        x0: 90,
        y0: 60,
        x1: 130,
        y1: 90,
    };
    let s = settings(Mode::Adaptive, 16, true);
    let full = same_in_a_region_and_on_one_thread(&scene(0.0005, true), &s, &region);
    let crop = full.crop(&region);
    assert!(
        crop.color.iter().any(|c| c.x > 0.3),
        "the disc is in the region"
    );
}

/// Renders `desc` whole, then `region` alone and whole on one thread, asserts that both give
/// the full render's pixels (light paths' splats included), and returns the full render.
pub(crate) fn same_in_a_region_and_on_one_thread(
    desc: &SceneDesc,
    s: &RenderSettings,
    region: &Region,
) -> Film {
    let device = dofray::embree::Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    let full = render::render(&world, &camera, s, &NoProgress).unwrap().0;
    let part = render::render_region(&world, &camera, s, region, &NoProgress)
        .unwrap()
        .0;
    assert_eq!(part.color, full.crop(region).color);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| render::render(&world, &camera, s, &NoProgress).unwrap().0);
    assert_eq!(one.color, full.color);
    full
}

/// A night scene's worth of sub-pixel lamps, far more than light tracing's budget of paths at
/// 4 spp: every lamp's share shrinks alike instead of the largest being left to camera rays
/// (which find a half-pixel lamp by luck, and adaptive sites miss most of them), so their
/// energy is kept in adaptive mode, within the budget.
#[test]
fn lamps_beyond_the_budget_share_it_and_keep_their_energy() {
    let (n, radius) = (20, 0.0005f32);
    let mut lamps = String::new();
    let mut want = 0.0;
    let camera = scene(radius, false).camera.build(|_| None).unwrap();
    let k = f64::from(camera.pixels_per_unit());
    for j in 0..n {
        for i in 0..n {
            let x = -0.06 + 0.12 * i as f32 / (n - 1) as f32;
            let y = -0.045 + 0.09 * j as f32 / (n - 1) as f32;
            if !lamps.is_empty() {
                lamps += "\nmaterial = \"lamp\"\n\n[[objects]]\n";
            }
            lamps +=
                &format!("type = \"sphere\"\ncenter = [{x}, {y}, {LAMP_DEPTH}]\nradius = {radius}");
            let d = f64::from(Vec3::new(x, y, LAMP_DEPTH).length());
            let r = f64::from(radius);
            let solid_angle = 2.0 * std::f64::consts::PI * (1.0 - (1.0 - r * r / (d * d)).sqrt());
            // Pixels per steradian fall as cos^3 off the axis.
            let cos = f64::from(LAMP_DEPTH) / d;
            want += f64::from(LAMP) * solid_angle * k * k * cos.powi(3);
        }
    }
    let desc = scene_with(&lamps, false);
    let spp = 4;
    let (film, stats) = render(&desc, &settings(Mode::Adaptive, spp, true));
    let got = total(&film);
    eprintln!("{} lamps keep {:.3} of their energy", n * n, got / want);
    assert!((got / want - 1.0).abs() < 0.05, "{got} of {want}");
    let budget = 0.5 * f64::from(WIDTH * HEIGHT) * f64::from(spp);
    assert!(
        stats.light_paths > 0 && (stats.light_paths as f64) < 1.5 * budget,
        "{} light paths, budget {budget}",
        stats.light_paths
    );
}
