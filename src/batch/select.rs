//! Which frames a run renders, from what its user gave: a frame list, a start / end / step
//! range, or nothing (then a frame pattern in the output renders the scene's whole animation).

use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use super::frames::{FrameSpecError, frame_range, parse_frames};
use super::pattern::{PatternError, check_frame_pattern, has_frame_pattern};
use crate::error_kind::{ErrorKind, HasKind};

/// The frames asked for. `list` and the range fields exclude each other.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrameRequest {
    /// A frame list (`1-48`, `1,5,10..20`, ...; [`parse_frames`]).
    pub list: Option<String>,
    /// First frame of a range (default: the animation's first).
    pub start: Option<i64>,
    /// Last frame of a range (default: the animation's last, else `start`).
    pub end: Option<i64>,
    /// Step of a range (default 1).
    pub step: Option<i64>,
}

/// Frames that cannot be rendered as asked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameSelectError {
    /// The frame list cannot be read.
    #[error("the frame list")]
    List(#[source] FrameSpecError),
    /// The range cannot be made.
    #[error(transparent)]
    Range(FrameSpecError),
    /// A range's end or step without a start, and no animation to take it from.
    #[error("a frame range's end or step needs its start: the scene has no animation")]
    NoStart,
    /// The output has a frame pattern, but nothing says which frames.
    #[error("{} has a frame pattern, but the scene has no animation", output.display())]
    PatternWithoutAnimation {
        /// The output path.
        output: PathBuf,
    },
    /// Several frames and one output file without a frame pattern.
    #[error("{count} frames would all be written to {}", output.display())]
    NoPattern {
        /// How many frames.
        count: usize,
        /// The output path.
        output: PathBuf,
    },
    /// The output's name mixes `#` runs with printf conversions (`shot_%04d_##.exr`).
    #[error(transparent)]
    Pattern(#[from] PatternError),
}

/// The frames `request` asks for (`None`: one image, not a frame of several), given the
/// output path and the scene's animation frames.
pub fn select_frames(
    request: &FrameRequest,
    output: &Path,
    animation: Option<RangeInclusive<i64>>,
) -> Result<Option<Vec<i64>>, FrameSelectError> {
    // Whatever the frames: a name that mixes the two pattern styles is ambiguous.
    check_frame_pattern(output, 1)?;
    let frames = if let Some(spec) = &request.list {
        Some(parse_frames(spec).map_err(FrameSelectError::List)?)
    } else if request.start.is_some() || request.end.is_some() || request.step.is_some() {
        let start = match (request.start, &animation) {
            (Some(s), _) => s,
            (None, Some(r)) => *r.start(),
            (None, None) => return Err(FrameSelectError::NoStart),
        };
        let end = request
            .end
            .or(animation.as_ref().map(|r| *r.end()))
            .unwrap_or(start);
        let step = request.step.unwrap_or(1);
        Some(frame_range(start, end, step).map_err(FrameSelectError::Range)?)
    } else if has_frame_pattern(output) {
        match animation {
            Some(r) => Some(r.collect()),
            None => {
                let output = output.to_path_buf();
                return Err(FrameSelectError::PatternWithoutAnimation { output });
            }
        }
    } else {
        None
    };
    if let Some(list) = &frames
        && list.len() > 1
        && !has_frame_pattern(output)
    {
        let (count, output) = (list.len(), output.to_path_buf());
        return Err(FrameSelectError::NoPattern { count, output });
    }
    Ok(frames)
}

impl HasKind for FrameSelectError {
    /// The frames asked for (flags, keywords) do not fit the scene or the output.
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_mixing_pattern_styles_is_refused_for_any_frames() {
        let mixed = Path::new("shot_%04d_##.exr");
        for request in [
            FrameRequest::default(),
            FrameRequest {
                list: Some("1-2".into()),
                ..Default::default()
            },
        ] {
            assert!(matches!(
                select_frames(&request, mixed, Some(1..=2)),
                Err(FrameSelectError::Pattern(PatternError::Mixed { .. }))
            ));
        }
    }

    #[test]
    fn frames_come_from_the_request_else_the_animation_for_a_pattern() {
        let pattern = Path::new("shot_####.exr");
        let list = FrameRequest {
            list: Some("1-3".into()),
            ..Default::default()
        };
        assert_eq!(select_frames(&list, pattern, None), Ok(Some(vec![1, 2, 3])));
        let end = FrameRequest {
            end: Some(4),
            ..Default::default()
        };
        assert_eq!(
            select_frames(&end, pattern, Some(2..=9)),
            Ok(Some(vec![2, 3, 4]))
        );
        assert_eq!(
            select_frames(&end, pattern, None),
            Err(FrameSelectError::NoStart)
        );
        let none = FrameRequest::default();
        assert_eq!(
            select_frames(&none, pattern, Some(1..=2)),
            Ok(Some(vec![1, 2]))
        );
        assert_eq!(
            select_frames(&none, Path::new("a.png"), Some(1..=2)),
            Ok(None)
        );
        assert!(matches!(
            select_frames(&list, Path::new("a.png"), None),
            Err(FrameSelectError::NoPattern { count: 3, .. })
        ));
    }
}
