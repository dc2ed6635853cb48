//! `include/dofray.h` is generated from `capi/src/lib.rs` by cbindgen (`capi/cbindgen.toml`) and
//! committed: this test fails when it is stale. `DOFRAY_BLESS=1 cargo test -p dofray-capi
//! --test header` rewrites it.

use std::path::Path;

#[test]
fn header_is_up_to_date() {
    let capi = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(capi.join("cbindgen.toml"))
        .expect("capi/cbindgen.toml is readable and valid");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(capi.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header from capi/src/lib.rs");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let header = capi.join("../include/dofray.h");
    if std::env::var_os("DOFRAY_BLESS").is_some_and(|v| !v.is_empty() && v != "0") {
        std::fs::write(&header, &generated).expect("include/dofray.h is writable");
        return;
    }
    let committed = std::fs::read(&header).unwrap_or_default();
    assert!(
        committed == generated,
        "include/dofray.h is stale (or missing): it differs from what cbindgen generates from \
         capi/src/lib.rs. Regenerate it with\n\n    DOFRAY_BLESS=1 cargo test -p dofray-capi \
         --test header\n\nand commit it.\n--- generated ---\n{}",
        String::from_utf8_lossy(&generated)
    );
}
