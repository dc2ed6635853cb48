//! The `dofray` command: summaries, outputs and clear rejections of bad arguments.

use std::process::{Command, Output};

use crate::scratch::Scratch;

fn dofray(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args(args)
        .output()
        .expect("run dofray")
}

/// A fresh, empty scratch directory for one test.
fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("cli-{name}"))
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
    // By bounce: the camera rays at 0, the path tracer's bounces after; they add up to the
    // kinds.
    let sum = |key: &str| -> u64 {
        let list = json[key]
            .as_array()
            .unwrap_or_else(|| panic!("{key} in {json}"));
        list.iter().map(|v| v.as_u64().unwrap()).sum()
    };
    assert_eq!(json["rays_by_bounce"][0], json["primary_rays"]);
    assert_eq!(
        sum("rays_by_bounce"),
        json["primary_rays"].as_u64().unwrap() + json["secondary_rays"].as_u64().unwrap()
    );
    assert_eq!(
        sum("shadow_rays_by_bounce"),
        json["shadow_rays"].as_u64().unwrap()
    );
    assert!(
        json["rays_by_bounce"].as_array().unwrap().len() > 2,
        "{json}"
    );
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (80, 60));
    assert!(dir.join("depth.png").is_file() && dir.join("interval.png").is_file());
    // The phases of the render add up to no more than its time.
    let phases: f64 = [
        "pinhole_seconds",
        "maps_seconds",
        "sites_seconds",
        "interpolate_seconds",
        "light_seconds",
    ]
    .iter()
    .map(|k| {
        json[*k]
            .as_f64()
            .unwrap_or_else(|| panic!("missing {k} in {json}"))
    })
    .sum();
    assert!(phases > 0.0 && phases <= json["seconds"].as_f64().unwrap());
    // Lending samples between sites (reuse, on by default) is part of the sites' time.
    let reuse = json["reuse_seconds"].as_f64().unwrap();
    assert!(
        reuse > 0.0 && reuse <= json["sites_seconds"].as_f64().unwrap(),
        "{json}"
    );
    // A missing --aov-dir is created.
    let nested = dir.join("new").join("aovs");
    let out = dofray(&[
        "render",
        "-o",
        png.to_str().unwrap(),
        "--width",
        "40",
        "--quiet",
        "--aov-dir",
        nested.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(nested.join("depth.png").is_file() && nested.join("interval.png").is_file());

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
    for name in dofray::output::exr::CHANNELS {
        assert!(
            names.iter().any(|n| n == name),
            "{name} missing from {names:?}"
        );
    }
    dir.close().unwrap();
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
        (
            &["--f-number", "0"],
            "--f-number must be a finite number > 0",
        ),
        (&["--f-number=-2"], "--f-number must be"),
        (
            &["--f-number", "2", "--focal-length", "0"],
            "--focal-length must be",
        ),
        (
            &["--f-number", "2", "--sensor-width", "nan"],
            "--sensor-width must be",
        ),
        (
            &["--anamorphic", "0"],
            "--anamorphic must be a finite number > 0",
        ),
        (
            &["--f-number", "2", "--focal-length", "1e-30"],
            "no usable field of view",
        ),
        (&["--blades", "2"], "--blades must be 0"),
        (&["--blade-rotation", "inf"], "--blade-rotation must be"),
        // The paper scene's lens is an aperture radius, not a photographic lens.
        (
            &["--focal-length", "85"],
            "--focal-length applies to a photographic lens",
        ),
        (&["--sensor-width", "24"], "give --f-number too"),
        (
            &["--autofocus", "1,1", "--focus-distance", "3"],
            "cannot be used with",
        ),
        (
            &["--aperture-radius", "0.1", "--f-number", "2"],
            "cannot be used with",
        ),
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
    dir.close().unwrap();
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
        "--exr-half",
        "--exr-compression",
    ] {
        assert!(text.contains(flag), "help lacks {flag}");
    }
    // How the lens flags combine with the scene's lens is documented.
    for phrase in [
        "from the scene's photographic\n          lens; else the sensor is 36 mm and the focal length the one that keeps the scene's\n          field of view on it",
        "it needs --f-number",
    ] {
        let flat = |t: &str| t.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            flat(&text).contains(&flat(phrase)),
            "help lacks {phrase:?}:\n{text}"
        );
    }
    let out = dofray(&["scenes"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("paper"));
}

#[test]
fn bench_reports_every_mode_and_caches_the_reference() {
    let dir = scratch("bench");
    let cache = dir.join("cache");
    let out_dir = dir.join("out");
    let args = [
        "bench",
        "--width",
        "64",
        "--reference-spp",
        "64",
        "--repeat",
        "1",
        "--json",
        "--cache-dir",
        cache.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ];
    let first = dofray(&args);
    assert!(first.status.success(), "{}", stderr(&first));
    let report: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
    assert_eq!(report["reference_cached"], false);
    assert_eq!(report["schema_version"], 1);
    assert_eq!(report["git_commit"], dofray::GIT_COMMIT);
    assert!(report["intersect_only_mrays_per_s"].as_f64().unwrap() > 0.0);
    let rows = report["rows"].as_array().unwrap();
    let labels: Vec<&str> = rows.iter().map(|r| r["label"].as_str().unwrap()).collect();
    assert_eq!(
        labels,
        [
            "pinhole",
            "dense",
            "adaptive",
            "adaptive-k0.4",
            "adaptive-k0.2",
            "adaptive-paper-k0.4"
        ]
    );
    for row in rows {
        for key in [
            "mode",
            "interval_factor",
            "seconds",
            "rays",
            "mrays_per_s",
            "sample_sites",
            "speedup_vs_dense",
            "psnr_vs_dense",
            "psnr_vs_reference",
            "ssim_vs_reference",
        ] {
            assert!(row.get(key).is_some(), "{key} missing in {row}");
        }
    }
    assert_eq!(rows[1]["speedup_vs_dense"], 1.0);
    // Dense against itself is infinitely close: JSON null.
    assert!(rows[1]["psnr_vs_dense"].is_null());
    // Adaptive traces fewer rays than dense, pinhole fewest.
    let rays = |i: usize| rows[i]["rays"].as_u64().unwrap();
    assert!(rays(0) < rays(2) && rays(2) < rays(1));
    for file in [
        "reference.png",
        "dense.png",
        "adaptive.png",
        "adaptive-k0.4.png",
        "depth.png",
        "interval.png",
        "samples.png",
        "comparison.png",
        "error-adaptive.png",
    ] {
        assert!(out_dir.join(file).is_file(), "{file} not written");
    }
    let second = dofray(&args);
    let report: serde_json::Value = serde_json::from_slice(&second.stdout).unwrap();
    assert_eq!(
        report["reference_cached"], true,
        "second run reuses the reference"
    );
    assert_eq!(report["integrator"], "path");
    // Reuse changes adaptive's renders only: dense and the reference are the same, so the
    // cached reference serves it.
    let reuse_args: Vec<&str> = args.iter().copied().chain(["--reuse", "on"]).collect();
    let reuse: serde_json::Value = serde_json::from_slice(&dofray(&reuse_args).stdout).unwrap();
    assert_eq!(reuse["reference_cached"], true, "--reuse on shares it");
    assert_eq!(reuse["rows"][1]["rays"], report["rows"][1]["rays"]);
    // The other integrator renders (and caches) its own reference: a reference is never
    // shared between integrators, whose images differ.
    let direct_args: Vec<&str> = args
        .iter()
        .copied()
        .chain(["--integrator", "direct"])
        .collect();
    let direct = dofray(&direct_args);
    assert!(direct.status.success(), "{}", stderr(&direct));
    let direct: serde_json::Value = serde_json::from_slice(&direct.stdout).unwrap();
    assert_eq!(direct["integrator"], "direct");
    assert_eq!(direct["reference_cached"], false);
    // The direct integrator's dense row traces fewer rays than the path tracer's (no bounces
    // beyond mirrors on the paper scene).
    let dense_rays = |r: &serde_json::Value| r["rows"][1]["rays"].as_u64().unwrap();
    assert!(dense_rays(&direct) < dense_rays(&report));
    let again: serde_json::Value = serde_json::from_slice(&dofray(&direct_args).stdout).unwrap();
    assert_eq!(again["reference_cached"], true);
    dir.close().unwrap();
}

