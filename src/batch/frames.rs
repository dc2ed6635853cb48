//! Frame lists as render-farm users write them.
//!
//! A list is comma-separated items; an item is a frame `N`, an inclusive range `A-B` (Nuke,
//! Deadline) or `A..B` (Blender), and a range may take a step, `A-BxS` (Nuke, Deadline) or
//! `A-B:S`. Frames may be negative (`-5--1`, `-5..-1`); white space around items and around the
//! separators inside them is ignored. [`parse_frames`] returns the frames in the order given, each
//! once (the first occurrence wins). [`frame_range`] is the same for Blender's `-s`/`-e`/`-j`.
//!
//! A list may hold at most [`MAX_FRAMES`] frames, counted (repeats included) before anything is
//! allocated, so `1-9999999999` is refused at once instead of exhausting memory.

use std::collections::HashSet;

use crate::error_kind::{ErrorKind, HasKind};

/// The most frames one list may hold (repeats included).
pub const MAX_FRAMES: usize = 1_000_000;

/// A frame list that cannot be used. Every message names the offending item and says what was
/// expected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameSpecError {
    /// The list is empty or only white space.
    #[error("the frame list is empty; give frames such as `1-100`, `1,5,10` or `1..240x2`")]
    Empty,
    /// Two commas with nothing between them, or a comma at either end.
    #[error(
        "item {position} of the frame list `{spec}` is empty; separate frames and ranges with \
         single commas, as in `1-10,20`"
    )]
    EmptyItem {
        /// The whole list.
        spec: String,
        /// The empty item's position in the list (1 = the first).
        position: usize,
    },
    /// An item that is neither a frame nor a range.
    #[error(
        "cannot read `{item}` in the frame list: expected a frame `N`, a range `A-B` or `A..B`, \
         or a range with a step, `A-BxS` or `A-B:S`"
    )]
    Invalid {
        /// The item, as written.
        item: String,
    },
    /// A number too large for a 64-bit integer.
    #[error(
        "the number `{number}` in `{item}` is too large; frames and steps must lie between {} \
         and {}",
        i64::MIN,
        i64::MAX
    )]
    OutOfRange {
        /// The item, as written.
        item: String,
        /// The number, as written.
        number: String,
    },
    /// A range whose end comes before its start.
    #[error(
        "the frame range `{item}` ends before it starts; give the first frame first, as in \
         `{suggestion}`"
    )]
    Backwards {
        /// The item, as written.
        item: String,
        /// The same range the right way round.
        suggestion: String,
    },
    /// A step of zero or less.
    #[error("the step in `{item}` is {step}, but a step must be at least 1")]
    BadStep {
        /// The item, as written.
        item: String,
        /// The step given.
        step: i64,
    },
    /// More than [`MAX_FRAMES`] frames.
    #[error(
        "the frame list holds {total} frames up to and including `{item}`, more than the limit \
         of {MAX_FRAMES}; split the frames over several runs"
    )]
    TooMany {
        /// The item that takes the count over the limit.
        item: String,
        /// The count (repeats included) up to and including that item.
        total: u128,
    },
}

/// Parses a frame list (see the module documentation): the frames in the order given, each once.
///
/// ```
/// use dofray::batch::parse_frames;
/// assert_eq!(parse_frames("1-5x2, 10, 3").unwrap(), vec![1, 3, 5, 10]);
/// assert_eq!(parse_frames("-2..1").unwrap(), vec![-2, -1, 0, 1]);
/// ```
pub fn parse_frames(spec: &str) -> Result<Vec<i64>, FrameSpecError> {
    if spec.trim().is_empty() {
        return Err(FrameSpecError::Empty);
    }
    let mut spans = Vec::new();
    let mut total: u128 = 0;
    for (i, item) in spec.split(',').enumerate() {
        let item = item.trim();
        if item.is_empty() {
            return Err(FrameSpecError::EmptyItem {
                spec: spec.trim().to_string(),
                position: i + 1,
            });
        }
        let span = parse_item(item)?;
        total += span.count();
        check_total(item, total)?;
        spans.push(span);
    }
    Ok(expand(&spans, total))
}

