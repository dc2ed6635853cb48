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

/// The vector maths crate of dofray's public types (`Vec3` in scenes, cameras and lights),
/// re-exported so callers use the same version.
pub use glam;

// README.md's Rust examples are compiled and run as doctests, so the README stays true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
