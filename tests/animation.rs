//! Camera and lens animation: the `[animation]` table of scene files (syntax, interpolation,
//! located errors) and the `focus_pull` example shot.

use std::path::{Path, PathBuf};

use dofray::camera::{CameraSpec, Focus, LensSpec};
use dofray::embree::Device;
use dofray::render::{Film, NoProgress, RenderSettings, render};
use dofray::scene::{self, Animation, SceneDesc, World, file};
use glam::Vec3;

/// A scene of one sphere with `camera` as its `[camera]` table's body and `animation` appended.
fn scene(camera: &str, animation: &str) -> String {
    format!(
        "[image]\nwidth = 64\nheight = 48\n\n[camera]\n{camera}\n\n\
         [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 6]\nradius = 1\n\n{animation}"
    )
}

const CAMERA: &str = "eye = [0, 0, 0]\nlook_at = [0, 0, 6]\naperture_radius = 0.1";

fn parse(src: &str) -> Result<SceneDesc, scene::LoadError> {
    file::parse(src, Path::new("anim.toml"))
}

/// The scene's animation (the scene must load and have one).
fn animated(camera: &str, animation: &str) -> (CameraSpec, Animation) {
    let desc = parse(&scene(camera, animation)).unwrap();
    (desc.camera, desc.animation.expect("an [animation] table"))
}

/// The camera at `frame`.
fn at(camera: &CameraSpec, animation: &Animation, frame: f64) -> CameraSpec {
    let mut c = camera.clone();
    animation.apply(&mut c, frame);
    c
}

fn distance(c: &CameraSpec) -> f32 {
    match c.focus {
        Focus::Distance(d) => d,
        other => panic!("focus {other:?}"),
    }
}

/// A track of one scalar: `vfov` keyed at the given frames with the given interpolation.
fn vfov_track(keys: &[(i64, f32)], interpolation: &str) -> impl Fn(f64) -> f32 {
    let mut text = format!("[animation]\ninterpolation = \"{interpolation}\"\n");
    for (frame, v) in keys {
        text += &format!("[[animation.key]]\nframe = {frame}\nvfov = {v}\n");
    }
    let (camera, animation) = animated(CAMERA, &text);
    move |f| at(&camera, &animation, f).vfov_deg
}

#[test]
fn the_documented_syntax_parses() {
    let (camera, animation) = animated(
        "eye = [0, 1, 6]\nlook_at = [0, 0, 0]\nf_number = 2\nfocus_pixel = [10, 10]",
        r#"
[animation]
fps = 24
frame_start = 1
frame_end = 48
interpolation = "smooth"     # default for every key

[[animation.key]]
frame = 1
focus_distance = 2.0
[[animation.key]]
frame = 48
focus_distance = 8.0
eye = [0, 1, 5]
interpolation = "ease"      # the segment starting at this key
"#,
    );
    assert_eq!(animation.fps, 24.0);
    assert_eq!(animation.frames(), 1..=48);
    assert_eq!(animation.parameters(), ["eye", "focus_distance"]);
    // The [camera] table is left as written; the animation replaces its focus pixel.
    assert_eq!(camera.focus, Focus::Pixel { x: 10, y: 10 });
    let first = at(&camera, &animation, 1.0);
    assert_eq!(first.focus, Focus::Distance(2.0));
    assert_eq!(
        first.eye,
        Vec3::new(0.0, 1.0, 5.0),
        "one key holds everywhere"
    );
    assert_eq!(distance(&at(&camera, &animation, 48.0)), 8.0);
    assert!(first.build(|_| None).is_ok());

    // Defaults: 24 fps, the range of the keys, "smooth".
    let (_, animation) = animated(
        CAMERA,
        "[animation]\n[[animation.key]]\nframe = 5\nvfov = 30\n[[animation.key]]\nframe = -3\nvfov = 50\n",
    );
    assert_eq!((animation.fps, animation.frames()), (24.0, -3..=5));
    // No animation: None.
    assert!(parse(&scene(CAMERA, "")).unwrap().animation.is_none());
    assert!(scene::builtin::paper().animation.is_none());
}

