//! A run's jobs from what a front end asks for: frames, a tile grid and a shard, made into the
//! plan ([`super::jobs::plan`]), this worker's share of it and whether the run assembles its
//! tiles. C and Python ask through this; the command line words each part's errors after its
//! flags and so checks them one by one, to the same plan.

use std::ops::RangeInclusive;
use std::path::Path;

use super::jobs::{self, Job};
use super::select::{FrameRequest, FrameSelectError, select_frames};
use super::shard::Shard;
use crate::error_kind::{ErrorKind, HasKind};
use crate::render::{Region, RegionError};

/// What a run renders, beyond the scene and its settings.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct JobRequest {
    /// The frames ([`select_frames`]: nothing asked and no frame pattern is one image).
    pub frames: FrameRequest,
    /// Each image as `(columns, rows)` tiles, merged into it once all are rendered.
    pub tiles: Option<(u32, u32)>,
    /// This worker's share of the jobs (`None`: all of them).
    pub shard: Option<Shard>,
}

/// A request that cannot be planned.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// The frames cannot be selected.
    #[error(transparent)]
    Frames(#[from] FrameSelectError),
    /// The tile grid does not fit the image.
    #[error("tiles")]
    Tiles(#[source] RegionError),
}

impl HasKind for RequestError {
    /// What was asked for does not fit the scene or the output.
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Frames(e) => e.kind(),
            Self::Tiles(e) => e.kind(),
        }
    }
}

/// The jobs of a request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RequestPlan {
    /// Every job of the whole run (every shard's).
    pub all: Vec<Job>,
    /// This worker's share of them, to give [`super::Batch::run`].
    pub mine: Vec<Job>,
    /// Whether the run assembles each image from its tiles ([`super::RunOptions::merge_tiles`]):
    /// with tiles and without a shard (a farm's images are merged once every worker is done).
    pub merge_tiles: bool,
}

impl JobRequest {
    /// The jobs writing to `output` (a frame pattern takes each frame's number), for a scene
    /// with these `animation` frames and an image of `size` (width, height) pixels.
    pub fn plan(
        &self,
        output: &Path,
        animation: Option<RangeInclusive<i64>>,
        size: (u32, u32),
    ) -> Result<RequestPlan, RequestError> {
        let frames = select_frames(&self.frames, output, animation)?;
        let tiles = self
            .tiles
            .map(|(columns, rows)| Region::grid(size.0, size.1, columns, rows))
            .transpose()
            .map_err(RequestError::Tiles)?;
        let all = jobs::plan(output, frames.as_deref(), tiles.as_deref());
        let mine = match &self.shard {
            Some(shard) => shard.pick(&all),
            None => all.clone(),
        };
        Ok(RequestPlan {
            all,
            mine,
            merge_tiles: tiles.is_some() && self.shard.is_none(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_tiles_and_a_shard_make_this_workers_jobs() {
        let request = JobRequest {
            frames: FrameRequest {
                list: Some("1-3".into()),
                ..Default::default()
            },
            tiles: Some((2, 1)),
            shard: Some(Shard::new(1, 2).unwrap()),
        };
        let plan = request
            .plan(Path::new("shot_##.png"), None, (64, 48))
            .unwrap();
        assert_eq!(plan.all.len(), 6);
        let mine: Vec<_> = plan
            .mine
            .iter()
            .map(|j| j.output.to_str().unwrap())
            .collect();
        assert_eq!(
            mine,
            [
                "shot_01.tile-001.png",
                "shot_02.tile-001.png",
                "shot_03.tile-001.png"
            ]
        );
        assert!(!plan.merge_tiles, "a shard's tiles are merged by the farm");

        let still = JobRequest {
            tiles: Some((2, 2)),
            ..Default::default()
        };
        let plan = still.plan(Path::new("still.exr"), Some(1..=9), (64, 48));
        let plan = plan.unwrap();
        assert_eq!((plan.mine.len(), plan.merge_tiles), (4, true));
        assert!(plan.mine.iter().all(|j| j.frame.is_none()));

        let fine = JobRequest {
            tiles: Some((65, 1)),
            ..Default::default()
        };
        let error = fine.plan(Path::new("a.png"), None, (64, 48)).unwrap_err();
        assert!(matches!(error, RequestError::Tiles(_)), "{error}");
        let message = crate::error_kind::full_message(&error);
        assert!(message.starts_with("tiles: "), "{message}");
        assert_eq!(message.matches("65").count(), 1, "{message}");

        let list = JobRequest {
            frames: FrameRequest {
                list: Some("1-x".into()),
                ..Default::default()
            },
            ..Default::default()
        };
        let error = list.plan(Path::new("f_#.png"), None, (64, 48)).unwrap_err();
        let message = crate::error_kind::full_message(&error);
        assert!(
            message.starts_with("the frame list: cannot read `1-x`"),
            "{message}"
        );
        assert_eq!(message.matches("cannot read").count(), 1, "{message}");
    }
}
