//! The rendered image and its per-pixel arbitrary output variables (AOVs).

use glam::{Vec3, Vec4};

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
    /// no samples.
    pub fn new(width: usize, height: usize) -> Self {
        let n = width * height;
        Self {
            width,
            height,
            color: vec![Vec3::ZERO; n],
            alpha: vec![1.0; n],
            depth: vec![f32::INFINITY; n],
            coc: vec![0.0; n],
            interval: vec![1; n],
            samples: vec![0; n],
        }
    }

    /// Index of pixel (`x`, `y`) in the row-major per-pixel vectors: `y * width + x`.
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// Sets colour and alpha from RGBA pixels.
    pub fn set_rgba(&mut self, rgba: &[Vec4]) {
        self.color = rgba.iter().map(|c| c.truncate()).collect();
        self.alpha = rgba.iter().map(|c| c.w).collect();
    }

    /// The pixels of `region` (which must lie inside the film) as a film of its own.
    pub fn crop(&self, region: &super::Region) -> Film {
        let w = self.width;
        Film {
            width: region.width() as usize,
            height: region.height() as usize,
            color: region.crop(&self.color, w),
            alpha: region.crop(&self.alpha, w),
            depth: region.crop(&self.depth, w),
            coc: region.crop(&self.coc, w),
            interval: region.crop(&self.interval, w),
            samples: region.crop(&self.samples, w),
        }
    }

    /// The colour as `[f32; 3]` pixels (for metrics and writers).
    pub fn rgb(&self) -> Vec<[f32; 3]> {
        self.color.iter().map(|c| c.to_array()).collect()
    }

    /// Colour and alpha interleaved, 4 floats per pixel, row-major (for C and numpy buffers).
    pub fn rgba_interleaved(&self) -> Vec<f32> {
        self.color
            .iter()
            .zip(&self.alpha)
            .flat_map(|(c, &a)| [c.x, c.y, c.z, a])
            .collect()
    }
}
