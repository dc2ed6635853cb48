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
//! own (the coherent lens rays of one pixel) as long as it starts on a packet boundary; sites
//! with fewer share packets with their neighbours. The packing depends only on the row, so images are bit-identical for any
//! thread count.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::estimate::Estimate;
use super::gather::{Gather, Slots};
use super::light_choice::LightTraced;
use super::reuse::{Record, SiteRecords};
use super::trace::{self, RayKind, Tally};
use super::{Integrator, path};
use super::{Mode, Progress, RenderSettings};
use crate::camera::{Camera, Lens, LensFilter};
use crate::embree::{LANES, RayHint, RayPacket16};
use crate::filter::FilterSampler;
use crate::sampler::{PixelSampler, SampleKey, sample_key};
use crate::scene::World;

/// What every site of a render shares.
pub struct SiteShader<'a> {
    /// The scene to trace.
    pub world: &'a World,
    /// The camera the samples' rays leave.
    pub camera: &'a Camera,
    /// The render's settings (seed, lens filter, bounces, exposure, transparency, ...).
    pub settings: &'a RenderSettings,
    /// Draws each sample's film offset from the pixel filter ([`RenderSettings::pixel_filter`]).
    pub pixel_filter: &'a FilterSampler,
    /// Emitters whose direct view is light-traced ([`super::light_trace`]): the camera's paths
    /// leave their emission out where they hit them first.
    pub light_traced: &'a LightTraced,
}

/// Per-thread scratch space for [`SiteShader::shade_row`]; its contents on entry do not
/// matter.
#[derive(Default)]
pub struct SiteScratch {
    packet: RayPacket16,
    trace: trace::Scratch,
    path: path::PathScratch,
    batch: Batch,
}

impl SiteScratch {
    /// Empty scratch space.
    pub fn new() -> Self {
        Self::default()
    }
}

/// Where a batch's samples go: a row run (whose first pixel is `origin`) of estimates, and
/// optionally of records for lending and of slots for gathering.
struct Sinks<'s> {
    origin: (usize, usize),
    estimates: &'s mut [Estimate],
    records: Option<&'s mut [SiteRecords]>,
    gather: Option<(&'s Gather<'s>, &'s mut [Slots])>,
}

impl Sinks<'_> {
    /// The same sinks, borrowed for one batch.
    fn reborrow(&mut self) -> Sinks<'_> {
        Sinks {
            origin: self.origin,
            estimates: &mut *self.estimates,
            records: self.records.as_deref_mut(),
            gather: self.gather.as_mut().map(|(g, s)| (*g, &mut **s)),
        }
    }
}

/// Up to 16 samples waiting to be traced together.
#[derive(Default)]
struct Batch {
    len: usize,
    /// The estimate (index in the row run being shaded) each sample belongs to.
    pixel: [usize; LANES],
    /// Each sample's key ([`crate::sampler::sample_key`]): what its path's decisions are drawn
    /// from.
    key: [SampleKey; LANES],
    film_x: [f32; LANES],
    film_y: [f32; LANES],
    lens_x: [f32; LANES],
    lens_y: [f32; LANES],
}

