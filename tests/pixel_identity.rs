//! Refactoring guard: every built-in and repository scene, in every mode and rule and with the
//! lens, filter and output options that take different code paths, renders to exactly the
//! pixels it rendered when `tests/pixel_identity.txt` was written (at the commit before the
//! architecture issue's refactor, 60dd6ef). Each case runs the `dofray` command (the interface
//! a refactor must not change) to a multilayer EXR and hashes every channel's samples bit for
//! bit (colour, alpha, depth, CoC, interval, samples).
//!
//! Embree is pinned to its AVX2 kernels (`DOFRAY_EMBREE_CONFIG=isa=avx2`, which every machine
//! this runs on has), so the hashes do not depend on whether the CPU has AVX-512. They do depend
//! on the CPU's maker: every case hashed differently on an AMD EPYC than on the Intel Xeon the
//! table was first written on, the pinhole and direct-integrator ones too. The likely cause is
//! Embree's kernels, which refine approximate reciprocals (`rcpps`, whose last bits differ
//! between AMD and Intel), so hit distances, and with them every pixel, round differently. The table keeps a section per Embree version
//! and CPU vendor (`# embree 3.13.5 on GenuineIntel`); a platform without one is skipped with
//! a notice.
//!
//! A change that is meant to change pixels re-blesses the table, and says so in its commit:
//! `DOFRAY_BLESS=1 cargo test --test integration pixel_identity` rewrites this platform's section; in the
//! other sections, every case whose pixels changed here (or that is new) becomes `unknown`,
//! which the test skips with a notice until someone blesses on that platform, and the cases
//! that did not change keep guarding there.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::scratch::Scratch;

const TABLE: &str = "tests/pixel_identity.txt";

/// (case name, arguments after `dofray render`). Small images keep the suite fast; every
/// case still crosses in-focus and blurred regions.
fn cases() -> Vec<(&'static str, Vec<&'static str>)> {
    let size = ["--width", "96", "--height", "72"];
    let mut cases: Vec<(&'static str, Vec<&'static str>)> = Vec::new();
    let scenes: [(&str, &str); 8] = [
        ("paper", "paper"),
        ("paper.toml", "scenes/paper.toml"),
        ("gallery", "scenes/gallery.toml"),
        ("vase", "scenes/vase.toml"),
        ("bokeh", "scenes/bokeh.toml"),
        ("night", "scenes/night.toml"),
        ("focus_pull", "scenes/focus_pull.toml"),
        ("blender_lights", "tests/scene_assets/blender/lights.gltf"),
    ];
    let modes: [(&str, &[&str]); 5] = [
        ("pinhole", &["--mode", "pinhole"]),
        ("dense", &["--mode", "dense"]),
        ("adaptive", &["--mode", "adaptive"]),
        ("seed_rule", &["-k", "0.4"]),
        ("paper_exact", &["-k", "0.4", "--paper-exact"]),
    ];
    for (scene_name, scene) in scenes {
        for (mode_name, mode) in modes {
            let name: &'static str =
                Box::leak(format!("{scene_name}/{mode_name}").into_boxed_str());
            let mut args = vec![scene];
            args.extend(size);
            args.extend(mode.iter().copied());
            cases.push((name, args));
        }
    }
    // Options that take their own code paths, on the paper scene.
    let variants: [(&'static str, &[&'static str]); 19] = [
        ("paper/transparent", &["--transparent"]),
        (
            "paper/tolerance_0.5_spp_32",
            &["--tolerance", "0.5", "--spp", "32"],
        ),
        (
            "paper/aa_8_gaussian",
            &["--aa", "8", "--pixel-filter", "gaussian"],
        ),
        (
            "paper/box_filter",
            &["--pixel-filter", "box", "--pixel-filter-width", "1"],
        ),
        (
            "paper/lens_filters",
            &["--filter", "gaussian", "--mode", "dense"],
        ),
        ("paper/tent_seed", &["--filter", "tent", "-k", "0.2"]),
        (
            "paper/hexagon_anamorphic",
            &[
                "--f-number",
                "1.4",
                "--focal-length",
                "50",
                "--blades",
                "6",
                "--blade-rotation",
                "15",
                "--anamorphic",
                "1.5",
            ],
        ),
        (
            "paper/autofocus",
            &["--autofocus", "20,50", "--aperture-radius", "0.3"],
        ),
        (
            "paper/seed_lens",
            &["--sharp-range", "1.5", "--spread", "4"],
        ),
        (
            "paper/focus_inf",
            &["--focus-distance", "inf", "--f-number", "2"],
        ),
        ("paper/region", &["--region", "16,8,80,40"]),
        ("paper/direct", &["--integrator", "direct"]),
        ("gallery/direct", &["--integrator", "direct"]),
        (
            "bokeh/bounces_clamp",
            &["--max-bounces", "3", "--clamp-indirect", "4"],
        ),
        ("paper/exposure_seed", &["--exposure", "-1", "--seed", "7"]),
        (
            "paper/lights",
            &[
                "--light",
                "sun:-1,-2,1:3",
                "--light",
                "point:0,4,0:80",
                "--ambient",
                "0.05",
            ],
        ),
        ("focus_pull/frame_40", &["--frames", "40"]),
        (
            "gallery/wide_aperture_dense",
            &["--aperture-radius", "0.1", "--mode", "dense"],
        ),
        (
            "gallery/wide_aperture_adaptive",
            &["--aperture-radius", "0.1"],
        ),
    ];
    for (name, extra) in variants {
        let scene = match name.split('/').next() {
            Some("focus_pull") => "scenes/focus_pull.toml",
            Some("gallery") => "scenes/gallery.toml",
            _ => "paper",
        };
        let mut args = vec![scene];
        args.extend(size);
        args.extend(extra.iter().copied());
        cases.push((name, args));
    }
    cases
}

