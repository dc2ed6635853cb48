//! Scenes and the overrides set on them.

use std::ffi::{c_char, c_int};
use std::path::Path;

use dofray::overrides::Overrides;
use dofray::render::{Mode, RulePatch, SettingsPatch};
use dofray::renderer::Renderer;
use dofray::scene::SceneDesc;

use crate::args::{arg_mut, free, out_arg, put, str_arg};
use crate::device::DofrayDevice;
use crate::status::{DofrayStatus, Failure, guard};

/// A scene with its overrides. Rendering builds its Embree world once and keeps it for the
/// next render on the same device while the scene overrides stay the same.
///
/// The `dofray_scene_set_*` functions store their value as given (they fail only for a NULL
/// scene or an unknown mode name); every value is checked when the scene is rendered, all
/// together (some depend on each other and on the scene): a bad one fails `dofray_render`
/// with `DOFRAY_USAGE` and a message naming the setter (`dofray_scene_set_f_number must be a
/// finite number > 0, got -1`). `dofray_scene_reset_overrides` clears them all.
pub struct DofrayScene {
    pub(crate) desc: SceneDesc,
    pub(crate) overrides: Overrides,
    pub(crate) settings: SettingsPatch,
    pub(crate) frame: Option<i64>,
    /// The renderer of the last render: its device's id and overrides, then itself.
    pub(crate) cache: Option<(u64, Overrides, Renderer)>,
    /// The device made for renders given no device.
    pub(crate) own_device: Option<DofrayDevice>,
}

impl DofrayScene {
    fn new(desc: SceneDesc) -> Self {
        Self {
            desc,
            overrides: Overrides::default(),
            settings: SettingsPatch::default(),
            frame: None,
            cache: None,
            own_device: None,
        }
    }
}

/// Loads a scene: a built-in scene by name (`"paper"`, ...), a `.toml` scene file, or a
/// `.obj`, `.gltf` or `.glb` model. Relative paths are relative to the working directory.
/// Fails with `DOFRAY_BAD_INPUT` (the message names the file and the fault) or
/// `DOFRAY_RESOURCE_LIMIT`.
///
/// # Safety
/// `path_or_name` is NULL or a NUL-terminated string; `out` is NULL or points to writable
/// storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_load(
    path_or_name: *const c_char,
    out: *mut *mut DofrayScene,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        // SAFETY: the function's contract.
        let name = unsafe { str_arg(path_or_name, "path_or_name") }?;
        let desc = dofray::scene::load(name)?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayScene::new(desc)) };
        Ok(())
    })
}

/// Parses a TOML scene (`docs/scene-format.md`) from the `len` bytes at `toml` (UTF-8; no
/// terminating NUL needed). `path` (NULL: `"<memory>.toml"`) names the scene in messages,
/// and the files it refers to by relative paths are looked up in `path`'s directory.
///
/// # Safety
/// `toml` is NULL or points to `len` readable bytes; `path` is NULL or a NUL-terminated
/// string; `out` is NULL or points to writable storage for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_parse(
    toml: *const c_char,
    len: usize,
    path: *const c_char,
    out: *mut *mut DofrayScene,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        if toml.is_null() {
            return Err(Failure::invalid("toml is NULL"));
        }
        // SAFETY: non-NULL and, by the function's contract, `len` readable bytes.
        let bytes = unsafe { std::slice::from_raw_parts(toml.cast::<u8>(), len) };
        let src = std::str::from_utf8(bytes)
            .map_err(|e| Failure::invalid(format!("toml is not valid UTF-8: {e}")))?;
        let path = if path.is_null() {
            "<memory>.toml"
        } else {
            // SAFETY: non-NULL, NUL-terminated by the function's contract.
            unsafe { str_arg(path, "path") }?
        };
        let desc = dofray::scene::file::parse(src, Path::new(path))?;
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayScene::new(desc)) };
        Ok(())
    })
}

/// Frees a scene (NULL: nothing).
///
/// # Safety
/// `scene` is NULL or a scene from `dofray_scene_load` or `dofray_scene_parse`, not used
/// afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_free(scene: *mut DofrayScene) {
    // SAFETY: the function's contract.
    unsafe { free(scene) }
}

/// Runs `change` on the scene behind `scene`.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
unsafe fn with_scene(
    scene: *mut DofrayScene,
    change: impl FnOnce(&mut DofrayScene) -> Result<(), Failure>,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the caller's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        change(scene)
    })
}

/// Clears every override and setting of the scene: it renders as its file describes again.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_reset_overrides(scene: *mut DofrayScene) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides = Overrides::default();
            s.settings = SettingsPatch::default();
            s.frame = None;
            Ok(())
        })
    }
}

/// Image size in pixels. 0 for one of them follows the scene's aspect ratio from the other;
/// 0 for both keeps the scene's size.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_size(
    scene: *mut DofrayScene,
    width: u32,
    height: u32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.width = (width > 0).then_some(width);
            s.overrides.height = (height > 0).then_some(height);
            Ok(())
        })
    }
}