#[test]
fn linear_midpoints_are_exact() {
    let (camera, animation) = animated(
        CAMERA,
        "[animation]\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 1\neye = [0, 1, -5]\nlook_at = [1, 0, 6]\nvfov = 30\naperture_radius = 0.1\n\
         [[animation.key]]\nframe = 3\neye = [2, 1, -3]\nlook_at = [3, 2, 6]\nvfov = 50\naperture_radius = 0.3\n",
    );
    let c = at(&camera, &animation, 2.0);
    assert_eq!(c.eye, Vec3::new(1.0, 1.0, -4.0));
    assert_eq!(c.look_at, Vec3::new(2.0, 1.0, 6.0));
    assert_eq!(c.vfov_deg, 40.0);
    assert_eq!(c.lens, LensSpec::Aperture { radius: 0.2 });
    let quarter = at(&camera, &animation, 1.5);
    assert_eq!(quarter.eye, Vec3::new(0.5, 1.0, -4.5));
}

#[test]
fn ease_is_flat_at_every_key_and_monotone_between() {
    let vfov = vfov_track(&[(0, 20.0), (10, 60.0), (40, 30.0)], "ease");
    let h = 1e-3;
    for key in [0.0, 10.0, 40.0] {
        let velocity = (vfov(key + h) - vfov(key - h)) / (2.0 * h as f32);
        assert!(velocity.abs() < 0.01, "velocity {velocity} at frame {key}");
    }
    let samples: Vec<f32> = (0..=100).map(|i| vfov(i as f64 * 0.1)).collect();
    assert!(samples.windows(2).all(|w| w[1] >= w[0]), "{samples:?}");
    assert_eq!(vfov(5.0), 40.0);
    let down: Vec<f32> = (100..=400).map(|i| vfov(i as f64 * 0.1)).collect();
    assert!(down.windows(2).all(|w| w[1] <= w[0]));
}

#[test]
fn smooth_passes_through_every_key_and_two_keys_do_not_overshoot() {
    let keys = [(0, 20.0), (3, 50.0), (10, 35.0), (11, 40.0), (30, 90.0)];
    let vfov = vfov_track(&keys, "smooth");
    for (frame, v) in keys {
        assert!((vfov(frame as f64) - v).abs() < 1e-4, "frame {frame}");
    }
    // Continuous velocity through an interior key (it is a spline, not a polyline).
    let h = 1e-3;
    let (before, after) = (
        (vfov(3.0) - vfov(3.0 - h)) / h as f32,
        (vfov(3.0 + h) - vfov(3.0)) / h as f32,
    );
    assert!((before - after).abs() < 0.05, "{before} {after}");

    let two = vfov_track(&[(1, 30.0), (25, 60.0)], "smooth");
    let samples: Vec<f32> = (0..=260).map(|i| two(i as f64 * 0.1)).collect();
    assert!(samples.iter().all(|v| (30.0..=60.0).contains(v)));
    assert!(samples.windows(2).all(|w| w[1] >= w[0]));
    // Eases in and out: slow at the ends, fastest in the middle.
    assert!(two(2.0) - two(1.0) < two(13.5) - two(12.5));
    assert!((two(13.0) - 45.0).abs() < 1e-4);
}

#[test]
fn constant_holds_until_the_next_key() {
    let vfov = vfov_track(&[(1, 30.0), (10, 60.0), (20, 40.0)], "constant");
    assert_eq!(vfov(1.0), 30.0);
    assert_eq!(vfov(9.999), 30.0);
    assert_eq!(vfov(10.0), 60.0);
    assert_eq!(vfov(19.0), 60.0);
    assert_eq!(vfov(20.0), 40.0);
}

