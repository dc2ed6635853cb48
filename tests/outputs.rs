//! What `dofray` writes, and what it never loses or clobbers: signals during a render or a
//! write leave no temporary file, read-only targets are refused, symbolic links are written
//! through, a render and its AOV pictures never overwrite one another, and `bench` checks its
//! cache directory before rendering.
//!
//! `DOFRAY_TEST_BIN` runs these tests against another build of the binary (for example an
//! older one, to see them fail).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> PathBuf {
    std::env::var_os("DOFRAY_TEST_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_dofray")))
}

fn dofray(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().expect("run dofray")
}

/// A fresh, empty scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dofray-outputs-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
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
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start dofray")
}

fn stderr_of(child: Child) -> String {
    String::from_utf8_lossy(&child.wait_with_output().unwrap().stderr).into_owned()
}

#[test]
fn sigint_during_a_large_exr_write_removes_the_temporary_file() {
    let dir = scratch("sigint-write");
    let out = dir.join("big.exr");
    // A pinhole render of 1200x900 takes well under a second; its EXR takes about as long to
    // encode and write. The temporary file appears when the write starts.
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
        if entries(&dir).iter().any(|n| n.starts_with(".big.exr.tmp")) {
            break;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("dofray exited ({status}) before its temporary file was seen");
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no write started");
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
    ]);
    // Well past start-up (handlers are installed first thing), long before the render ends.
    std::thread::sleep(Duration::from_millis(400));
    assert!(child.try_wait().unwrap().is_none(), "the render ended early");
    send("-TERM", &child);
    let status = wait_bounded(&mut child, Duration::from_secs(10));
    let err = stderr_of(child);
    assert_eq!(status.code(), Some(143), "{status}: {err}");
    assert!(err.contains("interrupted by SIGTERM"), "{err}");
    assert_eq!(entries(&dir), vec!["aov".to_owned()]);
    assert!(entries(&aov).is_empty(), "{:?}", entries(&aov));
}
