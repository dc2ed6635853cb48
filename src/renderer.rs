//! [`Renderer`]: a scene with its overrides and its Embree world, ready to render any frame.

use crate::camera::{Camera, CameraError, CameraSpec, Focus};
use crate::embree::Device;
use crate::error_kind::{ErrorKind, HasKind};
use crate::limits::MemoryError;
use crate::overrides::{OverrideError, Overrides};
use crate::params::Param;
use crate::render::{
    self, Film, Progress, Region, RenderError, RenderSettings, RenderStats, SettingsPatch,
};
use crate::scene::{LoadError, SceneDesc, SceneError, World};

/// Why a [`Renderer`] could not be made or could not render. Its [`HasKind`] kind is the
/// command line's: overrides (and a camera they made invalid) are usage errors, the scene's
/// own faults bad input, memory a resource limit.
#[derive(Debug, thiserror::Error)]
pub enum RendererError {
    /// The scene file or model could not be read or parsed.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The scene's description cannot be built into an Embree world.
    #[error("scene {name}")]
    Scene {
        /// The scene's name.
        name: String,
        /// What is wrong with it.
        #[source]
        source: SceneError,
    },
    /// An override has a value it cannot take.
    #[error(transparent)]
    Override(#[from] OverrideError),
    /// The image would need more memory than dofray allows itself.
    #[error(transparent)]
    Memory(#[from] MemoryError),
    /// The camera cannot be built.
    #[error("invalid camera")]
    Camera {
        /// Why.
        #[source]
        source: CameraError,
        /// Whether the overrides set its lens, focus or aperture (then it is a usage error).
        overridden: bool,
    },
    /// The scene's autofocus pixel, moved to a new image size, sees no surface.
    #[error(
        "invalid camera: the scene's autofocus pixel ({x0}, {y0}) of its {w0}x{h0} image (({x}, \
         {y}) at {width}x{height}) sees no surface to focus on"
    )]
    ScaledFocusPixelMisses {
        /// The scene's autofocus pixel, column.
        x0: u32,
        /// The scene's autofocus pixel, row.
        y0: u32,
        /// The scene's image width.
        w0: u32,
        /// The scene's image height.
        h0: u32,
        /// The pixel moved to the new size, column.
        x: u32,
        /// The pixel moved to the new size, row.
        y: u32,
        /// The new image width.
        width: u32,
        /// The new image height.
        height: u32,
    },
    /// The settings are invalid, or the render was cancelled ([`RenderError::Cancelled`]).
    #[error(transparent)]
    Render(#[from] RenderError),
}

impl RendererError {
    /// For an override or a setting out of range, its message with the parameter called
    /// `name(param)` (a front end's name for it: [`Param::flag`], [`Param::keyword_name`],
    /// ...); `None` for any other error.
    pub fn param_message(&self, name: impl Fn(Param) -> &'static str) -> Option<String> {
        match self {
            Self::Override(e) => Some(e.message(name)),
            Self::Render(RenderError::Setting(e)) => Some(e.message(name)),
            _ => None,
        }
    }
}

/// A scene ready to render: its description with the [`Overrides`] applied, the camera as the
/// scene gave it (each frame's camera is made from it), and the Embree world, built once.
///
/// ```rust
/// use dofray::embree::Device;
/// use dofray::overrides::Overrides;
/// use dofray::render::SettingsPatch;
/// use dofray::{render::NoProgress, renderer::Renderer};
///
/// let desc = dofray::scene::load("paper")?;
/// let (width, height, f_number) = (Some(64), Some(48), Some(2.8));
/// let overrides = Overrides { width, height, f_number, ..Default::default() };
/// let renderer = Renderer::with_overrides(desc, overrides, &Device::new()?)?;
/// let settings = renderer.settings(&SettingsPatch { spp: Some(32), ..Default::default() })?;
/// let (film, stats) = renderer.render(&settings, &NoProgress)?;
/// let path = std::env::temp_dir().join("dofray-doc-example.png");
/// dofray::output::write_film(&path, &film)?;
/// assert_eq!((film.width, film.height), (64, 48));
/// println!("{} rays in {:.2} s", stats.rays.total(), stats.seconds);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Renderer {
    desc: SceneDesc,
    base_camera: CameraSpec,
    overrides: Overrides,
    world: World,
}

impl Renderer {
    /// The scene as it is, on `device`.
    pub fn new(desc: SceneDesc, device: &Device) -> Result<Self, RendererError> {
        Self::with_overrides(desc, Overrides::default(), device)
    }

    /// The scene with `overrides` (checked before anything is built), on `device`.
    pub fn with_overrides(
        mut desc: SceneDesc,
        overrides: Overrides,
        device: &Device,
    ) -> Result<Self, RendererError> {
        let base_camera = desc.camera.clone();
        overrides.apply_scene(&mut desc)?;
        crate::limits::check_image_memory(desc.camera.width, desc.camera.height)?;
        let world = World::build(&desc, device).map_err(|source| match source {
            // Not the scene's fault: the memory its lights' distribution needs.
            SceneError::Memory(e) => RendererError::Memory(*e),
            source => RendererError::Scene {
                name: desc.name.clone(),
                source,
            },
        })?;
        Ok(Self {
            desc,
            base_camera,
            overrides,
            world,
        })
    }

