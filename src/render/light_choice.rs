//! Which emitters light tracing ([`super::light_trace`]) takes from the camera, and how many
//! light paths each gets.
//!
//! **Which primitives.** An emissive triangle or sphere whose sharp image (the bounding box of
//! its projected bounds) covers at most a quarter of its blurred footprint (that box grown by
//! half the largest CoC over its depths and the pixel filter's reach): defocused lamps and
//! sub-pixel ones. Each takes `spp` paths per pixel of its footprint in the frame, so its disc
//! converges as a dense render's pixels do; smallest footprints first, within a budget of half
//! the samples of a dense render (what is left over stays with the camera). Emitters the camera
//! sees large and sharp are better found by its own rays.
//!
//!
//! The choice depends only on the scene, the camera and the settings, so every region of a
//! render makes the same one.

use std::collections::HashSet;

use glam::Vec3;

use crate::camera::{Camera, Lens, LensFilter};
use crate::sampler::PixelSampler;
use crate::scene::World;
use crate::scene::emitters::primitive_bounds;
use crate::settings::{Integrator, Mode, RenderSettings};

/// Keys the light paths' sample streams apart from the camera's.
pub(super) const SALT: u64 = 0x6c69_6768_745f_7472;
/// The most light paths of one primitive.
const MAX_PATHS: u32 = 1 << 24;
/// A sharp image at most this fraction of the blurred footprint is light-traced.
const SHARP_FRACTION: f32 = 0.25;

/// One light-traced primitive.
#[derive(Debug, Clone, Copy)]
pub(super) struct Traced {
    pub(super) geometry: u32,
    pub(super) prim: u32,
    /// Light paths to trace.
    pub(super) paths: u32,
    /// Film rectangle its light can reach (x0, y0, x1, y1; pixels, the filter's reach
    /// included), unclipped.
    pub(super) reach: [f32; 4],
}

/// The emissive primitives whose direct view is light-traced in a render, and how many paths
/// each takes ([`LightTraced::choose`]).
#[derive(Debug, Default)]
pub struct LightTraced {
    pub(super) traced: Vec<Traced>,
    set: HashSet<(u32, u32)>,
    /// Mean lens weight over the aperture under the render's lens filter (1 for the box).
    pub(super) lens_weight_mean: f32,
}

/// Where an emitter's light can land on the film.
struct Footprint {
    /// Area (square pixels) of its sharp image's bounding box.
    sharp_area: f32,
    /// Film rectangle its light can reach through any lens position, filter included.
    reach: [f32; 4],
}

impl LightTraced {
    /// Nothing light-traced: the camera finds every emitter.
    pub fn none() -> Self {
        Self::default()
    }

    /// The primitives of `world` to light-trace for a render through `camera` with
    /// `settings` (none unless the path tracer renders with
    /// [`crate::render::PathLimits::light_tracing`]); see the module documentation.
    pub fn choose(world: &World, camera: &Camera, settings: &RenderSettings) -> Self {
        if settings.integrator != Integrator::Path || !settings.path.light_tracing {
            return Self::none();
        }
        let pinhole = settings.mode == Mode::Pinhole;
        let spp = if pinhole { settings.aa } else { settings.spp };
        let filter_reach = 0.5 * settings.pixel_filter.width;
        let (w, h) = (camera.width as f32, camera.height as f32);
        let mut candidates = Vec::new();
        for (geometry, prim) in world.emitters.primitives() {
            let (lo, hi) = primitive_bounds(world, geometry, prim);
            let Some(fp) = footprint(camera, lo, hi, filter_reach, pinhole) else {
                continue;
            };
            let [x0, y0, x1, y1] = fp.reach;
            let blurred_area = (x1 - x0) * (y1 - y0);
            if fp.sharp_area > SHARP_FRACTION * blurred_area {
                continue;
            }
            // Only what lands in the frame is traced for.
            let in_frame = (x1.min(w) - x0.max(0.0)).max(0.0) * (y1.min(h) - y0.max(0.0)).max(0.0);
            if in_frame <= 0.0 {
                continue;
            }
            let paths = (spp as f64 * f64::from(in_frame))
                .ceil()
                .min(f64::from(MAX_PATHS));
            candidates.push(Traced {
                geometry,
                prim,
                paths: paths as u32,
                reach: fp.reach,
            });
        }
        candidates.sort_by_key(|t| (t.paths, t.geometry, t.prim));
        let budget = 0.5 * f64::from(w) * f64::from(h) * spp as f64;
        let mut total = 0.0f64;
        let mut traced: Vec<Traced> = candidates
            .into_iter()
            .take_while(|t| {
                total += f64::from(t.paths);
                total <= budget
            })
            .collect();
        traced.sort_by_key(|t| (t.geometry, t.prim));
        let set = traced.iter().map(|t| (t.geometry, t.prim)).collect();
        Self {
            traced,
            set,
            lens_weight_mean: lens_weight_mean(camera, settings.filter),
        }
    }

