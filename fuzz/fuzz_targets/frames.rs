//! Frame lists. An input starting with an even byte (`0`) is a list for
//! `batch::parse_frames` (the rest, as UTF-8); one starting with an odd byte (`1`) gives
//! `batch::frame_range` its start, end and step (the next 24 bytes, little-endian i64s). What
//! either returns is checked: at most `MAX_FRAMES` frames, each once, a range's frames a step
//! apart, and a range gives the frames the same range written as a list gives.
#![no_main]

use std::collections::HashSet;

use dofray::batch::{MAX_FRAMES, frame_range, parse_frames};
use libfuzzer_sys::fuzz_target;

fn check(frames: &[i64]) {
    assert!(!frames.is_empty() && frames.len() <= MAX_FRAMES);
    let mut seen = HashSet::with_capacity(frames.len());
    assert!(frames.iter().all(|f| seen.insert(*f)), "a repeated frame");
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    dofray_fuzz::run(|| {
        if mode % 2 == 0 {
            let Ok(spec) = std::str::from_utf8(rest) else {
                return;
            };
            if let Ok(frames) = parse_frames(spec) {
                check(&frames);
            }
            return;
        }
        let mut bytes = [0u8; 24];
        let n = rest.len().min(24);
        bytes[..n].copy_from_slice(&rest[..n]);
        let int = |i: usize| i64::from_le_bytes(bytes[i * 8..i * 8 + 8].try_into().unwrap());
        let (start, end, step) = (int(0), int(1), int(2));
        let range = frame_range(start, end, step);
        if let Ok(frames) = &range {
            check(frames);
            assert_eq!(frames[0], start);
            assert!(frames.windows(2).all(|w| w[1] - w[0] == step));
            assert!(*frames.last().unwrap() <= end && end - frames.last().unwrap() < step);
        }
        // The same range as a list: the same frames, or refused too (the error names the
        // item as written, so only the frames are compared).
        let spec = format!("{start}..{end}x{step}");
        assert_eq!(range.ok(), parse_frames(&spec).ok(), "{spec}");
    });
});
