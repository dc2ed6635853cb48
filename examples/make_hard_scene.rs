//! Writes `scenes/bokeh.toml`, the hard depth-of-field scene (issue 13): bright small lights and
//! speculars defocused in front of and behind an in-focus subject, fine high-contrast texture
//! under slowly growing blur, and in-focus edges against a strongly blurred background.
//!
//! ```text
//! cargo run --release --example make_hard_scene -- scenes/bokeh.toml
//! ```
//!
//! The output is deterministic: positions come from a fixed-seed hash (SplitMix64), and only
//! `+ - * /` and `sqrt` (all correctly rounded in IEEE arithmetic) are used, never `sin` or
//! `pow`, so every platform writes the same bytes. `tests/hard_scene.rs` includes this file and
//! checks that the committed scene is what [`generate`] writes.

use std::fmt::Write;

/// The generator's fixed seed.
const SEED: u64 = 0x0d0f_4a7b_0c0e_2013;

/// Camera: an 85 mm f/1.4 portrait lens on a 36 mm sensor, 640 x 480, low over a long
/// checkered ground, focused at 2 m (the CoC of a point at infinity is 48 px).
const EYE: [f64; 3] = [0.0, 0.42, -2.0];
const LOOK_AT: [f64; 3] = [0.0, 0.24, 0.0];
const FOCAL_MM: f64 = 85.0;
const F_NUMBER: f64 = 1.4;
const SENSOR_MM: f64 = 36.0;
const WIDTH: f64 = 640.0;
const HEIGHT: f64 = 480.0;

/// The subject: a polka-dot ball on the ground, and a striped post beside it whose long edges
/// stand in focus against the far, blurred lights.
const BALL: [f64; 3] = [0.15, 0.115, 0.0];
const BALL_RADIUS: f64 = 0.115;
const POST_X: f64 = -0.2;
const POST_WIDTH: f64 = 0.065;
const POST_HEIGHT: f64 = 1.2;

/// The ground quad: from `GROUND_NEAR` to `GROUND_FAR` in z, stretched `GROUND_STRETCH` times
/// in depth so that its checker cells, 1 / `CHECKER_SCALE` across, are about square in the
/// image where the view foreshortens them near the focus.
const GROUND_NEAR: f64 = -6.0;
const GROUND_FAR: f64 = 80.0;
const GROUND_WIDTH: f64 = 40.0;
const GROUND_STRETCH: f64 = 5.0;
const CHECKER_SCALE: f64 = 300.0;

/// SplitMix64: a tiny, fixed, well-mixed sequence.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[(self.next_u64() % items.len() as u64) as usize]
    }
}

type V = [f64; 3];

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn mul(a: V, s: f64) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: V) -> V {
    mul(a, 1.0 / dot(a, a).sqrt())
}

/// The view: unit forward, right and up vectors, and the tangents of the half fields of view.
struct View {
    forward: V,
    right: V,
    up: V,
    tan_x: f64,
    tan_y: f64,
    /// Pixels per unit of image-plane tangent (focal length in pixels).
    focal_px: f64,
    /// Depth (along the view axis) in focus.
    focus: f64,
    /// CoC diameter in pixels of a point at infinite depth.
    coc_inf: f64,
}

impl View {
    fn new() -> Self {
        let forward = normalize(sub(LOOK_AT, EYE));
        let right = normalize(cross(forward, [0.0, 1.0, 0.0]));
        let up = cross(right, forward);
        let tan_x = SENSOR_MM / 2.0 / FOCAL_MM;
        let focal_px = WIDTH / 2.0 / tan_x;
        let focus = dot(sub(BALL, EYE), forward);
        // Thin lens: CoC = A f / (P - f) * |D - P| / D on the sensor (A the aperture diameter).
        let (f, a) = (FOCAL_MM / 1000.0, FOCAL_MM / 1000.0 / F_NUMBER);
        let coc_inf = a * f / (focus - f) / (SENSOR_MM / 1000.0) * WIDTH;
        Self {
            forward,
            right,
            up,
            tan_x,
            tan_y: tan_x * HEIGHT / WIDTH,
            focal_px,
            focus,
            coc_inf,
        }
    }

    /// The point at view depth `depth` seen at screen position (sx, sy), each -1 at the
    /// left / bottom edge and 1 at the right / top edge.
    fn at(&self, sx: f64, sy: f64, depth: f64) -> V {
        let d = add(
            self.forward,
            add(
                mul(self.right, sx * self.tan_x),
                mul(self.up, sy * self.tan_y),
            ),
        );
        add(EYE, mul(d, depth))
    }

    fn depth(&self, p: V) -> f64 {
        dot(sub(p, EYE), self.forward)
    }