impl SiteShader<'_> {
    /// [`SiteShader::shade_row`] for every row, in parallel (`from`, `to` and `estimates`
    /// hold the whole image); advances `progress` by one per row. Row tallies are merged in
    /// row order, so the ray log does not depend on scheduling.
    pub fn shade_rows(
        &self,
        from: &[u32],
        to: &[u32],
        estimates: &mut [Estimate],
        progress: &dyn Progress,
        tally: &mut Tally,
    ) -> Result<(), super::RenderError> {
        let width = self.camera.width as usize;
        let record = self.settings.record_rays;
        let tallies: Vec<Tally> = estimates
            .par_chunks_mut(width)
            .zip(from.par_chunks(width).zip(to.par_chunks(width)))
            .enumerate()
            .map_init(SiteScratch::new, |scratch, (y, (row, (from, to)))| {
                let mut local = Tally::new(record);
                if from != to && !progress.cancelled() {
                    self.shade_row((0, y), from, to, row, None, None, scratch, &mut local);
                }
                progress.advance(1);
                local
            })
            .collect();
        for local in tallies {
            tally.merge(local);
        }
        super::check_cancelled(progress)
    }

    /// Adds samples `from[i] .. to[i]` of pixel (x0 + i, y) to `estimates[i]` for every pixel
    /// of a run of row `y` starting at column `x0` (none where `to[i] <= from[i]`). A pixel's
    /// samples are the same whichever call takes them, so an estimate refined in several calls
    /// (or in a window of the image) equals one made in a single call. With `records`
    /// (indexed as `estimates`), each path-traced sample is also recorded there for lending
    /// ([`super::reuse`]); with `gather` (its slots indexed as `estimates`), each sample of a
    /// site that takes part adds to its slots ([`super::gather`]).
    #[allow(clippy::too_many_arguments)]
    pub fn shade_row(
        &self,
        (x0, y): (usize, usize),
        from: &[u32],
        to: &[u32],
        estimates: &mut [Estimate],
        records: Option<&mut [SiteRecords]>,
        gather: Option<(&Gather, &mut [Slots])>,
        scratch: &mut SiteScratch,
        tally: &mut Tally,
    ) {
        let mut sinks = Sinks {
            origin: (x0, y),
            estimates,
            records,
            gather,
        };
        let width = self.camera.width as usize;
        scratch.batch.len = 0;
        for (i, (&start, &end)) in from.iter().zip(to).enumerate() {
            if end <= start {
                continue;
            }
            let x = x0 + i;
            let sampler = PixelSampler::new(self.settings.seed, (y * width + x) as u64);
            // Samples are made 16 at a time (batched, bit for bit the single-sample values)
            // and queued; a pixel with 16 or more fills whole packets of its own.
            for first in (start..end).step_by(LANES) {
                let chunk = self.chunk(&sampler, (x, y), i, first);
                let count = (end - first).min(LANES as u32) as usize;
                if count == LANES {
                    // A whole packet of one pixel's coherent rays: traced at once, while any
                    // queued samples of smaller sites wait for more company.
                    self.trace_batch(&chunk, scratch, sinks.reborrow(), tally);
                    continue;
                }
                for lane in 0..count {
                    let b = &mut scratch.batch;
                    let slot = b.len;
                    b.film_x[slot] = chunk.film_x[lane];
                    b.film_y[slot] = chunk.film_y[lane];
                    b.lens_x[slot] = chunk.lens_x[lane];
                    b.lens_y[slot] = chunk.lens_y[lane];
                    b.pixel[slot] = i;
                    b.key[slot] = chunk.key[lane];
                    b.len += 1;
                    if b.len == LANES {
                        self.flush(scratch, sinks.reborrow(), tally);
                    }
                }
            }
        }
        if scratch.batch.len > 0 {
            self.flush(scratch, sinks, tally);
        }
    }

    /// Samples `first .. first + 16` of pixel (x, y), for estimate `slot`: film positions drawn
    /// from the pixel filter around the pixel centre and lens positions on the aperture (all
    /// at its centre for a pinhole camera).
    fn chunk(
        &self,
        sampler: &PixelSampler,
        (x, y): (usize, usize),
        slot: usize,
        first: u32,
    ) -> Batch {
        let (u, v) = sampler.get16(first);
        let (pu, pv) = sampler.get_pixel16(first);
        // Pinhole mode samples the pixel only: every ray leaves the lens centre.
        let (lens_x, lens_y) = if self.settings.mode != Mode::Pinhole {
            self.camera.lens.lens_points16(&u, &v)
        } else {
            ([0.0; LANES], [0.0; LANES])
        };
        let f = self.pixel_filter;
        let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
        let pixel = (y * self.camera.width as usize + x) as u64;
        let seed = self.settings.seed;
        Batch {
            len: LANES,
            pixel: [slot; LANES],
            key: std::array::from_fn(|l| sample_key(seed, pixel, first + l as u32)),
            film_x: pu.map(|u| cx + f.offset(u)),
            film_y: pv.map(|v| cy + f.offset(v)),
            lens_x,
            lens_y,
        }
    }

    /// Traces the queued samples and empties the queue.
    fn flush(&self, scratch: &mut SiteScratch, sinks: Sinks, tally: &mut Tally) {
        let batch = std::mem::take(&mut scratch.batch);
        self.trace_batch(&batch, scratch, sinks, tally);
    }

    /// Traces and shades a batch, adding each sample to its pixel's estimate (and record).
    fn trace_batch(&self, b: &Batch, scratch: &mut SiteScratch, sinks: Sinks, tally: &mut Tally) {
        let Sinks {
            origin: run,
            estimates,
            records,
            mut gather,
        } = sinks;
        let SiteScratch {
            packet,
            trace,
            path,
            ..
        } = scratch;
        let mut origin = [[0.0f32; LANES]; 3];
        let mut dir = [[0.0f32; LANES]; 3];
        let mut lens_weight = [0.0f32; LANES];
        // All 16 lanes are computed (lanes past `len` are simply not traced).
        self.camera.lens_rays16(
            (&b.film_x, &b.film_y),
            (&b.lens_x, &b.lens_y),
            &mut origin,
            &mut dir,
            &mut lens_weight,
        );
        // Rays the lens blocked (weight 0: a real lens's vignetting) are not traced.
        let wanted = (0..b.len)
            .filter(|&l| lens_weight[l] > 0.0)
            .fold(0u32, |m, l| m | 1 << l);
        packet.set_lanes_masked(wanted, &origin, &dir);
        let mut radiance = [Vec3::ZERO; LANES];
        let mut first = path::FirstHits::default();
        if records.is_some() {
            // Reuse lends the part of each sample that holds across the aperture.
            first.view_dependent = Some([Vec3::ZERO; LANES]);
        }
        match self.settings.integrator {
            Integrator::Path => path::trace_path(
                self.world,
                packet,
                &b.key,
                &self.settings.path,
                self.light_traced,
                &mut radiance,
                &mut first,
                path,
                tally,
            ),
            Integrator::Direct => trace::trace_and_shade(
                self.world,
                packet,
                RayKind::Primary,
                RayHint::Coherent,
                &mut radiance,
                &mut first.t,
                self.settings.bounces,
                trace,
                tally,
            ),
        }
        let filter = self.settings.filter;
        let transparent = self.settings.transparent;
        let scale = self.settings.exposure.exp2();
        for lane in 0..b.len {
            let hit = first.t[lane].is_finite();
            if transparent && !hit {
                // The background is left out (the plate goes there); mirrors still see it.
                radiance[lane] = Vec3::ZERO;
            }
            let w = if filter == LensFilter::Box {
                1.0
            } else {
                let lens = Vec2::new(b.lens_x[lane], b.lens_y[lane]);
                self.camera.lens.weight(filter, lens)
            };
            // A real lens's ray carries its irradiance (vignetting); a blocked one brings
            // no light and says nothing of the coverage.
            let blocked = wanted & (1 << lane) == 0;
            let value = radiance[lane] * (scale * lens_weight[lane]);
            if blocked {
                estimates[b.pixel[lane]].add_blocked(w);
            } else {
                estimates[b.pixel[lane]].add(value, w, hit);
            }
            if let Some((g, slots)) = gather.as_mut() {
                let at = (run.0 + b.pixel[lane], run.1);
                if g.takes_part(at) {
                    let film = Vec2::new(b.film_x[lane], b.film_y[lane]);
                    let (value, hit) = if blocked {
                        (Vec3::ZERO, None)
                    } else {
                        (value, Some(hit))
                    };
                    g.add(&mut slots[b.pixel[lane]], at, film, (value, w, hit));
                }
            }
        }
        if let Some(records) = records {
            self.record(b, (&origin, &dir), &radiance, &first, records);
        }
    }

    /// Keeps each sample of batch `b` (its camera ray from `origin` along `dir`, per axis and
    /// lane; its radiance; what it hit first) in its pixel's records for lending
    /// ([`crate::render::reuse`]).
    fn record(
        &self,
        b: &Batch,
        (origin, dir): (&[[f32; LANES]; 3], &[[f32; LANES]; 3]),
        radiance: &[Vec3; LANES],
        first: &path::FirstHits,
        records: &mut [SiteRecords],
    ) {
        let Some(re) = self.camera.reprojection() else {
            return;
        };
        let scale = self.settings.exposure.exp2();
        // The aperture's reach, for the angle it subtends (an oval's longer axis).
        let r = self.camera.aperture_radius() * re.aperture.outer_radius();
        for lane in 0..b.len {
            let d = Vec3::new(dir[0][lane], dir[1][lane], dir[2][lane]);
            let t = first.t[lane];
            let depth = t * d.dot(self.camera.forward);
            let film = Vec2::new(b.film_x[lane], b.film_y[lane]);
            let lens = Vec2::new(b.lens_x[lane], b.lens_y[lane]);
            let l = radiance[lane] * scale;
            let hit = t.is_finite();
            // Without the split, all of it may depend on the view.
            let view = first.view_dependent.map_or(l, |vd| vd[lane] * scale);
            let alpha = (first.view_alpha[lane], view);
            let o = Vec3::new(origin[0][lane], origin[1][lane], origin[2][lane]);
            let point = o + d * t - self.camera.eye;
            let gradient = re.gradient(self.camera, point, first.normal[lane]);
            let at = (depth, t, gradient);
            let record = Record::new(&re, r, (film, lens), at, alpha, l, hit);
            records[b.pixel[lane]].push(record);
        }
    }
}
