//! Whether an image on disk is a finished output: what `--skip-existing` trusts.
//!
//! A frame that exists is not necessarily finished: a copy or sync that broke off leaves a
//! truncated file, a full disk an empty one, an older run a frame of another size. dofray's
//! own writes are atomic, so an incomplete file always came from somewhere else; it is read
//! whole (every PNG row through its checksums, every EXR chunk decompressed) and its size
//! compared with the image the job would write.

use std::io::BufReader;
use std::path::Path;

use super::ImageFormat;

/// Checks that `path` is a complete, readable PNG or EXR of `width` x `height` pixels; the
/// reason it is not, otherwise (for a warning).
pub fn check_complete(path: &Path, width: u32, height: u32) -> Result<(), String> {
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err("not a regular file".into());
    }
    if meta.len() == 0 {
        return Err("empty (0 bytes)".into());
    }
    let size = match ImageFormat::from_path(path).map_err(|e| e.to_string())? {
        ImageFormat::Png => png_size(path, (width, height))?,
        ImageFormat::Exr => exr_size(path, (width, height))?,
    };
    if size != (width, height) {
        return Err(format!(
            "{}x{} pixels, but this render's image is {width}x{height}",
            size.0, size.1
        ));
    }
    Ok(())
}

/// The size of a PNG, reading every row (a truncated or corrupt file fails); a header of
/// another size is reported without decoding.
fn png_size(path: &Path, expected: (u32, u32)) -> Result<(u32, u32), String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut reader = png::Decoder::new(BufReader::new(file))
        .read_info()
        .map_err(|e| format!("unreadable PNG: {e}"))?;
    let size = (reader.info().width, reader.info().height);
    if size != expected {
        return Ok(size);
    }
    let mut row = Vec::new();
    while let Some(r) = reader
        .next_row()
        .map_err(|e| format!("incomplete PNG: {e}"))?
    {
        row.clear();
        row.extend_from_slice(r.data());
    }
    reader
        .finish()
        .map_err(|e| format!("incomplete PNG: {e}"))?;
    Ok(size)
}

/// The size of an EXR's first layer, decompressing every chunk.
fn exr_size(path: &Path, expected: (u32, u32)) -> Result<(u32, u32), String> {
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| format!("unreadable EXR header: {e}"))?;
    let header = meta.headers.first().ok_or("an EXR without layers")?;
    let size = (
        u32::try_from(header.layer_size.0).unwrap_or(u32::MAX),
        u32::try_from(header.layer_size.1).unwrap_or(u32::MAX),
    );
    if size != expected {
        return Ok(size);
    }
    super::exr::read_first_layer(path).map_err(|e| format!("incomplete EXR: {e}"))?;
    Ok(size)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::{WriteOptions, write_film_with};
    use crate::render::Film;

    #[test]
    fn finished_images_pass_and_broken_ones_say_why() {
        let scratch = tempfile::Builder::new()
            .prefix("dofray-verify-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        for ext in ["png", "exr"] {
            let path = dir.join(format!("f.{ext}"));
            let mut film = Film::new(33, 17);
            film.color
                .iter_mut()
                .enumerate()
                .for_each(|(i, c)| *c = glam::Vec3::splat(i as f32 / 600.0));
            write_film_with(&path, &film, &WriteOptions::default()).unwrap();
            assert_eq!(check_complete(&path, 33, 17), Ok(()), "{ext}");
            let other = check_complete(&path, 32, 17).unwrap_err();
            assert!(other.contains("33x17"), "{other}");
            let bytes = std::fs::read(&path).unwrap();
            let cut = dir.join(format!("cut.{ext}"));
            for keep in [bytes.len() - 20, bytes.len() / 2, 40, 0] {
                std::fs::write(&cut, &bytes[..keep]).unwrap();
                let e = check_complete(&cut, 33, 17).unwrap_err();
                assert!(!e.is_empty(), "{ext} cut to {keep}");
            }
        }
        assert!(check_complete(dir, 1, 1).unwrap_err().contains("regular"));
        scratch.close().unwrap();
    }
}
