//! Compiles the C programs (`capi/tests/c/smoke.c` and `jobs.c`, the README's
//! `capi/examples/render.c`)
//! with the system's C compiler against `include/dofray.h`, links them with `libdofray.so`
//! and with `libdofray.a`, and runs them; installs the library with
//! `scripts/install-capi.sh` and links the example through the installed `dofray.pc`.
//!
//! `cargo test` does not build the cdylib and staticlib for integration tests: the test
//! runs `cargo build -p dofray -p dofray-capi --lib --examples` first (see [`lib_dir`]).

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
/// cargo, target directory and the profile `cargo test` built the library and its
/// dependencies with (see [`profile`]), so nothing but the C library itself is compiled.
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
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        // `-p dofray --examples` as well: examples take dev-dependencies, so features resolve
        // as for `cargo test` (both default members, dev-dependencies on) and every
        // dependency it built is reused; `-p dofray-capi --lib` alone resolves some of them
        // (serde, libc, image, ...) with other features and compiles them again.
        .args([
            "build",
            "-p",
            "dofray",
            "-p",
            "dofray-capi",
            "--lib",
            "--examples",
            "--profile",
            profile(&dir),
        ])
        .arg("--target-dir")
        .arg(target_dir)
        .current_dir(root())
        .status()
        .expect("cargo runs");
    assert!(
        status.success(),
        "cargo build -p dofray -p dofray-capi --lib --examples failed"
    );
    for lib in ["libdofray.so", "libdofray.a"] {
        assert!(dir.join(lib).is_file(), "no {lib} in {}", dir.display());
    }
    // Programs linked with -ldofray ask for the SONAME (libdofray.so.0) at run time, which
    // cargo does not create: link it beside libdofray.so (replaced atomically, as another
    // test process may be using it).
    let temporary = dir.join(format!("{SONAME}.{}.tmp", std::process::id()));
    let _ = std::fs::remove_file(&temporary);
    std::os::unix::fs::symlink("libdofray.so", &temporary).expect("a symlink in target/<profile>");
    std::fs::rename(&temporary, dir.join(SONAME)).expect("the libdofray.so.0 symlink");
    dir
}

/// The cargo profile of this test's build directory. `cargo test` builds only the test
/// harnesses with the `test` profile; the library and every dependency are built with `dev`
/// into target/debug (`release` into target/release with `--release`). Building with `test`
/// or `bench` here compiled every dependency a second time (4 minutes of a clean `cargo test`).
fn profile(dir: &Path) -> &'static str {
    match dir.file_name().and_then(|n| n.to_str()) {
        Some("release") => "release",
        _ => "dev",
    }
}

/// libdofray.so's SONAME (capi/build.rs).
const SONAME: &str = env!("DOFRAY_CAPI_SONAME");

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
    let lens = root().join("lenses/double-gauss-50mm.dat");
    let text = run(&exe, &[&dir, &lens], &dir);
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

