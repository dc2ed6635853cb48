//! Which emitters light tracing ([`super::light_trace`]) takes from the camera, and how many
//! light paths each gets.
//!
//! **Which primitives.** An emissive triangle or sphere whose sharp image (the bounding box of
//! its projected bounds) covers at most a quarter of its blurred footprint (that box grown by
//! half the largest CoC over its depths and the pixel filter's reach): defocused lamps and
//! sub-pixel ones. Each takes `spp` paths per pixel of its footprint in the frame, so its disc
//! converges as a dense render's pixels do (more where a real lens's front element passes only
//! part of them, [`crate::camera::Lens::entry_yield`]). Their landing paths are held to half the
//! samples of a dense render: over it, every lamp's share shrinks alike (a night scene of
//! thousands of distant lamps), down to one path each, and only if even that does not fit are
//! the largest footprints left to the camera. Emitters the camera sees large and sharp are
//! better found by its own rays.
//!
//!
//! The choice depends only on the scene, the camera and the settings, so every region of a
//! render makes the same one.

use std::collections::HashSet;

use glam::Vec3;

use super::glossy_light::GlossyPaths;
use crate::camera::{BoxImage, Camera, Lens, LensFilter};
use crate::embree::GeometryId;
use crate::sampler::PixelSampler;
use crate::scene::World;
use crate::scene::emitters::primitive_bounds;
use crate::settings::{Integrator, Mode, RenderSettings};

/// Keys the light paths' sample streams apart from the camera's.
pub(super) const SALT: u64 = 0x6c69_6768_745f_7472;
/// The most light paths of one primitive.
const MAX_PATHS: u32 = 1 << 24;
/// The least share of landing light paths assumed when choosing how many to trace (a lamp
/// whose centre sends nothing through may still send light from its edges).
const MIN_YIELD: f32 = 1.0 / 16.0;
/// How far the rounding up of shrunk shares may take the paths over the budget.
const BUDGET_SLACK: f64 = 1.5;
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
    /// Lamps (point and spot lights, emitters) whose glossy reflections are traced from the
    /// light too.
    pub(super) glossy: Option<GlossyPaths>,
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
        let pinhole = settings.mode == Mode::Pinhole;
        // A pinhole render of a real lens looks along its chief rays, which light paths
        // through its front element do not follow.
        if settings.integrator != Integrator::Path
            || !settings.path.light_tracing
            || (pinhole && camera.lens.distorts())
        {
            return Self::none();
        }
        let spp = if pinhole { settings.aa } else { settings.spp };
        let filter_reach = 0.5 * settings.pixel_filter.width;
        let (w, h) = (camera.width as f32, camera.height as f32);
        let mut candidates = Vec::new();
        for (geometry, prim) in world.emitters.primitives() {
            // A light hidden from the camera sends nothing straight into the lens.
            let material = world.material_of(GeometryId(geometry), prim);
            if material.light.is_some_and(|l| !l.camera) {
                continue;
            }
            let (lo, hi) = primitive_bounds(world, geometry, prim);
            let Some((image, reach)) = footprint(camera, lo, hi, filter_reach, pinhole) else {
                continue;
            };
            let [x0, y0, x1, y1] = reach;
            let blurred_area = (x1 - x0) * (y1 - y0);
            if image.sharp_area() > SHARP_FRACTION * blurred_area {
                continue;
            }
            // Only what lands in the frame is traced for.
            let in_frame = (x1.min(w) - x0.max(0.0)).max(0.0) * (y1.min(h) - y0.max(0.0)).max(0.0);
            if in_frame <= 0.0 {
                continue;
            }
            // Paths the lens blocks land nowhere: take more so as many land.
            let landing = if pinhole {
                1.0
            } else {
                camera
                    .lens
                    .entry_yield(camera, 0.5 * (lo + hi))
                    .max(MIN_YIELD)
            };
            let paths = (spp as f64 * f64::from(in_frame) / f64::from(landing))
                .ceil()
                .min(f64::from(MAX_PATHS));
            let t = Traced {
                geometry,
                prim,
                paths: paths as u32,
                reach,
            };
            candidates.push((t, landing));
        }
        // The budget counts paths that land: one the lens blocks costs a fraction of a
        // camera sample (no ray leaves the lens). Over it, every lamp's share shrinks alike
        // (a few light paths still find a sub-pixel lamp far more often than camera rays
        // do); the smallest footprints come first while even one path each does not fit.
        let budget = 0.5 * f64::from(w) * f64::from(h) * spp as f64;
        let wanted: f64 = candidates
            .iter()
            .map(|(t, landing)| f64::from(t.paths) * f64::from(*landing))
            .sum();
        let share = if wanted > budget {
            budget / wanted
        } else {
            1.0
        };
        for (t, _) in &mut candidates {
            t.paths = ((f64::from(t.paths) * share).ceil() as u32).max(1);
        }
        candidates.sort_by_key(|(t, _)| (t.paths, t.geometry, t.prim));
        let mut total = 0.0f64;
        let mut traced: Vec<Traced> = candidates
            .into_iter()
            .take_while(|(t, landing)| {
                total += f64::from(t.paths) * f64::from(*landing);
                total <= BUDGET_SLACK * budget
            })
            .map(|(t, _)| t)
            .collect();
        traced.sort_by_key(|t| (t.geometry, t.prim));
        let set = traced.iter().map(|t| (t.geometry, t.prim)).collect();
        let lens_weight_mean = lens_weight_mean(camera, settings.filter);
        Self {
            traced,
            set,
            lens_weight_mean,
            glossy: GlossyPaths::choose(world, camera, settings, lens_weight_mean),
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

    /// The light paths a render traces (small lamps' and glossy reflections').
    pub fn paths(&self) -> u64 {
        let glossy = self.glossy.as_ref().map_or(0, GlossyPaths::paths);
        self.traced.iter().map(|t| u64::from(t.paths)).sum::<u64>() + glossy
    }
}

/// The image of the box `lo`..`hi` and the film rectangle its light can reach (in pinhole mode
/// its sharp image grown by the filter's reach); `None` when it has no bound.
fn footprint(
    camera: &Camera,
    lo: Vec3,
    hi: Vec3,
    filter_reach: f32,
    pinhole: bool,
) -> Option<(BoxImage, [f32; 4])> {
    let image = camera.box_image(lo, hi)?;
    let reach = if pinhole {
        image.grown(filter_reach)?
    } else {
        image.reach(camera, filter_reach)?
    };
    Some((image, reach))
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
