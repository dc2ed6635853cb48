//! Rendered images.

use std::ffi::c_char;
use std::path::Path;

use dofray::output::WriteOptions;
use dofray::render::{Film, RenderStats};

use crate::args::{arg, free, str_arg, value_of};
use crate::status::{DofrayStatus, guard};

/// A rendered image: linear RGBA, depth and CoC per pixel, and the render's statistics.
pub struct DofrayImage {
    pub(crate) film: Film,
    pub(crate) stats: RenderStats,
    pub(crate) rgba: Vec<f32>,
    pub(crate) transparent: bool,
}

/// Frees an image (NULL: nothing); its buffers go with it.
///
/// # Safety
/// `image` is NULL or an image from `dofray_render`, not used afterwards (nor its buffers).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_free(image: *mut DofrayImage) {
    // SAFETY: the function's contract.
    unsafe { free(image) }
}

/// The image's width in pixels (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_width(image: *const DofrayImage) -> u32 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.film.width as u32) }
}

/// The image's height in pixels (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_height(image: *const DofrayImage) -> u32 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.film.height as u32) }
}

/// The pixels: 4 floats per pixel (R, G, B, A), rows top to bottom, width x height pixels.
/// Linear radiance (not sRGB-encoded, not clamped); with a transparent background, RGB is
/// premultiplied by A (the coverage), else A is 1. Valid until `dofray_image_free`; NULL for
/// a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_rgba(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, std::ptr::null(), |i| i.rgba.as_ptr()) }
}

/// Depth per pixel (width x height floats, rows top to bottom): the distance along the view
/// axis to the surface seen through the pixel's centre, `INFINITY` where it sees the
/// background. Valid until `dofray_image_free`; NULL for a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_depth(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, std::ptr::null(), |i| i.film.depth.as_ptr()) }
}

/// Circle-of-confusion diameter in pixels per pixel (width x height floats, rows top to
/// bottom). Valid until `dofray_image_free`; NULL for a NULL image.
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_coc(image: *const DofrayImage) -> *const f32 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, std::ptr::null(), |i| i.film.coc.as_ptr()) }
}

/// Rays the render traced (camera, shadow and mirror rays; 0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_rays(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.stats.rays.total()) }
}

/// Pixels shaded directly, the sample sites (the rest were interpolated; 0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_sample_sites(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.stats.sample_sites) }
}

/// Sample sites that blur reaches, which took up to the render's `spp` samples (the others,
/// in focus, up to `aa`; 0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_defocused_sites(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.stats.defocused_sites) }
}

/// Sample sites whose value rests on their neighbours' lent samples as well as their own
/// (sample reuse, adaptive mode; 0 with reuse off, in other modes and for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_borrowing_sites(image: *const DofrayImage) -> u64 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0, |i| i.stats.borrowing_sites) }
}

/// Wall-clock seconds the render took, without building the scene (0 for NULL).
///
/// # Safety
/// `image` is NULL or a live image.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_seconds(image: *const DofrayImage) -> f64 {
    // SAFETY: the function's contract.
    unsafe { value_of(image, 0.0, |i| i.stats.seconds) }
}

/// Writes the image to `path`, replacing it atomically: `.png` (8-bit sRGB; RGBA with
/// straight alpha when the background was transparent) or `.exr` (float linear RGBA plus
/// depth, CoC and dofray's passes). Another extension is `DOFRAY_USAGE`; a file that cannot
/// be written `DOFRAY_IO`.
///
/// # Safety
/// `image` is NULL or a live image; `path` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_image_write(
    image: *const DofrayImage,
    path: *const c_char,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let image = unsafe { arg(image, "image") }?;
        // SAFETY: the function's contract.
        let path = unsafe { str_arg(path, "path") }?;
        let options = WriteOptions {
            png_alpha: image.transparent,
            ..Default::default()
        };
        dofray::output::write_film_with(Path::new(path), &image.film, &options)?;
        Ok(())
    })
}
