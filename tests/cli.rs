//! The `dofray` command: summaries, outputs and clear rejections of bad arguments.

use std::path::PathBuf;
use std::process::{Command, Output};

fn dofray(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args(args)
        .output()
        .expect("run dofray")
}

/// A fresh, empty scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dofray-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn renders_png_and_exr_with_a_json_summary() {
    let dir = scratch("ok");
    let png = dir.join("out.png");
    let out = dofray(&[
        "render",
        "-o",
        png.to_str().unwrap(),
        "--width",
        "80",
        "--height",
        "60",
        "--json",
        "--aov-dir",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    for key in [
        "mode",
        "width",
        "height",
        "spp",
        "interval_factor",
        "seconds",
        "rays",
        "primary_rays",
        "shadow_rays",
        "sample_sites",
        "mrays_per_s",
    ] {
        assert!(json.get(key).is_some(), "missing {key} in {json}");
    }
    assert_eq!(json["mode"], "adaptive");
    assert_eq!(json["width"], 80);
    assert_eq!(json["spp"], 16);
    let rays = json["rays"].as_u64().unwrap();
    let parts = json["primary_rays"].as_u64().unwrap()
        + json["shadow_rays"].as_u64().unwrap()
        + json["secondary_rays"].as_u64().unwrap();
    assert_eq!(rays, parts);
    assert!(json["primary_rays"].as_u64().unwrap() >= 80 * 60);
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (80, 60));
    assert!(dir.join("depth.png").is_file() && dir.join("interval.png").is_file());

    let exr = dir.join("out.exr");
    let out = dofray(&[
        "render",
        "-o",
        exr.to_str().unwrap(),
        "--width",
        "40",
        "--mode",
        "dense",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        out.stdout.is_empty() && out.stderr.is_empty(),
        "--quiet prints nothing"
    );
    let layers = exr::prelude::read_all_flat_layers_from_file(&exr).unwrap();
    let names: Vec<String> = layers.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for name in ["R", "G", "B", "Z", "coc", "interval", "samples"] {
        assert!(
            names.iter().any(|n| n == name),
            "{name} missing from {names:?}"
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bad_arguments_are_rejected_with_a_message_and_no_output() {
    let dir = scratch("bad");
    let png = dir.join("out.png");
    let p = png.to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["--width", "0"], "--width"),
        (&["--height", "0"], "--height"),
        (&["--aperture-radius=-0.5"], "--aperture-radius"),
        (&["--focus-distance", "0"], "--focus-distance"),
        (&["--focus-distance=-3"], "--focus-distance"),
        (&["--spp", "0"], "--spp"),
        (&["--interval-factor", "0"], "--interval-factor"),
        (&["--interval-factor=-1"], "--interval-factor"),
        (&["--f-number", "0"], "f_number"),
        (&["--blades", "2"], "blades"),
        (&["--autofocus", "5000,1"], "autofocus"),
        (&["no-such-scene"], "unknown scene"),
    ];
    for (args, needle) in cases {
        let mut all = vec!["render", "-o", p, "--width", "32", "--quiet"];
        all.extend_from_slice(args);
        let out = dofray(&all);
        let err = stderr(&out);
        assert!(!out.status.success(), "{args:?} should fail");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!png.exists(), "{args:?} left an output file");
    }
    let unwritable = dofray(&[
        "render",
        "-o",
        "/nonexistent-dir/x/out.png",
        "--width",
        "16",
    ]);
    assert!(!unwritable.status.success());
    assert!(
        stderr(&unwritable).contains("/nonexistent-dir/x/out.png"),
        "{}",
        stderr(&unwritable)
    );
    let jpg = dir.join("out.jpg");
    let unknown = dofray(&["render", "-o", jpg.to_str().unwrap(), "--width", "16"]);
    assert!(!unknown.status.success());
    assert!(
        stderr(&unknown).contains(".png or .exr"),
        "{}",
        stderr(&unknown)
    );
    assert!(!jpg.exists());
    // Nothing at all was left behind (no temporary files either).
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn help_and_scene_list() {
    let out = dofray(&["render", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    for flag in [
        "--mode",
        "--spp",
        "--interval-factor",
        "--paper-exact",
        "--json",
        "--aov-dir",
    ] {
        assert!(text.contains(flag), "help lacks {flag}");
    }
    let out = dofray(&["scenes"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("paper"));
}
