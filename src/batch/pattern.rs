//! Frame-numbered output paths, and the files of an image's tiles.
//!
//! A frame pattern is in the file name (never in the directories) and takes one of two forms:
//!
//! - **`#` runs** (Blender, Houdini, Deadline): every run of `#` becomes the frame number with at
//!   least as many digits as the run is long: `shot_####.exr` at frame 7 is `shot_0007.exr`,
//!   at 12345 `shot_12345.exr` (never truncated). A negative frame gets its sign in front of the
//!   padded digits, as Blender writes it (`%.*d`): `###` at -7 is `-007`.
//! - **printf conversions** (ffmpeg, Nuke): `%d`, or `%0Nd` with a width N of one or two digits,
//!   formatted as C's `printf` does: `%04d` at 7 is `0007`, at -7 `-007` (the width counts the
//!   sign). Any other `%` is kept as it is.
//!
//! One form per path: a name with both is refused by [`check_frame_pattern`], and
//! [`frame_path`] then replaces only the `#` runs.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use crate::error_kind::{ErrorKind, HasKind};

/// An output path that cannot take one image per frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PatternError {
    /// Several frames, but a file name without a frame pattern: every frame would overwrite the
    /// same file.
    #[error(
        "the output `{}` has no frame number in its name, so all {frames} frames would overwrite \
         one file; put a run of `#` where the number goes, as in `{}`, or a printf-style `%04d`",
        path.display(),
        example.display()
    )]
    Missing {
        /// The output path.
        path: PathBuf,
        /// How many frames were to be written.
        frames: usize,
        /// The path with `_####` before its extension.
        example: PathBuf,
    },
    /// A file name with both `#` runs and printf conversions.
    #[error(
        "the output name `{}` has both `#` and `%d`-style frame numbers; use one of the two",
        path.display()
    )]
    Mixed {
        /// The output path.
        path: PathBuf,
    },
    /// A file name that is not UTF-8, whose frame pattern cannot be read.
    #[error(
        "the output name `{}` is not valid UTF-8, so frame numbers cannot be put in it; choose a \
         UTF-8 file name",
        path.display()
    )]
    NotUnicode {
        /// The output path.
        path: PathBuf,
    },
}

/// One piece of a file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Piece<'a> {
    /// Kept as it is.
    Text(&'a str),
    /// A run of this many `#`.
    Hashes(usize),
    /// `%d` (width 0) or `%0Nd`: its width and its text.
    Printf(usize, &'a str),
}

/// Splits a file name into text, `#` runs and printf conversions.
fn pieces(name: &str) -> Vec<Piece<'_>> {
    let bytes = name.as_bytes();
    let mut pieces = Vec::new();
    let mut text_start = 0;
    let mut i = 0;
    while i < bytes.len() {
        let (piece, len) = if bytes[i] == b'#' {
            let n = bytes[i..].iter().take_while(|&&b| b == b'#').count();
            (Piece::Hashes(n), n)
        } else if let Some((width, len)) = printf_at(&bytes[i..]) {
            (Piece::Printf(width, &name[i..i + len]), len)
        } else {
            i += 1;
            continue;
        };
        if text_start < i {
            pieces.push(Piece::Text(&name[text_start..i]));
        }
        pieces.push(piece);
        i += len;
        text_start = i;
    }
    if text_start < bytes.len() {
        pieces.push(Piece::Text(&name[text_start..]));
    }
    pieces
}

/// A printf conversion at the start of `bytes`: `%d` or `%0Nd` (N one or two digits); its width
/// and length.
fn printf_at(bytes: &[u8]) -> Option<(usize, usize)> {
    match bytes {
        [b'%', b'd', ..] => Some((0, 2)),
        [b'%', b'0', a, b'd', ..] if a.is_ascii_digit() => Some(((a - b'0') as usize, 4)),
        [b'%', b'0', a, b, b'd', ..] if a.is_ascii_digit() && b.is_ascii_digit() => {
            Some((((a - b'0') * 10 + (b - b'0')) as usize, 5))
        }
        _ => None,
    }
}

