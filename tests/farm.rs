//! Batch and farm rendering from the command line: frame sequences, resume, tiles and their
//! merge, shards from flags and from Slurm's and Kubernetes' environment.

use std::path::Path;
use std::process::{Command, Output};

use crate::scratch::Scratch;

/// A dofray command with no scheduler in its environment.
fn cmd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_dofray"));
    for v in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_MAX",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_STEP",
        "JOB_COMPLETION_INDEX",
        "DOFRAY_SHARD_COUNT",
    ] {
        c.env_remove(v);
    }
    c
}

fn dofray(args: &[&str]) -> Output {
    cmd().args(args).output().expect("run dofray")
}

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("farm-{name}"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not JSON ({e}): {}\nstderr: {}",
            String::from_utf8_lossy(&o.stdout),
            stderr(o)
        )
    })
}

/// Every channel's samples (as bits) of an EXR, with its display and data windows.
fn exr_pixels(path: &Path) -> (Vec<(String, Vec<u32>)>, String) {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let bits = match &c.sample_data {
                FlatSamples::F16(v) => v.iter().map(|h| u32::from(h.to_bits())).collect(),
                FlatSamples::F32(v) => v.iter().map(|f| f.to_bits()).collect(),
                FlatSamples::U32(v) => v.clone(),
            };
            (c.name.to_string(), bits)
        })
        .collect();
    let windows = format!(
        "display {:?}, data at {:?} size {:?}",
        image.attributes.display_window, layer.attributes.layer_position, layer.size
    );
    (channels, windows)
}

fn png_pixels(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path).unwrap();
    (img.width(), img.height(), img.into_bytes())
}

const SIZE: [&str; 4] = ["--width", "160", "--height", "120"];
/// The focus pull's frames: [`SIZE`], 8 samples per blurred site, 4 where in focus.
const PULL: [&str; 8] = [
    "--width", "160", "--height", "120", "--spp", "8", "--aa", "4",
];

