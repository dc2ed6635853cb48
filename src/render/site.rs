//! The second primitive every mode shares: shade sample sites, each with its own number of
//! samples, 16 samples to a packet.
//!
//! Every sample is a point in pixel x lens (Cook's distributed ray tracing): a film position
//! drawn from the pixel filter around the site's pixel and a position on the aperture, both
//! from the pixel's own 4D Sobol stream (`sampler::PixelSampler`). A site's colour is the
//! lens-filter-weighted mean of its samples, so its expected value is the filtered,
//! lens-integrated radiance whatever the number of samples: modes choose only *how many*
//! samples a site gets, which changes noise, never what is estimated.
//!
//! Samples are packed in row order: a site with 16 or more samples fills whole packets of its
//! own (the coherent lens rays of one pixel); sites with fewer share packets with their
//! neighbours. The packing depends only on the row, so images are bit-identical for any
//! thread count.

use glam::{Vec2, Vec3};

use super::RenderSettings;
use super::trace::{self, RayKind, Tally};
use crate::camera::Camera;
use crate::embree::{LANES, RayHint, RayPacket16};
use crate::filter::FilterSampler;
use crate::sampler::{LensFilter, PixelSampler, aperture_point, aperture_points16};
use crate::scene::World;

/// What every site of a render shares.
pub struct SiteShader<'a> {
    pub world: &'a World,
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    pub pixel_filter: &'a FilterSampler,
    /// Sample the aperture (false: every ray leaves the lens centre, a pinhole camera).
    pub lens: bool,
}

/// Per-thread scratch space for [`SiteShader::shade_row`]; its contents on entry do not
/// matter.
#[derive(Default)]
pub struct SiteScratch {
    packet: RayPacket16,
    trace: trace::Scratch,
    batch: Batch,
    sums: Vec<Vec3>,
    weights: Vec<f32>,
}

impl SiteScratch {
    pub fn new() -> Self {
        Self::default()
    }
}

/// Up to 16 samples waiting to be traced together.
#[derive(Default)]
struct Batch {
    len: usize,
    /// The pixel (column) each sample belongs to.
    pixel: [usize; LANES],
    film_x: [f32; LANES],
    film_y: [f32; LANES],
    lens_x: [f32; LANES],
    lens_y: [f32; LANES],
}

impl SiteShader<'_> {
    /// Shades the sites of row `y`: pixel `x` with `samples[x]` samples (0: not a site, left
    /// as it is), writing each site's colour to `color[x]`.
    pub fn shade_row(
        &self,
        y: usize,
        samples: &[u32],
        color: &mut [Vec3],
        scratch: &mut SiteScratch,
        tally: &mut Tally,
    ) {
        let width = samples.len();
        scratch.sums.clear();
        scratch.sums.resize(width, Vec3::ZERO);
        scratch.weights.clear();
        scratch.weights.resize(width, 0.0);
        scratch.batch.len = 0;
        for (x, &n) in samples.iter().enumerate() {
            if n == 0 {
                continue;
            }
            let sampler = PixelSampler::new(self.settings.seed, (y * width + x) as u64);
            let mut i = 0;
            while i < n {
                if scratch.batch.len == 0 && i % LANES as u32 == 0 && n - i >= LANES as u32 {
                    self.fill_packet(&sampler, (x, y), i, &mut scratch.batch);
                    i += LANES as u32;
                } else {
                    self.push_sample(&sampler, (x, y), i, &mut scratch.batch);
                    i += 1;
                }
                if scratch.batch.len == LANES {
                    self.flush(scratch, tally);
                }
            }
        }
        if scratch.batch.len > 0 {
            self.flush(scratch, tally);
        }
        for (x, &n) in samples.iter().enumerate() {
            if n > 0 {
                color[x] = scratch.sums[x] / scratch.weights[x];
            }
        }
    }

    /// The film position of a sample of pixel (x, y) from its pixel coordinates in [0, 1)^2.
    fn film(&self, (x, y): (usize, usize), u: f32, v: f32) -> (f32, f32) {
        let f = self.pixel_filter;
        (x as f32 + 0.5 + f.offset(u), y as f32 + 0.5 + f.offset(v))
    }

    /// Samples `first .. first + 16` of one pixel as a whole packet (the batched path: bit for
    /// bit what `push_sample` gives each of them).
    fn fill_packet(
        &self,
        sampler: &PixelSampler,
        pixel: (usize, usize),
        first: u32,
        b: &mut Batch,
    ) {
        let (u, v) = sampler.get16(first);
        let (pu, pv) = sampler.get_pixel16(first);
        (b.lens_x, b.lens_y) = if self.lens {
            aperture_points16(&u, &v, &self.camera.aperture)
        } else {
            ([0.0; LANES], [0.0; LANES])
        };
        for lane in 0..LANES {
            (b.film_x[lane], b.film_y[lane]) = self.film(pixel, pu[lane], pv[lane]);
        }
        b.pixel = [pixel.0; LANES];
        b.len = LANES;
    }

    fn push_sample(&self, sampler: &PixelSampler, pixel: (usize, usize), i: u32, b: &mut Batch) {
        let lane = b.len;
        let lens = if self.lens {
            aperture_point(sampler.get(i), &self.camera.aperture)
        } else {
            Vec2::ZERO
        };
        let p = sampler.get_pixel(i);
        (b.lens_x[lane], b.lens_y[lane]) = (lens.x, lens.y);
        (b.film_x[lane], b.film_y[lane]) = self.film(pixel, p.x, p.y);
        b.pixel[lane] = pixel.0;
        b.len += 1;
    }

    /// Traces and shades the batch, adding each sample to its pixel's weighted sum.
    fn flush(&self, scratch: &mut SiteScratch, tally: &mut Tally) {
        let SiteScratch {
            packet,
            trace,
            batch: b,
            sums,
            weights,
        } = scratch;
        let mut origin = [[0.0f32; LANES]; 3];
        let mut dir = [[0.0f32; LANES]; 3];
        // All 16 lanes are computed (lanes past `len` are simply not traced).
        self.camera.lens_rays16(
            (&b.film_x, &b.film_y),
            (&b.lens_x, &b.lens_y),
            &mut origin,
            &mut dir,
        );
        packet.set_lanes(b.len, &origin, &dir);
        let mut radiance = [Vec3::ZERO; LANES];
        let mut t_hit = [0.0f32; LANES];
        trace::trace_and_shade(
            self.world,
            packet,
            RayKind::Primary,
            RayHint::Coherent,
            &mut radiance,
            &mut t_hit,
            self.settings.bounces,
            trace,
            tally,
        );
        let filter = self.settings.filter;
        for lane in 0..b.len {
            let w = if filter == LensFilter::Box {
                1.0
            } else {
                let lens = Vec2::new(b.lens_x[lane], b.lens_y[lane]);
                filter.weight(lens, self.camera.aperture.anamorphic)
            };
            sums[b.pixel[lane]] += radiance[lane] * w;
            weights[b.pixel[lane]] += w;
        }
        b.len = 0;
    }
}
