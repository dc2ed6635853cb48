//! Tells the C tests which Embree library dofray links (`embree3` or `embree4`, from the
//! `dofray` crate's build script: `links = "embree"`) and, for a private prefix
//! (`EMBREE_DIR`), its library directory, which also becomes libdofray.so's rpath.

use std::env;
use std::path::PathBuf;

fn main() {
    println!("cargo::rerun-if-env-changed=EMBREE_DIR");
    let major = env::var("DEP_EMBREE_MAJOR").unwrap_or_else(|_| "3".into());
    println!("cargo::rustc-env=DOFRAY_CAPI_EMBREE_LIB=embree{major}");
    let lib_dir = env::var_os("EMBREE_DIR")
        .map(PathBuf::from)
        .and_then(|prefix| {
            ["lib", "lib64"]
                .iter()
                .map(|d| prefix.join(d))
                .find(|d| d.join(format!("libembree{major}.so")).exists())
        });
    let shown = lib_dir
        .as_ref()
        .map(|d| d.display().to_string())
        .unwrap_or_default();
    println!("cargo::rustc-env=DOFRAY_CAPI_EMBREE_LIB_DIR={shown}");
    if lib_dir.is_some() {
        println!("cargo::rustc-link-arg-cdylib=-Wl,-rpath,{shown}");
    }
}
