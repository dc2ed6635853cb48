//! The `dofray` command's pieces: arguments, the subcommands, what they print, signals.

use anyhow::{Context, Result};
use dofray::embree::Device;
use dofray::overrides::Overrides;
use dofray::params::Param;
use dofray::renderer::{Renderer, RendererError};

use args::SceneArgs;
pub(crate) use progress::{Bar, ProgressMode};

/// Returns a usage error (exit status 2): a flag's value or a combination of flags is wrong.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new(dofray::exit::UsageError(format!($($arg)*))))
    };
}

pub(crate) mod args;
pub(crate) mod bench;
pub(crate) mod progress;
pub(crate) mod render;
pub(crate) mod report;
pub(crate) mod signals;

/// The scene overrides the flags ask for (reading --lens's prescription).
pub(crate) fn overrides(a: &SceneArgs) -> Result<Overrides> {
    // The f-number and sensor width apply to it as to a scene's lens (Overrides).
    let real_lens = match &a.lens {
        Some(path) => Some(dofray::camera::RealLensSpec::load(path)?),
        None => None,
    };
    Ok(Overrides {
        width: a.width,
        height: a.height,
        aperture_radius: a.aperture_radius,
        f_number: a.f_number,
        focal_length_mm: a.focal_length,
        sensor_width_mm: a.sensor_width,
        sharp_range: a.sharp_range.zip(a.spread),
        focus_distance: a.focus_distance,
        autofocus: a.autofocus,
        blades: a.blades,
        blade_rotation_deg: a.blade_rotation,
        anamorphic: a.anamorphic,
        lights: a.lights.clone(),
        ambient: a.ambient,
        real_lens,
    })
}

/// A renderer's error, an override's or a setting's worded for the command line (flag names).
pub(crate) fn cli_error(e: RendererError) -> anyhow::Error {
    match e.param_message(Param::flag) {
        Some(message) => dofray::exit::UsageError(message).into(),
        None => e.into(),
    }
}

/// A scene ready to render with the flags' overrides, and the worker threads to render it on.
pub(crate) struct Prepared {
    pub(crate) renderer: Renderer,
    pub(crate) pool: rayon::ThreadPool,
}

pub(crate) fn prepare(a: &SceneArgs) -> Result<Prepared> {
    let threads = a.threads.map(usize::from);
    // Every worker starts before anything large is allocated (`dofray::workers`).
    let pool = dofray::workers::pool(threads).context("cannot start worker threads")?;
    // Loading and building run on those workers too, never on rayon's global pool, which
    // would start its own threads there.
    pool.install(|| prepare_on(a, threads))
        .map(|renderer| Prepared { renderer, pool })
}

/// [`prepare`]'s scene, loaded and built on the current rayon pool.
fn prepare_on(a: &SceneArgs, threads: Option<usize>) -> Result<Renderer> {
    let defaults = dofray::scene::LoadOptions::default();
    let options = dofray::scene::LoadOptions {
        allow_outside_paths: a.allow_outside_paths,
        max_input_bytes: a
            .max_input_mib
            .map_or(defaults.max_input_bytes, |m| m.saturating_mul(1 << 20)),
        max_texture_bytes: a
            .max_texture_mib
            .map_or(defaults.max_texture_bytes, |m| m.saturating_mul(1 << 20)),
        max_instanced_triangles: a
            .max_instanced_triangles
            .unwrap_or(defaults.max_instanced_triangles),
        ..defaults
    };
    let desc = dofray::scene::load_with(&a.scene, &options)?;
    // Embree's own thread pool (BVH builds) gets the same bound as rayon's.
    let device = match threads {
        Some(n) => Device::with_threads(n),
        None => Device::new(),
    }
    .context("cannot create the Embree device")?;
    let renderer = Renderer::with_overrides(desc, overrides(a)?, &device).map_err(cli_error)?;
    // After the overrides: a lens flag answers the warning about a guessed lens.
    for warning in &renderer.desc().warnings {
        eprintln!("warning: {warning}");
    }
    Ok(renderer)
}
