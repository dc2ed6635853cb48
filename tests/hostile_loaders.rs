//! Issue 12, hostile and extreme input (loaders and resources): tiny files that would expand
//! into huge work, special files, wrapping indices, escapes in names, paths outside the model.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use dofray::scene::{self, LoadError, LoadOptions, Object, SceneDesc};

use crate::scratch::Scratch;

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("hostile-{name}"))
}

fn load(path: &Path) -> Result<SceneDesc, LoadError> {
    scene::load(path.to_str().unwrap())
}

fn load_with(path: &Path, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    scene::load_with(path.to_str().unwrap(), options)
}

fn error(path: &Path) -> String {
    match load(path) {
        Ok(_) => panic!("{}: expected an error", path.display()),
        Err(e) => e.to_string(),
    }
}

fn assert_contains(message: &str, parts: &[&str]) {
    for p in parts {
        assert!(message.contains(p), "message lacks {p:?}: {message}");
    }
}

/// Runs `f`, which must finish well within `limit`.
fn quick<T>(limit: Duration, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    let took = start.elapsed();
    assert!(took < limit, "took {took:?} (limit {limit:?})");
    out
}

const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

// ---------------------------------------------------------------------------------------------
// 1. Unbounded resources from tiny files.

#[test]
fn a_face_repeating_its_corners_loads_in_linear_time_as_one_triangle() {
    let dir = scratch("big-face");
    let mut obj = String::from(TRIANGLE);
    obj.push('f');
    for _ in 0..300_000 {
        obj.push_str(" 1 2 3");
    }
    obj.push('\n');
    let path = dir.join("face.obj");
    std::fs::write(&path, obj).unwrap();
    let desc = quick(Duration::from_millis(900), || load(&path).unwrap());
    // The fan repeats one triangle and makes degenerate ones: one triangle is left, so rays
    // do not test 300,000 coincident triangles each.
    let Object::Mesh { mesh, .. } = &desc.objects[0] else {
        panic!("a mesh")
    };
    assert_eq!(mesh.triangle_count(), 1);
}

/// A glTF document with one triangle mesh (positions in a data URI) and `nodes` (JSON).
fn gltf_with_nodes(nodes: &str, scene_nodes: &str) -> String {
    // Three vec3 positions: (0,0,0), (1,0,0), (0,1,0).
    let mut bin = Vec::new();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend(v.to_le_bytes());
    }
    let b64 = base64(&bin);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":{scene_nodes}}}],
