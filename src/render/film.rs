//! The rendered image and its per-pixel arbitrary output variables (AOVs).

use glam::{Vec3, Vec4};

use crate::limits::{MemoryError, try_collect, try_vec, try_with_capacity};

/// A rendered frame: linear RGB radiance plus the maps the seed's method works from.
#[derive(Debug, Clone)]
pub struct Film {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Linear RGB radiance, row-major, top row first. With
    /// [`RenderSettings::transparent`](super::RenderSettings) the background contributes
    /// nothing, so this is premultiplied by [`Film::alpha`].
    pub color: Vec<Vec3>,
    /// Coverage: the filter- and lens-weighted fraction of the pixel's camera samples that hit
    /// geometry (1 where everything hit, 0 where every sample saw the background).
    pub alpha: Vec<f32>,
    /// Distance along the camera's view axis of the surface the pinhole ray hit (inf for misses).
    pub depth: Vec<f32>,
    /// Circle-of-confusion diameter in pixels at `depth`.
    pub coc: Vec<f32>,
    /// Sample interval (power of two; 1 = every pixel is a site).
    pub interval: Vec<u32>,
    /// Lens samples traced for this pixel: 0 where it was interpolated, 1 where the pinhole
    /// sample was used, `spp` at defocused sample sites.
    pub samples: Vec<u32>,
}

impl Film {
    /// A `width` x `height` film with black colour, alpha 1, infinite depth, CoC 0, interval 1 and
    /// no samples. Aborts if the memory cannot be had: renders use [`Film::try_new`].
    pub fn new(width: usize, height: usize) -> Self {
        Self::try_new(width, height).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Film::new`], or a [`MemoryError`] when a buffer cannot be allocated.
    pub fn try_new(width: usize, height: usize) -> Result<Self, MemoryError> {
        let n = width
            .checked_mul(height)
            .ok_or_else(|| MemoryError::allocation("the film", width as u128 * height as u128))?;
        Ok(Self {
            width,
            height,
            color: try_vec(n, Vec3::ZERO, "the film's colour")?,
            alpha: try_vec(n, 1.0, "the film's alpha")?,
            depth: try_vec(n, f32::INFINITY, "the film's depth")?,
            coc: try_vec(n, 0.0, "the film's CoC")?,
            interval: try_vec(n, 1, "the film's intervals")?,
            samples: try_vec(n, 0, "the film's sample counts")?,
        })
    }

    /// Index of pixel (`x`, `y`) in the row-major per-pixel vectors: `y * width + x`.
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// Sets colour and alpha from RGBA pixels (one per film pixel), in place.
    pub fn set_rgba(&mut self, rgba: &[Vec4]) {
        debug_assert_eq!(
            rgba.len(),
            self.color.len(),
            "one RGBA pixel per film pixel"
        );
        for ((c, a), p) in self.color.iter_mut().zip(&mut self.alpha).zip(rgba) {
            *c = p.truncate();
            *a = p.w;
        }
    }

    /// The pixels of `region` (which must lie inside the film) as a film of its own. Aborts if
    /// the memory cannot be had: renders use [`Film::try_crop`].
    pub fn crop(&self, region: &super::Region) -> Film {
        self.try_crop(region).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Film::crop`], or a [`MemoryError`] when a buffer cannot be allocated.
    pub fn try_crop(&self, region: &super::Region) -> Result<Film, MemoryError> {
        let w = self.width;
        Ok(Film {
            width: region.width() as usize,
            height: region.height() as usize,
            color: region.try_crop(&self.color, w, "the region's colour")?,
            alpha: region.try_crop(&self.alpha, w, "the region's alpha")?,
            depth: region.try_crop(&self.depth, w, "the region's depth")?,
            coc: region.try_crop(&self.coc, w, "the region's CoC")?,
            interval: region.try_crop(&self.interval, w, "the region's intervals")?,
            samples: region.try_crop(&self.samples, w, "the region's sample counts")?,
        })
    }

    /// The colour as `[f32; 3]` pixels (for metrics and writers).
    pub fn rgb(&self) -> Vec<[f32; 3]> {
        self.color.iter().map(|c| c.to_array()).collect()
    }

    /// Colour and alpha interleaved, 4 floats per pixel, row-major (for C and numpy buffers).
    /// Aborts if the memory cannot be had: see [`Film::try_rgba_interleaved`].
    pub fn rgba_interleaved(&self) -> Vec<f32> {
        self.try_rgba_interleaved()
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Film::rgba_interleaved`], or a [`MemoryError`] when it cannot be allocated.
    pub fn try_rgba_interleaved(&self) -> Result<Vec<f32>, MemoryError> {
        let n = self.color.len().min(self.alpha.len());
        let mut out = try_with_capacity(n.saturating_mul(4), "the interleaved RGBA image")?;
        for (c, &a) in self.color.iter().zip(&self.alpha) {
            out.extend_from_slice(&[c.x, c.y, c.z, a]);
        }
        Ok(out)
    }

    /// The colour as `[f32; 3]` pixels, or a [`MemoryError`] when they cannot be allocated.
    pub fn try_rgb(&self) -> Result<Vec<[f32; 3]>, MemoryError> {
        try_collect(self.color.iter().map(|c| c.to_array()), "the RGB image")
    }
}
