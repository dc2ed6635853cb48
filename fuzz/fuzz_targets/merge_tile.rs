//! The tile reader of `dofray merge`: the input is written as `tile.png` when it starts with
//! the PNG signature, else as `tile.exr`, and merged alone (`output::merge::merge_into`) into
//! an image of the same format in the scratch folder. A tile that covers its whole image
//! merges and is written; any other is refused (by its reader, its metadata or coverage).
#![no_main]

use dofray::output::Target;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dofray_fuzz::run(|| {
        let dir = dofray_fuzz::scratch("merge", &[]);
        let ext = if data.starts_with(b"\x89PNG") {
            "png"
        } else {
            "exr"
        };
        let tile = dir.join(format!("tile.{ext}"));
        dofray_fuzz::write(&tile, data);
        let target = Target::new(dir.join(format!("merged.{ext}"))).expect("the output target");
        let _ = dofray::output::merge::merge_into(&[tile], &target);
    });
});
