//! Structure-aware property test: scene files that are *valid in shape* (every key known, every
//! reference resolving) but carry extreme numbers and extreme graph shapes, rendered by the real
//! `dofray` binary in a child process. Whatever the input, the process must either exit 0 with
//! a finite image or exit 1 with a message; it must never die of a signal (an Embree abort is
//! SIGABRT), panic, hang past a time limit, or write a NaN pixel.
//!
//! The number of cases is bounded (`FUZZ_CASES`, default 64) so the suite stays fast; raise it
//! to search longer: `FUZZ_CASES=2000 cargo test --release --test integration fuzz_scenes`.

use crate::scene_assets; // for its base64 encoder
use crate::scratch::Scratch;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

/// Numbers a hostile or careless scene might hold: the edges of f32 and of dofray's ranges.
fn extreme() -> impl Strategy<Value = f32> {
    prop_oneof![
        Just(0.0f32),
        Just(-0.0),
        Just(1e-45),
        Just(1e-20),
        Just(1e-7),
        Just(0.5),
        Just(1.0),
        Just(-1.0),
        Just(3.0),
        Just(1e7),
        Just(1e15),
        Just(-1e15),
        Just(1.1e15),
        Just(1e16),
        Just(2e18),
        Just(1e20),
        Just(3e38),
        Just(-3e38),
        Just(f32::MAX),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(f32::NAN),
        -1e3f32..1e3,
    ]
}

/// A TOML float (TOML spells the specials `inf`, `-inf`, `nan`).
fn num(v: f32) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{v:e}")
    }
}

fn vec3(v: [f32; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

/// Mostly ordinary values with an extreme one mixed in now and then.
fn mostly(ordinary: f32) -> impl Strategy<Value = f32> {
    prop_oneof![12 => Just(ordinary), 1 => extreme()]
}

fn mostly3(ordinary: [f32; 3]) -> impl Strategy<Value = [f32; 3]> {
    (
        mostly(ordinary[0]),
        mostly(ordinary[1]),
        mostly(ordinary[2]),
    )
        .prop_map(|(a, b, c)| [a, b, c])
}

#[derive(Debug, Clone)]
struct Case {
    eye: [f32; 3],
    look_at: [f32; 3],
    lens: (u8, f32, f32),
    focus: f32,
    anamorphic: f32,
    light: ([f32; 3], f32),
    material: (f32, f32, f32, f32, f32),
    sphere: ([f32; 3], f32),
    mesh: ([f32; 3], f32, [f32; 3]),
    obj_vertex: [f32; 3],
    gltf_depth: usize,
    gltf_fanout: usize,
    mode: &'static str,
}

fn case() -> impl Strategy<Value = Case> {
    (
        (mostly3([0.0, 1.0, -6.0]), mostly3([0.0, 0.5, 0.0])),
        (0u8..4, mostly(0.1), mostly(2.0)),
        (mostly(6.0), mostly(1.0)),
        (mostly3([-3.0, 6.0, -3.0]), mostly(50.0)),
        (
            mostly(0.8),
            mostly(0.2),
            mostly(16.0),
            mostly(0.0),
            mostly(4.0),
        ),
        (mostly3([0.0, 0.5, 0.0]), mostly(0.5)),
        (
            mostly3([1.0, 0.0, 0.0]),
            mostly(1.0),
            mostly3([0.0, 30.0, 0.0]),
        ),
        mostly3([1.0, 1.0, 0.0]),
        (prop_oneof![4 => 0usize..6, 1 => 0usize..64], 1usize..4),
        prop_oneof![Just("pinhole"), Just("dense"), Just("adaptive")],
    )
        .prop_map(
            |(
                (eye, look_at),
                lens,
                (focus, anamorphic),
                light,
                material,
                sphere,
                mesh,
                obj_vertex,
                (gltf_depth, gltf_fanout),
                mode,
            )| Case {
                eye,
                look_at,
                lens,
                focus,
                anamorphic,
                light,
                material,
                sphere,
                mesh,
                obj_vertex,
                gltf_depth,
                gltf_fanout,
                mode,
            },
        )
}

/// A glTF whose nodes form a chain `depth` long where every node instances the next `fanout`
/// times (a DAG that expands to fanout^depth copies of one triangle).
fn gltf_dag(depth: usize, fanout: usize) -> String {
    let positions: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = positions.iter().flat_map(|f| f.to_le_bytes()).collect();
    let data = scene_assets::base64(&bytes);
    let nodes: Vec<String> = (0..=depth)
        .map(|i| {
            if i == depth {
                "{\"mesh\": 0}".to_string()
            } else {
                let children = vec![(i + 1).to_string(); fanout].join(", ");
                format!("{{\"children\": [{children}], \"translation\": [0.1, 0, 0]}}")
            }
        })
        .collect();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
"nodes": [{}],
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
  "min": [0, 0, 0], "max": [1, 1, 0]}}],
"bufferViews": [{{"buffer": 0, "byteLength": 36}}],
"buffers": [{{"byteLength": 36, "uri": "data:application/octet-stream;base64,{data}"}}]}}"#,
        nodes.join(", ")
    )
}