/// A photographic lens of this f-number (> 0), replacing the scene's lens (focal length and
/// sensor width: those set here, else the scene's photographic lens's, else 50 mm on 36 mm).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_f_number(
    scene: *mut DofrayScene,
    f_number: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.f_number = Some(f_number);
            Ok(())
        })
    }
}

/// The focal length in mm (> 0) of a photographic lens (the scene's, or one an f-number
/// sets).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_focal_length_mm(
    scene: *mut DofrayScene,
    focal_length_mm: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.focal_length_mm = Some(focal_length_mm);
            Ok(())
        })
    }
}

/// A real lens: the lens prescription file at `path` (pbrt's lens format; see `lenses/` and
/// `docs/lenses.md`), traced element by element, replacing the scene's lens. Its focal
/// length frames the shot; `dofray_scene_set_f_number` stops it down and
/// `dofray_scene_set_sensor_width_mm` sizes its film. The file is read now: a missing or
/// malformed one fails with `DOFRAY_BAD_INPUT` naming the file and line (the scene is then
/// unchanged). NULL clears it.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread; `path` is NULL or a
/// NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_lens(
    scene: *mut DofrayScene,
    path: *const c_char,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.real_lens = if path.is_null() {
                None
            } else {
                // SAFETY: non-NULL, and the function's contract makes it a string.
                let path = str_arg(path, "path")?;
                Some(dofray::camera::RealLensSpec::load(Path::new(path))?)
            };
            Ok(())
        })
    }
}

/// A lens of this aperture radius in scene units (>= 0; 0: a pinhole), replacing the
/// scene's lens.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_aperture_radius(
    scene: *mut DofrayScene,
    radius: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.aperture_radius = Some(radius);
            Ok(())
        })
    }
}

/// Focus at this distance along the view axis in scene units (> 0; `INFINITY`: at
/// infinity). Clears an autofocus pixel set here.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_focus_distance(
    scene: *mut DofrayScene,
    distance: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.focus_distance = Some(distance);
            s.overrides.autofocus = None;
            Ok(())
        })
    }
}

/// Autofocus on the surface seen through pixel (`x`, `y`) of the image (after the size set
/// here); it must see a surface. Clears a focus distance set here.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_autofocus(
    scene: *mut DofrayScene,
    x: u32,
    y: u32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.overrides.autofocus = Some((x, y));
            s.overrides.focus_distance = None;
            Ok(())
        })
    }
}

/// Where sample sites go: `"pinhole"` (no depth of field), `"dense"` (every pixel) or
/// `"adaptive"` (the default). Another name is `DOFRAY_INVALID_ARGUMENT` at once.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread; `mode` is NULL or a
/// NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_mode(
    scene: *mut DofrayScene,
    mode: *const c_char,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let scene = unsafe { arg_mut(scene, "scene") }?;
        // SAFETY: the function's contract.
        let name = unsafe { str_arg(mode, "mode") }?;
        let mode = name
            .parse::<Mode>()
            .map_err(|e| Failure::invalid(e.to_string()))?;
        scene.settings.mode = Some(mode);
        Ok(())
    })
}

/// Samples (of pixel x lens) per sample site that blur reaches (1 to 65536).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_spp(scene: *mut DofrayScene, spp: u32) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.spp = Some(spp);
            Ok(())
        })
    }
}

/// Anti-aliasing samples per in-focus site, and per pixel in pinhole mode (1 to 65536).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_aa(scene: *mut DofrayScene, aa: u32) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.aa = Some(aa);
            Ok(())
        })
    }
}

/// The adaptive mode's error tolerance in 8-bit sRGB code values (> 0).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_tolerance(
    scene: *mut DofrayScene,
    tolerance: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.rule = Some(RulePatch::ErrorControlled {
                tolerance: Some(tolerance),
            });
            Ok(())
        })
    }
}

/// The random seed (default 0): the same seed gives the same image.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_seed(scene: *mut DofrayScene, seed: u64) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.seed = Some(seed);
            Ok(())
        })
    }
}

/// Exposure in stops (-64 to 64; default 0): radiance is scaled by 2^exposure.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_exposure(
    scene: *mut DofrayScene,
    exposure: f32,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.exposure = Some(exposure);
            Ok(())
        })
    }
}

/// Nonzero: a transparent background (RGBA premultiplied by coverage, PNGs written with
/// alpha); 0: as the scene says.
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_transparent(
    scene: *mut DofrayScene,
    transparent: c_int,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.settings.transparent = transparent != 0;
            Ok(())
        })
    }
}

/// The frame of an animated scene to render (default: its first frame; ignored by a scene
/// without animation).
///
/// # Safety
/// `scene` is NULL or a live scene used by no other thread.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_scene_set_frame(
    scene: *mut DofrayScene,
    frame: i64,
) -> DofrayStatus {
    // SAFETY: the function's contract.
    unsafe {
        with_scene(scene, |s| {
            s.frame = Some(frame);
            Ok(())
        })
    }
}