/// The kinds of pattern a file name holds: (`#` runs, printf conversions).
fn kinds(pieces: &[Piece<'_>]) -> (bool, bool) {
    let hashes = pieces.iter().any(|p| matches!(p, Piece::Hashes(_)));
    let printf = pieces.iter().any(|p| matches!(p, Piece::Printf(..)));
    (hashes, printf)
}

/// Whether `path`'s file name holds a frame pattern: a run of `#`, or a printf conversion
/// (`%d`, `%04d`). `#` in directory names does not count; nor does a name that is not UTF-8.
pub fn has_frame_pattern(path: &Path) -> bool {
    match path.file_name().and_then(|n| n.to_str()) {
        Some(name) => kinds(&pieces(name)) != (false, false),
        None => false,
    }
}

/// The path of `frame`'s image: every `#` run in the file name replaced by the frame number
/// padded to the run's length (or, without `#`, every printf conversion formatted); the
/// directories are kept as they are (see the module documentation). A path without a pattern
/// (or whose file name is not UTF-8) is returned unchanged; [`check_frame_pattern`] refuses those
/// when there are several frames.
///
/// ```
/// use std::path::Path;
/// use dofray::batch::frame_path;
/// assert_eq!(frame_path(Path::new("out/shot_####.exr"), 7), Path::new("out/shot_0007.exr"));
/// assert_eq!(frame_path(Path::new("shot_%04d.png"), -7), Path::new("shot_-007.png"));
/// ```
pub fn frame_path(path: &Path, frame: i64) -> PathBuf {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return path.to_path_buf();
    };
    let pieces = pieces(name);
    let (hashes, printf) = kinds(&pieces);
    if !hashes && !printf {
        return path.to_path_buf();
    }
    let mut out = String::with_capacity(name.len() + 20);
    for piece in pieces {
        match piece {
            Piece::Text(text) => out.push_str(text),
            Piece::Hashes(n) => {
                let sign = if frame < 0 { "-" } else { "" };
                out.push_str(&format!("{sign}{:0n$}", frame.unsigned_abs()));
            }
            // In a name with `#` runs, a printf conversion is text.
            Piece::Printf(_, text) if hashes => out.push_str(text),
            Piece::Printf(width, _) => out.push_str(&format!("{frame:0width$}")),
        }
    }
    path.with_file_name(out)
}

/// Checks that `path` can take the images of `frames` frames: with more than one frame its file
/// name needs a frame pattern, and no name may mix `#` runs with printf conversions.
pub fn check_frame_pattern(path: &Path, frames: usize) -> Result<(), PatternError> {
    let Some(name) = path.file_name() else {
        return Ok(());
    };
    let Some(name) = name.to_str() else {
        return if frames > 1 {
            Err(PatternError::NotUnicode {
                path: path.to_path_buf(),
            })
        } else {
            Ok(())
        };
    };
    match kinds(&pieces(name)) {
        (true, true) => Err(PatternError::Mixed {
            path: path.to_path_buf(),
        }),
        (false, false) if frames > 1 => Err(PatternError::Missing {
            path: path.to_path_buf(),
            frames,
            example: with_suffix(path, "_####"),
        }),
        _ => Ok(()),
    }
}

/// `path` with `suffix` added to its file stem, before the extension.
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut name = OsString::from(path.file_stem().unwrap_or_default());
    name.push(suffix);
    if let Some(ext) = path.extension() {
        name.push(".");
        name.push(ext);
    }
    path.with_file_name(name)
}

/// The file of tile `index` of `count` of the image at `path`: `.tile-NNN` before the extension,
/// the index zero-padded to the width of `count - 1` and at least 3 digits, so the tiles of an
/// image sort in order (`still.exr` -> `still.tile-003.exr`, `shot_0007.exr` ->
/// `shot_0007.tile-003.exr`, tile 12 of 2000 -> `still.tile-0012.exr`). The directory and the
/// extension are kept; a name without an extension just gets the suffix. Apply [`frame_path`]
/// first: `#` runs are kept as they are.
pub fn tile_path(path: &Path, index: usize, count: usize) -> PathBuf {
    let width = digits(count.saturating_sub(1).max(index)).max(3);
    with_suffix(path, &format!(".tile-{index:0width$}"))
}

/// The number of decimal digits of `n`.
fn digits(n: usize) -> usize {
    n.checked_ilog10().map_or(1, |d| d as usize + 1)
}