"nodes":{nodes},
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
"bufferViews":[{{"buffer":0,"byteLength":36}}],
"buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}]}}"#
    )
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Nodes 0..n, node i having children [i+1, i+1]; the last has the mesh.
fn dag_nodes(n: usize) -> String {
    let nodes: Vec<String> = (0..n)
        .map(|i| {
            if i + 1 < n {
                format!(r#"{{"children":[{},{}]}}"#, i + 1, i + 1)
            } else {
                r#"{"mesh":0}"#.to_string()
            }
        })
        .collect();
    format!("[{}]", nodes.join(","))
}

#[test]
fn a_gltf_dag_that_instances_exponentially_is_refused_before_expanding() {
    let dir = scratch("dag");
    let path = dir.join("dag.gltf");
    // 2^29 instances of one triangle: minutes to build, without the count.
    std::fs::write(&path, gltf_with_nodes(&dag_nodes(30), "[0]")).unwrap();
    let e = quick(Duration::from_millis(500), || error(&path));
    assert_contains(
        &e,
        &["dag.gltf", "536870912 triangles", "max_instanced_triangles"],
    );
    // 2^99: the count saturates instead of overflowing, and says so.
    std::fs::write(&path, gltf_with_nodes(&dag_nodes(100), "[0]")).unwrap();
    let e = quick(Duration::from_millis(500), || error(&path));
    assert_contains(&e, &["dag.gltf", "18446744073709551615 or more"]);
    // Within the limits the same shape loads: 2^4 instances, all in one place, so one mesh is
    // built (see the next test).
    std::fs::write(&path, gltf_with_nodes(&dag_nodes(5), "[0]")).unwrap();
    assert_eq!(load(&path).unwrap().objects.len(), 1);
    // And the limit (counted before the walk, repeats included) can be raised or lowered.
    let tight = LoadOptions {
        max_instanced_triangles: 15,
        ..LoadOptions::default()
    };
    let e = load_with(&path, &tight).unwrap_err().to_string();
    assert_contains(&e, &["16 triangles", "limit of 15"]);
}

/// A 32 x 24 render of `desc` (4 samples per pixel).
fn render_small(desc: SceneDesc) -> dofray::render::Film {
    use dofray::{overrides::Overrides, render::SettingsPatch, renderer::Renderer};
    let overrides = Overrides {
        width: Some(32),
        height: Some(24),
        ..Default::default()
    };
    let device = dofray::embree::Device::new().unwrap();
    let renderer = Renderer::with_overrides(desc, overrides, &device).unwrap();
    let patch = SettingsPatch {
        spp: Some(4),
        ..Default::default()
    };
    let settings = renderer.settings(&patch).unwrap();
    renderer
        .render(&settings, &dofray::render::NoProgress)
        .unwrap()
        .0
}

#[test]
fn a_mesh_placed_half_a_million_times_in_one_place_is_built_once() {
    let dir = scratch("coincident");
    // 2^19 = 524288 placements of one triangle by the identity: within the instancing limits,
    // and every ray through the triangle used to test all 524288 coincident copies (27 s for
    // 32 x 32 pixels, minutes at 640 x 480). A repeat (same mesh, same world transform) is
    // skipped and said in a warning.
    let many = dir.join("many.gltf");
    std::fs::write(&many, gltf_with_nodes(&dag_nodes(20), "[0]")).unwrap();
    let desc = quick(Duration::from_secs(3), || load(&many).unwrap());
    assert_eq!(desc.objects.len(), 1);
    assert!(
        desc.warnings
            .iter()
            .any(|w| w.contains("many.gltf") && w.contains("skipped 524287 placements")),
        "{:?}",
        desc.warnings
    );
    let film = quick(Duration::from_secs(3), || render_small(desc));
    // The image is the one placement's, bit for bit.
    let one = dir.join("one.gltf");
    std::fs::write(&one, gltf_with_nodes(r#"[{"mesh":0}]"#, "[0]")).unwrap();
    let single = render_small(load(&one).unwrap());
    assert_eq!(film.color, single.color);
    assert!(film.color.iter().any(|c| c.max_element() > 0.0));
    // Placements that differ are all built: two at the origin (one kept), one moved, one
    // mirrored.
    let nodes = r#"[{"children":[1,2,3,4]},{"mesh":0},{"mesh":0},{"mesh":0,"translation":[2,0,0]},{"mesh":0,"scale":[-1,1,1]}]"#;
    std::fs::write(&many, gltf_with_nodes(nodes, "[0]")).unwrap();
    let desc = load(&many).unwrap();
    assert_eq!(desc.objects.len(), 3);
    assert!(
        desc.warnings
            .iter()
            .any(|w| w.contains("skipped 1 placement "))
    );
}

/// Nodes `0..n` of a DAG whose every level places the one below twice, once where it is and
/// once moved by `1e-6 * 2^level` along x: 2^(n - 1) placements of the triangle, all
/// different, all within 0.07 of one another.
fn near_dag_nodes(n: usize) -> String {
    let mut nodes: Vec<String> = (0..n)
        .map(|i| {
            if i + 1 < n {
                format!(r#"{{"children":[{},{}]}}"#, i + 1, n + i)
            } else {
                r#"{"mesh":0}"#.to_string()
            }
        })
        .collect();
    for i in 0..n - 1 {
        let dx = 1e-6 * (1u64 << i) as f64;
        nodes.push(format!(
            r#"{{"children":[{}],"translation":[{dx},0,0]}}"#,
            i + 1
        ));
    }
    format!("[{}]", nodes.join(","))
}

/// 131,072 placements of one triangle a millionth apart are all loaded (they differ), but no
/// BVH can separate them: the scene is refused as a resource limit naming where they pile up,
/// at once, instead of a render that tests every copy on every ray (8 to 10 s for 32 x 32
/// pixels). A few thousand of them still render.
#[test]
fn near_coincident_copies_are_refused_before_rendering() {
    let dir = scratch("near-coincident");
    let many = dir.join("near.gltf");
    std::fs::write(&many, gltf_with_nodes(&near_dag_nodes(18), "[0]")).unwrap();
    let desc = quick(Duration::from_secs(5), || load(&many).unwrap());
    let device = dofray::embree::Device::new().unwrap();
    let e = quick(
        Duration::from_secs(3),
        || match dofray::renderer::Renderer::new(desc, &device) {
            Ok(_) => panic!("a pile of 131072 triangles was accepted"),
            Err(e) => e,
        },
    );
    assert_eq!(
        dofray::exit::classify(&e),
        dofray::exit::ErrorKind::ResourceLimit
    );
    let message = dofray::exit::full_message(&e);
    assert_contains(&message, &["131072 primitives", "piled up", "(1, 1, 1)"]);
    // 2^11 of them are few enough to render.
    std::fs::write(&many, gltf_with_nodes(&near_dag_nodes(12), "[0]")).unwrap();
    let film = render_small(load(&many).unwrap());
    assert!(film.color.iter().any(|c| c.max_element() > 0.0));
}

#[test]
fn gltf_node_cycles_are_an_error() {
    let dir = scratch("cycle");
    let path = dir.join("cycle.gltf");
    let nodes = r#"[{"children":[1]},{"children":[2],"mesh":0},{"children":[1]}]"#;
    std::fs::write(&path, gltf_with_nodes(nodes, "[0]")).unwrap();
    let e = quick(Duration::from_millis(500), || error(&path));
    assert_contains(&e, &["cycle.gltf", "cycle", "node 2", "node 1"]);
    // A node that is its own child, reachable from no scene.
    let nodes = r#"[{"mesh":0},{"children":[1]}]"#;
    std::fs::write(&path, gltf_with_nodes(nodes, "[0]")).unwrap();
    assert_contains(&error(&path), &["cycle"]);
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG whose header declares `width` x `height` RGB (its data is a small valid stream that
/// does not fill it; the size check comes first).
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let chunk = |png: &mut Vec<u8>, kind: &[u8], data: &[u8]| {
        png.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        png.extend(&body);
        png.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(width.to_be_bytes());
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(
        &mut png,
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    );
    chunk(&mut png, b"IEND", &[]);
    png
}

fn texture_scene(dir: &Path, image: &str) -> PathBuf {
    let scene = format!(
        "[[textures]]\nname = \"t\"\nimage = \"{image}\"\n[[materials]]\nname = \"m\"\ntexture = \"t\"\n\
         [[objects]]\ntype = \"sphere\"\nradius = 1\nmaterial = \"m\"\n"
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    path
}

#[test]
fn a_huge_texture_is_refused_from_its_header_with_the_size_it_needs() {
    let dir = scratch("huge-texture");
    std::fs::write(dir.join("big.png"), png_header(12000, 12000)).unwrap();
    let e = quick(Duration::from_millis(500), || {
        error(&texture_scene(&dir, "big.png"))
    });
    // 144e6 texels x (3 decoded + 3 RGB + 12 float) bytes.
    assert_contains(
        &e,
        &[
            "big.png",
            "12000x12000",
            "2592000000 bytes",
            "max_texture_bytes",
        ],
    );
}

#[test]
fn special_files_are_refused_without_being_opened() {
    let dir = scratch("special");
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.png")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.obj")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.bin")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.mtl")).unwrap();
    let status = std::process::Command::new("mkfifo")
        .arg(dir.join("pipe.png"))
        .status()
        .unwrap();
    assert!(status.success());
    std::fs::create_dir(dir.join("folder.png")).unwrap();
    let e = quick(Duration::from_millis(500), || {
        error(&texture_scene(&dir, "zero.png"))
    });
    assert_contains(&e, &["zero.png", "character device", "regular file"]);
    let e = quick(Duration::from_millis(500), || {
        error(&texture_scene(&dir, "pipe.png"))
    });
    assert_contains(&e, &["pipe.png", "named pipe"]);
    let e = error(&texture_scene(&dir, "folder.png"));
    assert_contains(&e, &["folder.png", "directory"]);
    assert_contains(
        &error(&dir.join("zero.obj")),
        &["zero.obj", "character device"],
    );
    assert_contains(&error(Path::new("/dev/zero.obj")), &["/dev/zero.obj"]);
    // The scene file itself.
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.toml")).unwrap();
    assert_contains(&error(&dir.join("zero.toml")), &["character device"]);
    // An MTL library and a glTF buffer.
    let obj = dir.join("m.obj");
    std::fs::write(&obj, format!("mtllib zero.mtl\n{TRIANGLE}f 1 2 3\n")).unwrap();
    assert_contains(&error(&obj), &["zero.mtl", "character device"]);
    let gltf = gltf_with_nodes(r#"[{"mesh":0}]"#, "[0]");
    let start = gltf.find("data:").unwrap();
    let end = start + gltf[start..].find('"').unwrap();
    let gltf = format!("{}zero.bin{}", &gltf[..start], &gltf[end..]);
    std::fs::write(dir.join("m.gltf"), gltf).unwrap();
    assert_contains(
        &error(&dir.join("m.gltf")),
        &["zero.bin", "character device"],
    );
}

#[test]
fn input_files_are_read_up_to_a_limit() {
    let dir = scratch("input-limit");
    let obj = dir.join("m.obj");
    std::fs::write(&obj, format!("{TRIANGLE}f 1 2 3\n")).unwrap();
    let small = LoadOptions {
        max_input_bytes: 20,
        ..LoadOptions::default()
    };
    let e = load_with(&obj, &small).unwrap_err().to_string();
    assert_contains(&e, &["m.obj", "input limit", "20 bytes", "max_input_bytes"]);
    assert!(load(&obj).is_ok());
    let e = load_with(&texture_scene(&dir, "t.png"), &small)
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["scene.toml", "input limit"]);
}

// ---------------------------------------------------------------------------------------------
// 2. Wrong acceptance and poor messages.

#[test]
fn obj_indices_that_would_wrap_around_or_are_zero_name_their_line() {
    let dir = scratch("obj-indices");
    let obj = dir.join("m.obj");
    let cases = [
        (
            "vn 0 0 1\nf 1//1 2//6148914691236517207 3//1\n",
            "normal index 6148914691236517207",
        ),
        ("vn 0 0 1\nf 1//0 2//1 3//1\n", "normal index 0"),
        ("vt 0 0\nf 1/1 2/0 3/1\n", "texture coordinate index 0"),
        ("f 1 0 3\n", "vertex index 0"),
        ("vt 0 0\nf 1/1 2/-2 3/1\n", "texture coordinate index -2"),
        ("f 1 2 99999999999999999999\n", "malformed face"),
    ];
    for (tail, what) in cases {
        std::fs::write(&obj, format!("{TRIANGLE}{tail}")).unwrap();
        let e = error(&obj);
        let line = 4 + tail.matches('\n').count() - 1;
        assert_contains(&e, &[&format!("m.obj:{line}:"), what]);
    }
    // Relative (negative) indices within range are fine.
    std::fs::write(&obj, format!("{TRIANGLE}vn 0 0 1\nf -3//-1 -2//1 -1//1\n")).unwrap();
    assert!(load(&obj).is_ok());
}

#[test]
fn scene_image_sizes_beyond_memory_name_the_file_and_key() {
    let dir = scratch("image-size");
    let path = dir.join("scene.toml");
    let sphere = "[[objects]]\ntype = \"sphere\"\nradius = 1\n";
    std::fs::write(
        &path,
        format!("[image]\nwidth = 4294967295\nheight = 4294967295\n{sphere}"),
    )
    .unwrap();
    let e = error(&path);
    assert_contains(
        &e,
        &[
            "scene.toml:2:",
            "image.width",
            "4294967295x4294967295",
            "2.0 ZiB",
        ],
    );
    std::fs::write(
        &path,
        format!("[image]\nwidth = 10\nheight = 4000000000\n{sphere}"),
    )
    .unwrap();
    assert_contains(&error(&path), &["scene.toml:3:", "image.height"]);
}

#[test]
fn control_characters_in_file_names_and_uris_are_escaped() {
    let dir = scratch("escapes");
    let scene = dir.join("scene.toml");
    std::fs::write(
        &scene,
        "[[objects]]\ntype = \"mesh\"\nfile = \"evil\\u001b]0;pwned\\u0007\\n.obj\"\n",
    )
    .unwrap();
    let e = error(&scene);
    assert!(
        !e.contains('\u{1b}') && !e.contains('\u{7}') && !e.contains('\n'),
        "{e:?}"
    );
    assert_contains(&e, &["evil\\u{1b}]0;pwned\\u{7}\\n.obj"]);
    // A glTF buffer URI and an MTL texture name.
    let gltf = gltf_with_nodes(r#"[{"mesh":0}]"#, "[0]");
    let start = gltf.find("data:").unwrap();
    let end = start + gltf[start..].find('"').unwrap();
    let gltf = format!("{}x\\u001b[2J.bin{}", &gltf[..start], &gltf[end..]);
    std::fs::write(dir.join("m.gltf"), gltf).unwrap();
    let e = error(&dir.join("m.gltf"));
    assert!(!e.contains('\u{1b}'), "{e:?}");
    assert_contains(&e, &["x\\u{1b}[2J.bin"]);
    std::fs::write(
        dir.join("m.mtl"),
        "newmtl a\u{1b}b\nmap_Kd t\u{1b}[1m.png\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("m.obj"),
        format!("mtllib m.mtl\n{TRIANGLE}usemtl a\u{1b}b\nf 1 2 3\n"),
    )
    .unwrap();
    let e = error(&dir.join("m.obj"));
    assert!(!e.contains('\u{1b}'), "{e:?}");
    assert_contains(&e, &["t\\u{1b}[1m.png"]);
}

// ---------------------------------------------------------------------------------------------
// 3. Files outside the model's folder.

#[test]
fn references_outside_the_model_folder_are_refused_unless_allowed() {
    let root = scratch("outside");
    let dir = root.join("model");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::write(root.join("out.mtl"), "newmtl a\nKd 1 0 0\n").unwrap();
    std::fs::write(dir.join("sub/in.mtl"), "newmtl a\nKd 1 0 0\n").unwrap();
    let obj = dir.join("m.obj");
    let allow = LoadOptions {
        allow_outside_paths: true,
        ..LoadOptions::default()
    };
    // An MTL library by `..` and by an absolute path.
    std::fs::write(
        &obj,
        format!("mtllib ../out.mtl\n{TRIANGLE}usemtl a\nf 1 2 3\n"),
    )
    .unwrap();
    assert_contains(
        &error(&obj),
        &[
            "m.obj:1",
            "`../out.mtl`",
            "outside",
            "--allow-outside-paths",
        ],
    );
    assert!(load_with(&obj, &allow).is_ok());
    let abs = root.join("out.mtl");
    std::fs::write(
        &obj,
        format!("mtllib {}\n{TRIANGLE}f 1 2 3\n", abs.display()),
    )
    .unwrap();
    assert_contains(&error(&obj), &["outside"]);
    assert!(load_with(&obj, &allow).is_ok());
    // Inside the folder, `..` back into it is fine.
    std::fs::write(
        &obj,
        format!("mtllib sub/../sub/in.mtl\n{TRIANGLE}f 1 2 3\n"),
    )
    .unwrap();
    assert!(load(&obj).is_ok());
    // A texture of an MTL, and a glTF buffer.
    std::fs::write(dir.join("sub/in.mtl"), "newmtl a\nmap_Kd ../../t.png\n").unwrap();
    std::fs::write(
        &obj,
        format!("mtllib sub/in.mtl\n{TRIANGLE}usemtl a\nf 1 2 3\n"),
    )
    .unwrap();
    assert_contains(&error(&obj), &["in.mtl", "`../../t.png`", "outside"]);
    let gltf = gltf_with_nodes(r#"[{"mesh":0}]"#, "[0]");
    let start = gltf.find("data:").unwrap();
    let end = start + gltf[start..].find('"').unwrap();
    std::fs::write(
        dir.join("m.gltf"),
        format!("{}/etc/passwd{}", &gltf[..start], &gltf[end..]),
    )
    .unwrap();
    assert_contains(
        &error(&dir.join("m.gltf")),
        &["m.gltf", "`/etc/passwd`", "outside"],
    );
}

/// The command line raises (or lowers) the loader limits.
#[test]
fn limit_flags_set_the_loader_limits() {
    let dir = Scratch::new("limit-flags");
    let obj = dir.join("big.obj");
    let mut text = "v 0 0 0\nv 1 0 0\nv 0 1 0\n".repeat(60_000);
    text.push_str("f 1 2 3\n");
    std::fs::write(&obj, text).unwrap(); // about 1.5 MB
    let render = |limit: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_dofray"))
            .args([
                "render",
                "--width",
                "16",
                "--quiet",
                "--max-input-mib",
                limit,
                "-o",
            ])
            .arg(dir.join("out.png"))
            .arg(&obj)
            .output()
            .unwrap()
    };
    let small = render("1");
    let err = String::from_utf8_lossy(&small.stderr);
    // Beyond an input size cap: a resource limit.
    assert_eq!(small.status.code(), Some(5), "{err}");
    assert!(
        err.contains("input limit of 1.0 MiB") && err.contains("--max-input-mib"),
        "{err}"
    );
    let raised = render("4");
    assert!(
        raised.status.success(),
        "{}",
        String::from_utf8_lossy(&raised.stderr)
    );
}

// ---------------------------------------------------------------------------------------------
// Found by fuzzing (fuzz/, scripts/fuzz.sh): the tile reader of `dofray merge`.

/// A one-channel EXR tile of a 1x1 image whose header then claims a `width` x `height` data
/// window, with nothing after its header (as the fuzzer's inputs had).
fn exr_tile_claiming(width: i32, height: i32) -> Vec<u8> {
    use exr::prelude::*;
    let channel = AnyChannel::new("R", FlatSamples::F32(vec![0.5]));
    let layer = Layer::new(
        (1, 1),
        LayerAttributes::default(),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(vec![channel].into()),
    );
    let mut image = Image::from_layer(layer);
    for (key, value) in [
        ("dofray:region", "0,0,1,1"),
        ("dofray:width", "1"),
        ("dofray:height", "1"),
    ] {
        image
            .attributes
            .other
            .insert(Text::from(key), AttributeValue::Text(Text::from(value)));
    }
    let mut bytes = std::io::Cursor::new(Vec::new());
    image.write().to_buffered(&mut bytes).unwrap();
    let mut bytes = bytes.into_inner();
    // dataWindow: box2i, 16 bytes: x min, y min, x max, y max.
    let key = b"dataWindow\0box2i\0\x10\0\0\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    bytes[at + 8..at + 12].copy_from_slice(&(width - 1).to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&(height - 1).to_le_bytes());
    // chunkCount: int, one chunk a scan line without compression.
    let key = b"chunkCount\0int\0\x04\0\0\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    bytes[at..at + 4].copy_from_slice(&height.to_le_bytes());
    // The header: magic and version, then attributes (name, type, size, value) up to a 0.
    let mut end = 8;
    while bytes[end] != 0 {
        let name = end + bytes[end..].iter().position(|&b| b == 0).unwrap();
        let kind = name + 1 + bytes[name + 1..].iter().position(|&b| b == 0).unwrap();
        let size = i32::from_le_bytes(bytes[kind + 1..kind + 5].try_into().unwrap());
        end = kind + 5 + size as usize;
    }
    bytes.truncate(end + 1);
    bytes
}

#[test]
fn merge_tiles_whose_headers_claim_terabytes_are_refused_before_allocating() {
    let dir = scratch("merge-claims");
    let merge = |name: &str, bytes: Vec<u8>| {
        let tile = dir.join(name);
        std::fs::write(&tile, bytes).unwrap();
        let out = dir.join(format!("out.{}", name.rsplit('.').next().unwrap()));
        quick(Duration::from_secs(2), || {
            dofray::output::merge::merge(&[tile], &out)
                .unwrap_err()
                .to_string()
        })
    };
    // The reader used to allocate what the header claims (2^58 floats here), and the process
    // aborted: "memory allocation of ... bytes failed".
    let e = merge("tile.exr", exr_tile_claiming(1 << 29, 1 << 29));
    assert_contains(&e, &["tile.exr", "536870912x536870912", "EiB", "but only"]);
    // A PNG whose header claims 2^20 x 2^20 RGB pixels (3 TiB).
    let e = merge("tile.png", png_header(1 << 20, 1 << 20));
    assert_contains(&e, &["tile.png", "1048576x1048576", "3.0 TiB", "but only"]);
}

#[test]
fn an_exr_tile_is_placed_by_its_header_before_its_pixels_are_read() {
    let dir = scratch("merge-window");
    // A data window of 2^26 x 1 pixels for a 1x1 region: within memory, but the reader used to
    // allocate (and, compressed, fill) it before the mismatch was noticed: a 2 KB tile took
    // 2.6 GB and 1.6 s. Now the header's data window is held against the region first.
    let tile = dir.join("wide.exr");
    std::fs::write(&tile, exr_tile_claiming(1 << 26, 1)).unwrap();
    let e = quick(Duration::from_millis(500), || {
        dofray::output::merge::merge(&[tile], &dir.join("out.exr"))
            .unwrap_err()
            .to_string()
    });
    assert_contains(
        &e,
        &["wide.exr", "holds 67108864x1 pixels", "needs 1x1 at (0, 0)"],
    );
}

#[test]
fn a_glb_declaring_less_than_its_own_header_is_refused_as_corrupt() {
    let dir = scratch("glb-length");
    // The GLB header's length word is 0: the glTF parser's `length - 12` underflowed (a panic
    // in checked builds, caught only as "the glTF parser failed on it").
    let mut glb = b"glTF".to_vec();
    glb.extend(2u32.to_le_bytes());
    glb.extend(0u32.to_le_bytes());
    glb.extend(b"....JSON{}");
    let path = dir.join("short.glb");
    std::fs::write(&path, glb).unwrap();
    assert_contains(
        &error(&path),
        &[
            "short.glb",
            "declares a length of 0 bytes",
            "12-byte header",
        ],
    );
}
