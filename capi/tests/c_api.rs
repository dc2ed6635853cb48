//! Compiles the C programs (`capi/tests/c/smoke.c` and `jobs.c`, the README's
//! `capi/examples/render.c`)
//! with the system's C compiler against `include/dofray.h`, links them with `libdofray.so`
//! and with `libdofray.a`, and runs them.
//!
//! `cargo test` does not build the cdylib and staticlib for integration tests: the test
//! runs `cargo build -p dofray-capi --lib` first (see [`lib_dir`]).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The repository root (the workspace).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The directory of this profile's artifacts (`target/debug`), with libdofray.so and
/// libdofray.a built up to date: `cargo test` builds only the test harnesses, not the
/// library's cdylib and staticlib, so this builds them (once per test process) with the same
/// cargo, target directory and profile (`test`, whose dependencies `cargo test` just built).
fn lib_dir() -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT.get_or_init(build_lib).clone()
}

fn build_lib() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's path");
    // target/debug/deps/c_api-<hash> -> target/debug
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf();
    let target_dir = dir.parent().expect("the target directory");
    // `cargo test` builds with the test profile into target/debug, `cargo test --release`
    // with the bench profile into target/release.
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("release") => "bench",
        _ => "test",
    };
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .args(["build", "-p", "dofray-capi", "--lib", "--profile", profile])
        .arg("--target-dir")
        .arg(target_dir)
        .current_dir(root())
        .status()
        .expect("cargo runs");
    assert!(status.success(), "cargo build -p dofray-capi --lib failed");
    for lib in ["libdofray.so", "libdofray.a"] {
        assert!(dir.join(lib).is_file(), "no {lib} in {}", dir.display());
    }
    dir
}

/// The Embree library dofray links (`embree3` or `embree4`), from the build script of the
/// `dofray` crate (through capi/build.rs).
const EMBREE_LIB: &str = env!("DOFRAY_CAPI_EMBREE_LIB");

/// Its directory when it is not the system's (empty otherwise).
const EMBREE_LIB_DIR: &str = env!("DOFRAY_CAPI_EMBREE_LIB_DIR");

/// Whether this test runs under an explicit dynamic loader (`ld-linux-x86-64.so.2
/// --library-path DIR test`), as scripts/embree4-check.sh runs every test against Debian 13's
/// Embree 4, whose glibc is newer than the system's: programs compiled here with the system's
/// C compiler cannot link or run against that Embree, so the C tests are skipped there (the C
/// API has no Embree-specific code; the library's own tests cover Embree 4).
fn under_foreign_loader() -> bool {
    let Ok(cmdline) = std::fs::read("/proc/self/cmdline") else {
        return false;
    };
    let argv0 = cmdline.split(|&b| b == 0).next().unwrap_or_default();
    let name = Path::new(std::str::from_utf8(argv0).unwrap_or_default()).file_name();
    let foreign = name.is_some_and(|n| n.to_string_lossy().starts_with("ld-"));
    if foreign {
        println!("SKIPPED: the C tests do not run under an explicit dynamic loader");
    }
    foreign
}

/// A fresh output directory for `name`.
fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("capi")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the output directory");
    dir
}

/// Compiles `source` into `exe`, linked with the shared or the static library.
fn compile(source: &Path, exe: &Path, lib_dir: &Path, shared: bool) {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let mut cmd = Command::new(cc);
    cmd.args([
        "-std=c99",
        "-Wall",
        "-Wextra",
        "-Werror",
        "-pedantic",
        "-O1",
    ])
    .arg("-I")
    .arg(root().join("include"))
    .arg(source)
    .arg("-o")
    .arg(exe);
    if shared {
        cmd.arg("-L")
            .arg(lib_dir)
            .arg("-ldofray")
            .arg(format!("-Wl,-rpath,{}", lib_dir.display()));
    } else {
        // What `rustc --print native-static-libs` lists for the staticlib, plus Embree.
        cmd.arg(lib_dir.join("libdofray.a")).args([
            &format!("-l{EMBREE_LIB}"),
            "-lgcc_s",
            "-lutil",
            "-lrt",
            "-lpthread",
            "-lm",
            "-ldl",
            "-lc",
        ]);
    }
    if !EMBREE_LIB_DIR.is_empty() {
        let dir = EMBREE_LIB_DIR;
        cmd.arg(format!("-L{dir}"))
            .arg(format!("-Wl,-rpath-link,{dir}"))
            .arg(format!("-Wl,-rpath,{dir}"));
    }
    cmd.arg("-lm");
    let output = cmd.output().expect("the C compiler (cc) runs");
    assert!(
        output.status.success(),
        "compiling {} failed: {cmd:?}\n{}{}",
        source.display(),
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Runs `exe` with `args` in `cwd`; its stdout and stderr, which must end in success.
fn run(exe: &Path, args: &[&Path], cwd: &Path) -> String {
    let mut cmd = Command::new(exe);
    cmd.args(args).current_dir(cwd);
    let output = cmd.output().expect("the C program runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    println!("{text}");
    assert!(
        output.status.success(),
        "{cmd:?} failed ({}):\n{text}",
        output.status
    );
    text
}

fn smoke(shared: bool) {
    if under_foreign_loader() {
        return;
    }
    let lib_dir = lib_dir();
    let name = if shared {
        "smoke-shared"
    } else {
        "smoke-static"
    };
    let dir = out_dir(name);
    let exe = dir.join(name);
    compile(&root().join("capi/tests/c/smoke.c"), &exe, &lib_dir, shared);
    let text = run(&exe, &[&dir], &dir);
    assert!(text.contains("all checks passed"), "{text}");
    for file in ["smoke.png", "smoke.exr", "sphere.png"] {
        assert!(dir.join(file).is_file(), "{file} was not written");
    }
}

#[test]
fn smoke_with_the_shared_library() {
    smoke(true);
}

#[test]
fn smoke_with_the_static_library() {
    smoke(false);
}

/// capi/tests/c/jobs.c: frames of scenes/focus_pull.toml rendered, re-run skipping them,
/// refused, a tiled still merged, cancelled runs, bad options.
#[test]
fn render_jobs() {
    if under_foreign_loader() {
        return;
    }
    let lib_dir = lib_dir();
    let dir = out_dir("jobs");
    let exe = dir.join("jobs");
    compile(&root().join("capi/tests/c/jobs.c"), &exe, &lib_dir, true);
    let scene = root().join("scenes/focus_pull.toml");
    let text = run(&exe, &[&scene], &dir);
    assert!(text.contains("all checks passed"), "{text}");
    for file in ["frames/shot_01.png", "frames/shot_03.png", "still.png"] {
        assert!(dir.join(file).is_file(), "{file} was not written");
    }
    assert!(
        !dir.join("still.tile-000.png").exists(),
        "the tiles were not removed"
    );
}

/// The README's example is capi/examples/render.c, which compiles and renders paper.png.
#[test]
fn readme_example() {
    let example = std::fs::read_to_string(root().join("capi/examples/render.c")).unwrap();
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    assert!(
        readme.contains(&format!("```c\n{example}```")),
        "README.md's C example (### From C) is not capi/examples/render.c: copy it there"
    );
    if under_foreign_loader() {
        return;
    }
    let lib_dir = lib_dir();
    let dir = out_dir("example");
    let exe = dir.join("render");
    compile(&root().join("capi/examples/render.c"), &exe, &lib_dir, true);
    let text = run(&exe, &[], &dir);
    assert!(text.contains("64x48"), "{text}");
    assert!(dir.join("paper.png").is_file());
}
