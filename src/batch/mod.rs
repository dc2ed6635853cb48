//! Batch and farm rendering: which frames to render, where each frame's (or tile's) image
//! goes, which share of the work this worker of a render farm takes, and the loop that renders
//! them.
//!
//! Apart from [`run`], nothing here renders, reads files or reads the environment by itself:
//! the caller passes the command-line text, the output path and an environment lookup, so
//! every rule is unit-tested.
//!
//! - [`frames`]: frame lists as render-farm users write them (`1-100x2`, `1..240`, `-5--1`,
//!   `1,5,10`) and Blender-style start / end / step ranges.
//! - [`pattern`]: frame-numbered output paths (`shot_####.exr`, `shot_%04d.exr`) and the files of
//!   an image's tiles (`still.tile-003.exr`).
//! - [`shard`]: this worker's round-robin share of the items (`I/N`), given on the command line
//!   or read from a Slurm job array or a Kubernetes Indexed Job.
//! - [`select`]: the frames a run renders, from a list, a range or the scene's animation.
//! - [`jobs`]: the plan: one job per frame, or per tile of each frame, with the file it writes.
//! - [`request`]: frames, tiles and a shard asked for together, made into this worker's jobs
//!   (what C and Python ask a run for).
//!
//! [`run`] is the job loop every front end shares (it does render and write): each job of a
//! plan rendered, skipped or failed, tiles merged, typed results ([`summary`]: the JSON
//! summaries) and progress reported through [`run::RunProgress`].

pub mod frames;
pub mod jobs;
pub mod pattern;
pub mod request;
pub mod run;
pub mod select;
pub mod shard;
pub mod summary;

pub use frames::{FrameSpecError, MAX_FRAMES, frame_range, parse_frames};
pub use pattern::{PatternError, check_frame_pattern, frame_path, has_frame_pattern, tile_path};
pub use request::{JobRequest, RequestError, RequestPlan};
pub use run::RunSummary;
pub use run::{
    Batch, ImageOptions, JobError, JobOutcome, JobResult, RunOptions, RunProgress, RunReport,
};
pub use select::{FrameRequest, FrameSelectError, select_frames};
pub use shard::{Shard, ShardError, ShardSource};
pub use summary::{JobSummary, LensSummary};
