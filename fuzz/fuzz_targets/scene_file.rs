//! Scene files: TOML text -> `scene::file::parse_with`, then, for a scene that parses, its
//! camera built (no Embree device: autofocus sees nothing) at the animation's first, middle
//! and last frame. The file is named as if it were in `scenes/`, so the seed scenes' models
//! and textures (`assets/...`) load too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(src) = std::str::from_utf8(data) else {
        return;
    };
    dofray_fuzz::run(|| {
        let path = dofray_fuzz::repo().join("scenes/fuzz-input.toml");
        let Ok(scene) = dofray::scene::file::parse_with(src, &path, &dofray_fuzz::options()) else {
            return;
        };
        let _ = scene.camera.build(|_| None);
        if let Some(animation) = &scene.animation {
            let (start, end) = (animation.frame_start, animation.frame_end);
            let middle = ((i128::from(start) + i128::from(end)) / 2) as i64;
            for frame in [start, middle, end] {
                let mut camera = scene.camera.clone();
                animation.apply(&mut camera, frame as f64);
                let _ = camera.build(|_| None);
            }
        }
    });
});
