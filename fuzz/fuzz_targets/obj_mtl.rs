//! OBJ models (and their MTL library): the input is the OBJ text, optionally followed by
//! `\n#--- m.mtl\n` and the text of `m.mtl` (which the seeds' `mtllib m.mtl` names). Both are
//! written to a scratch folder holding `tiles.png` and `bands.jpg` for `map_Kd`, and loaded
//! with `scene::load_with` (the model, then the scene framed around it).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dofray_fuzz::run(|| {
        let dir = dofray_fuzz::scratch(
            "obj",
            &["scenes/assets/tiles.png", "scenes/assets/bands.jpg"],
        );
        let (obj, mtl) = dofray_fuzz::split(data, b"\n#--- m.mtl\n");
        let obj_path = dir.join("m.obj");
        let mtl_path = dir.join("m.mtl");
        dofray_fuzz::write(&obj_path, obj);
        match mtl {
            Some(mtl) => dofray_fuzz::write(&mtl_path, mtl),
            None => {
                let _ = std::fs::remove_file(&mtl_path);
            }
        }
        let _ = dofray::scene::load_with(obj_path.to_str().unwrap(), &dofray_fuzz::options());
    });
});
