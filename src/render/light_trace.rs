//! Emitters the camera would find only by luck, traced from the light instead (light tracing:
//! the t = 1 strategy of bidirectional path tracing).
//!
//! A lamp much smaller on screen than its blur is the hardest case for a camera-side sampler:
//! a pixel inside its bokeh disc sees it through a fraction (sharp area / disc area) of the
//! aperture, so at 16 samples a 24 px disc of a sub-pixel lamp is a few speckles, and adaptive
//! sites that all miss it lose the disc. From the light's side every path lands in the disc:
//! pick a point where light enters the lens (the thin lens's aperture, a real lens's front
//! element), a direction from it towards the lamp, test that nothing is in between, and the
//! lens says where on the film that ray belongs ([`crate::camera::Lens::film_point`]).
//!
//! Which primitives, and how many paths each takes: [`super::light_choice`].
//!
//! **The split is exact.** For each primitive chosen, the light it sends straight into the
//! lens comes from here alone: camera paths add none of its emission at their first hit
//! ([`LightTraced::contains`]). What reaches the camera after a bounce (its reflection in a
//! window, its light on a wall) stays with the path tracer. Both estimators are unbiased, so is
//! their sum; only the noise moves.
//!
//! **Estimator.** A pixel is `I_p = E_u[ ∫ f(x - c_p) L(x, u) dx ]` over the camera's lens
//! positions `u` and film positions `x` (pixels), `f` the pixel filter's normalised density
//! ([`crate::filter::FilterDensity`]). For one lens position the film area per steradian of
//! ray direction is the lens's `per_sr`, so a direction `w` drawn towards the lamp with
//! density `p(w)` contributes `f(x - c_p) L_e V per_sr / p(w)` to every pixel `p` whose filter
//! reaches `x`; `N` paths each add a `1 / N` share. (A real lens's `per_sr` measures the same
//! from its front element, [`crate::camera::Landing`].) A non-box lens filter weighs each path
//! by its lens weight over the weights' mean, as the camera's weighted mean does.
//!
//! **Deterministic.** Paths are numbered per primitive (Owen-scrambled Sobol points keyed by
//! it), traced in parallel in fixed blocks and splatted in block order: the image is the same
//! for any thread count, and a region gets exactly the splats the full frame gives it.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::light_choice::{LightTraced, SALT, Traced};
use super::region::Region;
use super::site::SiteShader;
use super::trace::{Tally, trace_shadows};
use super::{Progress, RenderError, check_cancelled};
use crate::camera::{Landing, Lens, LensFilter};
use crate::embree::{LANES, RayHint, ShadowPacket16};
use crate::filter::FilterDensity;
use crate::limits::{MemoryError, try_with_capacity};
use crate::sampler::{PixelSampler, hash64};
use crate::scene::emitters::sample_primitive;
use crate::settings::Mode;

/// Light paths per work item.
const BLOCK: u32 = 4096;

/// Light that landed on the film: its position (pixels) and what it adds there.
#[derive(Debug, Clone, Copy)]
pub(super) struct Splat {
    /// Film position, pixels.
    pub(super) film: Vec2,
    /// What it adds to the pixels its filter reaches (weighted by the filter's density).
    pub(super) value: Vec3,
}

/// Traces the light paths of `traced` for the render `shader` describes and adds the light they
/// land on the film to `image`, the full frame's colours (row-major; only `region`'s pixels
/// change): what the camera's paths left out.
pub fn trace(
    shader: &SiteShader,
    traced: &LightTraced,
    region: &Region,
    progress: &dyn Progress,
    tally: &mut Tally,
    image: &mut [Vec3],
) -> Result<(), RenderError> {
    if traced.is_empty() {
        return Ok(());
    }
    // Work items (primitive, first path): only primitives whose light can reach the region.
    // A lens that distorts lands light away from the pinhole footprints: trace it all.
    let exact = !shader.camera.lens.distorts();
    let overlaps = |t: &Traced| {
        !exact
            || t.reach[0] < region.x1 as f32
                && t.reach[2] > region.x0 as f32
                && t.reach[1] < region.y1 as f32
                && t.reach[3] > region.y0 as f32
    };
    let items: Vec<(usize, u32)> = (traced.traced.iter().enumerate())
        .filter(|(_, t)| overlaps(t))
        .flat_map(|(i, t)| (0..t.paths).step_by(BLOCK as usize).map(move |f| (i, f)))
        .collect();
    let block = |&(i, first): &(usize, u32)| trace_block(shader, traced, &traced.traced[i], first);
    splat_blocks(
        shader, "lights", &items, block, region, progress, tally, image,
    )
}