fn write_case(dir: &Path, c: &Case) -> PathBuf {
    let v = c.obj_vertex;
    std::fs::write(
        dir.join("tri.obj"),
        format!(
            "v 0 0 0\nv {} {} {}\nv 0 1 0\nf 1 2 3\n",
            num(v[0]),
            num(v[1]),
            num(v[2])
        ),
    )
    .unwrap();
    std::fs::write(dir.join("dag.gltf"), gltf_dag(c.gltf_depth, c.gltf_fanout)).unwrap();
    let lens = match c.lens.0 {
        0 => format!("aperture_radius = {}", num(c.lens.1)),
        1 => format!("f_number = {}", num(c.lens.2)),
        2 => format!(
            "sharp_range = {}\nspread = {}",
            num(c.lens.1),
            num(c.lens.2)
        ),
        _ => String::new(),
    };
    let (diffuse, specular, shininess, mirror, scale) = c.material;
    let toml = format!(
        r#"[image]
width = 16
height = 12
[render]
spp = 4
aa = 2
[camera]
eye = {eye}
look_at = {look_at}
{lens}
focus_distance = {focus}
anamorphic = {anamorphic}
[[lights]]
type = "point"
position = {light}
intensity = {intensity}
[[textures]]
name = "checks"
pattern = "checker"
scale = {scale}
[[materials]]
name = "m"
diffuse = {diffuse}
specular = {specular}
shininess = {shininess}
mirror = {mirror}
texture = "checks"
[[objects]]
type = "sphere"
material = "m"
center = {center}
radius = {radius}
[[objects]]
type = "mesh"
file = "tri.obj"
material = "m"
translate = {translate}
scale = {mscale}
rotate = {rotate}
[[objects]]
type = "mesh"
file = "dag.gltf"
material = "m"
"#,
        eye = vec3(c.eye),
        look_at = vec3(c.look_at),
        focus = num(c.focus),
        anamorphic = num(c.anamorphic),
        light = vec3(c.light.0),
        intensity = num(c.light.1),
        scale = num(scale),
        diffuse = num(diffuse),
        specular = num(specular),
        shininess = num(shininess),
        mirror = num(mirror),
        center = vec3(c.sphere.0),
        radius = num(c.sphere.1),
        translate = vec3(c.mesh.0),
        mscale = num(c.mesh.1),
        rotate = vec3(c.mesh.2),
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    path
}

/// Runs `dofray render` on the scene with a time limit; returns (exit code, stderr).
fn run(scene: &Path, out: &Path, mode: &str) -> Result<(i32, String), String> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args(["render", "--quiet", "--threads", "1", "--mode", mode, "-o"])
        .arg(out)
        .arg(scene)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            use std::io::Read;
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            return match status.code() {
                Some(code) => Ok((code, err)),
                None => Err(format!("killed by a signal ({status:?}): {err}")),
            };
        }
        if start.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            let _ = child.wait(); // gone before the test's scratch directory is removed
            return Err("did not finish within 30 s".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Every pixel of an EXR written by dofray is finite: its colour and alpha (the
/// `ViewLayer.Combined` pass; docs/outputs.md).
fn exr_is_finite(path: &Path) -> bool {
    use exr::prelude::FlatSamples;
    let image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let channels = &image.layer_data[0].channel_data.list;
    let beauty: Vec<_> = channels
        .iter()
        .filter(|c| c.name.to_string().starts_with("ViewLayer.Combined."))
        .collect();
    assert_eq!(beauty.len(), 4, "R, G, B and A");
    beauty.iter().all(|c| match &c.sample_data {
        FlatSamples::F32(v) => v.iter().all(|x| x.is_finite()),
        FlatSamples::F16(v) => v.iter().all(|x| x.to_f32().is_finite()),
        FlatSamples::U32(_) => true,
    })
}

#[test]
fn extreme_but_well_formed_scenes_never_crash_or_produce_nan() {
    let cases: u32 = std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(64);
    let dir = Scratch::new("fuzz");
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    let (rendered, refused) = (std::cell::Cell::new(0), std::cell::Cell::new(0));
    let result = runner.run(&case(), |c| {
        let scene = write_case(&dir, &c);
        let out = dir.join("out.exr");
        let _ = std::fs::remove_file(&out);
        let (code, err) = run(&scene, &out, c.mode).map_err(TestCaseError::fail)?;
        match code {
            0 => {
                prop_assert!(out.is_file(), "exit 0 without an image");
                prop_assert!(exr_is_finite(&out), "exit 0 with a non-finite pixel");
                rendered.set(rendered.get() + 1);
            }
            // Refused: a bad input (3), a resource limit (5) or an internal error (1), never a
            // usage or output error (the flags and the output are fine).
            1 | 3 | 5 => {
                prop_assert!(
                    err.starts_with("error: "),
                    "exit {code} without a message: {err}"
                );
                prop_assert!(!err.contains("panicked"), "a panic: {err}");
                prop_assert!(!out.exists(), "exit {code} but an image was written");
                refused.set(refused.get() + 1);
                if std::env::var_os("FUZZ_VERBOSE").is_some() {
                    eprintln!("{}", err.trim());
                }
            }
            other => prop_assert!(false, "exit {other}: {err}"),
        }
        Ok(())
    });
    eprintln!("{} rendered, {} refused", rendered.get(), refused.get());
    if let Err(e) = result {
        panic!("{e}");
    }
}
