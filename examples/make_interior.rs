//! Writes `scenes/interior.toml`, a path-traced interior for depth-of-field benchmarks: a
//! 5 m x 4 m x 2.7 m room lit by the sun and the sky through a window and by a ceiling panel,
//! with a table of spheres (glossy, diffuse, metal, glass) in focus at mid distance, a chair
//! and a pendant lamp defocused in front of it and the far walls, a picture and a wall lamp
//! defocused behind it.
//!
//! ```text
//! cargo run --release --example make_interior -- scenes/interior.toml
//! ```
//!
//! The output is deterministic: the layout is fixed and only `+ - * /` and `sqrt` (correctly
//! rounded in IEEE arithmetic) are used, never `sin` or `pow`, so every platform writes the
//! same bytes. `tests/interior_scene.rs` includes this file and checks that the committed scene
//! is what [`generate`] writes.

use std::fmt::Write;

type V = [f64; 3];

/// The room: x from -`ROOM_X` to `ROOM_X`, z from -`ROOM_Z` to `ROOM_Z`, floor at y = 0.
const ROOM_X: f64 = 2.5;
const ROOM_Z: f64 = 2.0;
const ROOM_H: f64 = 2.7;

/// The window in the left wall (x = -`ROOM_X`): its opening's z and y ranges.
const WINDOW_Z: [f64; 2] = [-1.7, 0.1];
const WINDOW_Y: [f64; 2] = [0.7, 2.3];
/// Width (and depth) of the window's frame bars.
const MULLION: f64 = 0.05;

/// The table: its top's centre (x, z), size (x, z), thickness and the height of its top
/// surface, and its legs' width.
const TABLE: [f64; 2] = [-0.5, -0.05];
const TABLE_SIZE: [f64; 2] = [0.8, 0.8];
const TABLE_TOP: f64 = 0.75;
const TABLE_THICK: f64 = 0.04;
const LEG: f64 = 0.05;

/// Camera: a 50 mm f/2 lens on a 36 mm sensor, 640 x 480, standing in the room's front half
/// and looking past the table towards the far left corner (the window on the left, the far
/// wall on the right), focused on the glossy sphere on the table.
const EYE: V = [0.35, 1.05, 1.45];
const LOOK_AT: V = [-0.5, 0.9, -0.05];
const FOCAL_MM: f64 = 50.0;
const F_NUMBER: f64 = 2.0;
const SENSOR_MM: f64 = 36.0;
const WIDTH: f64 = 640.0;
const HEIGHT: f64 = 480.0;

/// The spheres on the table, (x, z) offsets from its centre and radius.
const GLOSSY: ([f64; 2], f64) = ([0.1, 0.12], 0.08);
const GLASS: ([f64; 2], f64) = ([0.25, 0.27], 0.06);
const METAL: ([f64; 2], f64) = ([-0.22, -0.05], 0.07);
const DIFFUSE: ([f64; 2], f64) = ([0.22, -0.18], 0.07);

/// A large rough ball on the floor behind the table (seen under it).
const FLOOR_BALL: V = [-1.3, 0.25, -1.5];
const FLOOR_BALL_R: f64 = 0.25;

/// A pendant lamp hanging close to the lens, at this screen position (-1 to 1, left to right
/// and bottom to top) and depth; and a wall lamp on the far wall.
const PENDANT_SCREEN: [f64; 3] = [-0.55, 0.55, 0.65];
const PENDANT_R: f64 = 0.01;
const SCONCE: V = [-0.45, 1.6, -1.88];
const SCONCE_R: f64 = 0.05;

/// A picture on the far wall: its centre and size (x, y).
const PICTURE: V = [-1.25, 1.38, -ROOM_Z];
const PICTURE_SIZE: [f64; 2] = [0.7, 0.5];

/// A chair in the near foreground, its back towards the camera: the top of its back's left
/// post is seen at this screen position (lower right); the seat's height and size, the
/// thickness of its posts and the height of its back.
const CHAIR_SCREEN: [f64; 2] = [0.72, -0.4];
const CHAIR_SEAT: f64 = 0.46;
const CHAIR_SIZE: f64 = 0.44;
const CHAIR_POST: f64 = 0.04;
const CHAIR_BACK: f64 = 0.92;

