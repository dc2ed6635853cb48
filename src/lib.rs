//! dofray: depth-of-field rendering on Intel Embree.
//!
//! The renderer traces 16-wide packets of thin-lens rays only at adaptive sample sites, dense
//! where the image is in focus and sparse where it is blurred, and interpolates between them
//! (Kumamoto, "A Faster Technique for Rendering Depth of Field Images").
//!
//! Data flows one way: [`scene::SceneDesc`] -> [`scene::World`] (Embree geometry, materials)
//! -> [`camera::Camera`] -> [`render::render`] -> [`render::Film`] -> [`output`].
//! [`renderer::Renderer`] does the middle for a scene with [`overrides::Overrides`] (what the
//! command line's flags set): load, override, render, write.
//!
//! # Rendering a scene
//!
//! ```rust
//! use dofray::embree::Device;
//! use dofray::overrides::Overrides;
//! use dofray::render::{NoProgress, SettingsPatch};
//! use dofray::renderer::Renderer;
//!
//! // A built-in scene, a scene file (.toml) or a model (.obj, .gltf, .glb).
//! let scene = dofray::scene::load("paper")?;
//! // What `dofray render --width 160 --f-number 2 --autofocus 80,60 --spp 32` changes.
//! let overrides = Overrides {
//!     width: Some(160),
//!     f_number: Some(2.0),
//!     autofocus: Some((80, 60)),
//!     ..Default::default()
//! };
//! let renderer = Renderer::with_overrides(scene, overrides, &Device::new()?)?;
//! let settings = renderer.settings(&SettingsPatch { spp: Some(32), ..Default::default() })?;
//! let (film, stats) = renderer.render(&settings, &NoProgress)?;
//! // PNG (sRGB) or multilayer EXR (linear; depth, CoC and the sampling maps too).
//! dofray::output::write_film(&std::env::temp_dir().join("dofray-lib-example.exr"), &film)?;
//! println!("{} rays in {:.2} s", stats.rays.total(), stats.seconds);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Architecture
//!
//! The modules form layers; each imports only from the layers below it (`tests/architecture.rs`
//! checks this on the source, and that no function is over 100 lines):
//!
//! | layer | modules | what they hold |
//! |---|---|---|
//! | 0 | [`error_kind`], [`params`] | the kinds of failure (exit codes, JSON kinds); the parameter table (flag, scene key, Python keyword, C setter) |
//! | 1 | [`embree`], [`limits`], [`filter`], [`sampler`], [`metrics`] | Embree (the only `unsafe`), resource limits, the pixel filter, sample numbers, image metrics |
//! | 2 | [`camera`], [`view`] | the camera makes rays: spec, focus, the lens seam ([`camera::lens`]), apertures; display views for PNGs (AgX, ...) |
//! | 3 | [`shade`], [`settings`] | materials, textures, lights; render settings resolved once from patches |
//! | 4 | [`scene`] | descriptions and loaders (TOML by concept, OBJ, glTF) and the Embree world |
//! | 5 | [`render`] | depth pass and maps, sites, error estimate and refinement, packets, film |
//! | 6 | [`overrides`], [`output`] | what flags change in a scene; the output target, PNG / EXR, merge, atomic files |
//! | 7 | [`renderer`] | a scene, its overrides and its world, built once; any frame or region |
//! | 8 | [`batch`] | frames, tiles, shards and the job loop the command line, C and Python share |
//! | 9 | `bench` | the seed's table and equal-error studies (feature `bench`) |
//! | 10 | [`exit`] | classifies any error chain (it knows every error type) |
//!
//! The `dofray` binary (`src/main.rs`, `src/cli/`) only parses flags, prints and handles
//! signals; the C library (`capi/`) and the Python module (`python/`) are the other front ends
//! over the same library.
//!
//! Where to add:
//! - **a lens** (a traced prescription beside the thin lens): a type implementing
//!   [`camera::Lens`] (the rays of a sample site from film and lens sample numbers, and the
//!   blur bound `coc_px` the adaptive sampler trusts), a variant of [`camera::CameraLens`] with
//!   its dispatch line, and a [`camera::LensSpec`] that builds it;
//! - **an output format**: an [`output::ImageFormat`] for its extension, a writer under
//!   `src/output/` that takes the resolved [`output::Target`], and a tile reader in
//!   `output::merge` if its tiles are to be merged;
//! - **an error estimator or site rule**: a [`settings::SamplingRule`] variant resolved by
//!   [`settings::SettingsPatch::resolve`], its refinement beside `src/render/refine.rs`, and its
//!   parameters as [`params::Param`] rows;
//! - **an error type**: derive `thiserror::Error`, implement [`error_kind::HasKind`] beside it
//!   and list it in `exit`'s `classified!` registry (it does not compile until listed).
//!
//! # Features
//!
//! `cli` (default) builds the `dofray` command and the crates only it needs (clap, indicatif,
//! anyhow, signal-hook), and turns on `bench`. `bench` is the `bench` module (the seed's
//! table, the equal-error study and its plot, drawn with plotters and an embedded font). A
//! library user can turn both off: `dofray = { version = "0.1", default-features = false }`,
//! adding `features = ["bench"]` for the benchmarks.
//!
//! dofray's own `.cargo/config.toml` builds for x86-64-v3 (AVX2, FMA); that file does not
//! apply when dofray is a dependency. For the same speed, set it in the application's
//! `.cargo/config.toml` (`rustflags = ["-C", "target-cpu=x86-64-v3"]`) or build with
//! `RUSTFLAGS="-C target-cpu=native"`.
#![deny(unsafe_code)]
#![warn(missing_docs)]

/// dofray's version (Cargo's package version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit dofray was built from (`git rev-parse --short HEAD` at build time, or the
/// `DOFRAY_GIT_COMMIT` environment variable), or `"unknown"` when built outside a git checkout.
pub const GIT_COMMIT: &str = env!("DOFRAY_GIT_COMMIT");

pub mod batch;
#[cfg(feature = "bench")]
pub mod bench;
pub mod camera;
// The only module with FFI; its unsafe blocks are documented (clippy::undocumented_unsafe_blocks).
#[allow(unsafe_code)]
pub mod embree;
pub mod error_kind;
pub mod exit;
pub mod filter;
pub mod limits;
pub mod metrics;
pub mod output;
pub mod overrides;
pub mod params;
pub mod render;
pub mod renderer;
pub mod sampler;
pub mod scene;
pub mod settings;
pub mod shade;
pub mod view;
pub mod workers;

/// The vector maths crate of dofray's public types (`Vec3` in scenes, cameras and lights),
/// re-exported so callers use the same version.
pub use glam;

// README.md's Rust examples are compiled and run as doctests, so the README stays true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
