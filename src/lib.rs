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
#![deny(unsafe_code)]

/// dofray's version (Cargo's package version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit dofray was built from (`git rev-parse --short HEAD` at build time, or the
/// `DOFRAY_GIT_COMMIT` environment variable), or `"unknown"` when built outside a git checkout.
pub const GIT_COMMIT: &str = env!("DOFRAY_GIT_COMMIT");

pub mod batch;
pub mod bench;
pub mod camera;
// The only module with FFI; its unsafe blocks are documented (clippy::undocumented_unsafe_blocks).
#[allow(unsafe_code)]
pub mod embree;
pub mod exit;
pub mod filter;
pub mod limits;
pub mod metrics;
pub mod output;
pub mod overrides;
pub mod render;
pub mod renderer;
pub mod sampler;
pub mod scene;
pub mod shade;

/// The vector maths crate of dofray's public types (`Vec3` in scenes, cameras and lights),
/// re-exported so callers use the same version.
pub use glam;
