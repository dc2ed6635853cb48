//! The layout's rules, checked on the source so they stay true as the renderer grows
//! (README "Architecture"):
//!
//! - the library's top-level modules form layers, and a module imports only from layers below
//!   it (so there is no import circle between them);
//! - the binary is thin: `src/main.rs` is a page, and the command line's code (src/cli/) is
//!   not part of the library;
//! - no product function (library, binary, C ABI, Python module) is longer than 100 lines;
//! - every file of `tests/` is a module of the one test binary, `tests/main.rs` (cargo's
//!   automatic test targets are off), so none is silently left out.
//!
//! The checks read the source as text (comments and string literals removed), which is all
//! they need: `crate::module` paths and `fn` bodies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The library's top-level modules, lowest layer first. A module may import from modules of a
/// lower layer only. `error_kind` is at the bottom: every error type says its own kind next to
/// its definition, so the module that names the kinds needs none of them; `exit`, which
/// classifies any error chain by trying every error type, is at the top.
const LAYERS: &[&[&str]] = &[
    &["error_kind", "params"],
    &[
        "embree", "limits", "filter", "sampler", "metrics", "workers",
    ],
    &["camera", "view"],
    &["shade", "settings"],
    &["scene"],
    &["render"],
    &["overrides", "output"],
    &["renderer"],
    &["batch"],
    &["bench"],
    &["exit"],
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The source without comments, string and character literals (each replaced by nothing, so
/// lines keep their numbers).
fn code_only(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if c == b'/' && b.get(i + 1) == Some(&b'*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if b[i] == b'\n' {
                        out.push('\n');
                    }
                    i += 1;
                }
            }
        } else if c == b'r' && matches!(b.get(i + 1), Some(b'"') | Some(b'#')) && !ident(b, i) {
            // A raw string: r"...", r#"..."#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&b'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&b'"') {
                out.push(c as char);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == b'"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&b'#')) {
                    j += 1 + hashes;
                    break;
                }
                if b[j] == b'\n' {
                    out.push('\n');
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
        } else if c == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    i += 1;
                }
                if i < b.len() && b[i] == b'\n' {
                    out.push('\n');
                }
                i += 1;
            }
            out.push_str("\"\"");
            i += 1;
        } else if c == b'\'' {
            // A character literal ('x', '\n', '\u{..}'), not a lifetime ('a).
            let end = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..]
                    .iter()
                    .position(|&x| x == b'\'')
                    .map(|p| i + 2 + p)
            } else if b.get(i + 2) == Some(&b'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(e) => {
                    out.push_str("' '");
                    i = e + 1;
                }
                None => {
                    out.push('\'');
                    i += 1;
                }
            }
        } else {
            out.push(c as char);
            i += 1;
        }
    }
    out
}

fn ident(b: &[u8], i: usize) -> bool {
    i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')
}

/// The top-level library module a file under src/ belongs to (`render` for
/// src/render/refine.rs, `camera` for src/camera.rs); `None` for lib.rs, main.rs and the
/// binary's src/cli/.
fn module_of(path: &Path) -> Option<String> {
    let rel = path.strip_prefix(root().join("src")).ok()?;
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    let name = first.trim_end_matches(".rs").to_string();
    (!matches!(name.as_str(), "lib" | "main" | "cli")).then_some(name)
}

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// The top-level modules a file names through `crate::` paths, including grouped imports
/// (`use crate::{a, b::C}`), each with the first line naming it.
fn crate_imports(code: &str) -> BTreeMap<String, usize> {
    let mut found = BTreeMap::new();
    for (n, line) in code.lines().enumerate() {
        let mut rest = line;
        while let Some(p) = rest.find("crate::") {
            if p > 0 && {
                let b = rest.as_bytes()[p - 1];
                b.is_ascii_alphanumeric() || b == b'_' || b == b'$'
            } {
                rest = &rest[p + 7..];
                continue;
            }
            rest = &rest[p + 7..];
            let names: Vec<String> = if let Some(group) = rest.strip_prefix('{') {
                // Only the group's first level, on this line (rustfmt keeps short groups on one
                // line; longer ones put one path per line, caught below).
                let end = group.find('}').unwrap_or(group.len());
                group[..end]
                    .split(',')
                    .filter_map(|s| s.trim().split("::").next().map(str::to_string))
                    .collect()
            } else {
                vec![
                    rest.chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect(),
                ]
            };
            for name in names.into_iter().filter(|s| !s.is_empty()) {
                found.entry(name).or_insert(n + 1);
            }
        }
    }
    // Multi-line groups: `use crate::{` then one path per line.
    let mut in_group = false;
    for (n, line) in code.lines().enumerate() {
        let t = line.trim();
        if t.starts_with("use crate::{") && !t.contains('}') {
            in_group = true;
            continue;
        }
        if in_group {
            if t.starts_with('}') {
                in_group = false;
                continue;
            }
            let name: String = t
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                found.entry(name).or_insert(n + 1);
            }
        }
    }
    found
}