    /// Whether nothing is light-traced.
    pub fn is_empty(&self) -> bool {
        self.traced.is_empty()
    }

    /// Whether primitive `prim` of geometry `geometry` is light-traced: camera paths must
    /// leave its emission out where they hit it first.
    #[inline]
    pub fn contains(&self, geometry: u32, prim: u32) -> bool {
        !self.set.is_empty() && self.set.contains(&(geometry, prim))
    }

    /// The light paths a render traces.
    pub fn paths(&self) -> u64 {
        self.traced.iter().map(|t| u64::from(t.paths)).sum()
    }
}

/// The film footprint of the box `lo`..`hi`: `None` when part of it is not in front of the lens
/// (behind the camera or around it), whose image has no bound.
fn footprint(
    camera: &Camera,
    lo: Vec3,
    hi: Vec3,
    filter_reach: f32,
    pinhole: bool,
) -> Option<Footprint> {
    let mut rect = [
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    ];
    let (mut near, mut far) = (f32::INFINITY, 0.0f32);
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        // `project` refuses points not in front of the lens; a NaN comes out as one.
        let p = camera.project(corner).filter(|p| p.is_finite())?;
        let depth = (corner - camera.eye).dot(camera.forward);
        (near, far) = (near.min(depth), far.max(depth));
        rect = [
            rect[0].min(p.x),
            rect[1].min(p.y),
            rect[2].max(p.x),
            rect[3].max(p.y),
        ];
    }
    // A box wholly in front projects within its corners' projections; through any lens
    // position a point moves at most half its CoC from there, and the CoC over a depth range
    // is largest at one of its ends.
    let blur = if pinhole {
        0.0
    } else {
        0.5 * camera.coc_px(near).max(camera.coc_px(far))
    };
    let grow = blur + filter_reach;
    let reach = [
        rect[0] - grow,
        rect[1] - grow,
        rect[2] + grow,
        rect[3] + grow,
    ];
    reach.iter().all(|v| v.is_finite()).then_some(Footprint {
        sharp_area: (rect[2] - rect[0]) * (rect[3] - rect[1]),
        reach,
    })
}

/// The mean lens weight under `filter` over the camera's aperture distribution (4096 Sobol
/// points), which the camera's weighted mean divides by.
fn lens_weight_mean(camera: &Camera, filter: LensFilter) -> f32 {
    if filter == LensFilter::Box {
        return 1.0;
    }
    const POINTS: u32 = 4096;
    let sampler = PixelSampler::new(SALT, 0);
    let sum: f64 = (0..POINTS)
        .map(|i| {
            let lens = camera.lens.lens_point(sampler.get(i));
            f64::from(camera.lens.weight(filter, lens))
        })
        .sum();
    (sum / f64::from(POINTS)) as f32
}