#[test]
fn tracks_hold_their_end_values_and_keys_outside_the_range_shape_the_curve() {
    let (camera, animation) = animated(
        CAMERA,
        "[animation]\nframe_start = 1\nframe_end = 10\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = -10\nvfov = 20\n\
         [[animation.key]]\nframe = 5\nvfov = 50\n\
         [[animation.key]]\nframe = 20\nvfov = 60\n\
         [[animation.key]]\nframe = 4\naperture_radius = 0.2\n",
    );
    let vfov = |f| at(&camera, &animation, f).vfov_deg;
    assert_eq!(vfov(-100.0), 20.0);
    assert!((vfov(1.0) - 42.0).abs() < 1e-5);
    assert_eq!(vfov(100.0), 60.0);
    // A single key holds at every frame.
    assert_eq!(
        at(&camera, &animation, -5.0).lens,
        LensSpec::Aperture { radius: 0.2 }
    );
    // Parameters that are not animated keep the camera's values.
    assert_eq!(at(&camera, &animation, 3.0).eye, camera.eye);
    assert_eq!(at(&camera, &animation, 3.0).focus, camera.focus);
}

#[test]
fn focus_distance_interpolates_in_dioptres() {
    let (camera, animation) = animated(
        CAMERA,
        "[animation]\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 0\nfocus_distance = 2\n\
         [[animation.key]]\nframe = 10\nfocus_distance = inf\n",
    );
    let d = |f| distance(&at(&camera, &animation, f));
    assert_eq!(d(5.0), 4.0);
    assert_eq!(d(0.0), 2.0);
    assert_eq!(d(10.0), f32::INFINITY);
    assert_eq!(d(7.5), 8.0);
    assert!(at(&camera, &animation, 10.0).build(|_| None).is_ok());

    // Without focus keys, a camera focused on look_at by default keeps focusing on it; one
    // with a focus key keeps that.
    let pan = "[animation]\n[[animation.key]]\nframe = 0\nlook_at = [0, 0, 6]\n\
               [[animation.key]]\nframe = 10\nlook_at = [2, 0, 6]\n";
    let (camera, animation) = animated("eye = [0, 0, 0]\nlook_at = [0, 0, 6]", pan);
    assert_eq!(
        at(&camera, &animation, 10.0).focus,
        Focus::Point(Vec3::new(2.0, 0.0, 6.0))
    );
    let (camera, animation) = animated(
        "eye = [0, 0, 0]\nlook_at = [0, 0, 6]\nfocus_point = [0, 0, 6]",
        pan,
    );
    assert_eq!(
        at(&camera, &animation, 10.0).focus,
        Focus::Point(Vec3::new(0.0, 0.0, 6.0))
    );

    // focus_point replaces the focus at every frame too.
    let (camera, animation) = animated(
        CAMERA,
        "[animation]\n[[animation.key]]\nframe = 0\nfocus_point = [1, 0, 3]\n",
    );
    assert_eq!(
        at(&camera, &animation, 7.0).focus,
        Focus::Point(Vec3::new(1.0, 0.0, 3.0))
    );
}

#[test]
fn the_f_number_moves_in_stops_and_the_focal_length_in_millimetres() {
    let (camera, animation) = animated(
        "eye = [0, 0, 0]\nlook_at = [0, 0, 6]\nf_number = 2",
        "[animation]\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 0\nf_number = 2\nfocal_length_mm = 35\n\
         [[animation.key]]\nframe = 2\nf_number = 8\nfocal_length_mm = 85\n",
    );
    match at(&camera, &animation, 1.0).lens {
        LensSpec::Photographic {
            f_number,
            focal_length_mm,
            ..
        } => {
            assert!((f_number - 4.0).abs() < 1e-5, "{f_number}");
            assert_eq!(focal_length_mm, 60.0);
        }
        other => panic!("{other:?}"),
    }
}

/// Asserts that `animation` (with `camera`) is refused with a message naming the file, the
/// line, the key and the other given parts.
fn assert_error(camera: &str, animation: &str, line: usize, key: &str, parts: &[&str]) {
    let src = scene(camera, animation);
    let message = match parse(&src) {
        Ok(_) => panic!("accepted:\n{src}"),
        Err(e) => e.to_string(),
    };
    let at = format!("anim.toml:{line}:");
    assert!(message.starts_with(&at), "{message:?} is not at {at}");
    assert!(
        message.contains(&format!("`{key}`")),
        "{message:?} lacks {key}"
    );
    for part in parts {
        assert!(message.contains(part), "{message:?} lacks {part:?}");
    }
}