#[test]
fn library_modules_import_only_from_layers_below() {
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    let mut problems = Vec::new();
    for path in &files {
        let Some(module) = module_of(path) else {
            continue;
        };
        let Some(layer) = layer_of(&module) else {
            problems.push(format!(
                "{}: module `{module}` is in no layer of tests/architecture.rs (add it where it belongs)",
                path.display()
            ));
            continue;
        };
        let code = code_only(&std::fs::read_to_string(path).unwrap());
        for (name, line) in crate_imports(&code) {
            if name == module {
                continue;
            }
            match layer_of(&name) {
                Some(l) if l < layer => {}
                Some(_) => problems.push(format!(
                    "{}:{line}: `{module}` imports `crate::{name}`, which is not in a lower layer",
                    path.display()
                )),
                // Items of lib.rs (VERSION, GIT_COMMIT, glam) sit below everything.
                None => {}
            }
        }
    }
    assert!(
        problems.is_empty(),
        "layering broken:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_binary_is_a_page_and_not_part_of_the_library() {
    let main = std::fs::read_to_string(root().join("src/main.rs")).unwrap();
    let lines = main.lines().count();
    assert!(
        lines < 200,
        "src/main.rs has {lines} lines; the command line's code belongs in src/cli/"
    );
    let lib = code_only(&std::fs::read_to_string(root().join("src/lib.rs")).unwrap());
    assert!(
        !lib.lines()
            .any(|l| l.trim_start().starts_with("mod cli") || l.contains("pub mod cli")),
        "src/cli/ is the binary's; lib.rs must not declare it"
    );
}

/// Each function's length in lines, from its `fn` line to its closing brace, skipping test
/// modules (`#[cfg(test)]`).
fn function_lengths(code: &str) -> Vec<(usize, usize, String)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut out = Vec::new();
    let mut skip_until_depth: Option<i32> = None;
    let mut depth = 0i32;
    let mut pending_cfg_test = false;
    let mut i = 0;
    while i < lines.len() {
        let t = lines[i].trim();
        if skip_until_depth.is_none() {
            if t.starts_with("#[cfg(test)]") {
                pending_cfg_test = true;
            } else if pending_cfg_test && (t.starts_with("mod ") || t.starts_with("pub mod ")) {
                skip_until_depth = Some(depth);
                pending_cfg_test = false;
            } else if !t.starts_with("#[") && !t.is_empty() {
                pending_cfg_test = false;
            }
            if let Some(name) = fn_name(t) {
                // Find the body's end by brace matching from here.
                // A `;` outside brackets before any `{` ends a body-less declaration (`[f32;
                // 16]` in a signature does not).
                let (mut d, mut started, mut j, mut brackets) = (0i32, false, i, 0i32);
                'scan: while j < lines.len() {
                    for ch in lines[j].chars() {
                        match ch {
                            '{' => {
                                d += 1;
                                started = true;
                            }
                            '}' => d -= 1,
                            '(' | '[' => brackets += 1,
                            ')' | ']' => brackets -= 1,
                            ';' if !started && brackets == 0 => break 'scan,
                            _ => {}
                        }
                        if started && d == 0 {
                            break 'scan;
                        }
                    }
                    j += 1;
                }
                if started {
                    out.push((j - i + 1, i + 1, name));
                }
            }
        }
        for ch in lines[i].chars() {
            match ch {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
        }
        if skip_until_depth.is_some_and(|d| depth <= d && lines[i].contains('}')) {
            skip_until_depth = None;
        }
        i += 1;
    }
    out
}

