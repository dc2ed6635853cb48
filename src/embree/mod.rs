//! Safe Rust over Intel Embree: the only module of dofray with `unsafe` code and raw FFI.
//!
//! [`Device`] -> [`SceneBuilder`] (add [`TriangleMesh`]es and [`Spheres`]) -> [`Scene`], which is
//! immutable, `Send + Sync`, and traces single rays or 16-wide packets ([`RayPacket16`],
//! [`ShadowPacket16`]). Geometry data is validated before Embree sees it; Embree's errors come
//! back as [`EmbreeError`].
//!
//! The crate root denies `unsafe` everywhere else; here every `unsafe` block states why it is
//! sound in a `SAFETY:` comment.
#![warn(clippy::undocumented_unsafe_blocks)]

mod device;
mod filter;
mod geometry;
mod packet;
mod scene;
mod sys;
mod version;

pub use device::{CONFIG_ENV, Device, EmbreeError, ErrorCode, Result, env_config, limited_isas};
pub use filter::{CandidateHit, HitFilter};
pub use geometry::{Geometry, GeometryId, Spheres, TriangleMesh};
pub use packet::{Hit, LANES, Ray, RayHint, RayPacket16, ShadowPacket16};
pub use scene::{BuildQuality, PacketWidth, Scene, SceneBuilder};
pub use version::EMBREE_MAJOR;