/// The line of the scene text at which the animation starts (the first line is 1).
fn first_line(camera: &str) -> usize {
    scene(camera, "").lines().count() + 1
}

#[test]
fn every_mistake_is_reported_with_file_line_and_key() {
    let l = first_line(CAMERA);
    let key = |frame: i64, rest: &str| format!("[[animation.key]]\nframe = {frame}\n{rest}\n");
    // Unknown keys, in the table and in a key.
    assert_error(
        CAMERA,
        "[animation]\nfsp = 24\n",
        l + 1,
        "animation.fsp",
        &["unknown field"],
    );
    assert_error(
        CAMERA,
        &format!("[animation]\n{}", key(1, "focus = 2")),
        l + 3,
        "animation.key[0].focus",
        &["unknown field"],
    );
    assert_error(
        CAMERA,
        &format!(
            "[animation]\n{}",
            key(1, "vfov = 30\ninterpolation = \"cubic\"")
        ),
        l + 4,
        "animation.key[0].interpolation",
        &["linear", "smooth", "ease", "constant"],
    );
    // fps.
    for fps in ["0", "-24", "nan", "inf"] {
        assert_error(
            CAMERA,
            &format!("[animation]\nfps = {fps}\n{}", key(1, "vfov = 30")),
            l + 1,
            "animation.fps",
            &["a finite number > 0"],
        );
    }
    // The range.
    assert_error(
        CAMERA,
        &format!(
            "[animation]\nframe_start = 10\nframe_end = 9\n{}",
            key(1, "vfov = 30")
        ),
        l + 2,
        "animation.frame_end",
        &["`frame_end` (9) must be at least `frame_start` (10)"],
    );
    assert_error(
        CAMERA,
        &format!(
            "[animation]\nframe_start = 0\nframe_end = 1000000\n{}",
            key(1, "vfov = 30")
        ),
        l + 2,
        "animation.frame_end",
        &["1000001 frames", "at most 1000000"],
    );
    assert_error(
        CAMERA,
        "[animation]\nframe_start = 1\n",
        l,
        "animation.frame_end",
        &["without keys"],
    );
    assert_error(
        CAMERA,
        &format!("[animation]\n{}", key(1, "")),
        l + 1,
        "animation.key[0]",
        &["sets no parameter"],
    );
    // Two keys of one track on one frame (other tracks may share the frame).
    assert_error(
        CAMERA,
        &format!(
            "[animation]\n{}{}{}",
            key(3, "vfov = 30"),
            key(3, "eye = [0, 0, 1]"),
            key(3, "vfov = 35")
        ),
        l + 9,
        "animation.key[2].vfov",
        &["keyed twice at frame 3", "animation.key[0]"],
    );
    // Lens conflicts.
    assert_error(
        CAMERA,
        &format!("[animation]\n{}", key(1, "f_number = 2")),
        l + 3,
        "animation.key[0].f_number",
        &["photographic", "aperture_radius"],
    );
    assert_error(
        CAMERA,
        &format!("[animation]\n{}", key(1, "focal_length_mm = 35")),
        l + 3,
        "animation.key[0].focal_length_mm",
        &["photographic"],
    );
    let photographic = "eye = [0, 0, 0]\nlook_at = [0, 0, 6]\nf_number = 2";
    assert_error(
        photographic,
        &format!("[animation]\n{}", key(1, "vfov = 30")),
        l + 3,
        "animation.key[0].vfov",
        &["focal_length_mm"],
    );
    assert_error(
        photographic,
        &format!("[animation]\n{}", key(1, "aperture_radius = 0.1")),
        l + 3,
        "animation.key[0].aperture_radius",
        &["photographic", "f_number"],
    );
    let seed = "eye = [0, 0, 0]\nlook_at = [0, 0, 6]\nsharp_range = 1\nspread = 4";
    assert_error(
        seed,
        &format!("[animation]\n{}", key(1, "aperture_radius = 0.1")),
        first_line(seed) + 3,
        "animation.key[0].aperture_radius",
        &["seed"],
    );
    // Both kinds of focus.
    assert_error(
        CAMERA,
        &format!(
            "[animation]\n{}{}",
            key(1, "focus_distance = 3"),
            key(5, "focus_point = [0, 0, 4]")
        ),
        l + 6,
        "animation.key[1].focus_point",
        &["both keyed", "animation.key[0]"],
    );
    // Values out of range, checked as the [camera] keys are.
    for (text, key_name, expected) in [
        ("vfov = 180", "vfov", "between 0 and 180"),
        ("f_number = 0", "f_number", "a finite number > 0"),
        (
            "aperture_radius = -1",
            "aperture_radius",
            "a finite number >= 0",
        ),
        (
            "focus_distance = 0",
            "focus_distance",
            "a number > 0, or inf",
        ),
        (
            "focus_distance = -inf",
            "focus_distance",
            "a number > 0, or inf",
        ),
        ("eye = [0, nan, 0]", "eye", "a finite number"),
        ("up = [0, 1]", "up", "length 3"),
    ] {
        assert_error(
            CAMERA,
            &format!("[animation]\n{}", key(1, text)),
            l + 3,
            &format!("animation.key[0].{key_name}"),
            &[expected],
        );
    }
    assert_error(
        CAMERA,
        &format!("[animation]\n{}", key(1_000_000_001, "vfov = 30")),
        l + 2,
        "animation.key[0].frame",
        &["frame number"],
    );
}