/// Traces the work items `items` with `block` and adds the light they land on the film to
/// `image` (only `region`'s pixels change), in item order whatever the thread count. Batches
/// keep the splats held at once bounded: the items of one batch are traced in parallel while
/// the previous batch is splatted.
#[allow(clippy::too_many_arguments)]
pub(super) fn splat_blocks<I: Sync>(
    shader: &SiteShader,
    name: &str,
    items: &[I],
    block: impl Fn(&I) -> Result<(Vec<Splat>, Tally), MemoryError> + Sync,
    region: &Region,
    progress: &dyn Progress,
    tally: &mut Tally,
    image: &mut [Vec3],
) -> Result<(), RenderError> {
    let w = shader.camera.width as usize;
    progress.start(name, items.len() as u64);
    let density = shader.settings.pixel_filter.density();
    let batch = 8 * rayon::current_num_threads().max(1);
    let trace_batch = |chunk: &[I]| -> Vec<Result<(Vec<Splat>, Tally), MemoryError>> {
        chunk
            .par_iter()
            .map(|item| {
                let out = block(item);
                progress.advance(1);
                out
            })
            .collect()
    };
    let mut splat_batch = |results: Vec<Result<(Vec<Splat>, Tally), MemoryError>>| {
        for result in results {
            let (splats, local) = result?;
            tally.merge(local);
            for s in &splats {
                splat(image, w, region, &density, s);
            }
        }
        Ok::<(), MemoryError>(())
    };
    let mut pending = Vec::new();
    for chunk in items.chunks(batch) {
        check_cancelled(progress)?;
        let (traced, splatted) = rayon::join(
            || trace_batch(chunk),
            || splat_batch(std::mem::take(&mut pending)),
        );
        splatted?;
        pending = traced;
    }
    splat_batch(pending)?;
    check_cancelled(progress)
}

/// Traces paths `first .. first + BLOCK` (at most the primitive's count) of `t`, 16 at a
/// time, and returns the unoccluded ones' splats.
fn trace_block(
    shader: &SiteShader,
    traced: &LightTraced,
    t: &Traced,
    first: u32,
) -> Result<(Vec<Splat>, Tally), MemoryError> {
    let SiteShader {
        world,
        camera,
        settings,
        ..
    } = *shader;
    let mut tally = Tally::new(settings.record_rays);
    let end = first.saturating_add(BLOCK).min(t.paths);
    let mut splats = try_with_capacity((end - first) as usize, "the light paths' splats")?;
    let key = hash64(u64::from(t.geometry) << 32 | u64::from(t.prim));
    let sampler = PixelSampler::new(settings.seed ^ SALT, key);
    let pinhole = settings.mode == Mode::Pinhole;
    let filter = settings.filter;
    // The share of one path, with the exposure the camera's samples get.
    let share = settings.exposure.exp2() / (t.paths as f32 * traced.lens_weight_mean);
    let mut shadow = ShadowPacket16::new();
    for start in (first..end).step_by(LANES) {
        let mut origin = [[0.0f32; LANES]; 3];
        let mut dir = [[0.0f32; LANES]; 3];
        let mut seg_end = [0.0f32; LANES];
        let mut pending = [None; LANES];
        let mut lit = 0u32;
        for (lane, j) in (start..end.min(start + LANES as u32)).enumerate() {
            let entry = if pinhole {
                Vec2::ZERO
            } else {
                camera.lens.entry_point(sampler.get(j))
            };
            let o = camera.entry_origin(entry);
            let Some(es) = sample_primitive(world, t.geometry, t.prim, o, sampler.get_pixel(j))
            else {
                continue;
            };
            let Some(Landing { film, per_sr, lens }) = camera.film_point(entry, es.dir) else {
                continue;
            };
            let lens_weight = if filter == LensFilter::Box {
                1.0
            } else {
                camera.lens.weight(filter, lens)
            };
            let value = es.radiance * (per_sr * lens_weight * share / es.pdf);
            if !(value.max_element() > 0.0 && value.is_finite()) {
                continue;
            }
            for k in 0..3 {
                origin[k][lane] = o[k];
                dir[k][lane] = es.dir[k];
            }
            seg_end[lane] = es.distance * (1.0 - 1e-4);
            pending[lane] = Some(Splat { film, value });
            lit |= 1 << lane;
        }
        if lit == 0 {
            continue;
        }
        let hint = RayHint::Incoherent;
        trace_shadows(
            world,
            &mut shadow,
            lit,
            &origin,
            &dir,
            &seg_end,
            hint,
            &mut tally,
        );
        for (lane, s) in pending.iter().enumerate() {
            if let Some(s) = s
                && shadow.is_active(lane)
                && !shadow.occluded(lane)
            {
                splats.push(*s);
            }
        }
    }
    Ok((splats, tally))
}

/// Adds splat `s` to the pixels of `region` whose filter reaches it, weighted by the filter's
/// density at its offset from each pixel's centre.
fn splat(image: &mut [Vec3], w: usize, region: &Region, density: &FilterDensity, s: &Splat) {
    /// Pixels along one axis a filter of the largest width (16 px) reaches.
    const SPAN: usize = 18;
    let r = density.reach();
    // The pixels whose centres (i + 0.5) are within r of the splat, and their weights.
    let weights = |c: f32, lo: u32, hi: u32| {
        let first = (c - r - 0.5).ceil().max(lo as f32) as i64;
        let last = (c + r - 0.5).floor().min(hi as f32 - 1.0) as i64;
        let mut w = [0.0f32; SPAN];
        let n = (last - first + 1).clamp(0, SPAN as i64) as usize;
        for (k, w) in w.iter_mut().enumerate().take(n) {
            *w = density.at(c - ((first + k as i64) as f32 + 0.5));
        }
        (first, n, w)
    };
    let (x0, nx, wx) = weights(s.film.x, region.x0, region.x1);
    let (y0, ny, wy) = weights(s.film.y, region.y0, region.y1);
    for (j, &wy) in wy.iter().enumerate().take(ny) {
        let row = (y0 + j as i64) as usize * w;
        for (i, &wx) in wx.iter().enumerate().take(nx) {
            if wx * wy > 0.0 {
                image[row + (x0 + i as i64) as usize] += s.value * (wx * wy);
            }
        }
    }
}
