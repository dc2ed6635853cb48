//! Frame-numbered output names. The input gives a frame (8 bytes, little-endian i64), a frame
//! count (2 bytes) and a path (the rest, any bytes: names need not be UTF-8) to
//! `batch::has_frame_pattern`, `check_frame_pattern`, `frame_path` and `tile_path`, and checks
//! what they promise: the folders are never changed, a name without a pattern is kept, and a
//! name accepted for several frames gives every frame its own file.
#![no_main]

use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::path::Path;

use dofray::batch::{check_frame_pattern, frame_path, has_frame_pattern, tile_path};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 10 {
        return;
    }
    dofray_fuzz::run(|| {
        let frame = i64::from_le_bytes(data[..8].try_into().unwrap());
        let frames = usize::from(u16::from_le_bytes(data[8..10].try_into().unwrap()));
        let path = Path::new(OsStr::from_bytes(&data[10..]));
        let patterned = has_frame_pattern(path);
        let checked = check_frame_pattern(path, frames);
        let named = frame_path(path, frame);
        assert_eq!(named.parent(), path.parent(), "{}", path.display());
        if !patterned {
            assert_eq!(named, path);
        } else if checked.is_ok() {
            assert_ne!(
                named,
                frame_path(path, frame.wrapping_add(1)),
                "{}",
                path.display()
            );
        }
        if frames > 1 && path.file_name().is_some() && checked.is_ok() {
            assert!(patterned, "{} accepted for {frames} frames", path.display());
        }
        let tile = tile_path(&named, frames / 2, frames.max(1));
        if named.file_name().is_some() {
            assert_eq!(tile.parent(), named.parent(), "{}", named.display());
        }
    });
});