fn fn_name(t: &str) -> Option<String> {
    let mut words = t.split_whitespace().peekable();
    while let Some(w) = words.next() {
        let w = w
            .trim_start_matches("pub(crate)")
            .trim_start_matches("pub(super)");
        match w {
            "" | "pub" | "const" | "async" | "unsafe" | "extern" | "\"\"" | "default" => continue,
            "fn" => {
                let name: String = words
                    .next()?
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                return (!name.is_empty()).then_some(name);
            }
            _ => return None,
        }
    }
    None
}

#[test]
fn no_product_function_is_longer_than_100_lines() {
    let mut files = Vec::new();
    for dir in ["src", "capi/src", "python/src"] {
        rust_files(&root().join(dir), &mut files);
    }
    let mut long = Vec::new();
    for path in &files {
        let code = code_only(&std::fs::read_to_string(path).unwrap());
        for (len, line, name) in function_lengths(&code) {
            if len > 100 {
                long.push(format!(
                    "{}:{line}: fn {name} is {len} lines",
                    path.display()
                ));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over 100 lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn every_test_file_is_in_the_test_binary() {
    let dir = root().join("tests");
    let main = std::fs::read_to_string(dir.join("main.rs")).expect("tests/main.rs");
    let declared: Vec<&str> = (main.lines())
        .filter_map(|l| l.trim().strip_prefix("mod ")?.strip_suffix(';'))
        .collect();
    // A test binary of its own (a [[test]] of Cargo.toml: one that needs its process alone).
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).expect("Cargo.toml");
    let own: Vec<&str> = (manifest.lines())
        .filter_map(|l| {
            l.trim()
                .strip_prefix("path = \"tests/")?
                .strip_suffix(".rs\"")
        })
        .collect();
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("tests/") {
        let path = entry.expect("a directory entry").path();
        let name = if path.is_dir() && path.join("mod.rs").is_file() {
            path.file_name()
        } else if path.extension().is_some_and(|e| e == "rs") {
            path.file_stem()
        } else {
            None
        };
        let Some(name) = name.and_then(|n| n.to_str()) else {
            continue;
        };
        if name != "main" && !declared.contains(&name) && !own.contains(&name) {
            missing.push(name.to_owned());
        }
    }
    assert!(
        missing.is_empty(),
        "tests/ files that tests/main.rs does not declare (they would never run): {missing:?}"
    );
    assert!(declared.len() >= 30, "{declared:?}");
}

#[test]
fn the_checks_see_what_they_check() {
    // The scanners themselves, on known text, so a broken scanner cannot pass everything.
    let code = code_only(
        "use crate::{render::Film, scene};\n// crate::bench in a comment\nlet s = \"crate::batch\";\n\
         fn f(a: [u8; 2]) {\n    let x = crate::camera::X;\n}\nfn g();\n#[cfg(test)]\nmod tests {\n    fn long() {\n    }\n}\n",
    );
    let imports: Vec<String> = crate_imports(&code).into_keys().collect();
    assert_eq!(imports, ["camera", "render", "scene"]);
    let fns: Vec<(usize, String)> = function_lengths(&code)
        .into_iter()
        .map(|(n, _, name)| (n, name))
        .collect();
    assert_eq!(fns, [(3, "f".to_string())]);
    assert_eq!(
        module_of(&root().join("src/render/refine.rs")).as_deref(),
        Some("render")
    );
    assert_eq!(module_of(&root().join("src/cli/args.rs")), None);
}