    fn coc_px(&self, depth: f64) -> f64 {
        self.coc_inf * (depth - self.focus).abs() / depth
    }

    /// The radius that makes a sphere at `depth` about `px` pixels across in a pinhole image.
    fn radius_for(&self, px: f64, depth: f64) -> f64 {
        px * depth / (2.0 * self.focal_px)
    }
}

/// A number as the scene file shows it: at most `digits` decimals, trailing zeros dropped.
fn num(x: f64, digits: usize) -> String {
    let s = format!("{x:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

fn vec3(v: V, digits: usize) -> String {
    format!(
        "[{}, {}, {}]",
        num(v[0], digits),
        num(v[1], digits),
        num(v[2], digits)
    )
}

/// Light colours (linear, brightest component 1): warm white, amber, sodium, cyan, rose,
/// cool white.
const PALETTE: [V; 6] = [
    [1.0, 0.86, 0.66],
    [1.0, 0.62, 0.22],
    [1.0, 0.45, 0.1],
    [0.35, 0.85, 1.0],
    [1.0, 0.4, 0.55],
    [0.8, 0.9, 1.0],
];

/// An emissive sphere: a lamp whose bokeh disc is about `brightness` (linear) on average.
struct Lamp {
    center: V,
    radius: f64,
    emission: V,
    /// Pinhole diameter and CoC in pixels, for the comment.
    size_px: f64,
    coc_px: f64,
}

/// A lamp at `center`, `ratio` of its CoC across (but at least 3 px), whose disc has the mean
/// radiance `brightness` times `colour`.
fn lamp(view: &View, center: V, ratio: f64, brightness: f64, colour: V) -> Lamp {
    let depth = view.depth(center);
    let coc = view.coc_px(depth);
    let size_px = (coc * ratio).max(3.0);
    let radius = view.radius_for(size_px, depth);
    // The disc spreads the lamp's image over the CoC: its mean is the emission times the
    // ratio of the areas (the lamp's image fills the disc when it is larger).
    let spread = if coc > size_px {
        (coc / size_px) * (coc / size_px)
    } else {
        1.0
    };
    Lamp {
        center,
        radius,
        emission: mul(colour, brightness * spread),
        size_px,
        coc_px: coc,
    }
}

/// The scene file's text.
pub fn generate() -> String {
    let view = View::new();
    let mut rng = Rng(SEED);

    // Lamps (emissive spheres), each with its own material.
    let mut lamps: Vec<(Lamp, &str)> = Vec::new();
    // A string of fairy lights sagging across the top of the frame, close to the lens.
    for i in 0..9 {
        let t = i as f64 / 8.0;
        let sx = -1.1 + 2.2 * t;
        let sag = 4.0 * t * (1.0 - t);
        let depth = rng.range(0.75, 0.95);
        let p = view.at(sx + rng.range(-0.04, 0.04), 0.93 - 0.4 * sag, depth);
        let colour = *rng.pick(&PALETTE);
        let ratio = rng.range(0.12, 0.18);
        lamps.push((lamp(&view, p, ratio, 0.45, colour), "front, fairy light"));
    }
    // Loose lamps near the lens, low in the frame, over the ground and the subject's base.
    for _ in 0..5 {
        let depth = rng.range(0.6, 1.3);
        let p = view.at(rng.range(-1.05, 1.05), rng.range(-1.0, -0.3), depth);
        let colour = *rng.pick(&PALETTE);
        let ratio = rng.range(0.12, 0.18);
        lamps.push((lamp(&view, p, ratio, 0.4, colour), "front"));
    }
    // Far lamps behind the subject, above the ground, denser towards the horizon.
    let mut far = 0;
    while far < 36 {
        let u = rng.range(0.0, 1.0);
        let depth = 4.5 + 30.0 * u * u;
        let p = view.at(rng.range(-1.1, 1.1), rng.range(-0.3, 1.1), depth);
        let colour = *rng.pick(&PALETTE);
        let ratio = rng.range(0.12, 0.18);
        let brightness = rng.range(0.3, 0.8);
        if p[1] < 0.1 {
            continue;
        }
        lamps.push((lamp(&view, p, ratio, brightness, colour), "far"));
        far += 1;
    }
    // Two far lamps seen exactly behind the post's left edge and the ball's right outline:
    // discs cut by an in-focus edge.
    let behind = |p: V, depth: f64| add(EYE, mul(sub(p, EYE), depth / view.depth(p)));
    let post_edge = [POST_X - POST_WIDTH / 2.0, 0.5, BALL[2] + 0.03];
    lamps.push((
        lamp(&view, behind(post_edge, 9.0), 0.15, 0.8, PALETTE[0]),
        "far, behind the post's edge",
    ));
    // The ball's outline (as the eye sees it) towards its upper left in the image (world +x
    // is image left); near enough that the line of sight meets the lamp before the ground.
    let d = normalize(sub(BALL, EYE));
    let v = [0.7, 1.0, 0.0];
    let u = normalize(sub(v, mul(d, dot(v, d))));
    let ball_edge = add(BALL, mul(u, BALL_RADIUS));
    lamps.push((
        lamp(&view, behind(ball_edge, 3.8), 0.2, 0.8, PALETTE[3]),
        "far, behind the ball's outline",
    ));

    // Chrome balls: speculars of the point lights and reflections of the lamps. Two hang in
    // front of the lens, five stand on the ground behind the subject.
    let mut chrome = Vec::new();
    for (sx, sy, depth, px) in [(-0.72, -0.5, 1.0, 34.0), (0.78, 0.25, 1.15, 28.0)] {
        chrome.push((view.at(sx, sy, depth), view.radius_for(px, depth)));
    }
    for _ in 0..5 {
        let depth = rng.range(3.0, 8.0);
        let r = rng.range(0.04, 0.1);
        let p = view.at(rng.range(-0.9, 0.9), 0.0, depth);
        chrome.push(([p[0], r, p[2]], r));
    }

    let coc = |keep: &dyn Fn(f64) -> bool| {
        let cocs: Vec<f64> = lamps
            .iter()
            .filter(|(l, _)| keep(view.depth(l.center)))
            .map(|(l, _)| l.coc_px)
            .collect();
        let lo = cocs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = cocs.iter().copied().fold(0.0, f64::max);
        format!("{} to {}", num(lo, 0), num(hi, 0))
    };
    let (focus, in_front, behind_focus) = (
        view.focus,
        coc(&|d| d < view.focus),
        coc(&|d| d > view.focus),
    );
    // Where the ground meets the bottom of the image, and its blur there.
    let bottom = view.at(0.0, -1.0, 1.0);
    let ground_bottom = view.depth(add(
        EYE,
        mul(sub(bottom, EYE), EYE[1] / (EYE[1] - bottom[1])),
    ));

    let mut s = String::new();
    let w = &mut s;
    writeln!(
        w,
        "\
# GENERATED by examples/make_hard_scene.rs; do not edit by hand. Regenerate with
#   cargo run --release --example make_hard_scene -- scenes/bokeh.toml
# (tests/hard_scene.rs checks that this file is exactly what the generator writes).
#
# A hard depth-of-field scene (issue 13), at night: an 85 mm f/1.4 lens focused at {focus} m
# on a polka-dot ball beside a striped post, over a fine checkered ground. It tests
# - bokeh: small bright lamps (emissive spheres, 1/8 to 1/5.5 of their CoC across) and chrome-ball
#   speculars, defocused in front of the subject (CoC {in_front} px) and behind it (CoC
#   {behind_focus} px): round discs with hard rims, two of them cut by an in-focus edge;
# - fine high-contrast texture under slowly growing blur: the ground's checker has a period of
#   about 5 px where it is in focus; its blur grows from 0 at the ball's foot to {bottom_coc} px at the
#   bottom of the image and {coc_inf} px at the horizon;
# - in-focus edges (the post, the ball's outline) against a strongly blurred background of
#   lamps and a far wall of lit windows.
# Only the lamps' own pixels (and a lit window behind the camera that the chrome balls reflect)
# glow: the path tracer samples them as lights, with three point lights and a dim moon.",
        focus = num(focus, 2),
        bottom_coc = num(view.coc_px(ground_bottom), 0),
        coc_inf = num(view.coc_inf, 0),
    )
    .unwrap();

    writeln!(
        w,
        r#"
name = "bokeh"
ambient = 0.02

[image]
width = {width}
height = {height}

[render]
spp = 16

[camera]
eye = {eye}
look_at = {look_at}
f_number = {f_number}
focal_length_mm = {focal}
sensor_width_mm = {sensor}
focus_point = {focus_point}

[background]
horizon = [0.025, 0.0225, 0.03]
zenith = [0.003, 0.005, 0.015]

[[lights]]
type = "point"
position = [-1.1, 1.6, -1.3]
intensity = [8.482, 7.854, 6.912]

[[lights]]
type = "point"
position = [1.5, 1.1, 2.3]
intensity = [4.084, 5.655, 8.482]

[[lights]]
type = "point"
position = [-1.7, 1.7, 6]
intensity = [11.31, 8.482, 5.655]

[[lights]]
type = "directional"
direction = [0.3, -1, 0.5]
irradiance = [0.1257, 0.1571, 0.2513]

[[textures]]
name = "ground"
pattern = "checker"
a = [0.85, 0.8, 0.7]
b = 0.03
scale = {checker}

[[textures]]
name = "dots"
pattern = "dots"
a = [0.9, 0.86, 0.78]
b = [0.7, 0.06, 0.05]
scale = 12

[[textures]]
name = "post"
pattern = "stripes"
a = [0.92, 0.92, 0.9]
b = [0.04, 0.05, 0.08]
scale = 75

[[textures]]
name = "windows"
pattern = "grid"
a = [0.08, 0.08, 0.1]
b = [0.9, 0.75, 0.45]
scale = 0.5

[[materials]]
name = "ground"
texture = "ground"
roughness = 0.50

[[materials]]
name = "ball"
texture = "dots"
roughness = 0.36

[[materials]]
name = "post"
texture = "post"
roughness = 0.47

[[materials]]
name = "wall"
texture = "windows"

[[materials]]
name = "lightbox"
diffuse = 0
emission = [36, 30, 23]

[[materials]]
name = "chrome"
diffuse = 0.9
metallic = 0.85
roughness = 0.05
"#,
        width = WIDTH,
        height = HEIGHT,
        eye = vec3(EYE, 3),
        look_at = vec3(LOOK_AT, 3),
        f_number = F_NUMBER,
        focal = FOCAL_MM,
        sensor = SENSOR_MM,
        focus_point = vec3(BALL, 3),
        checker = num(CHECKER_SCALE, 3),
    )
    .unwrap();

    for (i, (l, _)) in lamps.iter().enumerate() {
        writeln!(
            w,
            "[[materials]]\nname = \"lamp{i}\"\ndiffuse = 0\nemission = {}\n",
            vec3(l.emission, 2)
        )
        .unwrap();
    }

    let length = GROUND_FAR - GROUND_NEAR;
    writeln!(
        w,
        r#"# The ground: {width} m wide, from z = {near} to z = {far}; stretched {stretch}x in depth, so
# its UVs, hence its checker cells, are {stretch}x longer in z.
[[objects]]
type = "quad"
center = [0, 0, {center}]
size = [{width}, {depth}]
scale = [1, 1, {stretch}]
material = "ground"

# A lit window behind the camera (out of view): the chrome balls reflect it.
[[objects]]
type = "quad"
size = [4, 2]
rotate = [90, 0, 0]
translate = [0.3, 2, -5.5]
material = "lightbox"

# A far wall of lit windows, 60 m ahead, facing the camera.
[[objects]]
type = "quad"
size = [120, 24]
rotate = [-90, 0, 0]
translate = [0, 12, 60]
material = "wall"

# The subject (in focus).
[[objects]]
type = "sphere"
center = {ball}
radius = {ball_r}
material = "ball"

[[objects]]
type = "quad"
size = [{post_w}, {post_h}]
rotate = [-90, 0, 0]
translate = [{post_x}, {post_y}, {post_z}]
material = "post"
"#,
        width = num(GROUND_WIDTH, 3),
        near = num(GROUND_NEAR, 3),
        far = num(GROUND_FAR, 3),
        stretch = num(GROUND_STRETCH, 3),
        center = num((GROUND_NEAR + length / 2.0) / GROUND_STRETCH, 4),
        depth = num(length / GROUND_STRETCH, 4),
        ball = vec3(BALL, 3),
        ball_r = num(BALL_RADIUS, 4),
        post_w = num(POST_WIDTH, 4),
        post_h = num(POST_HEIGHT, 3),
        post_x = num(POST_X, 4),
        post_y = num(POST_HEIGHT / 2.0, 4),
        post_z = num(BALL[2] + 0.03, 3),
    )
    .unwrap();

    writeln!(w, "# Chrome balls (specular bokeh).").unwrap();
    for (c, r) in &chrome {
        writeln!(
            w,
            "[[objects]]\ntype = \"sphere\"\ncenter = {}\nradius = {}\nmaterial = \"chrome\"\n",
            vec3(*c, 3),
            num(*r, 4)
        )
        .unwrap();
    }

    writeln!(w, "# Lamps (emissive spheres).").unwrap();
    for (i, (l, what)) in lamps.iter().enumerate() {
        writeln!(
            w,
            "# {what}: {} px across, CoC {} px\n[[objects]]\ntype = \"sphere\"\ncenter = {}\n\
             radius = {}\nmaterial = \"lamp{i}\"\n",
            num(l.size_px, 0),
            num(l.coc_px, 0),
            vec3(l.center, 3),
            num(l.radius, 5)
        )
        .unwrap();
    }
    while s.ends_with("\n\n") {
        s.pop();
    }
    s
}

#[allow(dead_code)]
fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "scenes/bokeh.toml".into());
    let text = generate();
    if let Err(e) = std::fs::write(&path, &text) {
        eprintln!("error: cannot write {path}: {e}");
        std::process::exit(1);
    }
    eprintln!("wrote {path} ({} bytes)", text.len());
}