    /// The scene with the overrides applied (its camera: the first frame's).
    pub fn desc(&self) -> &SceneDesc {
        &self.desc
    }

    /// The Embree world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The overrides.
    pub fn overrides(&self) -> &Overrides {
        &self.overrides
    }

    /// The camera at `frame` (the scene's animation evaluated there; `None`: the animation's
    /// first frame), with the overrides on top; autofocus looks into the world.
    pub fn camera(&self, frame: Option<i64>) -> Result<Camera, RendererError> {
        let mut spec = self.base_camera.clone();
        if let Some(animation) = &self.desc.animation {
            let frame = frame.unwrap_or(*animation.frames().start());
            animation.apply(&mut spec, frame as f64);
        }
        // The scene's own autofocus pixel and size, for messages after a new size moved it.
        let scene_focus = (spec.focus, spec.width, spec.height);
        self.overrides.apply_camera(&mut spec)?;
        crate::limits::check_image_memory(spec.width, spec.height)?;
        let forward = (spec.look_at - spec.eye).normalize_or_zero();
        let world = &self.world;
        spec.build(|ray| {
            world
                .scene
                .intersect1(ray)
                .map(|hit| (ray.at(hit.t) - ray.origin).dot(forward))
        })
        .map_err(|e| match (e, scene_focus) {
            (CameraError::FocusPixelMisses { x, y }, (Focus::Pixel { x: x0, y: y0 }, w0, h0))
                if (x, y) != (x0, y0) =>
            {
                RendererError::ScaledFocusPixelMisses {
                    x0,
                    y0,
                    w0,
                    h0,
                    x,
                    y,
                    width: spec.width,
                    height: spec.height,
                }
            }
            (source, _) => RendererError::Camera {
                source,
                overridden: self.overrides.lens_given(),
            },
        })
    }

    /// The render settings for this scene: each value from `patch`, else the scene's, else
    /// the default ([`SettingsPatch::over`] the scene's, [`SettingsPatch::resolve`]d).
    pub fn settings(&self, patch: &SettingsPatch) -> Result<RenderSettings, RendererError> {
        let settings = patch.over(&self.desc.settings).resolve();
        Ok(settings.map_err(RenderError::from)?)
    }

    /// Renders the whole image (the first frame of an animated scene).
    pub fn render(
        &self,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<(Film, RenderStats), RendererError> {
        self.render_frame(None, None, settings, progress)
    }

    /// Renders `region` (`None`: the whole image) of `frame` ([`Renderer::camera`]). A region's
    /// pixels are bit for bit those of the whole image's render; the film covers the region only.
    ///
    /// ```rust
    /// use dofray::render::{CancelFlag, Region};
    /// use dofray::{embree::Device, overrides::Overrides, renderer::Renderer};
    ///
    /// let overrides = Overrides { width: Some(96), ..Default::default() };
    /// let renderer = Renderer::with_overrides(dofray::scene::load("paper")?, overrides, &Device::new()?)?;
    /// let settings = renderer.settings(&Default::default())?;
    /// let window = Region { x0: 32, y0: 16, x1: 64, y1: 48 };
    /// let cancel = CancelFlag::new(); // cancel() it from another thread to stop the render
    /// let (tile, _) = renderer.render_frame(None, Some(&window), &settings, &cancel)?;
    /// assert_eq!((tile.width, tile.height), (32, 32));
    ///
    /// cancel.cancel();
    /// let stopped = renderer.render_frame(None, None, &settings, &cancel);
    /// assert!(matches!(
    ///     stopped,
    ///     Err(dofray::renderer::RendererError::Render(dofray::render::RenderError::Cancelled))
    /// ));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn render_frame(
        &self,
        frame: Option<i64>,
        region: Option<&Region>,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<(Film, RenderStats), RendererError> {
        let camera = self.camera(frame)?;
        let full = Region::full(camera.width, camera.height);
        Ok(render::render_region(
            &self.world,
            &camera,
            settings,
            region.unwrap_or(&full),
            progress,
        )?)
    }
}

impl HasKind for RendererError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Load(e) => e.kind(),
            Self::Scene { source, .. } => source.kind(),
            Self::Override(e) => e.kind(),
            Self::Memory(e) => e.kind(),
            // The caller asked for this camera.
            Self::Camera {
                overridden: true, ..
            } => ErrorKind::Usage,
            Self::Camera { .. } | Self::ScaledFocusPixelMisses { .. } => ErrorKind::BadInput,
            Self::Render(e) => e.kind(),
        }
    }
}