#[test]
fn a_bad_view_names_the_first_bad_frame() {
    let l = first_line(CAMERA);
    // eye reaches look_at at frame 5 (linear from [0, 0, -4] to [0, 0, 14] over 0..9).
    assert_error(
        CAMERA,
        "[animation]\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 0\neye = [0, 0, -4]\n\
         [[animation.key]]\nframe = 9\neye = [0, 0, 14]\n",
        l + 4,
        "animation.key[0].eye",
        &["at frame 5:", "`look_at` must differ from `eye`"],
    );
    // up turns through the view direction at frame 10 (the last key is to blame there).
    assert_error(
        CAMERA,
        "[animation]\nframe_start = 0\nframe_end = 20\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 0\nup = [0, 1, -1]\n\
         [[animation.key]]\nframe = 10\nup = [0, 0, 1]\n",
        l + 9,
        "animation.key[1].up",
        &["at frame 10:", "parallel"],
    );
    // A focus point that ends up behind the camera.
    assert_error(
        CAMERA,
        "[animation]\nframe_start = 0\nframe_end = 3\n\
         [[animation.key]]\nframe = 2\nfocus_point = [0, 0, -1]\n",
        l + 5,
        "animation.key[0].focus_point",
        &["at frame 0:", "in front of the camera"],
    );
    // Outside the range, the same motion is fine.
    let desc = parse(&scene(
        CAMERA,
        "[animation]\nframe_start = 0\nframe_end = 4\ninterpolation = \"linear\"\n\
         [[animation.key]]\nframe = 0\neye = [0, 0, -4]\n\
         [[animation.key]]\nframe = 9\neye = [0, 0, 14]\n",
    ));
    assert!(desc.is_ok(), "{:?}", desc.err());
}

// ---------------------------------------------------------------------------------------------
// The example shot.

fn focus_pull() -> SceneDesc {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/focus_pull.toml");
    scene::load(path.to_str().unwrap()).unwrap()
}

/// Depth along the view axis of `p` seen from `c`.
fn depth(c: &CameraSpec, p: Vec3) -> f32 {
    (p - c.eye).dot((c.look_at - c.eye).normalize())
}

const NEAR: Vec3 = Vec3::new(-0.2, 0.1, 1.3);
const FAR: Vec3 = Vec3::new(0.5, 0.4, 5.5);