impl HasKind for PatternError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fp(path: &str, frame: i64) -> String {
        frame_path(Path::new(path), frame)
            .to_str()
            .unwrap()
            .to_string()
    }

    fn tp(path: &str, index: usize, count: usize) -> String {
        tile_path(Path::new(path), index, count)
            .to_str()
            .unwrap()
            .to_string()
    }

    #[test]
    fn hash_runs_are_padded_to_their_length() {
        assert_eq!(fp("shot_####.exr", 7), "shot_0007.exr");
        assert_eq!(fp("shot_#.exr", 7), "shot_7.exr");
        assert_eq!(fp("shot_###.exr", 0), "shot_000.exr");
        assert_eq!(fp("####", 42), "0042");
        assert_eq!(fp("shot_####.exr", 1234), "shot_1234.exr");
    }

    #[test]
    fn long_numbers_are_not_truncated() {
        assert_eq!(fp("shot_####.exr", 12345), "shot_12345.exr");
        assert_eq!(fp("shot_#.exr", i64::MAX), format!("shot_{}.exr", i64::MAX));
        assert_eq!(fp("shot_%02d.exr", 12345), "shot_12345.exr");
    }

    #[test]
    fn negative_frames_put_the_sign_before_the_padding() {
        // Blender's `%.*d`: the run counts digits, the sign comes in front.
        assert_eq!(fp("shot_###.exr", -7), "shot_-007.exr");
        assert_eq!(fp("shot_####.exr", -7), "shot_-0007.exr");
        assert_eq!(fp("shot_#.exr", -12), "shot_-12.exr");
        assert_eq!(fp("shot_#.exr", i64::MIN), format!("shot_{}.exr", i64::MIN));
        // printf: the width counts the sign.
        assert_eq!(fp("shot_%04d.exr", -7), "shot_-007.exr");
        assert_eq!(fp("shot_%d.exr", -7), "shot_-7.exr");
    }

    #[test]
    fn every_run_in_the_file_name_is_replaced() {
        assert_eq!(fp("a_##_b_####.exr", 5), "a_05_b_0005.exr");
        assert_eq!(fp("v%02d_f%04d.png", 3), "v03_f0003.png");
    }

    #[test]
    fn directories_are_left_alone() {
        assert_eq!(
            fp("renders_##/shot_####.exr", 7),
            "renders_##/shot_0007.exr"
        );
        assert_eq!(
            fp("/farm/%04d/shot_####.exr", 7),
            "/farm/%04d/shot_0007.exr"
        );
        assert_eq!(fp("renders_##/shot.exr", 7), "renders_##/shot.exr");
        assert!(!has_frame_pattern(Path::new("renders_##/shot.exr")));
        assert!(!has_frame_pattern(Path::new("renders_%04d/shot.exr")));
    }

    #[test]
    fn printf_conversions() {
        assert_eq!(fp("shot_%04d.exr", 7), "shot_0007.exr");
        assert_eq!(fp("shot_%d.exr", 7), "shot_7.exr");
        assert_eq!(fp("shot_%010d.exr", 7), "shot_0000000007.exr");
        assert_eq!(fp("out/%03d", 7), "out/007");
    }

    #[test]
    fn other_percent_signs_are_text() {
        for name in [
            "50%.png", "a%s.png", "a%4d.png", "a%x.png", "a%%.png", "a%0d.png", "%",
        ] {
            assert_eq!(fp(name, 7), name, "{name}");
            assert!(!has_frame_pattern(Path::new(name)), "{name}");
        }
        assert_eq!(fp("50%_%04d.png", 7), "50%_0007.png");
        assert_eq!(
            fp("a%004d.png", 7),
            "a0007.png",
            "as in C: flag 0, width 04"
        );
    }

    #[test]
    fn hash_runs_win_over_printf_in_a_mixed_name() {
        assert_eq!(fp("a_%04d_##.png", 7), "a_%04d_07.png");
        assert_eq!(fp("a_%d_##.png", 7), "a_%d_07.png");
    }

    #[test]
    fn names_without_a_pattern_are_unchanged() {
        assert_eq!(fp("still.exr", 7), "still.exr");
        assert_eq!(fp("", 7), "");
        assert_eq!(fp("/", 7), "/");
        assert_eq!(fp("out/..", 7), "out/..");
    }

    #[test]
    fn has_frame_pattern_reads_the_file_name() {
        assert!(has_frame_pattern(Path::new("shot_#.exr")));
        assert!(has_frame_pattern(Path::new("dir/shot_####.exr")));
        assert!(has_frame_pattern(Path::new("shot_%04d.exr")));
        assert!(has_frame_pattern(Path::new("shot_%d.exr")));
        assert!(!has_frame_pattern(Path::new("shot.exr")));
        assert!(!has_frame_pattern(Path::new("")));
    }

    #[test]
    fn distinct_frames_get_distinct_files() {
        for pattern in ["f_#.exr", "f_###.exr", "f_%d.exr", "f_%03d.exr"] {
            let mut names: Vec<_> = (-1200..1200).map(|f| fp(pattern, f)).collect();
            names.sort();
            names.dedup();
            assert_eq!(names.len(), 2400, "{pattern}");
        }
    }

    #[test]
    fn check_frame_pattern_needs_a_pattern_for_several_frames() {
        assert_eq!(check_frame_pattern(Path::new("still.exr"), 1), Ok(()));
        assert_eq!(check_frame_pattern(Path::new("still.exr"), 0), Ok(()));
        assert_eq!(check_frame_pattern(Path::new("shot_####.exr"), 100), Ok(()));
        assert_eq!(check_frame_pattern(Path::new("shot_%04d.exr"), 100), Ok(()));
        let err = check_frame_pattern(Path::new("out/shot.exr"), 24).unwrap_err();
        assert_eq!(
            err,
            PatternError::Missing {
                path: "out/shot.exr".into(),
                frames: 24,
                example: "out/shot_####.exr".into()
            }
        );
        assert_eq!(
            err.to_string(),
            "the output `out/shot.exr` has no frame number in its name, so all 24 frames would \
             overwrite one file; put a run of `#` where the number goes, as in \
             `out/shot_####.exr`, or a printf-style `%04d`"
        );
        let err = check_frame_pattern(Path::new("renders_##/shot"), 2).unwrap_err();
        assert!(matches!(err, PatternError::Missing { ref example, .. }
            if example == Path::new("renders_##/shot_####")));
    }

    #[test]
    fn check_frame_pattern_refuses_mixed_names() {
        for frames in [1, 5] {
            assert_eq!(
                check_frame_pattern(Path::new("a_%04d_##.exr"), frames),
                Err(PatternError::Mixed {
                    path: "a_%04d_##.exr".into()
                })
            );
        }
        assert!(
            PatternError::Mixed { path: "x".into() }
                .to_string()
                .contains("use one of the two")
        );
    }

    #[cfg(unix)]
    #[test]
    fn names_that_are_not_utf8() {
        use std::ffi::OsStr;
        use std::os::unix::ffi::OsStrExt;
        let path = Path::new(OsStr::from_bytes(b"dir/shot_\xff_####.exr"));
        assert!(!has_frame_pattern(path));
        assert_eq!(frame_path(path, 7), path);
        assert_eq!(check_frame_pattern(path, 1), Ok(()));
        assert_eq!(
            check_frame_pattern(path, 2),
            Err(PatternError::NotUnicode {
                path: path.to_path_buf()
            })
        );
        // Tiles need no UTF-8.
        assert_eq!(
            tile_path(path, 3, 4),
            Path::new(OsStr::from_bytes(b"dir/shot_\xff_####.tile-003.exr"))
        );
    }

    #[test]
    fn tile_files_keep_directory_and_extension() {
        assert_eq!(tp("still.exr", 3, 16), "still.tile-003.exr");
        assert_eq!(tp("out/shot_0007.exr", 3, 16), "out/shot_0007.tile-003.exr");
        assert_eq!(tp("/abs/still.png", 0, 1), "/abs/still.tile-000.png");
        assert_eq!(tp("still", 3, 16), "still.tile-003");
        assert_eq!(tp("archive.tar.gz", 1, 2), "archive.tar.tile-001.gz");
        assert_eq!(tp(".hidden", 1, 2), ".hidden.tile-001");
    }

    #[test]
    fn tile_indices_are_padded_to_the_largest_index() {
        assert_eq!(tp("s.exr", 7, 1000), "s.tile-007.exr", "999 has 3 digits");
        assert_eq!(tp("s.exr", 7, 1001), "s.tile-0007.exr", "1000 has 4");
        assert_eq!(tp("s.exr", 12, 2000), "s.tile-0012.exr");
        assert_eq!(tp("s.exr", 1999, 2000), "s.tile-1999.exr");
        assert_eq!(tp("s.exr", 0, 0), "s.tile-000.exr");
        // An index beyond the count still gets all its digits.
        assert_eq!(tp("s.exr", 12345, 4), "s.tile-12345.exr");
        // Lexical order is tile order.
        let names: Vec<_> = (0..1500).map(|i| tp("s.exr", i, 1500)).collect();
        assert!(names.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn tiles_of_frames() {
        let frame = frame_path(Path::new("out/shot_####.exr"), 7);
        assert_eq!(
            tile_path(&frame, 3, 8),
            Path::new("out/shot_0007.tile-003.exr")
        );
    }

    #[test]
    fn digit_counts() {
        assert_eq!(digits(0), 1);
        assert_eq!(digits(9), 1);
        assert_eq!(digits(10), 2);
        assert_eq!(digits(999), 3);
        assert_eq!(digits(1000), 4);
        assert_eq!(digits(usize::MAX), 20);
    }
}