#[test]
fn tiles_merge_into_the_full_render_bit_for_bit() {
    let dir = scratch("tiles");
    for ext in ["exr", "png"] {
        let full = dir.join(format!("full.{ext}"));
        let tiled = dir.join(format!("tiled.{ext}"));
        let o = dofray(&[&["render", "-o", s(&full), "-q"][..], &SIZE].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let o = dofray(
            &[
                &["render", "-o", s(&tiled), "--tiles", "3x2", "--json"][..],
                &SIZE,
            ]
            .concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let j = json(&o);
        assert_eq!(j["jobs"], 6);
        assert_eq!(j["rendered"], 6);
        assert_eq!(j["merged"][0], s(&tiled));
        // The tiles were merged and removed.
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tile-"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
        // The merged image is an output too: --no-overwrite keeps it.
        let stamp = std::fs::metadata(&tiled).unwrap().modified().unwrap();
        let o = dofray(
            &[
                &[
                    "render",
                    "-q",
                    "-o",
                    s(&tiled),
                    "--tiles",
                    "3x2",
                    "--no-overwrite",
                ][..],
                &SIZE,
            ]
            .concat(),
        );
        assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
        assert_eq!(
            std::fs::metadata(&tiled).unwrap().modified().unwrap(),
            stamp
        );
        if ext == "exr" {
            let (a, wa) = exr_pixels(&full);
            let (b, wb) = exr_pixels(&tiled);
            assert_eq!(wa, wb);
            assert_eq!(a.len(), 8);
            assert!(a == b, "the merged EXR differs from the full render");
        } else {
            assert_eq!(png_pixels(&full), png_pixels(&tiled));
        }
    }
}

#[test]
fn region_tiles_carry_their_place_and_merge_checks_them() {
    let dir = scratch("merge");
    let tile = |name: &str, region: &str, extra: &[&str]| {
        let path = dir.join(name);
        let o = dofray(
            &[
                &["render", "-q", "-o", s(&path), "--region", region][..],
                &SIZE,
                extra,
            ]
            .concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        path
    };
    let left = tile("left.exr", "0,0,100,120", &[]);
    let right = tile("right.exr", "100,0,160,120", &[]);
    // The tile is placed by its data window in the whole image's display window.
    let (_, windows) = exr_pixels(&right);
    assert!(
        windows.contains("data at Vec2(100, 0) size Vec2(60, 120)"),
        "{windows}"
    );
    assert!(windows.contains("size: Vec2(160, 120)"), "{windows}");
    let full = dir.join("full.exr");
    let o = dofray(&["merge", s(&left), s(&right), "-o", s(&full), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&o)["tiles"], 2);
    let reference = dir.join("ref.exr");
    let o = dofray(&[&["render", "-q", "-o", s(&reference)][..], &SIZE].concat());
    assert!(o.status.success());
    assert!(exr_pixels(&reference).0 == exr_pixels(&full).0);

    // Refusals, each naming what is wrong, exit 3 (bad input) and write nothing.
    let bad_out = dir.join("bad.exr");
    let overlap = tile("overlap.exr", "90,0,160,120", &[]);
    let other_spp = tile("spp.exr", "100,0,160,120", &["--spp", "32", "--aa", "16"]);
    let cases: Vec<(Vec<&Path>, &str)> = vec![
        (vec![&left, &overlap], "overlap"),
        (vec![&left], "uncovered, the first at (100, 0)"),
        (
            vec![&left, &other_spp],
            "dofray:spp is \"16\" in the first and \"32\"",
        ),
        (vec![&left, &reference], "is not a dofray tile"),
    ];
    for (tiles, message) in cases {
        let mut args = vec!["merge"];
        args.extend(tiles.iter().map(|p| s(p)));
        args.extend(["-o", s(&bad_out)]);
        let o = dofray(&args);
        assert_eq!(o.status.code(), Some(3), "{message}: {}", stderr(&o));
        assert!(stderr(&o).contains(message), "{message}: {}", stderr(&o));
        assert!(!bad_out.exists());
    }
    let o = dofray(&["merge", s(&left), s(&right), "-o", s(&dir.join("x.png"))]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = dofray(&[
        "render",
        "--region",
        "0,0,161,10",
        "-o",
        s(&bad_out),
        "--width",
        "160",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--region"), "{}", stderr(&o));
}

/// Frames written by a run, by name.
fn written(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png") && !n.starts_with('.'))
        .collect();
    names.sort();
    names
}

#[test]
fn shards_split_the_frames_from_flags_slurm_and_kubernetes() {
    let dir = scratch("shards");
    let run = |out: &Path, env: &[(&str, &str)], extra: &[&str]| {
        let pattern = out.join("f_###.png");
        let mut c = cmd();
        c.args([
            "render", "-q", "--json", "--width", "32", "--height", "24", "--frames", "1-7",
        ])
        .args(["-o", s(&pattern)])
        .args(extra);
        for (k, v) in env {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    let slurm = |id: &str| {
        vec![
            ("SLURM_ARRAY_TASK_ID", id.to_string()),
            ("SLURM_ARRAY_TASK_MIN", "1".into()),
            ("SLURM_ARRAY_TASK_MAX", "3".into()),
            ("SLURM_ARRAY_TASK_COUNT", "3".into()),
        ]
    };
    let mut by_source: Vec<Vec<String>> = Vec::new();
    for source in ["flag", "slurm", "kubernetes"] {
        let out = dir.join(source);
        std::fs::create_dir_all(&out).unwrap();
        let mut seen = Vec::new();
        for i in 0..3 {
            let o = match source {
                "flag" => run(&out, &[], &["--shard", &format!("{i}/3")]),
                "slurm" => {
                    let env = slurm(&(i + 1).to_string());
                    let env: Vec<(&str, &str)> =
                        env.iter().map(|(k, v)| (*k, v.as_str())).collect();
                    run(&out, &env, &[])
                }
                _ => run(
                    &out,
                    &[
                        ("JOB_COMPLETION_INDEX", &i.to_string()),
                        ("DOFRAY_SHARD_COUNT", "3"),
                    ],
                    &[],
                ),
            };
            assert!(o.status.success(), "{source} {i}: {}", stderr(&o));
            let j = json(&o);
            assert_eq!(j["shard"], format!("{i}/3"), "{source}");
            let frames: Vec<i64> = j["frames"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| f["frame"].as_i64().unwrap())
                .collect();
            // Round robin: shard i renders frames 1 + i, 4 + i, ...
            let want: Vec<i64> = (1..=7).filter(|f| (f - 1) % 3 == i).collect();
            assert_eq!(frames, want, "{source} shard {i}");
            seen.extend(frames);
        }
        seen.sort();
        assert_eq!(
            seen,
            (1..=7).collect::<Vec<_>>(),
            "{source}: every frame once"
        );
        by_source.push(written(&out));
    }
    assert_eq!(by_source[0].len(), 7);
    assert!(by_source.iter().all(|w| *w == by_source[0]));
    // --shard overrides the environment.
    let out = dir.join("override");
    std::fs::create_dir_all(&out).unwrap();
    let env = slurm("2");
    let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let o = run(&out, &env, &["--shard", "0/1"]);
    assert_eq!(json(&o)["rendered"], 7, "{}", stderr(&o));
    // Broken environments are usage errors naming the variable.
    let o = run(&out, &[("JOB_COMPLETION_INDEX", "1")], &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("DOFRAY_SHARD_COUNT"), "{}", stderr(&o));
    let sparse = [
        ("SLURM_ARRAY_TASK_ID", "3"),
        ("SLURM_ARRAY_TASK_MIN", "0"),
        ("SLURM_ARRAY_TASK_MAX", "5"),
        ("SLURM_ARRAY_TASK_COUNT", "3"),
    ];
    let o = run(&out, &sparse, &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--shard"), "{}", stderr(&o));
}

#[test]
fn a_failing_frame_is_reported_and_the_others_still_render() {
    let dir = scratch("failures");
    let pattern = dir.join("f_####.png");
    let base = [
        "render", "--width", "32", "--height", "24", "--frames", "1-4", "--json",
    ];
    let o = dofray(&[&base[..], &["-o", s(&pattern), "-q"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let j = json(&o);
    assert_eq!(
        (j["rendered"].as_u64(), j["failed"].as_u64()),
        (Some(4), Some(0))
    );
    // Frame 2 removed: --skip-existing renders only it.
    std::fs::remove_file(dir.join("f_0002.png")).unwrap();
    let o = dofray(&[&base[..], &["-o", s(&pattern), "--skip-existing"]].concat());
    let j = json(&o);
    assert_eq!(
        (j["rendered"].as_u64(), j["skipped"].as_u64()),
        (Some(1), Some(3))
    );
    assert_eq!(j["frames"][1]["status"], "rendered");
    assert_eq!(j["frames"][1]["frame"], 2);
    // --no-overwrite: the existing frames fail, named, and the run exits 4 (io) at the end.
    std::fs::remove_file(dir.join("f_0004.png")).unwrap();
    let o = dofray(&[&base[..], &["-o", s(&pattern), "--no-overwrite"]].concat());
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    let j = json(&o);
    assert_eq!(
        (j["rendered"].as_u64(), j["failed"].as_u64()),
        (Some(1), Some(3))
    );
    assert_eq!(j["frames"][3]["status"], "rendered");
    assert_eq!(j["frames"][0]["error"]["kind"], "io");
    assert_eq!(j["error"]["exit_code"], 4);
    assert!(stderr(&o).contains("error: frame 1:"), "{}", stderr(&o));
    // --fail-fast stops at the first failure.
    let o = dofray(
        &[
            &base[..],
            &["-o", s(&pattern), "--no-overwrite", "--fail-fast"],
        ]
        .concat(),
    );
    let j = json(&o);
    assert_eq!(
        (j["failed"].as_u64(), j["not_run"].as_u64()),
        (Some(1), Some(3))
    );
    // Several frames need a pattern; a pattern needs frames.
    let o = dofray(&[&base[..], &["-o", s(&dir.join("one.png"))]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("####"), "{}", stderr(&o));
    let o = dofray(&["render", "-o", s(&pattern)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--frames"), "{}", stderr(&o));
}

/// The acceptance run: scenes/focus_pull.toml's 48 frames from one command, killed
/// part-way (SIGKILL: no clean-up), then resumed with --skip-existing, which renders only the
/// rest. Writes a contact sheet of every 8th frame (and the last) for a person to look at.
/// Half size and 8 samples ([`PULL`]): the test is about the frames, not their pixels (at the
/// scene's own 320 x 240 and 32 spp it took over two minutes of the suite).
#[test]
fn a_killed_focus_pull_resumes_with_skip_existing() {
    let dir = scratch("pull");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/focus_pull.toml");
    let pattern = dir.join("pull_####.png");
    let mut child = cmd()
        .args(["render", s(&scene), "-o", s(&pattern), "-q"])
        .args(PULL)
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    loop {
        if written(&dir).len() >= 24 {
            break;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the render ended before it could be killed"
        );
        if started.elapsed().as_secs() >= 600 {
            // Killed, so that it is gone before the scratch directory it writes to is removed.
            let _ = child.kill();
            let _ = child.wait();
            panic!("no frames after 10 minutes");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let before = written(&dir);
    assert!(before.len() < 48, "{} frames before the kill", before.len());
    let stamps: Vec<_> = before
        .iter()
        .map(|n| std::fs::metadata(dir.join(n)).unwrap().modified().unwrap())
        .collect();

    let o = dofray(
        &[
            &[
                "render",
                s(&scene),
                "-o",
                s(&pattern),
                "--skip-existing",
                "--json",
                "-q",
            ][..],
            &PULL,
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let j = json(&o);
    assert_eq!(j["jobs"], 48);
    assert_eq!(j["skipped"].as_u64(), Some(before.len() as u64));
    assert_eq!(j["rendered"].as_u64(), Some(48 - before.len() as u64));
    let frames = j["frames"].as_array().unwrap();
    for f in frames {
        let name = format!("pull_{:04}.png", f["frame"].as_i64().unwrap());
        let expected = if before.contains(&name) {
            "skipped"
        } else {
            "rendered"
        };
        assert_eq!(f["status"], expected, "{name}");
    }
    // The frames from before the kill were left alone; the killed frame's temporary file is
    // gone (the resumed write of that frame removed it); every frame is a whole picture.
    for (n, t) in before.iter().zip(&stamps) {
        assert_eq!(
            std::fs::metadata(dir.join(n)).unwrap().modified().unwrap(),
            *t,
            "{n}"
        );
    }
    let all: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(all.len(), 48, "{all:?}");
    // The focus racks out monotonically over the rendered frames.
    let focus: Vec<f64> = frames
        .iter()
        .filter(|f| f["status"] == "rendered")
        .map(|f| f["focus_distance"].as_f64().unwrap())
        .collect();
    assert!(focus.windows(2).all(|w| w[1] >= w[0]), "{focus:?}");

    // Contact sheet: frames 1, 9, ..., 41 and 48, four to a row.
    let picks = [1, 9, 17, 25, 33, 41, 48];
    let mut sheet = image::RgbImage::new(160 * 4, 120 * 2);
    for (i, f) in picks.iter().enumerate() {
        let frame = image::open(dir.join(format!("pull_{f:04}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(frame.dimensions(), (160, 120));
        let (x, y) = ((i % 4) as i64 * 160, (i / 4) as i64 * 120);
        image::imageops::overlay(&mut sheet, &frame, x, y);
    }
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("focus_pull_contact_sheet.png");
    sheet.save(&out).unwrap();
    eprintln!("contact sheet of the focus pull: {}", out.display());
}

#[test]
fn frames_of_an_unanimated_scene_warn_that_they_are_identical() {
    let dir = scratch("unanimated");
    let pattern = dir.join("still_##.png");
    let o = cmd()
        .args([
            "render", "-q", "--width", "16", "--height", "12", "--frames", "1-2",
        ])
        .args(["-o", s(&pattern)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: paper has no [animation]: its 2 frames will be identical"),
        "{}",
        stderr(&o)
    );
    assert!(dir.join("still_01.png").exists() && dir.join("still_02.png").exists());
}

#[test]
fn a_whole_image_tile_merges_and_merge_refuses_what_is_not_a_file() {
    let dir = scratch("one-tile");
    let full = dir.join("full.exr");
    let tiled = dir.join("tiled.exr");
    let o = dofray(&[&["render", "-o", s(&full), "-q"][..], &SIZE].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    // --tiles 1x1: one tile covering the image still records its place and merges.
    let o = dofray(
        &[
            &["render", "-o", s(&tiled), "--tiles", "1x1", "--json"][..],
            &SIZE,
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&o)["merged"][0], s(&tiled));
    assert!(
        exr_pixels(&full) == exr_pixels(&tiled),
        "the one-tile merge differs"
    );
    // A FIFO (or a directory) given as a tile is refused at once instead of blocking.
    let fifo = dir.join("t.tile-000.exr");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    for tile in [fifo.clone(), dir.to_path_buf()] {
        let start = std::time::Instant::now();
        let o = dofray(&["merge", s(&tile), "-o", s(&dir.join("m.exr"))]);
        assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
        assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
        assert!(start.elapsed().as_secs() < 30);
    }
    dir.close().unwrap();
}

#[test]
fn skip_existing_renders_again_frames_that_are_not_finished() {
    let dir = scratch("broken-frames");
    let scene = format!("{}/scenes/focus_pull.toml", env!("CARGO_MANIFEST_DIR"));
    let pattern = dir.join("f_##.png");
    let args = |extra: &[&'static str]| {
        let mut a = vec![
            "render",
            scene.as_str(),
            "-o",
            s(&pattern),
            "--frames",
            "1-4",
        ];
        a.extend_from_slice(&["--width", "40", "--spp", "2", "--json"]);
        a.extend_from_slice(extra);
        a.iter().map(|x| x.to_string()).collect::<Vec<_>>()
    };
    let run = |extra: &[&'static str]| {
        let a = args(extra);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        dofray(&a)
    };
    let o = run(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frame = |n: u32| dir.join(format!("f_{n:02}.png"));
    let good: Vec<Vec<u8>> = (1..=4).map(|n| std::fs::read(frame(n)).unwrap()).collect();
    // Frame 2 truncated (a broken copy), 3 empty (a full disk), 4 of another size.
    std::fs::write(frame(2), &good[1][..good[1].len() / 2]).unwrap();
    std::fs::write(frame(3), b"").unwrap();
    let small = dir.join("small.png");
    let o = dofray(&[
        "render",
        "-o",
        s(&small),
        "--width",
        "8",
        "--height",
        "6",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::rename(&small, frame(4)).unwrap();
    let o = run(&["--skip-existing"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j = json(&o);
    let status: Vec<&str> = j["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["skipped", "rendered", "rendered", "rendered"]);
    let err = stderr(&o);
    for (n, why) in [(2, "incomplete PNG"), (3, "empty"), (4, "8x6 pixels")] {
        let name = format!("f_{n:02}.png");
        assert!(
            err.lines()
                .any(|l| l.contains(&name) && l.contains(why) && l.starts_with("warning:")),
            "frame {n}: {err}"
        );
    }
    // The frames rendered again are the frames a clean run writes.
    for n in 2..=4 {
        assert_eq!(png_pixels(&frame(n)), {
            let p = dir.join("ref.png");
            std::fs::write(&p, &good[n as usize - 1]).unwrap();
            png_pixels(&p)
        });
    }
    dir.close().unwrap();
}

#[test]
fn concurrent_runs_of_the_same_tiles_all_succeed() {
    // A requeued task overlapping its original: one run merges and removes the tiles while
    // another is about to read them. Before, the second failed (and with afterok cancelled
    // the work downstream); four at once, three times, hit that race nearly every time.
    let dir = scratch("twins");
    let reference = dir.join("ref.exr");
    let size = ["--width", "64", "--height", "48", "--spp", "4"];
    let o = dofray(&[&["render", "-o", s(&reference), "-q"][..], &size].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let image = dir.join("img.exr");
    for round in 0..3 {
        let children: Vec<_> = (0..4)
            .map(|_| {
                cmd()
                    .args(["render", "-o", s(&image), "--tiles", "4x2", "-q"])
                    .args(size)
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        // All four waited for before any is checked: none still writes to the scratch
        // directory when a failed check ends the test and removes it.
        let outputs: Vec<Output> = children
            .into_iter()
            .map(|child| child.wait_with_output().unwrap())
            .collect();
        for o in outputs {
            assert!(o.status.success(), "round {round}: {}", stderr(&o));
        }
        assert!(
            exr_pixels(&image) == exr_pixels(&reference),
            "round {round}"
        );
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tile-"))
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "round {round}: tiles left {left:?}");
    }
    dir.close().unwrap();
}
