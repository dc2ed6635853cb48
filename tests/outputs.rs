//! What `dofray` writes, and what it never loses or clobbers: signals during a render or a
//! write leave no temporary file, read-only targets are refused, symbolic links are written
//! through, a render and its AOV pictures never overwrite one another, and `bench` checks its
//! cache directory before rendering. And what readers make of the EXR: OpenImageIO's
//! `oiiotool` (skipped, with a notice, where it is not installed) and the exr crate.
//!
//! `DOFRAY_TEST_BIN` runs these tests against another build of the binary (for example an
//! older one, to see them fail).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

use crate::scratch::Scratch;

fn bin() -> PathBuf {
    std::env::var_os("DOFRAY_TEST_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_dofray")))
}

fn dofray(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().expect("run dofray")
}

/// A fresh, empty scratch directory for one test.
fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("outputs-{name}"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The names in `dir`, hidden ones included, sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Waits at most `limit` for `child` to exit; kills it and fails the test if it does not.
fn wait_bounded(child: &mut Child, limit: Duration) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("dofray did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn send(signal: &str, child: &Child) {
    let ok = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("run kill")
        .success();
    assert!(ok, "kill {signal} failed");
}

fn spawn(args: &[&str]) -> Child {
    Command::new(bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start dofray")
}

fn stderr_of(child: Child) -> String {
    String::from_utf8_lossy(&child.wait_with_output().unwrap().stderr).into_owned()
}

/// Stdout and stderr of a child that has exited.
fn outputs_of(child: Child) -> (String, String) {
    let out = child.wait_with_output().unwrap();
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (text(&out.stdout), text(&out.stderr))
}

#[test]
fn sigint_during_a_large_exr_write_removes_the_temporary_file() {
    let dir = scratch("sigint-write");
    let out = dir.join("big.exr");
    // A pinhole render of 1200x900 takes well under a second; its EXR takes about as long to
    // encode and write. The temporary file is being written once it holds bytes (the empty
    // one the up-front writability probe makes and removes at once does not count).
    let mut child = spawn(&[
        "render",
        "-o",
        s(&out),
        "--width",
        "1200",
        "--mode",
        "pinhole",
        "--aa",
        "1",
        "--quiet",
    ]);
    let start = Instant::now();
    loop {
        let writing = entries(&dir).iter().any(|n| {
            n.starts_with(".big.exr.tmp")
                && std::fs::metadata(dir.join(n)).is_ok_and(|m| m.len() > 0)
        });
        if writing {
            break;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("dofray exited ({status}) before its temporary file was seen");
        }
        if start.elapsed() >= Duration::from_secs(30) {
            // Killed, so that it is gone before the scratch directory it writes to is removed.
            let _ = child.kill();
            let _ = child.wait();
            panic!("no write started");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    send("-INT", &child);
    let status = wait_bounded(&mut child, Duration::from_secs(10));
    let err = stderr_of(child);
    assert!(entries(&dir).is_empty(), "left behind: {:?}", entries(&dir));
    assert_eq!(status.code(), Some(130), "{status}: {err}");
    assert!(err.contains("interrupted by SIGINT"), "{err}");
}

#[test]
fn sigterm_during_a_render_exits_143_and_leaves_nothing() {
    let dir = scratch("sigterm-render");
    let out = dir.join("r.exr");
    let aov = dir.join("aov");
    let mut child = spawn(&[
        "render",
        "-o",
        s(&out),
        "--width",
        "640",
        "--mode",
        "dense",
        "--spp",
        "4096",
        "--aa",
        "4096",
        "--aov-dir",
        s(&aov),
        "--quiet",
        "--json",
    ]);
    // Well past start-up (handlers are installed first thing), long before the render ends.
    std::thread::sleep(Duration::from_millis(400));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the render ended early"
    );
    send("-TERM", &child);
    let status = wait_bounded(&mut child, Duration::from_secs(10));
    let (out, err) = outputs_of(child);
    assert_eq!(status.code(), Some(143), "{status}: {err}");
    assert!(err.contains("interrupted by SIGTERM"), "{err}");
    // --json: the same error as an object on stdout.
    let json: serde_json::Value = serde_json::from_str(out.trim()).expect(&out);
    assert_eq!(json["error"]["kind"], "interrupted", "{json}");
    assert_eq!(json["error"]["exit_code"], 143, "{json}");
    assert!(
        json["error"]["message"]
            .as_str()
            .unwrap()
            .contains("SIGTERM")
    );
    assert_eq!(entries(&dir), vec!["aov".to_owned()]);
    assert!(entries(&aov).is_empty(), "{:?}", entries(&aov));
}

/// A tiny render to `out` with extra flags.
fn render_tiny(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["render", "-o", s(out), "--width", "16", "--quiet"];
    args.extend_from_slice(extra);
    dofray(&args)
}

#[cfg(unix)]
fn set_mode(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
}

#[cfg(unix)]
#[test]
fn read_only_targets_are_refused_before_rendering() {
    use std::os::unix::fs::PermissionsExt;

    let dir = scratch("read-only");
    let out = dir.join("keep.png");
    std::fs::write(&out, b"old").unwrap();
    // No write bit at all: refused even for root, whom permission bits do not stop.
    set_mode(&out, 0o444);
    let o = render_tiny(&out, &[]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("read-only") && err.contains("keep.png"),
        "{err}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), b"old");
    let mode = std::fs::metadata(&out).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o444);
    assert_eq!(entries(&dir), vec!["keep.png".to_owned()]);

    // A read-only AOV picture is refused too, before the image is rendered or written.
    let aov = dir.join("aov");
    std::fs::create_dir(&aov).unwrap();
    std::fs::write(aov.join("interval.png"), b"old").unwrap();
    set_mode(&aov.join("interval.png"), 0o400);
    let img = dir.join("new.png");
    let o = render_tiny(&img, &["--aov-dir", s(&aov)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("interval.png"), "{}", stderr(&o));
    assert!(!img.exists());
    assert_eq!(entries(&aov), vec!["interval.png".to_owned()]);

    // One write bit is enough.
    set_mode(&out, 0o644);
    let o = render_tiny(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(image::open(&out).unwrap().width(), 16);
}

#[cfg(unix)]
#[test]
fn symlinks_are_written_through_to_their_target() {
    use std::os::unix::fs::symlink;

    let dir = scratch("symlink");
    let real = dir.join("real");
    std::fs::create_dir(&real).unwrap();
    std::fs::write(real.join("target.png"), b"old").unwrap();
    // A relative link, resolved against its own directory.
    let link = dir.join("link.png");
    symlink("real/target.png", &link).unwrap();
    let o = render_tiny(&link, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(image::open(real.join("target.png")).unwrap().width(), 16);
    assert_eq!(entries(&real), vec!["target.png".to_owned()]);

    // A chain of links to an EXR, and a dangling link, which creates the file it names.
    let chain = dir.join("chain.exr");
    symlink(real.join("chained.exr"), dir.join("middle.exr")).unwrap();
    symlink("middle.exr", &chain).unwrap();
    let o = render_tiny(&chain, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(real.join("chained.exr").is_file());
    for name in ["chain.exr", "middle.exr"] {
        let meta = std::fs::symlink_metadata(dir.join(name)).unwrap();
        assert!(meta.file_type().is_symlink(), "{name}");
    }

    // A link to a read-only file is refused like the file itself; a loop is an error.
    set_mode(&real.join("target.png"), 0o444);
    let o = render_tiny(&link, &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("read-only"), "{}", stderr(&o));
    symlink("loop-b.png", dir.join("loop-a.png")).unwrap();
    symlink("loop-a.png", dir.join("loop-b.png")).unwrap();
    let o = render_tiny(&dir.join("loop-a.png"), &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("symbolic links"), "{}", stderr(&o));
    assert_eq!(
        entries(&real),
        vec!["chained.exr".to_owned(), "target.png".to_owned()]
    );
}

#[test]
fn the_image_and_its_aov_pictures_never_overwrite_one_another() {
    let dir = scratch("collide");
    // Refused whether the AOV directory exists or not (then it is not created either).
    for existing in [true, false] {
        let aov = dir.join(if existing { "aov" } else { "new" });
        if existing {
            std::fs::create_dir(&aov).unwrap();
        }
        let cases = [
            aov.join("depth.png"),
            aov.join("interval.png"),
            dir.join("x")
                .join("..")
                .join(aov.file_name().unwrap())
                .join("./depth.png"),
        ];
        for out in &cases {
            let o = render_tiny(out, &["--aov-dir", s(&aov)]);
            assert!(!o.status.success(), "{}", out.display());
            let err = stderr(&o);
            assert!(err.contains("same file"), "{err}");
            let name = out.file_name().unwrap().to_str().unwrap();
            assert!(
                err.contains(&format!("{}", out.display()))
                    && err.contains(&format!("{}", aov.join(name).display())),
                "names both: {err}"
            );
            assert_eq!(entries(&dir), ["aov"], "nothing created");
            assert!(entries(&dir.join("aov")).is_empty());
        }
    }
    let aov = dir.join("aov");
    // Through a symbolic link to the AOV directory.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&aov, dir.join("alias")).unwrap();
        let out = dir.join("alias").join("depth.png");
        let o = render_tiny(&out, &["--aov-dir", s(&aov)]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("same file"), "{}", stderr(&o));
        assert!(entries(&aov).is_empty());
    }
    // Distinct names in the same directory are fine, even one that does not exist yet.
    let o = render_tiny(&aov.join("image.png"), &["--aov-dir", s(&aov)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        entries(&aov),
        ["depth.png", "image.png", "interval.png", "samples.png"]
    );
    let fresh = dir.join("fresh");
    let o = render_tiny(&fresh.join("image.png"), &["--aov-dir", s(&fresh)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        entries(&fresh),
        ["depth.png", "image.png", "interval.png", "samples.png"]
    );
}

#[test]
fn bench_checks_its_cache_directory_before_rendering() {
    let dir = scratch("bench-cache");
    let file = dir.join("file");
    std::fs::write(&file, b"x").unwrap();
    let cache = file.join("cache");
    // A reference this large would take minutes: the error must come first.
    let mut child = spawn(&[
        "bench",
        "--width",
        "64",
        "--repeat",
        "1",
        "--reference-spp",
        "65536",
        "--cache-dir",
        s(&cache),
        "--quiet",
    ]);
    let status = wait_bounded(&mut child, Duration::from_secs(15));
    let err = stderr_of(child);
    assert!(!status.success());
    assert!(
        err.contains(s(&cache)) && err.contains("--cache-dir"),
        "names the directory: {err}"
    );
    assert_eq!(entries(&dir), vec!["file".to_owned()]);
}

/// A process killed outright (SIGKILL) cannot clean up after itself; the next write to the
/// same target sweeps the temporary files of dead processes, and leaves other files alone.
#[test]
fn temporary_files_of_killed_processes_are_swept_by_the_next_write() {
    let dir = scratch("sweep");
    // PIDs above the kernel's maximum (4194304) belong to no process.
    let stale = dir.join(".out.png.tmp-99999999-0");
    let other = dir.join(".other.png.tmp-99999999-0");
    let unrelated = dir.join(".out.png.tmp-notes");
    for f in [&stale, &other, &unrelated] {
        std::fs::write(f, b"partial").unwrap();
    }
    let target = dir.join("out.png");
    let out = dofray(&[
        "render",
        "--width",
        "16",
        "--quiet",
        "-o",
        target.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        !stale.exists(),
        "the dead process's temporary file is swept"
    );
    assert!(
        other.exists() && unrelated.exists(),
        "other files are left alone"
    );
}

/// Whether `oiiotool` (OpenImageIO; Debian's openimageio-tools, which CI installs) runs here.
fn have_oiiotool() -> bool {
    Command::new("oiiotool")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

fn run_oiiotool(args: &[&str]) -> String {
    let out = Command::new("oiiotool").args(args).output().unwrap();
    assert!(out.status.success(), "oiiotool {args:?}: {}", stderr(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// What OpenImageIO (the library behind oiiotool, and the EXR reader of many DCC tools) makes
/// of dofray's EXRs: the layered channel names with the right per-channel type, the alpha and
/// depth channels recognised as such, the compression, and the metadata header attributes.
#[test]
fn oiiotool_reads_layers_alpha_depth_precision_compression_and_metadata() {
    if !have_oiiotool() {
        println!(
            "SKIPPED oiiotool_reads_layers_alpha_depth_precision_compression_and_metadata: \
             oiiotool is not installed (apt-get install openimageio-tools; CI installs it)"
        );
        return;
    }
    let dir = scratch("oiiotool");
    let cases: [(&[&str], bool, &str); 4] = [
        (&[], false, "zip"),
        (&["--exr-half"], true, "zip"),
        (&["--exr-compression", "piz"], false, "piz"),
        (&["--exr-half", "--exr-compression", "dwab"], true, "dwab"),
    ];
    for (extra, half, compression) in cases {
        let path = dir.join(format!("{compression}-{half}.exr"));
        let mut flags = vec!["--seed", "3"];
        flags.extend_from_slice(extra);
        let run = render_tiny(&path, &flags);
        assert!(run.status.success(), "{extra:?}: {}", stderr(&run));
        let info = run_oiiotool(&["--info", "-v", s(&path)]);
        let case = format!("{extra:?}:\n{info}");

        // "channel list: A (half), B (float), ..." when the types differ, else untyped and
        // the one type on the summary line ("8 channel, float openexr").
        let list = info
            .lines()
            .find_map(|l| l.trim().strip_prefix("channel list: "))
            .unwrap_or_else(|| panic!("no channel list in {case}"));
        let channels: Vec<(String, String)> = list
            .split(", ")
            .map(|c| match c.split_once(" (") {
                Some((name, ty)) => (name.to_owned(), ty.trim_end_matches(')').to_owned()),
                None => (c.to_owned(), "float".to_owned()),
            })
            .collect();
        let names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
        // OpenImageIO lists R, G, B, A first within their layer; the set is dofray's.
        assert_eq!(
            names,
            [
                "ViewLayer.CoC.X",
                "ViewLayer.Combined.R",
                "ViewLayer.Combined.G",
                "ViewLayer.Combined.B",
                "ViewLayer.Combined.A",
                "ViewLayer.Depth.Z",
                "ViewLayer.Interval.X",
                "ViewLayer.Samples.X",
            ],
            "{case}"
        );
        for (name, ty) in &channels {
            let expected = if half && name.starts_with("ViewLayer.Combined.") {
                "half"
            } else {
                "float"
            };
            assert_eq!(ty, expected, "{name} in {case}");
        }
        assert!(
            info.contains(&format!("compression: \"{compression}\"")),
            "{case}"
        );
        for attribute in [
            "BlenderMultiChannel: \"Blender V2.55.1 and newer\"",
            "software: \"dofray ",
            "dofray:mode: \"adaptive\"",
            "dofray:seed: \"3\"",
            "dofray:width: \"16\"",
            "dofray:commit: ",
        ] {
            assert!(info.contains(attribute), "{attribute} missing: {case}");
        }
        // The alpha and depth channels are recognised as such (indices into the list above).
        let roles = run_oiiotool(&[
            s(&path),
            "--echo",
            "alpha={TOP.alpha_channel} z={TOP.z_channel}",
        ]);
        assert!(roles.contains("alpha=4 z=5"), "{roles} for {case}");
    }
    dir.close().unwrap();
}

/// Every channel of an EXR by name, widened to f32, with whether it was stored as half.
fn exr_channels(path: &Path) -> Vec<(String, bool, Vec<f32>)> {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).unwrap();
    assert_eq!(image.layer_data.len(), 1);
    image.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| match &c.sample_data {
            FlatSamples::F32(v) => (c.name.to_string(), false, v.clone()),
            FlatSamples::F16(v) => (
                c.name.to_string(),
                true,
                v.iter().map(|h| h.to_f32()).collect(),
            ),
            FlatSamples::U32(_) => panic!("{}: u32 samples", c.name),
        })
        .collect()
}

/// The same render written as float and as half: the same channels, the beauty within half
/// precision, depth and dofray's passes bit for bit.
#[test]
fn exr_half_round_trips_the_beauty_within_half_precision() {
    let dir = scratch("half");
    let (float, half) = (dir.join("float.exr"), dir.join("half.exr"));
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/gallery.toml");
    for (out, extra) in [(&float, None), (&half, Some("--exr-half"))] {
        let mut args = vec!["render", scene, "-o", s(out), "--width", "48", "-q"];
        args.extend(extra);
        let run = dofray(&args);
        assert!(run.status.success(), "{}", stderr(&run));
    }
    let (f, h) = (exr_channels(&float), exr_channels(&half));
    let names = |c: &[(String, bool, Vec<f32>)]| -> Vec<String> {
        c.iter().map(|(n, _, _)| n.clone()).collect()
    };
    assert_eq!(names(&f), names(&h));
    assert_eq!(names(&f), dofray::output::exr::CHANNELS.map(String::from));
    for ((name, f_half, fv), (_, h_half, hv)) in f.iter().zip(&h) {
        assert!(!f_half, "{name}: float file has no half channels");
        let beauty = name.starts_with("ViewLayer.Combined.");
        assert_eq!(*h_half, beauty, "{name}: only the beauty is half");
        for (i, (&a, &b)) in fv.iter().zip(hv).enumerate() {
            if beauty {
                // 11 significant bits: relative error <= 2^-11, plus half's subnormal step.
                assert!(
                    (a - b).abs() <= a.abs() / 2048.0 + 6e-8,
                    "{name}[{i}]: {a} as half {b}"
                );
            } else {
                assert_eq!(a.to_bits(), b.to_bits(), "{name}[{i}]");
            }
        }
    }
    // Misses have a finite depth (the gallery's sky).
    let depth = &f
        .iter()
        .find(|(n, _, _)| n == "ViewLayer.Depth.Z")
        .unwrap()
        .2;
    assert!(depth.contains(&dofray::output::exr::DEPTH_MISS));
    assert!(depth.iter().all(|d| d.is_finite() && *d > 0.0));
    dir.close().unwrap();
}

/// The EXR says which colour space its linear values are in (Rec.709 primaries, D65 white), as
/// Blender, Nuke and OpenImageIO read it; merged tiles keep it.
#[test]
fn exr_carries_rec709_d65_chromaticities() {
    let dir = scratch("chroma");
    let (full, left, right, merged) = (
        dir.join("full.exr"),
        dir.join("left.exr"),
        dir.join("right.exr"),
        dir.join("merged.exr"),
    );
    for (out, region) in [
        (&full, None),
        (&left, Some("0,0,24,36")),
        (&right, Some("24,0,48,36")),
    ] {
        let mut args = vec!["render", "-o", s(out), "--width", "48", "--spp", "1", "-q"];
        args.extend(region.map(|r| ["--region", r]).into_iter().flatten());
        let run = dofray(&args);
        assert!(run.status.success(), "{}", stderr(&run));
    }
    let run = dofray(&["merge", s(&left), s(&right), "-o", s(&merged), "-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    for path in [&full, &left, &merged] {
        let meta = exr::meta::MetaData::read_from_file(path, false).unwrap();
        let c = meta.headers[0]
            .shared_attributes
            .chromaticities
            .unwrap_or_else(|| panic!("{}: no chromaticities", path.display()));
        let xy = |v: exr::math::Vec2<f32>| (v.0, v.1);
        assert_eq!(xy(c.red), (0.64, 0.33));
        assert_eq!(xy(c.green), (0.30, 0.60));
        assert_eq!(xy(c.blue), (0.15, 0.06));
        assert_eq!(xy(c.white), (0.3127, 0.3290));
    }
    dir.close().unwrap();
}
