//! The jobs of a batch render: every frame, or every tile of every frame, with the file it
//! writes. A farm worker takes its share of this list ([`super::shard::Shard::pick`]); the
//! list depends only on the arguments, so every worker computes the same one.

use std::path::{Path, PathBuf};

use super::pattern::{frame_path, has_frame_pattern, tile_path};
use crate::render::Region;

/// Which tile of an image a job renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRef {
    /// Row-major from the top left, 0-based.
    pub index: usize,
    /// How many tiles the image is split into.
    pub count: usize,
    /// The pixels of the image the tile covers.
    pub region: Region,
}

/// One render: a frame (or the scene's only image), or one tile of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Job {
    /// `None` for a render that is not one of several frames.
    pub frame: Option<i64>,
    /// The tile this job renders; `None` for the whole image.
    pub tile: Option<TileRef>,
    /// The file this job writes (the tile's file for a tile).
    pub output: PathBuf,
    /// The frame's whole image (the same as `output` without tiles).
    pub image: PathBuf,
}

impl Job {
    /// How messages name the job: `frame 12`, `frame 12, tile 3 of 16`, `tile 3 of 16`.
    pub fn label(&self) -> String {
        let tile = self
            .tile
            .map(|t| format!("tile {} of {}", t.index, t.count));
        match (self.frame, tile) {
            (Some(f), Some(t)) => format!("frame {f}, {t}"),
            (Some(f), None) => format!("frame {f}"),
            (None, Some(t)) => t,
            (None, None) => "image".into(),
        }
    }
}

/// The jobs for `frames` (`None`: one image) and `tiles` (`None`: whole images), frame by
/// frame. `output` names the image; a frame pattern in it (`shot_####.exr`) takes each
/// frame's number, and tiles are written next to their image (`shot_0007.tile-003.exr`).
pub fn plan(output: &Path, frames: Option<&[i64]>, tiles: Option<&[Region]>) -> Vec<Job> {
    let frames: Vec<Option<i64>> = match frames {
        Some(list) => list.iter().copied().map(Some).collect(),
        None => vec![None],
    };
    let mut jobs = Vec::new();
    for frame in frames {
        let image = match frame {
            Some(f) if has_frame_pattern(output) => frame_path(output, f),
            _ => output.to_path_buf(),
        };
        match tiles {
            None => jobs.push(Job {
                frame,
                tile: None,
                output: image.clone(),
                image,
            }),
            Some(regions) => {
                for (index, &region) in regions.iter().enumerate() {
                    jobs.push(Job {
                        frame,
                        tile: Some(TileRef {
                            index,
                            count: regions.len(),
                            region,
                        }),
                        output: tile_path(&image, index, regions.len()),
                        image: image.clone(),
                    });
                }
            }
        }
    }
    jobs
}

/// The jobs grouped by the image they belong to, in plan order.
pub fn by_image(jobs: &[Job]) -> Vec<(PathBuf, Vec<&Job>)> {
    let mut groups: Vec<(PathBuf, Vec<&Job>)> = Vec::new();
    for job in jobs {
        match groups.last_mut() {
            Some((image, list)) if *image == job.image => list.push(job),
            _ => groups.push((job.image.clone(), vec![job])),
        }
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_tiles_make_one_job_each_with_its_own_file() {
        let tiles = Region::grid(100, 50, 2, 1).unwrap();
        let jobs = plan(Path::new("out/shot_####.exr"), Some(&[3, 4]), Some(&tiles));
        let files: Vec<_> = jobs.iter().map(|j| j.output.to_str().unwrap()).collect();
        assert_eq!(
            files,
            [
                "out/shot_0003.tile-000.exr",
                "out/shot_0003.tile-001.exr",
                "out/shot_0004.tile-000.exr",
                "out/shot_0004.tile-001.exr"
            ]
        );
        assert_eq!(jobs[1].image, Path::new("out/shot_0003.exr"));
        assert_eq!(jobs[3].label(), "frame 4, tile 1 of 2");
        let groups = by_image(&jobs);
        assert_eq!(groups.len(), 2);
        assert!(groups.iter().all(|(_, g)| g.len() == 2));

        let one = plan(Path::new("still.png"), None, None);
        assert_eq!(one.len(), 1);
        assert_eq!(
            (one[0].output.to_str(), one[0].label()),
            (Some("still.png"), "image".into())
        );
        // A single frame without a pattern writes -o itself.
        let single = plan(Path::new("f.png"), Some(&[7]), None);
        assert_eq!(single[0].output, Path::new("f.png"));
    }
}