#[test]
fn bench_reference_ceiling_predicts_what_dense_measures() {
    // The reference (32 spp) is two independent 16-spp halves, averaged. A dense rung at 16
    // spp is a third such render: its squared error against the reference is v + v / 2 (its
    // own noise v, the reference's v / 2), three times the reference's, so the ceiling (what
    // a noise-free render would measure) lies 10 log10(3) = 4.77 dB above dense's PSNR.
    let dir = scratch("ceiling");
    let cache = dir.join("cache");
    let args = [
        "bench",
        "--equal-error",
        "--width",
        "128",
        "--height",
        "96",
        "--ladder",
        "16",
        "--levels",
        "30",
        "--reference-spp",
        "32",
        "--repeat",
        "1",
        "--cache-dir",
        cache.to_str().unwrap(),
    ];
    let out = dofray(&[&args[..], &["--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let ceiling = report["reference_ceiling_db"].as_f64().expect("a ceiling");
    let dense = report["dense"][0]["psnr_vs_reference"].as_f64().unwrap();
    assert!(
        (ceiling - dense - 4.77).abs() < 0.75,
        "ceiling {ceiling:.2} dB, dense {dense:.2} dB: {:.2} apart",
        ceiling - dense
    );
    // The cached reference keeps its ceiling.
    let again = dofray(&args);
    assert!(again.status.success(), "{}", stderr(&again));
    let text = String::from_utf8_lossy(&again.stdout);
    assert!(text.contains("(cached)"), "{text}");
    assert!(
        text.contains(&format!("would measure {ceiling:.2} dB against it")),
        "{text}"
    );
    dir.close().unwrap();
}

#[test]
fn bench_equal_error_reports_levels_rungs_and_a_plot() {
    let dir = scratch("equal-error");
    let cache = dir.join("cache");
    let out_dir = dir.join("out");
    let common = [
        "bench",
        "--equal-error",
        "--width",
        "64",
        "--height",
        "48",
        "--ladder",
        "8,4",
        "--levels",
        "15,35,90",
        "--reference-spp",
        "32",
        "--repeat",
        "1",
        "--cache-dir",
        cache.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ];
    let out = dofray(&[&common[..], &["--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["width"], 64);
    assert_eq!(report["reference_spp"], 32);
    assert_eq!(report["schema_version"], 1);
    assert_eq!(report["dofray_version"], env!("CARGO_PKG_VERSION"));
    for method in ["dense", "adaptive"] {
        let rungs = report[method].as_array().unwrap();
        // The ladder, sorted.
        let spp: Vec<u64> = rungs.iter().map(|r| r["spp"].as_u64().unwrap()).collect();
        assert_eq!(spp, [4, 8], "{method}");
        for r in rungs {
            for key in [
                "seconds",
                "rays",
                "psnr_vs_reference",
                "samples",
                "sample_sites",
                "light_paths",
            ] {
                assert!(r.get(key).is_some(), "{key} missing in {r}");
            }
            assert!(r["samples"].as_u64().unwrap() > 0);
            assert!(r["psnr_vs_reference"].as_f64().unwrap() > 10.0, "{r}");
            // Where the error is: six blur bands whose pixels and errors add up to the whole.
            let bands = r["error_by_blur"].as_array().unwrap();
            assert_eq!(bands.len(), 6, "{r}");
            let sum = |key: &str| bands.iter().map(|b| b[key].as_f64().unwrap()).sum::<f64>();
            assert!((sum("pixels") - 1.0).abs() < 1e-9, "{r}");
            assert!((sum("error") - 1.0).abs() < 1e-9, "{r}");
            assert!(bands[0]["lo"].is_null() && bands[5]["hi"].is_null(), "{r}");
            // The paper scene at 64 px: most of it is blurred, some of it sharp.
            assert!(bands[0]["pixels"].as_f64().unwrap() < 0.5, "{r}");
            assert!(bands[0]["pixels"].as_f64().unwrap() > 0.0, "{r}");
        }
    }
    // Dense shades every pixel: 4 spp at every site (the path tracer's in-focus sites take
    // as many samples as blurred ones: the scene's aa / spp is 1).
    assert_eq!(report["dense"][0]["aa"], 4);
    assert_eq!(report["dense"][0]["sample_sites"], 64 * 48);
    assert!(report["dense"][0]["tolerance"].is_null());
    assert_eq!(report["adaptive"][0]["tolerance"], 2.0);
    let levels = report["levels"].as_array().unwrap();
    let db: Vec<f64> = levels
        .iter()
        .map(|l| l["psnr_db"].as_f64().unwrap())
        .collect();
    assert_eq!(db, [15.0, 35.0, 90.0]);
    // 15 dB: both reach it at their cheapest rung (upper bounds).
    assert_eq!(levels[0]["dense"]["at_first_rung"], true);
    assert_eq!(levels[0]["speedup_bound"], "unknown");
    assert!(levels[0]["speedup"].as_f64().unwrap() > 0.0);
    // 90 dB: beyond any ladder.
    assert!(levels[2]["dense"]["seconds"].is_null());
    assert!(levels[2]["adaptive"]["seconds"].is_null());
    assert!(levels[2]["speedup"].is_null());
    assert!(report["highest_common"]["psnr_db"].as_f64().unwrap() > 10.0);
    let plot = out_dir.join("equal-error.png");
    assert_eq!(report["plot"], plot.to_str().unwrap());
    let png = image::open(&plot).expect("a PNG");
    assert_eq!((png.width(), png.height()), (960, 600));
    // The equal-time picture: reference, dense and adaptive, whole and cropped, under labels.
    let pair = &report["equal_time"];
    let picture = out_dir.join("equal-time.png");
    assert_eq!(pair["picture"], picture.to_str().unwrap());
    let crop: Vec<u64> = (0..4).map(|i| pair["crop"][i].as_u64().unwrap()).collect();
    assert_eq!(crop[2..], [16, 16], "a third of the shorter side");
    assert!(crop[0] + 16 <= 64 && crop[1] + 16 <= 48);
    assert!(
        pair["dense_rung"].as_u64().unwrap() < 2 && pair["adaptive_rung"].as_u64().unwrap() < 2
    );
    let png = image::open(&picture).expect("a PNG").to_rgb8();
    assert_eq!((png.width(), png.height()), (3 * 64, 40 + 2 * 48));
    // The reference column's top half is the cached reference's sRGB picture: not blank.
    let top: std::collections::HashSet<_> = (0..48).map(|y| png.get_pixel(10, 40 + y).0).collect();
    assert!(top.len() > 3, "{top:?}");

    // The table, with the reference now cached.
    let out = dofray(&common);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = String::from_utf8_lossy(&out.stdout);
    for phrase in [
        "reference 32 spp (cached)",
        "90 dB",
        "not reached",
        "highest level both reach",
        "where the error is at 8 spp",
        "plot: ",
        "at about equal time: dense ",
        "side by side",
    ] {
        assert!(table.contains(phrase), "table lacks {phrase:?}:\n{table}");
    }
    dir.close().unwrap();
}

#[test]
fn bench_equal_error_flags_are_checked() {
    for (args, expected) in [
        (&["bench", "--ladder", "4,8"][..], "--equal-error"),
        (
            &["bench", "--equal-error", "--spp", "4"][..],
            "cannot be used",
        ),
        (
            &["bench", "--equal-error", "--ladder", "4,0", "--width", "8"][..],
            "--ladder",
        ),
        (
            &[
                "bench",
                "--equal-error",
                "--levels",
                "30,nan",
                "--width",
                "8",
            ][..],
            "--levels",
        ),
        (
            &[
                "bench",
                "--equal-error",
                "--ladder",
                "4,64",
                "--reference-spp",
                "64",
            ][..],
            "must exceed the ladder's largest rung (64)",
        ),
    ] {
        let out = dofray(args);
        assert!(!out.status.success(), "{args:?} was accepted");
        assert!(
            stderr(&out).contains(expected),
            "{args:?}: {}",
            stderr(&out)
        );
    }
    let help = dofray(&["bench", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    for phrase in [
        "--equal-error",
        "--ladder",
        "--levels",
        "log seconds",
        "equal-error.png",
    ] {
        assert!(text.contains(phrase), "help lacks {phrase:?}");
    }
}

fn repo(rel: &str) -> String {
    format!("{}/{rel}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn renders_scene_files_and_models() {
    let dir = scratch("files");
    for (input, extra) in [
        ("scenes/paper.toml", &["--autofocus", "40,30"][..]),
        ("scenes/gallery.toml", &[][..]),
        ("scenes/vase.toml", &["--spp", "4", "--f-number", "2"][..]),
        ("scenes/assets/vase.glb", &[][..]),
        ("scenes/assets/torus.obj", &["--mode", "dense"][..]),
    ] {
        let png = dir.join("out.png");
        let _ = std::fs::remove_file(&png);
        let path = repo(input);
        let mut args = vec![
            "render",
            &path,
            "-o",
            png.to_str().unwrap(),
            "--width",
            "80",
            "--json",
        ];
        args.extend_from_slice(extra);
        let out = dofray(&args);
        assert!(out.status.success(), "{input}: {}", stderr(&out));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(json["width"], 80, "{input}");
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(img.width(), 80, "{input}");
        // Something is in view: the picture is not one flat colour.
        let first = img.get_pixel(0, 0);
        assert!(img.pixels().any(|p| p != first), "{input}: a flat image");
    }
}

#[test]
fn bad_scene_files_and_huge_images_are_refused_without_output() {
    let dir = scratch("refuse");
    let png = dir.join("out.png");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[camera]\nvfov = 40\nfov = 40\n").unwrap();
    let missing = dir.join("missing.obj");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec![bad.display().to_string()], "bad.toml:3"),
        (vec![bad.display().to_string()], "unknown field `fov`"),
        (
            vec![missing.display().to_string()],
            "missing.obj: cannot read",
        ),
        (
            vec!["no-such-scene".into()],
            "unknown scene \"no-such-scene\"",
        ),
        (
            vec![
                "paper".into(),
                "--width".into(),
                "400000".into(),
                "--height".into(),
                "400000".into(),
            ],
            "choose a smaller --width/--height",
        ),
    ];
    for (args, expected) in cases {
        let mut all = vec!["render".to_string(), "-o".into(), png.display().to_string()];
        all.extend(args);
        let all: Vec<&str> = all.iter().map(String::as_str).collect();
        let out = dofray(&all);
        assert!(!out.status.success(), "{all:?} succeeded");
        let err = stderr(&out);
        assert!(err.contains(expected), "{all:?}: {err}");
        assert!(!png.exists(), "{all:?} left an output file");
    }
}

#[test]
fn lights_from_the_command_line_replace_the_scenes() {
    let dir = scratch("lights");
    let mean = |light: &str| {
        let png = dir.join("l.png");
        let out = dofray(&[
            "render",
            "-o",
            png.to_str().unwrap(),
            "--width",
            "48",
            "--mode",
            "pinhole",
            "--ambient",
            "0",
            "--light",
            light,
            "--quiet",
        ]);
        assert!(out.status.success(), "{light}: {}", stderr(&out));
        let img = image::open(&png).unwrap().to_luma8();
        img.pixels().map(|p| p.0[0] as f64).sum::<f64>() / img.pixels().len() as f64
    };
    // A spot light parses and renders.
    assert!(mean("spot:0,6,4:0,-1,-0.5:200:40:30") > 0.0);
    let bright = mean("sun:0.3,-1,0.2:3");
    let dim = mean("sun:0.3,-1,0.2:0.5");
    assert!(bright > dim + 10.0, "bright {bright} vs dim {dim}");

    for (light, expected) in [
        ("moon:1,2,3", "expected point, sun or spot"),
        ("spot:0,5,0", "expected spot:X,Y,Z:DX,DY,DZ"),
        ("spot:0,5,0:0,0,0", "must not be 0,0,0"),
        ("spot:0,5,0:0,-1,0:100:30:40", "0 <= inner <= outer"),
        ("point:1,2", "three coordinates"),
        ("point:1,2,3:-4", ">= 0"),
        ("sun:0,0,0", "must not be 0,0,0"),
    ] {
        let out = dofray(&["render", "-o", "x.png", "--light", light]);
        assert!(!out.status.success(), "{light} accepted");
        assert!(stderr(&out).contains(expected), "{light}: {}", stderr(&out));
    }
}

/// Renders the repository's `scene` 40 pixels wide to `png` with `flags`, which must succeed;
/// returns what it printed.
fn render_small(png: &std::path::Path, scene: &str, flags: &[&[&str]]) -> Vec<u8> {
    let path = repo(scene);
    let mut args = vec![
        "render",
        &path,
        "-o",
        png.to_str().unwrap(),
        "--width",
        "40",
    ];
    args.extend(flags.iter().flat_map(|f| f.iter().copied()));
    let out = dofray(&args);
    assert!(out.status.success(), "{scene} {flags:?}: {}", stderr(&out));
    out.stdout
}

/// The JSON summary of a small one-sample render of `scene` with `extra` flags.
fn summary(dir: &std::path::Path, scene: &str, extra: &[&str]) -> serde_json::Value {
    let out = render_small(
        &dir.join("lens.png"),
        scene,
        &[&["--spp", "1", "--json"], extra],
    );
    serde_json::from_slice(&out).unwrap()
}

#[test]
fn lens_flags_keep_what_the_scene_says_unless_replaced() {
    let dir = scratch("lens");
    let radius = |v: &serde_json::Value| v["aperture_radius"].as_f64().unwrap();
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6 * b;
    // gallery.toml: a 35 mm f/1.4 lens on a 36 mm sensor; radius = focal / (2 N).
    let scene = radius(&summary(&dir, "scenes/gallery.toml", &[]));
    assert!(close(scene, 0.035 / 2.8), "{scene}");
    // --f-number alone keeps the scene's focal length (not 50 mm).
    let f4 = radius(&summary(&dir, "scenes/gallery.toml", &["--f-number", "4"]));
    assert!(close(f4, 0.035 / 8.0), "{f4}");
    // --focal-length alone changes the scene's photographic lens.
    let f85 = radius(&summary(
        &dir,
        "scenes/gallery.toml",
        &["--focal-length", "85"],
    ));
    assert!(close(f85, 0.085 / 2.8), "{f85}");
    let both = radius(&summary(
        &dir,
        "scenes/gallery.toml",
        &["--f-number", "2", "--focal-length", "50"],
    ));
    assert!(close(both, 0.05 / 4.0), "{both}");
    // On a scene whose lens is not photographic, --f-number brings the focal length that keeps
    // its field of view on a 36 mm sensor (a new aperture does not reframe the shot).
    let vase = summary(&dir, "scenes/vase.toml", &["--f-number", "2"]);
    let text = std::fs::read_to_string(repo("scenes/vase.toml")).unwrap();
    let table: toml::Table = text.parse().unwrap();
    let v = &table["camera"]["vfov"];
    let vfov = v.as_float().or(v.as_integer().map(|i| i as f64)).unwrap();
    let (w, h) = (
        vase["width"].as_f64().unwrap(),
        vase["height"].as_f64().unwrap(),
    );
    let focal_mm = 18.0 / ((vfov.to_radians() / 2.0).tan() * w / h);
    assert!(
        (radius(&vase) - focal_mm / 1000.0 / 4.0).abs() < 1e-4 * radius(&vase),
        "{vase} against {focal_mm} mm"
    );

    // --sensor-width alone changes the field of view of a photographic scene: another picture.
    let picture = |extra: &[&str]| {
        let png = dir.join("fov.png");
        let flags: &[&[&str]] = &[&["--mode", "pinhole", "--quiet"], extra];
        render_small(&png, "scenes/gallery.toml", flags);
        image::open(&png).unwrap().to_rgb8().into_raw()
    };
    let wide = picture(&[]);
    assert_eq!(
        wide,
        picture(&["--sensor-width", "36"]),
        "the scene's own width"
    );
    assert_ne!(
        wide,
        picture(&["--sensor-width", "18"]),
        "--sensor-width ignored"
    );
    assert_ne!(
        wide,
        picture(&["--focal-length", "70"]),
        "--focal-length ignored"
    );
    // Replacing the photographic lens by an aperture radius keeps the field of view it gave.
    assert_eq!(
        wide,
        picture(&["--aperture-radius", "0.01"]),
        "the framing changed"
    );
    dir.close().unwrap();
}

#[test]
fn bad_model_files_fail_with_the_file_named_and_no_output() {
    let dir = scratch("badmodels");
    let png = dir.join("out.png");
    let jpg = std::fs::read(repo("scenes/assets/bands.jpg")).unwrap();
    std::fs::write(dir.join("t.jpg"), &jpg[..jpg.len() * 9 / 10]).unwrap();
    std::fs::write(
        dir.join("tex.toml"),
        "[[textures]]\nname = \"t\"\nimage = \"t.jpg\"\n[[materials]]\nname = \"m\"\n\
         texture = \"t\"\n[[objects]]\ntype = \"sphere\"\nradius = 1\nmaterial = \"m\"\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("short.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("huge.obj"),
        "v 3e38 0 0\nv -3e38 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("huge.toml"),
        "[[objects]]\ntype = \"sphere\"\nradius = 1e38\n",
    )
    .unwrap();
    for (file, expected) in [
        ("tex.toml", "t.jpg: truncated JPEG"),
        ("short.obj", "short.obj:5: face with 2 corners"),
        (
            "huge.obj",
            "huge.obj: the scene bounds are too large to frame",
        ),
        (
            "huge.toml",
            "huge.toml:1:1: `objects[0]`: the scene bounds are too large",
        ),
    ] {
        let input = dir.join(file);
        let out = dofray(&[
            "render",
            input.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
            "--width",
            "32",
            "--quiet",
        ]);
        assert!(!out.status.success(), "{file} accepted");
        assert!(stderr(&out).contains(expected), "{file}: {}", stderr(&out));
        assert!(
            !stderr(&out).contains("panicked"),
            "{file}: {}",
            stderr(&out)
        );
        assert!(!png.exists(), "{file} left an output file");
    }
    dir.close().unwrap();
}

/// The seed's lens from the command line: the aperture follows from the sharp range and the
/// spread (`R = spread P^2 / (2 k range)`, k the pixels per unit at unit distance), and the two
/// flags only make sense together.
#[test]
fn seed_lens_flags_derive_the_aperture() {
    let dir = scratch("seedlens");
    let png = dir.join("seed.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "-o", png.to_str().unwrap(), "--width", "160"];
        args.extend_from_slice(&["--mode", "pinhole", "--json", "--quiet"]);
        args.extend_from_slice(extra);
        dofray(&args)
    };
    let out = render(&["--sharp-range", "1", "--spread", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let p = json["focus_distance"].as_f64().unwrap();
    let k = 120.0 / (2.0 * 20f64.to_radians().tan()); // 160x120, vfov 40 degrees
    let want = 2.0 * p * p / (2.0 * k * 1.0);
    let got = json["aperture_radius"].as_f64().unwrap();
    assert!(
        (got - want).abs() < 1e-3 * want,
        "aperture {got}, want {want}"
    );
    std::fs::remove_file(&png).unwrap();

    for (extra, message) in [
        (&["--sharp-range", "1"][..], "--spread"),
        (
            &["--sharp-range", "0", "--spread", "2"][..],
            "--sharp-range must be",
        ),
        (
            &["--sharp-range", "1", "--spread", "-1"][..],
            "unexpected argument",
        ),
        (
            &["--sharp-range", "1", "--spread", "2", "--f-number", "2"][..],
            "cannot be used",
        ),
    ] {
        let out = render(extra);
        assert!(!out.status.success(), "{extra:?} was accepted");
        assert!(
            stderr(&out).contains(message),
            "{extra:?}: {}",
            stderr(&out)
        );
        assert!(!png.exists(), "{extra:?} left an output file");
    }
}

/// `--threads N` bounds every thread of the process, Embree's BVH builders included (they
/// used to start one per core whatever `--threads` said), and `DOFRAY_EMBREE_CONFIG` pins
/// Embree's kernels for a run.
#[test]
fn threads_bound_embree_too_and_the_environment_configures_embree() {
    let dir = scratch("threads");
    let png = dir.join("t.png");
    // What this test run's own DOFRAY_EMBREE_CONFIG says (`isa=avx2` to run the suite on
    // the AVX2 kernels) comes first.
    let inherited = std::env::var("DOFRAY_EMBREE_CONFIG").unwrap_or_default();
    let sep = if inherited.is_empty() { "" } else { "," };
    for n in [1u64, 2] {
        let json = summary(&dir, "scenes/gallery.toml", &["--threads", &n.to_string()]);
        assert_eq!(json["threads"], n);
        assert_eq!(
            json["embree"]["config"],
            format!("{inherited}{sep}threads={n}")
        );
        // n render workers; Embree's builder pool is the main thread plus n - 1 workers and
        // never runs at the same time as the render: at most n threads compute at once. One
        // more thread only waits for SIGINT / SIGTERM (to remove temporary files).
        let process = json["process_threads"]
            .as_u64()
            .expect("Linux reports threads");
        assert!(
            process <= 2 * n + 1,
            "--threads {n}: {process} threads in all"
        );
    }
    for bad in ["0", "5000", "x"] {
        let out = dofray(&["render", "-o", png.to_str().unwrap(), "--threads", bad]);
        assert!(!out.status.success() && stderr(&out).contains("--threads"));
        assert!(!png.exists());
    }
    let out = Command::new(env!("CARGO_BIN_EXE_dofray"))
        .args(["render", "--width", "40", "--spp", "1", "--json", "-o"])
        .arg(&png)
        .env("DOFRAY_EMBREE_CONFIG", "isa=sse4.2")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["embree"]["config"], "isa=sse4.2");
    assert_eq!(json["embree"]["native_packet_width"], 4);
    assert_eq!(json["embree"]["lanes_per_call"], 16);
}

#[test]
fn the_site_rule_follows_the_flags_and_the_scene_file() {
    let dir = scratch("rule");
    let png = dir.join("rule.png");
    let json = |flags: &[&str]| -> serde_json::Value {
        let mut args = vec!["render", "-o", png.to_str().unwrap(), "--width", "64"];
        args.extend_from_slice(&["--height", "48", "--json"]);
        args.extend_from_slice(flags);
        let out = dofray(&args);
        assert!(out.status.success(), "{flags:?}: {}", stderr(&out));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    // The error-controlled rule by default, at 4 / sqrt(spp).
    let default = json(&["--aov-dir", dir.to_str().unwrap()]);
    assert_eq!(default["rule"], "error");
    assert_eq!(default["tolerance"], 1.0);
    assert!(default["interval_factor"].is_null());
    assert!(default["rounds"].as_u64().unwrap() >= 1);
    assert!(dir.join("samples.png").is_file());
    assert_eq!(json(&["--spp", "64"])["tolerance"], 0.5);
    assert_eq!(json(&["--tolerance", "2.5"])["tolerance"], 2.5);
    // -k or --paper-exact: the seed's rule.
    let seed = json(&["-k", "0.3"]);
    assert_eq!(
        (seed["rule"].as_str(), seed["rounds"].as_u64()),
        (Some("seed"), Some(0))
    );
    assert_eq!(seed["interval_factor"], 0.3);
    assert!(seed["tolerance"].is_null());
    assert_eq!(json(&["--paper-exact"])["interval_factor"], 0.4);
    // Both rules at once, or a tolerance that is no error bound, are refused.
    for (flags, want) in [
        (&["--tolerance", "1", "-k", "0.4"][..], "--tolerance"),
        (
            &["--tolerance", "0"][..],
            "--tolerance must be a finite number > 0",
        ),
        (&["--tolerance", "nan"][..], "--tolerance"),
    ] {
        let mut args = vec!["render", "-o", png.to_str().unwrap(), "--width", "16"];
        args.extend_from_slice(flags);
        let out = dofray(&args);
        assert!(!out.status.success(), "{flags:?} was accepted");
        assert!(stderr(&out).contains(want), "{flags:?}: {}", stderr(&out));
    }
    // A scene file picks a rule too; the command line's wins.
    let scene = dir.join("rule.toml");
    let base = "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 5]\nradius = 1\n\
                [image]\nwidth = 32\nheight = 24\n[render]\n";
    std::fs::write(&scene, format!("{base}interval_factor = 0.25\n")).unwrap();
    let s = scene.to_str().unwrap();
    let seed = json(&[s]);
    assert_eq!(
        (seed["rule"].as_str(), seed["interval_factor"].as_f64()),
        (Some("seed"), Some(0.25))
    );
    assert_eq!(json(&[s, "--tolerance", "3"])["rule"], "error");
    std::fs::write(&scene, format!("{base}tolerance = 0.75\n")).unwrap();
    assert_eq!(json(&[s])["tolerance"], 0.75);
    std::fs::write(
        &scene,
        format!("{base}tolerance = 1\ninterval_factor = 0.4\n"),
    )
    .unwrap();
    let out = dofray(&["render", s, "-o", png.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("render.tolerance") && err.contains("rule.toml"),
        "{err}"
    );
    dir.close().unwrap();
}

/// The one JSON object a failing `--json` run prints on stdout.
fn json_error(out: &Output) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not one JSON object ({e}): {:?}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    assert_eq!(v["schema_version"], 1, "{v}");
    v
}

#[test]
fn exit_codes_name_the_kind_of_failure() {
    let dir = scratch("exit");
    let png = dir.join("out.png");
    let p = png.to_str().unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[camera]\nfov = 40\n").unwrap();
    let missing = dir.join("missing.toml");
    let read_only = dir.join("read-only.png");
    std::fs::write(&read_only, b"keep").unwrap();
    let mut perms = std::fs::metadata(&read_only).unwrap().permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(&read_only, perms).unwrap();
    let (b, m, r) = (
        bad.to_str().unwrap(),
        missing.to_str().unwrap(),
        read_only.to_str().unwrap(),
    );
    let cases: &[(&[&str], i32, &str, &str)] = &[
        // clap's own errors, and values checked after parsing.
        (
            &["render", "--no-such-flag", "-o", p],
            2,
            "usage",
            "--no-such-flag",
        ),
        (&["render", "--spp", "0", "-o", p], 2, "usage", "--spp"),
        (&["render", "--width", "0", "-o", p], 2, "usage", "--width"),
        (
            &["render", "--tolerance=-1", "-o", p],
            2,
            "usage",
            "--tolerance",
        ),
        (&["render", "-o", "out.jpg"], 2, "usage", ".png or .exr"),
        (
            &["render", "--exr-compression", "lzma", "-o", "o.exr"],
            2,
            "usage",
            "choose one of: none, rle, zip, zips, piz, pxr24, b44, b44a, dwaa, dwab",
        ),
        (
            &["render", "--exr-compression", "htj2k", "-o", "o.exr"],
            2,
            "usage",
            "cannot be written",
        ),
        (
            &["render", "--exr-half", "-o", p],
            2,
            "usage",
            "apply to .exr output only",
        ),
        (
            &["render", "--png-16", "-o", "o.exr"],
            2,
            "usage",
            "--png-16 applies to .png output only",
        ),
        (&["bench", "--repeat", "0"], 2, "usage", "--repeat"),
        // Inputs.
        (
            &["render", b, "-o", p],
            3,
            "bad_input",
            "unknown field `fov`",
        ),
        (
            &["render", m, "-o", p],
            3,
            "bad_input",
            "missing.toml: cannot read",
        ),
        (
            &["render", "no-such-scene", "-o", p],
            3,
            "bad_input",
            "unknown scene",
        ),
        // Outputs.
        (
            &["render", "-o", "/nonexistent-dir/x/out.png"],
            4,
            "io",
            "/nonexistent-dir",
        ),
        (&["render", "-o", r], 4, "io", "read-only"),
        // Resource limits.
        (
            &["render", "--width", "200000", "--height", "200000", "-o", p],
            5,
            "resource_limit",
            "choose a smaller --width/--height",
        ),
    ];
    for &(args, code, kind, needle) in cases {
        let mut all = args.to_vec();
        if !args.contains(&"--width") {
            all.extend(["--width", "16"]);
        }
        all.push("--quiet");
        let plain = dofray(&all);
        let err = stderr(&plain);
        assert_eq!(plain.status.code(), Some(code), "{all:?}: {err}");
        assert!(err.contains(needle), "{all:?}: {err}");
        assert!(plain.stdout.is_empty(), "{all:?} printed on stdout");
        // With --json: the same status, the message on stderr, one error object on stdout.
        all.push("--json");
        let json = dofray(&all);
        assert_eq!(json.status.code(), Some(code), "{all:?}: {}", stderr(&json));
        assert!(stderr(&json).contains(needle), "{all:?}: {}", stderr(&json));
        let v = json_error(&json);
        assert_eq!(v["error"]["kind"], kind, "{all:?}: {v}");
        assert_eq!(v["error"]["exit_code"], code, "{all:?}: {v}");
        let message = v["error"]["message"].as_str().unwrap();
        assert!(message.contains(needle), "{all:?}: {v}");
        assert!(!png.exists(), "{all:?} left an output file");
    }
    assert_eq!(std::fs::read(&read_only).unwrap(), b"keep");
}

#[test]
fn json_summaries_carry_the_schema_and_build() {
    let dir = scratch("schema");
    let png = dir.join("out.png");
    let out = dofray(&[
        "render",
        "-o",
        png.to_str().unwrap(),
        "--width",
        "16",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["schema_version"], 1);
    assert_eq!(v["dofray_version"], env!("CARGO_PKG_VERSION"));
    let commit = v["git_commit"].as_str().unwrap();
    assert!(!commit.is_empty(), "{v}");
    assert_eq!(commit, dofray::GIT_COMMIT);
    let width = v["embree"]["native_packet_width"].as_u64().unwrap();
    assert!([1, 4, 8, 16].contains(&width), "{v}");
    assert!(v["embree"]["isa"].is_string(), "{v}");
}

#[test]
fn version_names_the_commit_and_embree() {
    for flag in ["--version", "-V"] {
        let out = dofray(&[flag]);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.starts_with(&format!("dofray {}\n", env!("CARGO_PKG_VERSION"))),
            "{text}"
        );
        assert!(
            text.contains(&format!("commit: {}\n", dofray::GIT_COMMIT)),
            "{text}"
        );
        let version = text
            .lines()
            .find_map(|l| l.strip_prefix("embree: "))
            .unwrap_or_else(|| panic!("no Embree version: {text}"));
        assert!(
            version.split('.').count() == 3 && version.starts_with(['3', '4']),
            "{text}"
        );
        assert!(text.contains("native packet width"), "{text}");
    }
}

/// The text chunks and colour-space chunk of a PNG.
fn png_info(path: &std::path::Path) -> (Vec<(String, String)>, bool, png::BitDepth) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    let text = info
        .uncompressed_latin1_text
        .iter()
        .map(|t| (t.keyword.clone(), t.text.clone()))
        .collect();
    (text, info.srgb.is_some(), info.bit_depth)
}

#[test]
fn outputs_record_their_settings_and_colour_space() {
    let dir = scratch("meta");
    let scene = repo("scenes/gallery.toml");
    let png8 = dir.join("g8.png");
    let png16 = dir.join("g16.png");
    let exr = dir.join("g.exr");
    for (out, extra) in [(&png8, None), (&png16, Some("--png-16")), (&exr, None)] {
        let mut args = vec!["render", &scene, "-o", out.to_str().unwrap()];
        args.extend_from_slice(&["--width", "48", "--spp", "4", "--seed", "7", "-q"]);
        args.extend(extra);
        let run = dofray(&args);
        assert!(run.status.success(), "{}", stderr(&run));
    }
    let (text, srgb, depth) = png_info(&png8);
    assert!(srgb, "an sRGB chunk");
    assert_eq!(depth, png::BitDepth::Eight);
    let get = |text: &[(String, String)], key: &str| {
        text.iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("{key} missing in {text:?}"))
    };
    assert_eq!(get(&text, "dofray:spp"), "4");
    assert_eq!(get(&text, "dofray:seed"), "7");
    assert_eq!(get(&text, "dofray:mode"), "adaptive");
    assert_eq!(get(&text, "dofray:rule"), "error");
    assert_eq!(get(&text, "dofray:scene"), "gallery");
    assert!(get(&text, "dofray:scene_file").ends_with("gallery.toml"));
    assert_eq!(get(&text, "dofray:scene_fnv1a64").len(), 16);
    let embree = get(&text, "dofray:embree");
    assert!(
        embree.starts_with(&dofray::embree::EMBREE_MAJOR.to_string()),
        "{embree}"
    );
    assert!(get(&text, "Software").starts_with("dofray "));
    // 16-bit: the same picture, finer steps.
    let (text16, srgb16, depth16) = png_info(&png16);
    assert!(srgb16 && depth16 == png::BitDepth::Sixteen);
    assert_eq!(get(&text16, "dofray:spp"), "4");
    let (a, b) = (
        image::open(&png8).unwrap().to_rgb16(),
        image::open(&png16).unwrap().to_rgb16(),
    );
    let worst = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| (i32::from(x) - i32::from(y)).abs())
        .max()
        .unwrap();
    assert!(worst <= 129, "8- and 16-bit differ by {worst} of 65535");
    // EXR: the same settings as header attributes.
    let meta = exr::meta::MetaData::read_from_file(&exr, false).unwrap();
    let attrs = &meta.headers[0].own_attributes.other;
    let text_of = |key: &str| match attrs.get(&exr::prelude::Text::from(key)) {
        Some(exr::meta::attribute::AttributeValue::Text(t)) => t.to_string(),
        other => panic!("{key}: {other:?}"),
    };
    assert_eq!(text_of("dofray:spp"), "4");
    assert_eq!(text_of("dofray:scene"), "gallery");
    dir.close().unwrap();
}

#[test]
fn transparent_renders_carry_coverage_alpha() {
    let dir = scratch("transparent");
    // A sphere on nothing: the corners see only the background.
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        "[image]\nwidth = 40\nheight = 30\n[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n\
         vfov = 30\n[[objects]]\ntype = \"sphere\"\nradius = 0.5\n",
    )
    .unwrap();
    let scene = scene.to_str().unwrap();
    let png = dir.join("t.png");
    let run = dofray(&[
        "render",
        scene,
        "-o",
        png.to_str().unwrap(),
        "--transparent",
        "--json",
        "-q",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let json: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(json["transparent"], true);
    let image = image::open(&png).unwrap();
    assert_eq!(image.color(), image::ColorType::Rgba8);
    let rgba = image.to_rgba8();
    assert_eq!(rgba.get_pixel(0, 0)[3], 0, "a corner sees nothing");
    assert_eq!(rgba.get_pixel(20, 15)[3], 255, "the centre sees the sphere");
    // Without the flag: RGB, the background in the corner.
    let opaque = dir.join("o.png");
    let run = dofray(&["render", scene, "-o", opaque.to_str().unwrap(), "-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_eq!(
        image::open(&opaque).unwrap().color(),
        image::ColorType::Rgb8
    );
    // The scene file can ask for it too.
    let text = std::fs::read_to_string(scene).unwrap();
    std::fs::write(scene, format!("[render]\ntransparent = true\n{text}")).unwrap();
    let run = dofray(&["render", scene, "-o", png.to_str().unwrap(), "-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_eq!(image::open(&png).unwrap().color(), image::ColorType::Rgba8);
}

#[test]
fn json_lists_the_warnings_of_the_files_loaded() {
    let dir = scratch("warnings");
    // Blender's orthographic-camera file (its point light has a `range`), in a scene with its
    // own camera: both ignored features are named, once, in stderr and in the JSON.
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        format!(
            "[image]\nwidth = 32\nheight = 24\n[camera]\neye = [6, 4, 6]\nlook_at = [0, 0, 0]\n\
             [[objects]]\ntype = \"mesh\"\nfile = {:?}\n",
            repo("tests/scene_assets/blender/ortho.gltf")
        ),
    )
    .unwrap();
    let out = dir.join("w.png");
    let run = dofray(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--json",
        "-q",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let json: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let warnings = json["warnings"].as_array().expect("a warnings array");
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = warnings[0].as_str().unwrap();
    assert!(
        w.contains("ortho.gltf") && w.contains("orthographic") && w.contains("range"),
        "{w}"
    );
    assert_eq!(
        stderr(&run).matches("warning: ").count(),
        1,
        "{}",
        stderr(&run)
    );
}

#[test]
fn exposure_is_a_flag_in_stops_and_checked() {
    let dir = scratch("exposure");
    let out = dir.join("e.png");
    let o = out.to_str().unwrap();
    let base = [
        "render", "-o", o, "--width", "40", "--spp", "4", "--json", "-q",
    ];
    let run = dofray(&[&base[..], &["--exposure", "-1.5"]].concat());
    assert!(run.status.success(), "{}", stderr(&run));
    let json: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(json["exposure"], -1.5);
    for bad in ["nan", "100", "x"] {
        let run = dofray(&[&base[..], &["--exposure", bad]].concat());
        assert_eq!(
            run.status.code(),
            Some(2),
            "--exposure {bad}: {}",
            stderr(&run)
        );
        assert!(stderr(&run).contains("--exposure"), "{}", stderr(&run));
    }
}

#[test]
fn progress_is_plain_lines_when_stderr_is_not_a_terminal() {
    let dir = scratch("progress");
    let png = dir.join("p.png");
    let run = |extra: &[&str]| {
        let mut args = vec!["render", "-o", png.to_str().unwrap(), "--width", "48"];
        args.extend(["--spp", "4"]);
        args.extend(extra);
        let out = dofray(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        out
    };
    // Here stderr is a pipe, as in a farm's log: lines, not a bar's escape codes.
    let auto = stderr(&run(&[]));
    assert!(auto.contains("progress: "), "{auto}");
    assert!(!auto.contains('\r') && !auto.contains('\u{1b}'), "{auto:?}");
    assert!(!stderr(&run(&["--progress", "none"])).contains("progress: "));
    // --json keeps stderr quiet unless progress is asked for; stdout stays one JSON object.
    assert!(!stderr(&run(&["--json"])).contains("progress: "));
    let asked = run(&["--json", "--progress", "plain"]);
    assert!(stderr(&asked).contains("progress: "));
    serde_json::from_slice::<serde_json::Value>(&asked.stdout).unwrap();
    dir.close().unwrap();
}

#[test]
fn png_views_apply_record_and_reject_what_they_cannot_do() {
    let dir = scratch("views");
    let scene = repo("scenes/interior.toml");
    let render = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let mut args = vec!["render", &scene, "-o", out.to_str().unwrap()];
        args.extend_from_slice(&["--width", "40", "--spp", "2", "--seed", "3", "-q"]);
        args.extend_from_slice(extra);
        (dofray(&args), out)
    };
    let (run, standard) = render("standard.png", &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let (run, agx) = render(
        "agx.png",
        &["--view", "agx", "--look", "AgX - High Contrast"],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    let get = |path: &std::path::Path, key: &str| {
        png_info(path)
            .0
            .into_iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v)
            .unwrap_or_else(|| panic!("{key} missing"))
    };
    assert_eq!(get(&standard, "dofray:view"), "Standard");
    assert_eq!(get(&agx, "dofray:view"), "AgX");
    assert_eq!(get(&agx, "dofray:look"), "AgX - High Contrast");
    // The interior's window and lamps are far above 1: Standard clips them to white, AgX
    // rolls them off below it.
    let (s, a) = (
        image::open(&standard).unwrap().to_rgb8(),
        image::open(&agx).unwrap().to_rgb8(),
    );
    let white = |img: &image::RgbImage| img.pixels().filter(|p| p.0 == [255; 3]).count();
    assert!(white(&s) > 0, "standard has clipped highlights");
    assert!(
        white(&a) < white(&s),
        "AgX keeps fewer pixels at pure white"
    );

    for (flags, expect) in [
        (
            &["--look", "high-contrast"][..],
            "--look: the look \"AgX - High Contrast\" needs the AgX view",
        ),
        (&["--view", "filmic"][..], "Filmic view is not available"),
        (&["--view", "agx", "--look", "punchy"][..], "Punchy"),
        (&["--view-gamma", "0"][..], "--view-gamma"),
        (&["--view-exposure", "99"][..], "--view-exposure"),
    ] {
        let (run, out) = render("bad.png", flags);
        assert_eq!(run.status.code(), Some(2), "{flags:?}: {}", stderr(&run));
        assert!(stderr(&run).contains(expect), "{flags:?}: {}", stderr(&run));
        assert!(!out.exists());
    }
    let (run, _) = render("x.exr", &["--view", "agx"]);
    assert_eq!(run.status.code(), Some(2));
    assert!(
        stderr(&run).contains("apply to .png output only"),
        "{}",
        stderr(&run)
    );

    // A scene file's [view] is the default, checked where it is written.
    let file = dir.join("viewed.toml");
    let text = std::fs::read_to_string(&scene).unwrap();
    std::fs::write(
        &file,
        format!("{text}\n[view]\ntransform = \"AgX\"\nlook = \"AgX - High Contrast\"\n"),
    )
    .unwrap();
    let out = dir.join("from-scene.png");
    let run = dofray(&[
        "render",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "40",
        "--spp",
        "2",
        "--seed",
        "3",
        "-q",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_eq!(
        image::open(&out).unwrap().to_rgb8(),
        a,
        "the scene's [view] = the flags"
    );
    std::fs::write(
        &file,
        format!("{text}\n[view]\ntransform = \"Standard\"\nlook = \"AgX - Greyscale\"\n"),
    )
    .unwrap();
    let run = dofray(&[
        "render",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--width",
        "40",
        "-q",
    ]);
    assert_eq!(run.status.code(), Some(3), "{}", stderr(&run));
    let err = stderr(&run);
    assert!(
        err.contains("viewed.toml")
            && err.contains("view.look")
            && err.contains("needs the AgX view"),
        "{err}"
    );
    dir.close().unwrap();
}

/// `--filter-glossy` and a scene's `filter_glossy` take a finite number >= 0; anything else is
/// refused with the flag's or the key's name (and the file and line), before rendering.
#[test]
fn a_bad_glossy_filter_is_refused_by_name() {
    let dir = scratch("filter-glossy");
    let png = dir.join("out.png");
    let png = png.to_str().unwrap();
    let out = dofray(&["render", "--width", "16", "--filter-glossy=-1", "-o", png]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--filter-glossy"), "{}", stderr(&out));
    let scene = dir.join("glossy.toml");
    let base = "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 5]\nradius = 1\n\
                [image]\nwidth = 16\nheight = 12\n[render]\n";
    std::fs::write(&scene, format!("{base}filter_glossy = nan\n")).unwrap();
    let out = dofray(&["render", scene.to_str().unwrap(), "-o", png]);
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.contains("render.filter_glossy") && err.contains("glossy.toml:9"),
        "{err}"
    );
    std::fs::write(&scene, format!("{base}filter_glossy = 1\n")).unwrap();
    let out = dofray(&["render", scene.to_str().unwrap(), "--spp", "1", "-o", png]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!std::path::Path::new(png).with_extension("png.tmp").exists());
    dir.close().unwrap();
}