/// capi/tests/c/memory.c under an address-space limit (`ulimit -v`, about 3 GB; a small
/// render needs about 0.4 GB of address space, Embree's and the threads' included): an image
/// whose buffers cannot fit is `DOFRAY_RESOURCE_LIMIT` naming the limit, not an abort of the
/// host process, which then renders a small image.
#[test]
fn an_image_beyond_the_address_space_limit_is_a_resource_limit() {
    if under_foreign_loader() {
        return;
    }
    let lib_dir = lib_dir();
    let dir = out_dir("memory");
    let exe = dir.join("memory");
    compile(&root().join("capi/tests/c/memory.c"), &exe, &lib_dir, true);
    let output = Command::new("sh")
        .args([
            "-c",
            "ulimit -v 3000000 && exec \"$0\"",
            exe.to_str().unwrap(),
        ])
        .current_dir(&dir)
        .output()
        .expect("sh runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    println!("{text}");
    assert!(output.status.success(), "{}:\n{text}", output.status);
    assert!(text.contains("memory checks passed"), "{text}");
    assert!(text.contains("huge render -> resource_limit"), "{text}");
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

/// scripts/install-capi.sh into a staging directory (DESTDIR, so no ldconfig): the library
/// as libdofray.so.<version> with its SONAME and the libdofray.so.0 and libdofray.so links,
/// libdofray.a, dofray.h and dofray.pc (with the prefix given); then capi/examples/render.c
/// compiled with `pkg-config --cflags --libs dofray` against the installed copy and run from
/// it (LD_LIBRARY_PATH), and linked with libdofray.a and `pkg-config --static`'s
/// Libs.private. The script installs this test's own build (DOFRAY_PROFILE=test), not a
/// release build, so it only copies files.
#[test]
fn install_script_and_pkg_config() {
    if under_foreign_loader() {
        return;
    }
    if Command::new("pkg-config")
        .arg("--version")
        .output()
        .is_err()
    {
        println!("SKIPPED: pkg-config is not installed (Debian: apt-get install pkgconf)");
        return;
    }
    let lib_dir = lib_dir();
    let dir = out_dir("install");
    let destdir = dir.join("stage");
    let prefix = "/opt/dofray-install-test";
    let installed = destdir.join(prefix.trim_start_matches('/'));
    let lib = installed.join("lib");

    // A fake ldconfig first on PATH tells whether the script ran it: not with DESTDIR.
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let ldconfig = bin.join("ldconfig");
    std::fs::write(&ldconfig, "#!/bin/sh\ntouch \"$0-ran\"\n").unwrap();
    let executable = std::os::unix::fs::PermissionsExt::from_mode(0o755);
    std::fs::set_permissions(&ldconfig, executable).unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let started = std::time::Instant::now();
    let mut script = Command::new("bash");
    script
        .arg(root().join("scripts/install-capi.sh"))
        .arg(prefix)
        .arg("--target-dir")
        .arg(lib_dir.parent().expect("the target directory"))
        // Resolve features as `cargo test` did, so its build is reused (see `build_lib`).
        .args(["-p", "dofray", "--examples"])
        .env("DESTDIR", &destdir)
        .env("DOFRAY_PROFILE", profile(&lib_dir))
        .env("PATH", &path)
        .current_dir(&dir);
    let text = output_of(&mut script);
    println!(
        "install-capi.sh: {:.1} s\n{text}",
        started.elapsed().as_secs_f64()
    );
    assert!(
        !bin.join("ldconfig-ran").exists(),
        "install-capi.sh ran ldconfig with DESTDIR set"
    );

    let version = env!("CARGO_PKG_VERSION");
    let real = format!("libdofray.so.{version}");
    let link = |name: &str| std::fs::read_link(lib.join(name)).unwrap_or_default();
    assert!(lib.join(&real).symlink_metadata().unwrap().is_file());
    assert_eq!(link(SONAME), Path::new(&real), "{SONAME}");
    assert_eq!(link("libdofray.so"), Path::new(SONAME), "libdofray.so");
    assert!(lib.join("libdofray.a").is_file());
    assert_eq!(
        std::fs::read(installed.join("include/dofray.h")).unwrap(),
        std::fs::read(root().join("include/dofray.h")).unwrap()
    );
    let pc = std::fs::read_to_string(lib.join("pkgconfig/dofray.pc")).unwrap();
    assert!(pc.contains(&format!("\nprefix={prefix}\n")), "{pc}");
    let dynamic = output_of(Command::new("readelf").arg("-d").arg(lib.join(&real)));
    assert!(
        dynamic.contains(&format!("Library soname: [{SONAME}]")),
        "{dynamic}"
    );

    // pkg-config finds the staged dofray.pc; PKG_CONFIG_SYSROOT_DIR puts DESTDIR before the
    // paths it gives, as for any staged installation.
    let pkg_config = |args: &[&str]| -> Vec<String> {
        let mut cmd = Command::new("pkg-config");
        cmd.args(args)
            .arg("dofray")
            .env("PKG_CONFIG_PATH", lib.join("pkgconfig"))
            .env("PKG_CONFIG_SYSROOT_DIR", &destdir);
        output_of(&mut cmd)
            .split_whitespace()
            .map(String::from)
            .collect()
    };
    assert_eq!(pkg_config(&["--modversion"]), [version]);
    let shared_flags = pkg_config(&["--cflags", "--libs"]);
    for flag in [
        format!("-I{}", installed.join("include").display()),
        format!("-L{}", lib.display()),
        "-ldofray".into(),
    ] {
        assert!(
            shared_flags.contains(&flag),
            "{flag} not in {shared_flags:?}"
        );
    }
    // Static: the archive itself (-ldofray would pick the shared library), and what it needs.
    let mut static_flags = pkg_config(&["--cflags", "--static", "--libs"]);
    static_flags.retain(|f| f != "-ldofray");
    static_flags.insert(0, lib.join("libdofray.a").display().to_string());
    assert!(
        static_flags.contains(&format!("-l{EMBREE_LIB}")),
        "{static_flags:?}"
    );

    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    for (name, flags) in [("shared", shared_flags), ("static", static_flags)] {
        let work = dir.join(name);
        std::fs::create_dir_all(&work).unwrap();
        let exe = work.join("render");
        output_of(
            Command::new(&cc)
                .args([
                    "-std=c99",
                    "-Wall",
                    "-Wextra",
                    "-Werror",
                    "-pedantic",
                    "-O1",
                ])
                .arg(root().join("capi/examples/render.c"))
                .args(&flags)
                .arg("-o")
                .arg(&exe),
        );
        let libraries = output_of(Command::new("ldd").arg(&exe).env("LD_LIBRARY_PATH", &lib));
        let from_installed = format!("{SONAME} => {}", lib.join(SONAME).display());
        if name == "shared" {
            assert!(libraries.contains(&from_installed), "{libraries}");
        } else {
            assert!(!libraries.contains("libdofray"), "{libraries}");
        }
        let text = output_of(
            Command::new(&exe)
                .current_dir(&work)
                .env("LD_LIBRARY_PATH", &lib),
        );
        assert!(text.contains("64x48"), "{name}: {text}");
        assert!(work.join("paper.png").is_file(), "{name}: no paper.png");
    }
    println!(
        "install, two compiles and two renders: {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// Runs `cmd`, which must succeed; its stdout and stderr.
fn output_of(cmd: &mut Command) -> String {
    let output = cmd
        .output()
        .unwrap_or_else(|e| panic!("{cmd:?} cannot run: {e}"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        output.status.success(),
        "{cmd:?} failed ({}):\n{text}",
        output.status
    );
    text
}