/// FNV-1a (64 bit) over every channel's name and its samples' bits, in the file's order.
fn exr_hash(path: &Path) -> u64 {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for layer in &image.layer_data {
        eat(format!("{:?}", layer.size).as_bytes());
        for c in &layer.channel_data.list {
            eat(c.name.to_string().as_bytes());
            match &c.sample_data {
                FlatSamples::F16(v) => v.iter().for_each(|x| eat(&x.to_bits().to_le_bytes())),
                FlatSamples::F32(v) => v.iter().for_each(|x| eat(&x.to_bits().to_le_bytes())),
                FlatSamples::U32(v) => v.iter().for_each(|x| eat(&x.to_le_bytes())),
            }
        }
    }
    h
}

fn render_hash(args: &[&str], dir: &Path, index: usize) -> Result<u64, String> {
    let out = dir.join(format!("case-{index}.exr"));
    let status = Command::new(env!("CARGO_BIN_EXE_dofray"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("DOFRAY_EMBREE_CONFIG", "isa=avx2")
        .arg("render")
        .args(args)
        .args(["--quiet", "--threads", "2", "-o"])
        .arg(&out)
        .output()
        .map_err(|e| e.to_string())?;
    if !status.status.success() {
        return Err(String::from_utf8_lossy(&status.stderr).into_owned());
    }
    Ok(exr_hash(&out))
}

#[test]
fn every_scene_and_mode_renders_the_pixels_it_did_before() {
    if !std::arch::is_x86_feature_detected!("avx2") {
        eprintln!("NOTICE: pixel identity skipped: the hashes are of Embree's AVX2 kernels");
        return;
    }
    // Another Embree (Debian 13's 4.x under scripts/embree4-check.sh) may round hits
    // differently, and so does another CPU vendor: each section holds the hashes of one.
    let embree = dofray::embree::Device::new().unwrap().embree_version();
    let table = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(TABLE);
    let platform = format!("# embree {embree} on {}", cpu_vendor());
    let bless = std::env::var_os("DOFRAY_BLESS").is_some();
    let text = std::fs::read_to_string(&table).unwrap();
    let sections = sections(&text);
    if !bless && !sections.contains_key(&platform) {
        eprintln!(
            "NOTICE: pixel identity skipped: the table has no hashes for {platform:?} (it has {:?})",
            sections.keys().collect::<Vec<_>>()
        );
        return;
    }
    let dir = tempdir();
    let mut got = BTreeMap::new();
    for (i, (name, args)) in cases().into_iter().enumerate() {
        let hash = render_hash(&args, &dir, i).unwrap_or_else(|e| panic!("{name}: {e}"));
        got.insert(name.to_string(), format!("{hash:016x}"));
    }
    dir.close().ok();
    if bless {
        std::fs::write(&table, blessed(&sections, &platform, &got)).unwrap();
        eprintln!("wrote {} for {platform}", table.display());
        return;
    }
    let want = &sections[&platform];
    let unknown: Vec<_> = (want.iter())
        .filter(|(_, v)| *v == UNKNOWN)
        .map(|(k, _)| k.as_str())
        .collect();
    if !unknown.is_empty() {
        eprintln!(
            "NOTICE: pixel identity skipped for {unknown:?}: not blessed on {platform:?} since they changed"
        );
    }
    let differ: Vec<_> = got
        .iter()
        .filter(|(k, v)| want.get(*k).is_none_or(|w| w != *v && w != UNKNOWN))
        .map(|(k, v)| format!("{k}: now {v}, was {:?}", want.get(k)))
        .collect();
    assert!(differ.is_empty(), "renders changed:\n{}", differ.join("\n"));
    assert_eq!(
        got.len(),
        want.len(),
        "the table has cases this test no longer renders"
    );
}

/// A case's hash in a platform's section after its pixels changed on another platform.
const UNKNOWN: &str = "unknown";

/// The table with `platform`'s section set to `got`; in the other sections of `sections`, the
/// cases whose hash changed on `platform` (or are new) become [`UNKNOWN`].
fn blessed(
    sections: &BTreeMap<String, BTreeMap<String, String>>,
    platform: &str,
    got: &BTreeMap<String, String>,
) -> String {
    let before = sections.get(platform);
    let mut out = String::new();
    let mut write = |header: &str, cases: &BTreeMap<String, String>| {
        out.push_str(header);
        out.push('\n');
        for (k, v) in cases {
            out.push_str(&format!("{k} {v}\n"));
        }
    };
    write(platform, got);
    for (header, cases) in sections.iter().filter(|(h, _)| *h != platform) {
        let kept = (got.iter())
            .map(|(k, v)| {
                let same = before.and_then(|b| b.get(k)) == Some(v);
                let old = cases.get(k).filter(|_| same);
                (
                    k.clone(),
                    old.cloned().unwrap_or_else(|| UNKNOWN.to_string()),
                )
            })
            .collect();
        write(header, &kept);
    }
    out
}

/// The table's sections: each `# embree ... on VENDOR` line's cases and hashes.
fn sections(text: &str) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut out: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    let mut header = None;
    for line in text.lines() {
        if line.starts_with("# embree ") {
            header = Some(line);
            out.entry(line.to_string()).or_default();
        } else if let (Some(h), Some((k, v))) = (header, line.split_once(' ')) {
            out.entry(h.to_string())
                .or_default()
                .insert(k.to_string(), v.to_string());
        }
    }
    out
}

/// The CPU's vendor string (`GenuineIntel`, `AuthenticAMD`), from /proc/cpuinfo.
fn cpu_vendor() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find_map(|l| l.strip_prefix("vendor_id"))
                .and_then(|rest| rest.split(':').nth(1))
                .map(|v| v.trim().to_string())
        })
        .unwrap_or_else(|| "an unknown CPU".to_string())
}

fn tempdir() -> Scratch {
    Scratch::new("pixel-identity")
}