/// The frames `start`, `start + step`, ... up to `end` inclusive, as Blender's `-s`, `-e` and
/// `-j` give them. Refused like the same range in [`parse_frames`]: `end` before `start`, a step
/// below 1, or more than [`MAX_FRAMES`] frames.
pub fn frame_range(start: i64, end: i64, step: i64) -> Result<Vec<i64>, FrameSpecError> {
    let item = if step == 1 {
        format!("{start}..{end}")
    } else {
        format!("{start}..{end}x{step}")
    };
    let span = Span::new(&item, (start, end, step), "..", 'x')?;
    let total = span.count();
    check_total(&item, total)?;
    Ok(expand(&[span], total))
}

/// An inclusive range with a step, checked: `start <= end`, `step >= 1`.
#[derive(Debug, Clone, Copy)]
struct Span {
    start: i64,
    end: i64,
    step: i64,
}

impl Span {
    /// Checks the range `(start, end, step)` written as `item`; `sep` (`-` or `..`) and `mark`
    /// (`x` or `:`, before the step) are its notation, for the suggestion.
    fn new(
        item: &str,
        (start, end, step): (i64, i64, i64),
        sep: &str,
        mark: char,
    ) -> Result<Span, FrameSpecError> {
        if step < 1 {
            return Err(FrameSpecError::BadStep {
                item: item.to_string(),
                step,
            });
        }
        if end < start {
            let step = if step == 1 {
                String::new()
            } else {
                format!("{mark}{step}")
            };
            return Err(FrameSpecError::Backwards {
                item: item.to_string(),
                suggestion: format!("{end}{sep}{start}{step}"),
            });
        }
        Ok(Span { start, end, step })
    }

    /// How many frames the range holds (exact: 128-bit).
    fn count(&self) -> u128 {
        (self.end as i128 - self.start as i128) as u128 / self.step as u128 + 1
    }

    /// The range's frames. Never overflows: the last frame yielded is at most `end`.
    fn frames(self) -> impl Iterator<Item = i64> {
        let n = self.count();
        (0..n).map(move |k| (self.start as i128 + k as i128 * self.step as i128) as i64)
    }
}

fn check_total(item: &str, total: u128) -> Result<(), FrameSpecError> {
    if total > MAX_FRAMES as u128 {
        return Err(FrameSpecError::TooMany {
            item: item.to_string(),
            total,
        });
    }
    Ok(())
}

/// The spans' frames in order, repeats removed; `total` (at most [`MAX_FRAMES`]) sizes the
/// buffers.
fn expand(spans: &[Span], total: u128) -> Vec<i64> {
    let total = total as usize;
    let mut seen = HashSet::with_capacity(total);
    let mut frames = Vec::with_capacity(total);
    for span in spans {
        frames.extend(span.frames().filter(|&f| seen.insert(f)));
    }
    frames
}

/// Parses one trimmed, non-empty item.
fn parse_item(item: &str) -> Result<Span, FrameSpecError> {
    let invalid = || FrameSpecError::Invalid {
        item: item.to_string(),
    };
    let mut rest = item;
    let start = take_int(item, &mut rest)?.ok_or_else(invalid)?;
    rest = rest.trim_start();
    if rest.is_empty() {
        return Ok(Span {
            start,
            end: start,
            step: 1,
        });
    }
    let sep = if let Some(r) = rest.strip_prefix("..") {
        rest = r;
        ".."
    } else if let Some(r) = rest.strip_prefix('-') {
        rest = r;
        "-"
    } else {
        return Err(invalid());
    };
    rest = rest.trim_start();
    let end = take_int(item, &mut rest)?.ok_or_else(invalid)?;
    rest = rest.trim_start();
    let mark = rest.chars().next().filter(|c| matches!(c, 'x' | ':'));
    let step = match mark {
        Some(mark) => {
            rest = rest[mark.len_utf8()..].trim_start();
            let step = take_int(item, &mut rest)?.ok_or_else(invalid)?;
            rest = rest.trim_start();
            step
        }
        None => 1,
    };
    if !rest.is_empty() {
        return Err(invalid());
    }
    Span::new(item, (start, end, step), sep, mark.unwrap_or('x'))
}

