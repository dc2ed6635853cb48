//! What dofray's fuzz targets share: loader limits small enough for a fuzzer, a scratch folder
//! per process for the inputs the loaders read from files, and the panic policy.

use std::panic::{self, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once, OnceLock};

use dofray::scene::LoadOptions;

/// The limits every target loads with: no input can make a loader read more than 16 MiB from
/// a file, decode a texture into more than 64 MiB, or expand a glTF node tree into more than
/// a million triangles, so a fuzz input cannot allocate gigabytes (libFuzzer's
/// `-rss_limit_mb=2048` would report that as a crash).
pub fn options() -> LoadOptions {
    LoadOptions {
        max_input_bytes: 16 << 20,
        max_texture_bytes: 64 << 20,
        max_instanced_triangles: 1 << 20,
        max_node_instances: 1 << 14,
        allow_outside_paths: false,
    }
}

/// The repository's root (the fuzz crate is its `fuzz/`).
pub fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// A folder of this process for target `name`, made once, holding copies of the files `assets`
/// names (paths relative to the repository) under their file names, for inputs that refer to
/// textures, MTL libraries or buffers. Under `$TMPDIR` (scripts/fuzz.sh points that at a
/// folder it removes afterwards).
pub fn scratch(name: &str, assets: &[&str]) -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("dofray-fuzz-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        for asset in assets {
            let from = repo().join(asset);
            let to = dir.join(from.file_name().expect("an asset file name"));
            std::fs::copy(&from, &to).unwrap_or_else(|e| panic!("{}: {e}", from.display()));
        }
        dir
    })
}

/// Writes `bytes` to `path` (a file in [`scratch`]).
pub fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// `data` split at the first `separator`: (before, after it if it occurs).
pub fn split<'a>(data: &'a [u8], separator: &[u8]) -> (&'a [u8], Option<&'a [u8]>) {
    match data.windows(separator.len()).position(|w| w == separator) {
        Some(at) => (&data[..at], Some(&data[at + separator.len()..])),
        None => (data, None),
    }
}

/// The message of the last panic let through to a loader's guard (see [`run`]).
static LAST_GUARDED: Mutex<Option<String>> = Mutex::new(None);

/// Runs one input under dofray's panic policy:
///
/// - A panic in dofray's own code, or in the standard library on its behalf, is a bug, even
///   where a loader would catch it: libFuzzer's hook prints it and aborts, a crash.
/// - A panic in a third-party parser's own code (a crate from the registry: tobj, gltf, exr,
///   png, image, toml) is what the loaders catch by design (`scene::mesh_input::guarded` turns
///   it into an error naming the file), so it unwinds quietly to that guard. If nothing
///   catches it, it is printed here and aborts all the same.
///
/// `DOFRAY_FUZZ_STRICT=1` makes every panic a crash (to find the parser panics to report
/// upstream).
pub fn run(body: impl FnOnce()) {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let strict = std::env::var_os("DOFRAY_FUZZ_STRICT").is_some_and(|v| v == "1");
        // libfuzzer-sys's hook: prints the panic and aborts.
        let crash = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            let third_party = info
                .location()
                .is_some_and(|l| l.file().contains("/registry/src/"));
            if third_party && !strict {
                *LAST_GUARDED.lock().unwrap_or_else(|e| e.into_inner()) = Some(info.to_string());
            } else {
                crash(info);
            }
        }));
    });
    if panic::catch_unwind(AssertUnwindSafe(body)).is_err() {
        if let Some(message) = LAST_GUARDED
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            eprintln!("a third-party panic no loader caught: {message}");
        }
        std::process::abort();
    }
}