#[test]
fn focus_pull_racks_from_the_near_ball_to_the_far_one() {
    let desc = focus_pull();
    let animation = desc.animation.as_ref().unwrap();
    assert_eq!((animation.fps, animation.frames()), (24.0, 1..=48));
    assert_eq!((desc.camera.width, desc.camera.height), (320, 240));
    assert!(matches!(desc.camera.lens, LensSpec::Photographic { .. }));
    let cameras: Vec<CameraSpec> = animation
        .frames()
        .map(|f| at(&desc.camera, animation, f as f64))
        .collect();
    let focus: Vec<f32> = cameras.iter().map(distance).collect();
    assert!(focus.windows(2).all(|w| w[1] >= w[0]), "{focus:?}");
    let (first, last) = (&cameras[0], &cameras[47]);
    let near = depth(first, NEAR);
    let far = depth(last, FAR);
    assert!(
        (focus[0] / near - 1.0).abs() < 0.02,
        "{} vs {near}",
        focus[0]
    );
    assert!(
        (focus[47] / far - 1.0).abs() < 0.02,
        "{} vs {far}",
        focus[47]
    );
    // The dolly: forward and a little to the right (-x, looking down +z with y up).
    assert!(last.eye.z - first.eye.z > 0.15 && last.eye.x < first.eye.x);
    for c in &cameras {
        c.build(|_| None).unwrap();
    }
}

/// Mean squared difference of neighbouring pixels' luminance in a square of half-size `r`
/// pixels around `centre`: high where the image is sharp.
fn contrast(film: &Film, centre: glam::Vec2, r: i32) -> f64 {
    let lum = |x: i32, y: i32| {
        let c = film.color[film.index(x as usize, y as usize)];
        (0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z) as f64
    };
    let (cx, cy) = (centre.x as i32, centre.y as i32);
    let (mut sum, mut n) = (0.0, 0);
    for y in cy - r..cy + r {
        for x in cx - r..cx + r {
            sum += (lum(x + 1, y) - lum(x, y)).powi(2) + (lum(x, y + 1) - lum(x, y)).powi(2);
            n += 1;
        }
    }
    sum / n as f64
}

#[test]
fn focus_pull_renders_the_near_ball_sharp_first_and_the_far_ball_last() {
    let desc = focus_pull();
    let animation = desc.animation.as_ref().unwrap();
    let device = Device::new().unwrap();
    let world = World::build(&desc, &device).unwrap();
    let frame = |f: f64| {
        let camera = at(&desc.camera, animation, f).build(|_| None).unwrap();
        let settings = RenderSettings {
            spp: 16,
            ..Default::default()
        };
        let (film, _) = render(&world, &camera, &settings, &NoProgress).unwrap();
        (camera, film)
    };
    let (first_camera, first) = frame(1.0);
    let (last_camera, last) = frame(48.0);
    // Squares inside each ball's image (both are about 70 px across).
    let near = |c: &dofray::camera::Camera| c.project(NEAR).unwrap();
    let far = |c: &dofray::camera::Camera| c.project(FAR).unwrap();
    let near_first = contrast(&first, near(&first_camera), 12);
    let near_last = contrast(&last, near(&last_camera), 12);
    let far_first = contrast(&first, far(&first_camera), 12);
    let far_last = contrast(&last, far(&last_camera), 12);
    eprintln!(
        "near ball {near_first:.5} -> {near_last:.5}; far ball {far_first:.5} -> {far_last:.5}"
    );
    assert!(near_first > 2.0 * near_last, "{near_first} {near_last}");
    assert!(far_last > 2.0 * far_first, "{far_first} {far_last}");
}

#[test]
fn frame_numbers_beyond_the_range_are_refused_even_at_the_integer_limits() {
    for frame in [
        i64::MIN,
        i64::MIN + 1,
        -1_000_000_001,
        1_000_000_001,
        i64::MAX,
    ] {
        let text = format!(
            "[animation]\n[[animation.key]]\nframe = 1\nvfov = 30\n[[animation.key]]\nframe = {frame}\nvfov = 50\n"
        );
        let err = parse(&scene(CAMERA, &text)).unwrap_err().to_string();
        assert!(
            err.contains("anim.toml") && err.contains("frame number from -1000000000"),
            "{frame}: {err}"
        );
    }
}
