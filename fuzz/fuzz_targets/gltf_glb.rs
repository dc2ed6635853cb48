//! glTF models: the input is written as `m.glb` when it starts with the GLB magic `glTF`,
//! else as `m.gltf`, in a scratch folder holding the external buffers and texture the seeds
//! refer to (`ortho.bin`, `lights.bin`, `tiles.png`), and loaded with `scene::load_with`
//! (the model with its cameras and lights, then the scene around it).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dofray_fuzz::run(|| {
        let dir = dofray_fuzz::scratch(
            "gltf",
            &[
                "tests/scene_assets/blender/ortho.bin",
                "tests/scene_assets/blender/lights.bin",
                "scenes/assets/tiles.png",
            ],
        );
        let name = if data.starts_with(b"glTF") {
            "m.glb"
        } else {
            "m.gltf"
        };
        let path = dir.join(name);
        dofray_fuzz::write(&path, data);
        let _ = dofray::scene::load_with(path.to_str().unwrap(), &dofray_fuzz::options());
    });
});
