//! Batch and farm rendering, as pure functions: which frames to render, where each frame's (or
//! tile's) image goes, and which share of the work this worker of a render farm takes.
//!
//! Nothing here renders, reads files or reads the environment by itself: the caller passes the
//! command-line text, the output path and an environment lookup, so every rule is unit-tested.
//!
//! - [`frames`]: frame lists as render-farm users write them (`1-100x2`, `1..240`, `-5--1`,
//!   `1,5,10`) and Blender-style start / end / step ranges.
//! - [`pattern`]: frame-numbered output paths (`shot_####.exr`, `shot_%04d.exr`) and the files of
//!   an image's tiles (`still.tile-003.exr`).
//! - [`shard`]: this worker's round-robin share of the items (`I/N`), given on the command line
//!   or read from a Slurm job array or a Kubernetes Indexed Job.

pub mod frames;
pub mod jobs;
pub mod pattern;
pub mod shard;

pub use frames::{FrameSpecError, MAX_FRAMES, frame_range, parse_frames};
pub use pattern::{PatternError, check_frame_pattern, frame_path, has_frame_pattern, tile_path};
pub use shard::{Shard, ShardError, ShardSource};