/// Lights: the sun's direction (travelling into the room through the window) and
/// irradiance (W/m^2), the sky's radiance, and the ceiling panel (behind and above the
/// camera, out of view): its centre, size and power (W).
const SUN_DIRECTION: V = [1.0, -0.75, 0.55];
const SUN_IRRADIANCE: f64 = 5.0;
const SKY: V = [0.5, 0.6, 0.8];
const PANEL: V = [0.7, ROOM_H - 0.01, 0.6];
const PANEL_SIZE: [f64; 2] = [0.6, 0.6];
const PANEL_POWER: f64 = 60.0;

fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn mul(a: V, s: f64) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: V) -> V {
    mul(a, 1.0 / dot(a, a).sqrt())
}

/// The thin lens, as dofray models it: the view's frame, and CoC diameters in pixels.
struct View {
    forward: V,
    right: V,
    up: V,
    /// Tangents of the half fields of view.
    tan_x: f64,
    tan_y: f64,
    /// Depth (along the view axis) in focus.
    focus: f64,
    /// Aperture diameter times the focal length in pixels: CoC = this x |1/focus - 1/depth|.
    coc_scale: f64,
}

impl View {
    fn new() -> Self {
        let forward = normalize(sub(LOOK_AT, EYE));
        let right = normalize(cross(forward, [0.0, 1.0, 0.0]));
        let up = cross(right, forward);
        let focus = dot(sub(focus_point(), EYE), forward);
        let aperture = FOCAL_MM / 1000.0 / F_NUMBER;
        let tan_x = SENSOR_MM / 2.0 / FOCAL_MM;
        Self {
            forward,
            right,
            up,
            tan_x,
            tan_y: tan_x * HEIGHT / WIDTH,
            focus,
            coc_scale: aperture * WIDTH / 2.0 / tan_x,
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

    fn coc_px(&self, p: V) -> f64 {
        self.coc_scale * (1.0 / self.focus - 1.0 / self.depth(p)).abs()
    }

    fn coc_inf(&self) -> f64 {
        self.coc_scale / self.focus
    }
}

/// The chair's seat centre (x, z): its back's left post stands at `CHAIR_SCREEN`.
fn chair() -> [f64; 2] {
    let view = View::new();
    let [sx, sy] = CHAIR_SCREEN;
    let ray = sub(view.at(sx, sy, 1.0), EYE);
    let p = add(EYE, mul(ray, (CHAIR_BACK - EYE[1]) / ray[1]));
    let h = (CHAIR_SIZE - CHAIR_POST) / 2.0;
    [p[0] + h, p[2] - h]
}

/// Where the pendant lamp hangs.
fn pendant() -> V {
    let [sx, sy, depth] = PENDANT_SCREEN;
    View::new().at(sx, sy, depth)
}

/// The centre of a sphere of radius `r` resting on the table at offset `at`.
fn on_table(at: [f64; 2], r: f64) -> V {
    [TABLE[0] + at[0], TABLE_TOP + r, TABLE[1] + at[1]]
}

/// The point in focus: the glossy sphere's centre.
fn focus_point() -> V {
    on_table(GLOSSY.0, GLOSSY.1)
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

fn vec3(v: V) -> String {
    format!("[{}, {}, {}]", num(v[0], 4), num(v[1], 4), num(v[2], 4))
}

/// The objects section of the file.
struct Objects(String);

impl Objects {
    fn comment(&mut self, text: &str) {
        writeln!(self.0, "# {text}").unwrap();
    }

    /// A horizontal quad (facing +y) centred at `c`, `size` along x and z.
    fn flat(&mut self, c: V, size: [f64; 2], material: &str) {
        writeln!(
            self.0,
            "[[objects]]\ntype = \"quad\"\ncenter = {}\nsize = [{}, {}]\nmaterial = \"{material}\"\n",
            vec3(c),
            num(size[0], 4),
            num(size[1], 4)
        )
        .unwrap();
    }

    /// A quad in the plane z = `c[2]` (rotated 90 degrees about x), `size` along x and y.
    fn facing_z(&mut self, c: V, size: [f64; 2], material: &str) {
        self.rotated([90.0, 0.0, 0.0], c, size, material);
    }

    /// A quad in the plane x = `c[0]` (rotated 90 degrees about z), `size` along y and z.
    fn facing_x(&mut self, c: V, size: [f64; 2], material: &str) {
        self.rotated([0.0, 0.0, 90.0], c, size, material);
    }

    fn rotated(&mut self, rotate: V, c: V, size: [f64; 2], material: &str) {
        writeln!(
            self.0,
            "[[objects]]\ntype = \"quad\"\nsize = [{}, {}]\nrotate = {}\ntranslate = {}\n\
             material = \"{material}\"\n",
            num(size[0], 4),
            num(size[1], 4),
            vec3(rotate),
            vec3(c)
        )
        .unwrap();
    }

    /// An axis-aligned box of quads centred at `c` with sides `s`; `ends`: with its top and
    /// bottom faces (a leg standing on the floor needs neither).
    fn cuboid(&mut self, c: V, s: V, ends: bool, material: &str) {
        let h = mul(s, 0.5);
        if ends {
            self.flat([c[0], c[1] + h[1], c[2]], [s[0], s[2]], material);
            self.flat([c[0], c[1] - h[1], c[2]], [s[0], s[2]], material);
        }
        for side in [-1.0, 1.0] {
            self.facing_z([c[0], c[1], c[2] + side * h[2]], [s[0], s[1]], material);
            self.facing_x([c[0] + side * h[0], c[1], c[2]], [s[1], s[2]], material);
        }
    }

    fn sphere(&mut self, c: V, r: f64, material: &str) {
        writeln!(
            self.0,
            "[[objects]]\ntype = \"sphere\"\ncenter = {}\nradius = {}\nmaterial = \"{material}\"\n",
            vec3(c),
            num(r, 4)
        )
        .unwrap();
    }
}

/// The room's walls, floor and ceiling, the window's frame, and the furniture.
fn objects() -> String {
    let mut o = Objects(String::new());
    let (x, z, h) = (ROOM_X, ROOM_Z, ROOM_H);

    o.comment("The room: floor, ceiling, the far wall (z = -2, terracotta), the wall behind the");
    o.comment("camera (z = 2) and the right wall (x = 2.5).");
    o.flat([0.0, 0.0, 0.0], [2.0 * x, 2.0 * z], "floor");
    o.flat([0.0, h, 0.0], [2.0 * x, 2.0 * z], "ceiling");
    o.facing_z([0.0, h / 2.0, -z], [2.0 * x, h], "accent");
    o.facing_z([0.0, h / 2.0, z], [2.0 * x, h], "wall");
    o.facing_x([x, h / 2.0, 0.0], [h, 2.0 * z], "wall");

    let [z0, z1] = WINDOW_Z;
    let [y0, y1] = WINDOW_Y;
    o.comment("The left wall (x = -2.5): four quads around the window's opening.");
    o.facing_x([-x, y0 / 2.0, 0.0], [y0, 2.0 * z], "wall");
    o.facing_x([-x, (y1 + h) / 2.0, 0.0], [h - y1, 2.0 * z], "wall");
    o.facing_x(
        [-x, (y0 + y1) / 2.0, (z0 - z) / 2.0],
        [y1 - y0, z0 + z],
        "wall",
    );
    o.facing_x(
        [-x, (y0 + y1) / 2.0, (z1 + z) / 2.0],
        [y1 - y0, z - z1],
        "wall",
    );

    o.comment("The window's cross bars (their shadows stripe the sunlit patch).");
    let (m, mz, my) = (MULLION, (z0 + z1) / 2.0, y0 + 0.62 * (y1 - y0));
    o.cuboid([-x, (y0 + y1) / 2.0, mz], [m, y1 - y0, m], true, "frame");
    o.cuboid([-x, my, mz], [m, m, z1 - z0], true, "frame");

    o.comment("A picture on the far wall: a frame and its canvas.");
    let [px, py, pz] = PICTURE;
    let [pw, ph] = PICTURE_SIZE;
    o.cuboid(
        [px, py, pz + 0.015],
        [pw + 0.06, ph + 0.06, 0.03],
        true,
        "frame",
    );
    o.facing_z([px, py, pz + 0.031], [pw, ph], "canvas");

    o.comment("The ceiling light's housing, a thin box around the panel.");
    o.cuboid(
        [PANEL[0], h - 0.005, PANEL[2]],
        [PANEL_SIZE[0] + 0.04, 0.008, PANEL_SIZE[1] + 0.04],
        false,
        "frame",
    );

    o.comment("The table: a top and four legs.");
    let (tx, tz) = (TABLE[0], TABLE[1]);
    let [sx, sz] = TABLE_SIZE;
    o.cuboid(
        [tx, TABLE_TOP - TABLE_THICK / 2.0, tz],
        [sx, TABLE_THICK, sz],
        true,
        "wood",
    );
    let leg_h = TABLE_TOP - TABLE_THICK;
    for (dx, dz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let c = [
            tx + dx * (sx / 2.0 - 0.08),
            leg_h / 2.0,
            tz + dz * (sz / 2.0 - 0.08),
        ];
        o.cuboid(c, [LEG, leg_h, LEG], false, "wood");
    }

    o.comment("A chair in the near foreground: seat, legs, back posts and a back rail.");
    let [cx, cz] = chair();
    let cs = CHAIR_SIZE;
    o.cuboid([cx, CHAIR_SEAT - 0.02, cz], [cs, 0.04, cs], true, "chair");
    let post = CHAIR_POST;
    for (dx, dz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let px = cx + dx * (cs - post) / 2.0;
        let pz = cz + dz * (cs - post) / 2.0;
        // The back (towards +z, the camera) legs run up into the back posts.
        let top = if dz > 0.0 {
            CHAIR_BACK
        } else {
            CHAIR_SEAT - 0.04
        };
        o.cuboid([px, top / 2.0, pz], [post, top, post], dz > 0.0, "chair");
    }
    o.cuboid(
        [cx, CHAIR_BACK - 0.07, cz + (cs - post) / 2.0],
        [cs - 2.0 * post, 0.1, 0.025],
        true,
        "chair",
    );

    o.comment("The pendant lamp's cord.");
    let pendant = pendant();
    let cord_bottom = pendant[1] + PENDANT_R;
    o.cuboid(
        [pendant[0], (cord_bottom + h) / 2.0, pendant[2]],
        [0.008, h - cord_bottom, 0.008],
        false,
        "cord",
    );

    o.comment("Spheres on the table: glossy (the focus), diffuse, metal and glass.");
    o.sphere(focus_point(), GLOSSY.1, "glossy");
    o.sphere(on_table(DIFFUSE.0, DIFFUSE.1), DIFFUSE.1, "clay");
    o.sphere(on_table(METAL.0, METAL.1), METAL.1, "metal");
    o.sphere(on_table(GLASS.0, GLASS.1), GLASS.1, "glass");
    o.comment("A rough ball on the floor, the pendant lamp and the far wall's lamp.");
    o.sphere(FLOOR_BALL, FLOOR_BALL_R, "ball");
    o.sphere(pendant, PENDANT_R, "lamp");
    o.sphere(SCONCE, SCONCE_R, "lamp");

    let mut s = o.0;
    while s.ends_with("\n\n") {
        s.pop();
    }
    s
}

/// The scene file's text.
pub fn generate() -> String {
    let view = View::new();
    let [cx, cz] = chair();
    let h = (CHAIR_SIZE - CHAIR_POST) / 2.0;
    let chair_corner = [cx - h, CHAIR_BACK, cz + h];
    let far_corner = [-ROOM_X, 1.0, -ROOM_Z];
    let mut s = String::new();
    let w = &mut s;
    writeln!(
        w,
        "\
# GENERATED by examples/make_interior.rs; do not edit by hand. Regenerate with
#   cargo run --release --example make_interior -- scenes/interior.toml
# (tests/interior_scene.rs checks that this file is exactly what the generator writes).
#
# A path-traced interior for depth-of-field benchmarks: a 5 m x 4 m x 2.7 m room (y up,
# metres) lit by the sun ({sun} W/m^2) and a blue sky coming in through a window in the left
# wall, and by a {panel} W ceiling panel behind the camera. Most surfaces in view are lit by
# light that has bounced off the walls and floor (the terracotta far wall tints the room);
# the sun lights a patch of the table (hard shadows), the panel gives soft ones. Glossy,
# diffuse, metal and glass spheres stand on the table; two small lamps (emissive spheres) and
# the window give bokeh. A 50 mm f/2 lens focused at {focus} m on the glossy (blue) sphere;
# depths along the view axis and CoC diameters (640 x 480):
# - pendant lamp {d_pendant} m: {c_pendant} px; chair back {d_chair} m: {c_chair} px (in front);
# - metal sphere {d_metal} m: {c_metal} px; floor ball {d_ball} m: {c_ball} px;
# - far corner {d_far} m: {c_far} px; wall lamp {d_sconce} m: {c_sconce} px; infinity
#   (the sky through the window): {c_inf} px.",
        sun = num(SUN_IRRADIANCE, 2),
        panel = num(PANEL_POWER, 1),
        focus = num(view.focus, 2),
        d_pendant = num(view.depth(pendant()), 2),
        c_pendant = num(view.coc_px(pendant()), 0),
        d_chair = num(view.depth(chair_corner), 2),
        c_chair = num(view.coc_px(chair_corner), 0),
        d_metal = num(view.depth(on_table(METAL.0, METAL.1)), 2),
        c_metal = num(view.coc_px(on_table(METAL.0, METAL.1)), 0),
        d_ball = num(view.depth(FLOOR_BALL), 2),
        c_ball = num(view.coc_px(FLOOR_BALL), 0),
        d_far = num(view.depth(far_corner), 2),
        c_far = num(view.coc_px(far_corner), 0),
        d_sconce = num(view.depth(SCONCE), 2),
        c_sconce = num(view.coc_px(SCONCE), 0),
        c_inf = num(view.coc_inf(), 0),
    )
    .unwrap();

    writeln!(
        w,
        r#"
name = "interior"

[image]
width = {width}
height = {height}

[render]
clamp_indirect = 10

[camera]
eye = {eye}
look_at = {look_at}
f_number = {f_number}
focal_length_mm = {focal}
sensor_width_mm = {sensor}
focus_point = {focus_point}

[world]
color = {sky}
strength = 1

[[lights]]
type = "directional"
direction = {sun_dir}
irradiance = {sun}
color = [1, 0.93, 0.82]

[[lights]]
type = "rect"
position = {panel}
direction = [0, -1, 0]
size = [{panel_w}, {panel_d}]
power = {power}
color = [1, 0.95, 0.88]

[[textures]]
name = "tiles"
pattern = "checker"
a = [0.72, 0.66, 0.56]
b = [0.34, 0.27, 0.21]
scale = 2.5

[[textures]]
name = "canvas"
pattern = "marble"
a = [0.82, 0.8, 0.72]
b = [0.1, 0.22, 0.36]
scale = 5

[[materials]]
name = "canvas"
texture = "canvas"

[[materials]]
name = "floor"
texture = "tiles"
roughness = 0.35

[[materials]]
name = "wall"
diffuse = [0.78, 0.76, 0.72]

[[materials]]
name = "ceiling"
diffuse = 0.82

[[materials]]
name = "accent"
diffuse = [0.6, 0.25, 0.14]

[[materials]]
name = "frame"
diffuse = 0.85
roughness = 0.5

[[materials]]
name = "wood"
diffuse = [0.42, 0.25, 0.13]
roughness = 0.45

[[materials]]
name = "chair"
diffuse = [0.2, 0.11, 0.06]
roughness = 0.55

[[materials]]
name = "cord"
diffuse = 0.05

[[materials]]
name = "glossy"
diffuse = [0.08, 0.2, 0.6]
roughness = 0.3

[[materials]]
name = "clay"
diffuse = [0.75, 0.55, 0.12]

[[materials]]
name = "metal"
diffuse = [1, 0.8, 0.5]
metallic = 1
roughness = 0.15

[[materials]]
name = "glass"
diffuse = 1
transmission = 1
ior = 1.5
roughness = 0

[[materials]]
name = "ball"
diffuse = [0.55, 0.6, 0.62]

[[materials]]
name = "lamp"
diffuse = 0
emission = [14, 11, 7]
"#,
        width = WIDTH,
        height = HEIGHT,
        eye = vec3(EYE),
        look_at = vec3(LOOK_AT),
        f_number = num(F_NUMBER, 2),
        focal = num(FOCAL_MM, 1),
        sensor = num(SENSOR_MM, 1),
        focus_point = vec3(focus_point()),
        sky = vec3(SKY),
        sun_dir = vec3(SUN_DIRECTION),
        sun = num(SUN_IRRADIANCE, 3),
        panel = vec3(PANEL),
        panel_w = num(PANEL_SIZE[0], 3),
        panel_d = num(PANEL_SIZE[1], 3),
        power = num(PANEL_POWER, 1),
    )
    .unwrap();
    s.push_str(&objects());
    s
}

#[allow(dead_code)]
fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "scenes/interior.toml".into());
    let text = generate();
    if let Err(e) = std::fs::write(&path, &text) {
        eprintln!("error: cannot write {path}: {e}");
        std::process::exit(1);
    }
    eprintln!("wrote {path} ({} bytes)", text.len());
}