/// Takes an integer (an optional `-`, then ASCII digits) from the front of `rest`. `None` when
/// `rest` does not start with one; an error when it does not fit in an `i64`.
fn take_int(item: &str, rest: &mut &str) -> Result<Option<i64>, FrameSpecError> {
    let sign = usize::from(rest.starts_with('-'));
    let digits = rest[sign..].bytes().take_while(u8::is_ascii_digit).count();
    if digits == 0 {
        return Ok(None);
    }
    let (number, tail) = rest.split_at(sign + digits);
    let value = number
        .parse::<i64>()
        .map_err(|_| FrameSpecError::OutOfRange {
            item: item.to_string(),
            number: number.to_string(),
        })?;
    *rest = tail;
    Ok(Some(value))
}

impl HasKind for FrameSpecError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(spec: &str) -> Vec<i64> {
        parse_frames(spec).unwrap_or_else(|e| panic!("{spec:?}: {e}"))
    }

    fn error(spec: &str) -> FrameSpecError {
        match parse_frames(spec) {
            Ok(f) => panic!("{spec:?} parsed as {f:?}"),
            Err(e) => e,
        }
    }

    #[test]
    fn single_frames_and_lists() {
        assert_eq!(frames("7"), vec![7]);
        assert_eq!(frames("0"), vec![0]);
        assert_eq!(frames("1,5,10"), vec![1, 5, 10]);
        assert_eq!(frames("10,5,1"), vec![10, 5, 1], "the order given is kept");
        assert_eq!(frames("-3"), vec![-3]);
        assert_eq!(frames("007"), vec![7]);
    }

    #[test]
    fn ranges_in_every_notation_are_inclusive() {
        assert_eq!(frames("1-5"), vec![1, 2, 3, 4, 5]);
        assert_eq!(frames("1..5"), vec![1, 2, 3, 4, 5]);
        assert_eq!(frames("4-4"), vec![4]);
        assert_eq!(frames("4..4"), vec![4]);
    }

    #[test]
    fn steps_in_both_notations() {
        assert_eq!(frames("1-10x3"), vec![1, 4, 7, 10]);
        assert_eq!(frames("1-10:3"), vec![1, 4, 7, 10]);
        assert_eq!(frames("1..10x3"), vec![1, 4, 7, 10]);
        assert_eq!(
            frames("1-9x3"),
            vec![1, 4, 7],
            "the end is a bound, not always a frame"
        );
        assert_eq!(
            frames("1-5x10"),
            vec![1],
            "a step beyond the end leaves the start"
        );
        assert_eq!(frames("1-5x1"), frames("1-5"));
    }

    #[test]
    fn negative_frames() {
        assert_eq!(frames("-5--1"), vec![-5, -4, -3, -2, -1]);
        assert_eq!(frames("-5..-1"), vec![-5, -4, -3, -2, -1]);
        assert_eq!(frames("-2-2"), vec![-2, -1, 0, 1, 2]);
        assert_eq!(frames("-2..2"), vec![-2, -1, 0, 1, 2]);
        assert_eq!(frames("-10--1x4"), vec![-10, -6, -2]);
    }

    #[test]
    fn white_space_is_tolerated() {
        assert_eq!(frames(" 1 , 3 - 5 ,\t7..8x1 "), vec![1, 3, 4, 5, 7, 8]);
        assert_eq!(frames("1 .. 10 x 4"), vec![1, 5, 9]);
        assert_eq!(frames("-5 - -3"), vec![-5, -4, -3]);
    }

    #[test]
    fn repeats_are_removed_and_the_first_occurrence_wins() {
        assert_eq!(frames("3,1-4,2"), vec![3, 1, 2, 4]);
        assert_eq!(frames("5,5,5"), vec![5]);
        assert_eq!(frames("1-10x2,1-10x3"), vec![1, 3, 5, 7, 9, 4, 10]);
    }

    #[test]
    fn extremes_do_not_overflow() {
        assert_eq!(
            frames(&format!("{}-{}", i64::MAX - 2, i64::MAX)),
            vec![i64::MAX - 2, i64::MAX - 1, i64::MAX]
        );
        assert_eq!(
            frames(&format!("{}..{}", i64::MIN, i64::MIN + 1)),
            vec![i64::MIN, i64::MIN + 1]
        );
        // One frame from each end: the count is computed without overflow.
        let huge_step = i64::MAX;
        assert_eq!(
            frames(&format!("{}..{}x{huge_step}", -1, i64::MAX)),
            vec![-1, i64::MAX - 1]
        );
        assert_eq!(
            frame_range(i64::MIN, i64::MAX, i64::MAX).unwrap(),
            vec![i64::MIN, -1, i64::MAX - 1]
        );
    }

    #[test]
    fn empty_lists_and_items_are_refused() {
        assert_eq!(error(""), FrameSpecError::Empty);
        assert_eq!(error("  \t"), FrameSpecError::Empty);
        assert_eq!(
            error("1,,2"),
            FrameSpecError::EmptyItem {
                spec: "1,,2".into(),
                position: 2
            }
        );
        assert_eq!(
            error("1,2,"),
            FrameSpecError::EmptyItem {
                spec: "1,2,".into(),
                position: 3
            }
        );
        assert_eq!(
            error(",1"),
            FrameSpecError::EmptyItem {
                spec: ",1".into(),
                position: 1
            }
        );
        assert_eq!(
            error("1, ,2"),
            FrameSpecError::EmptyItem {
                spec: "1, ,2".into(),
                position: 2
            }
        );
    }

    #[test]
    fn garbage_is_refused_naming_the_item() {
        for item in [
            "a", "1-", "-", "..5", "1..", "1-5x", "1-5:", "1-5y2", "1 2", "1-2-3", "5x2", "1.5",
            "+3", "--5", "1...5", "1-5x2x2", "0x10", "1e3", "١",
        ] {
            assert_eq!(
                error(&format!("1,{item},9")),
                FrameSpecError::Invalid {
                    item: item.trim().to_string()
                },
                "{item:?}"
            );
        }
    }

    #[test]
    fn backwards_ranges_are_refused_with_the_right_way_round() {
        assert_eq!(
            error("10-1"),
            FrameSpecError::Backwards {
                item: "10-1".into(),
                suggestion: "1-10".into()
            }
        );
        assert_eq!(
            error("10..1x3"),
            FrameSpecError::Backwards {
                item: "10..1x3".into(),
                suggestion: "1..10x3".into()
            }
        );
        assert_eq!(
            error("10-1:3"),
            FrameSpecError::Backwards {
                item: "10-1:3".into(),
                suggestion: "1-10:3".into()
            }
        );
        assert_eq!(
            error("-1--5"),
            FrameSpecError::Backwards {
                item: "-1--5".into(),
                suggestion: "-5--1".into()
            }
        );
        assert_eq!(error("3--3").to_string(), {
            "the frame range `3--3` ends before it starts; give the first frame first, as in `-3-3`"
        });
    }

    #[test]
    fn steps_below_one_are_refused() {
        assert_eq!(
            error("1-10x0"),
            FrameSpecError::BadStep {
                item: "1-10x0".into(),
                step: 0
            }
        );
        assert_eq!(
            error("1-10:-2"),
            FrameSpecError::BadStep {
                item: "1-10:-2".into(),
                step: -2
            }
        );
        // The step is checked before the direction: a backwards range with step 0 names the step.
        assert_eq!(
            error("10-1x0"),
            FrameSpecError::BadStep {
                item: "10-1x0".into(),
                step: 0
            }
        );
    }

    #[test]
    fn numbers_beyond_64_bits_are_refused() {
        assert_eq!(
            error("1-99999999999999999999"),
            FrameSpecError::OutOfRange {
                item: "1-99999999999999999999".into(),
                number: "99999999999999999999".into()
            }
        );
        assert_eq!(
            error("-9223372036854775809"),
            FrameSpecError::OutOfRange {
                item: "-9223372036854775809".into(),
                number: "-9223372036854775809".into()
            }
        );
        assert!(matches!(
            error("1-5x99999999999999999999"),
            FrameSpecError::OutOfRange { .. }
        ));
    }

    #[test]
    fn the_frame_count_is_capped_before_allocating() {
        let max = MAX_FRAMES as i64;
        assert_eq!(frames(&format!("1-{max}")).len(), MAX_FRAMES);
        assert_eq!(
            error(&format!("1-{}", max + 1)),
            FrameSpecError::TooMany {
                item: format!("1-{}", max + 1),
                total: MAX_FRAMES as u128 + 1
            }
        );
        // Far beyond memory: refused from the count alone (this would otherwise abort).
        assert_eq!(
            error(&format!("{}-{}", i64::MIN, i64::MAX)),
            FrameSpecError::TooMany {
                item: format!("{}-{}", i64::MIN, i64::MAX),
                total: u64::MAX as u128 + 1
            }
        );
        // Repeats count: the item that crosses the limit is named.
        assert_eq!(
            error(&format!("1-{max},5,6")),
            FrameSpecError::TooMany {
                item: "5".into(),
                total: MAX_FRAMES as u128 + 1
            }
        );
        // A step brings a long range under the limit.
        assert_eq!(frames(&format!("1-{}x10", 10 * max)).len(), MAX_FRAMES);
    }

    #[test]
    fn frame_range_follows_blender() {
        assert_eq!(frame_range(1, 5, 1).unwrap(), vec![1, 2, 3, 4, 5]);
        assert_eq!(frame_range(1, 10, 4).unwrap(), vec![1, 5, 9]);
        assert_eq!(frame_range(-3, -1, 1).unwrap(), vec![-3, -2, -1]);
        assert_eq!(frame_range(7, 7, 1).unwrap(), vec![7]);
        assert_eq!(
            frame_range(5, 1, 1),
            Err(FrameSpecError::Backwards {
                item: "5..1".into(),
                suggestion: "1..5".into()
            })
        );
        assert_eq!(
            frame_range(1, 5, 0),
            Err(FrameSpecError::BadStep {
                item: "1..5x0".into(),
                step: 0
            })
        );
        assert!(matches!(
            frame_range(0, i64::MAX, 1),
            Err(FrameSpecError::TooMany { .. })
        ));
        // The same range through either door gives the same frames.
        assert_eq!(frame_range(-20, 33, 7).unwrap(), frames("-20..33x7"));
    }

    #[test]
    fn messages_are_sentences_naming_the_item() {
        let text = error("1,x3").to_string();
        assert!(
            text.starts_with("cannot read `x3` in the frame list: expected"),
            "{text}"
        );
        let text = error("1-3x0").to_string();
        assert_eq!(
            text,
            "the step in `1-3x0` is 0, but a step must be at least 1"
        );
        let text = error(&format!("0-{}", MAX_FRAMES)).to_string();
        assert!(
            text.contains("1000001 frames") && text.contains("1000000"),
            "{text}"
        );
        let text = error("1,,b").to_string();
        assert!(
            text.starts_with("item 2 of the frame list `1,,b` is empty"),
            "{text}"
        );
    }
}
