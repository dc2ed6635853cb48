//! Finds Embree and generates its Rust bindings with bindgen over `ffi/wrapper.h`.
//!
//! Search order: `EMBREE_DIR` (an install prefix with `include/` and `lib/`, such as Intel's
//! release archive), then the system's Embree 4, then the system's Embree 3. The major version
//! found is exported as `cfg(embree3)` or `cfg(embree4)`; `src/embree/version.rs` is the only
//! code that looks at it.

use std::env;
use std::path::{Path, PathBuf};

/// Where the system keeps headers and shared libraries on Debian and most other Linux systems.
const SYSTEM_INCLUDE_DIRS: &[&str] = &["/usr/include", "/usr/local/include"];
const SYSTEM_LIB_DIRS: &[&str] = &[
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/usr/local/lib64",
];

struct Embree {
    major: u32,
    include_dir: PathBuf,
    lib_dir: PathBuf,
    /// True for a private prefix (`EMBREE_DIR`): the binary then needs an rpath to find the library.
    private_prefix: bool,
}

fn main() {
    println!("cargo::rustc-check-cfg=cfg(embree3)");
    println!("cargo::rustc-check-cfg=cfg(embree4)");
    println!("cargo::rerun-if-env-changed=EMBREE_DIR");
    println!("cargo::rerun-if-env-changed=LIBCLANG_PATH");
    println!("cargo::rerun-if-changed=ffi/wrapper.h");
    println!("cargo::rerun-if-changed=build.rs");
    git_commit();

    let embree = match find_embree() {
        Ok(e) => e,
        Err(why) => fail(&why),
    };
    let header = embree
        .include_dir
        .join(format!("embree{}/rtcore.h", embree.major));
    println!("cargo::rerun-if-changed={}", header.display());

    println!("cargo::rustc-cfg=embree{}", embree.major);
    println!(
        "cargo::rustc-link-search=native={}",
        embree.lib_dir.display()
    );
    println!("cargo::rustc-link-lib=dylib=embree{}", embree.major);
    if embree.private_prefix {
        println!(
            "cargo::rustc-link-arg=-Wl,-rpath,{}",
            embree.lib_dir.display()
        );
    }
    println!("cargo::metadata=include={}", embree.include_dir.display());
    println!("cargo::metadata=major={}", embree.major);

    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("bindings.rs");
    if let Err(why) = generate_bindings(&embree, &out) {
        fail(&why);
    }
}

/// Exports the git commit as `DOFRAY_GIT_COMMIT` (`dofray --version`, `--json`): the
/// environment variable of that name if set (builds from a source archive), else
/// `git rev-parse --short HEAD`, else "unknown". Never fails the build.
fn git_commit() {
    println!("cargo::rerun-if-env-changed=DOFRAY_GIT_COMMIT");
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .and_then(|o| String::from_utf8(o.stdout).ok())
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
    };
    let commit = env::var("DOFRAY_GIT_COMMIT")
        .ok()
        .filter(|s| !s.trim().is_empty())
        .or_else(|| git(&["rev-parse", "--short", "HEAD"]))
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo::rustc-env=DOFRAY_GIT_COMMIT={commit}");
    // Run again when HEAD moves: HEAD itself (a checkout), the branch it names (a commit) and
    // packed-refs. Only existing files: a missing one would make every build rerun this script.
    let mut watch = Vec::new();
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        watch.push(PathBuf::from(dir).join("HEAD"));
    }
    if let Some(common) = git(&["rev-parse", "--git-common-dir"]) {
        let common = PathBuf::from(common);
        watch.push(common.join("packed-refs"));
        if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
            watch.push(common.join(branch));
        }
    }
    for path in watch.iter().filter(|p| p.is_file()) {
        println!("cargo::rerun-if-changed={}", path.display());
    }
}

fn find_embree() -> Result<Embree, String> {
    if let Some(dir) = env::var_os("EMBREE_DIR") {
        let dir = PathBuf::from(dir);
        let include_dir = dir.join("include");
        for major in [4, 3] {
            if include_dir
                .join(format!("embree{major}/rtcore.h"))
                .is_file()
            {
                let lib_dir = [dir.join("lib"), dir.join("lib64")]
                    .into_iter()
                    .find(|d| has_library(d, major))
                    .ok_or_else(|| {
                        format!(
                            "EMBREE_DIR={} has include/embree{major}/rtcore.h but no libembree{major} \
                             under lib/ or lib64/",
                            dir.display()
                        )
                    })?;
                return Ok(Embree {
                    major,
                    include_dir,
                    lib_dir,
                    private_prefix: true,
                });
            }
        }
        return Err(format!(
            "EMBREE_DIR={} does not contain include/embree4/rtcore.h or include/embree3/rtcore.h",
            dir.display()
        ));
    }
    for major in [4, 3] {
        let include_dir = SYSTEM_INCLUDE_DIRS
            .iter()
            .map(PathBuf::from)
            .find(|d| d.join(format!("embree{major}/rtcore.h")).is_file());
        let lib_dir = SYSTEM_LIB_DIRS
            .iter()
            .map(PathBuf::from)
            .find(|d| has_library(d, major));
        if let (Some(include_dir), Some(lib_dir)) = (include_dir, lib_dir) {
            return Ok(Embree {
                major,
                include_dir,
                lib_dir,
                private_prefix: false,
            });
        }
    }
    Err(
        "Embree was not found: no embree4/rtcore.h or embree3/rtcore.h with its libembree \
         in the system include and library directories"
            .to_string(),
    )
}

fn has_library(dir: &Path, major: u32) -> bool {
    dir.join(format!("libembree{major}.so")).exists()
        || dir.join(format!("libembree{major}.dylib")).exists()
        || dir.join(format!("libembree{major}.a")).exists()
}

fn generate_bindings(embree: &Embree, out: &Path) -> Result<(), String> {
    let mut builder = bindgen::Builder::default()
        .header("ffi/wrapper.h")
        .clang_arg(format!("-I{}", embree.include_dir.display()))
        .allowlist_function("rtc.*")
        .allowlist_type("RTC.*")
        .allowlist_var("RTC.*")
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false)
        .generate_comments(false);
    if embree.major == 4 {
        builder = builder.clang_arg("-DDOFRAY_EMBREE4");
    }
    // bindgen panics (inside clang-sys) when libclang cannot be loaded; turn that into our message.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let generated =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || builder.generate()));
    std::panic::set_hook(default_hook);
    let bindings = match generated {
        Ok(Ok(b)) => b,
        Ok(Err(e)) => return Err(format!("bindgen could not parse the Embree headers: {e}")),
        Err(payload) => {
            let detail = payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            return Err(format!(
                "bindgen could not load libclang ({})",
                detail.lines().next().unwrap_or("no detail")
            ));
        }
    };
    bindings
        .write_to_file(out)
        .map_err(|e| format!("could not write {}: {e}", out.display()))
}

fn fail(why: &str) -> ! {
    eprintln!(
        "\n\
         error: dofray cannot be built: {why}.\n\
         \n\
         dofray needs Intel Embree (3.13 or 4.x) and libclang (for bindgen).\n\
         On Debian or Ubuntu:   apt-get install libembree-dev libclang-dev\n\
         (Debian 12 ships Embree 3.13, Debian 13 Embree 4.3; both work.)\n\
         Elsewhere, point EMBREE_DIR at an Embree install prefix containing include/ and lib/,\n\
         and set LIBCLANG_PATH if libclang is not on the default search path.\n"
    );
    std::process::exit(1);
}
