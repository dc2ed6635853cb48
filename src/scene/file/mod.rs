//! The TOML scene format (documented key by key in `docs/scene-format.md`).
//!
//! Every table rejects unknown keys, so a typo is an error rather than a silently ignored
//! setting. Numbers are checked as they are read (finite; sizes and radii > 0; colours >= 0),
//! so errors carry the line, column and key of the offending value.
//!
//! `raw` is the file's shape as serde reads it; the tables become a scene in the order their
//! errors are reported: textures, materials and objects (`objects`), the image size, the camera
//! (`camera`), its animation (`animation`), lights and sky (`lights`), and the render settings.

mod animation;
mod camera;
mod lights;
mod objects;
mod raw;

use std::ops::Range;
use std::path::{Path, PathBuf};

use self::objects::FromModel;
use self::raw::{RawImage, RawRender, RawScene, RawView};
use super::SceneDesc;
use super::error::{LoadError, Location, shown};
use super::input::{self, LoadOptions};
use super::model::{self, Transform};
use super::texture::TextureCache;
use crate::camera::{DEFAULT_HEIGHT, DEFAULT_WIDTH};
use crate::params::Param;
use crate::settings::{RulePatch, SettingsPatch};
use crate::view::{DisplayView, ViewError};

/// The scene file being built: its path and text, for error locations and relative paths.
struct Ctx<'a> {
    path: &'a Path,
    src: &'a str,
    dir: PathBuf,
}

impl Ctx<'_> {
    fn at(&self, span: Range<usize>) -> Location {
        Location::at_offset(self.path, self.src, span.start)
    }

    fn at_key(&self, span: Range<usize>, key: impl Into<String>) -> Location {
        self.at(span).with_key(key)
    }

    fn invalid(
        &self,
        span: Range<usize>,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> LoadError {
        LoadError::invalid(self.at_key(span, key), message)
    }

    fn resolve(&self, file: &str) -> PathBuf {
        self.dir.join(file)
    }
}

/// Loads a TOML scene file.
pub fn load(path: &Path, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let bytes = input::read(path, options)?;
    let src = String::from_utf8(bytes).map_err(|e| {
        let (line, column) = super::error::line_column(
            &String::from_utf8_lossy(e.as_bytes()),
            e.utf8_error().valid_up_to(),
        );
        LoadError::Toml {
            at: Location {
                line: Some(line),
                column: Some(column),
                ..Location::file(path)
            },
            message: "invalid UTF-8 (a TOML file must be UTF-8 text)".into(),
        }
    })?;
    parse_with(&src, path, options)
}

/// Parses a TOML scene from `src`; `path` names it in errors, and relative file names in it
/// resolve against `path`'s directory.
///
/// ```rust
/// use std::path::Path;
///
/// let src = r#"
/// [image]
/// width = 320
/// height = 240
///
/// [camera]
/// eye = [0, 1, 5]
/// look_at = [0, 1, 0]
/// f_number = 2
/// focal_length_mm = 50
/// focus_point = [0, 1, 0]
///
/// [[materials]]
/// name = "red"
/// diffuse = [0.8, 0.1, 0.1]
///
/// [[objects]]
/// type = "sphere"
/// center = [0, 1, 0]
/// radius = 1
/// material = "red"
/// "#;
/// let scene = dofray::scene::file::parse(src, Path::new("memory.toml"))?;
/// assert_eq!(scene.objects.len(), 1);
///
/// // Errors give the file, line and column, and what was expected.
/// let e = dofray::scene::file::parse("[camera]\neye = 3\n", Path::new("bad.toml")).unwrap_err();
/// assert!(e.to_string().starts_with("bad.toml:2:7"), "{e}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn parse(src: &str, path: &Path) -> Result<SceneDesc, LoadError> {
    parse_with(src, path, &LoadOptions::default())
}

/// [`parse`] with explicit limits and path policy for the files the scene refers to.
pub fn parse_with(src: &str, path: &Path, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let raw: RawScene = toml::from_str(src).map_err(|e| {
        let at = match e.span() {
            Some(span) => Location::at_offset(path, src, span.start),
            None => Location::file(path),
        };
        LoadError::Toml {
            at,
            message: e.message().trim().replace('\n', "; "),
        }
    })?;
    let ctx = Ctx {
        path,
        src,
        dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
    };
    build(&ctx, raw, options)
}

/// The scene of a parsed file.
fn build(ctx: &Ctx, raw: RawScene, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let mut cache = TextureCache::new(*options);
    let textures = objects::textures(ctx, raw.textures, &mut cache)?;
    let mut materials = objects::Materials::read(ctx, raw.materials, &textures)?;
    let objects = objects::objects(ctx, raw.objects, &mut materials, &mut cache)?;
    let (width, height) = image_size(ctx, raw.image.as_ref(), objects.camera.as_ref())?;
    // Without a focus key, the focus is on look_at, and follows it when it is animated.
    let focus_on_look_at = !raw.camera.as_ref().is_some_and(|c| {
        let c = c.get_ref();
        c.focus_distance.is_some() || c.focus_point.is_some() || c.focus_pixel.is_some()
    });
    let camera = camera::camera(ctx, raw.camera, width, height, &objects)?;
    let animation = raw
        .animation
        .map(|a| animation::animation(ctx, a, &camera, focus_on_look_at))
        .transpose()?;
    let lights::FileLights { lights, areas } =
        lights::lights(ctx, raw.lights, objects.lights, &camera)?;
    let (mut material_list, mut object_list) = (materials.list, objects.list);
    for (i, area) in &areas {
        material_list.push(area.material());
        let object = area.object(material_list.len() - 1).map_err(|e| {
            ctx.invalid(
                0..0,
                format!("lights[{i}]"),
                format!("the area light is degenerate: {e}"),
            )
        })?;
        object_list.push(object);
    }
    let background = match (raw.world, raw.background) {
        (Some(w), Some(_)) => {
            return Err(ctx.invalid(
                w.span(),
                "world",
                "give either `[world]` or the older `[background]`, not both",
            ));
        }
        (Some(w), None) => lights::world(ctx, w, options)?,
        (None, b) => lights::background(ctx, b)?,
    };
    let settings = render_settings(ctx, raw.render.unwrap_or_default())?;
    let view = raw
        .view
        .map(|v| display_view(ctx, v))
        .transpose()?
        .unwrap_or_default();
    let name = raw.name.unwrap_or_else(|| {
        ctx.path
            .file_stem()
            .map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned())
    });
    Ok(SceneDesc {
        name,
        camera,
        materials: material_list,
        objects: object_list,
        lights,
        ambient: lights::ambient(raw.ambient),
        background,
        settings,
        warnings: objects.warnings,
        lens_guessed: None,
        animation,
        view,
    })
}

/// `[view]`: the view transform and look by Blender's names, exposure and gamma, each
/// checked where it is written.
fn display_view(ctx: &Ctx, raw: RawView) -> Result<DisplayView, LoadError> {
    let mut view = DisplayView::default();
    if let Some(t) = &raw.transform {
        view.view = t
            .get_ref()
            .parse()
            .map_err(|e: ViewError| ctx.invalid(t.span(), "view.transform", e.to_string()))?;
    }
    if let Some(l) = &raw.look {
        view.look = l
            .get_ref()
            .parse()
            .map_err(|e: ViewError| ctx.invalid(l.span(), "view.look", e.to_string()))?;
    }
    if let Some(e) = &raw.exposure {
        view.exposure = *e.get_ref();
    }
    if let Some(g) = &raw.gamma {
        view.gamma = *g.get_ref();
    }
    view.validate().map_err(|e| {
        let (span, key) = match e {
            ViewError::Exposure(_) => (raw.exposure.as_ref().map(|s| s.span()), "view.exposure"),
            ViewError::Gamma(_) => (raw.gamma.as_ref().map(|s| s.span()), "view.gamma"),
            _ => (raw.look.as_ref().map(|s| s.span()), "view.look"),
        };
        ctx.invalid(span.unwrap_or(0..0), key, e.to_string())
    })?;
    Ok(view)
}

/// The image size: `[image]`'s, the height else from a model camera's aspect ratio, else the
/// defaults; refused when its render buffers cannot fit.
fn image_size(
    ctx: &Ctx,
    image: Option<&RawImage>,
    model_camera: Option<&FromModel>,
) -> Result<(u32, u32), LoadError> {
    let width = image
        .and_then(|i| i.width.as_ref())
        .map_or(DEFAULT_WIDTH, |p| p.get_ref().0);
    // A model camera's aspect ratio sets the height when the file gives none.
    let aspect = model_camera
        .and_then(|(c, _, _)| c.aspect)
        .filter(|a| a.is_finite() && *a > 0.05 && *a < 20.0);
    let height = image.and_then(|i| i.height.as_ref()).map_or_else(
        || {
            aspect.map_or(DEFAULT_HEIGHT, |a| {
                ((width as f32 / a).round() as u32).max(1)
            })
        },
        |p| p.get_ref().0,
    );
    // An image whose render buffers cannot fit is refused here, naming the key that asks for
    // it (the larger side's; the command line's --width/--height cannot rescue such a file).
    if let Err(e) = crate::limits::check_image_memory(width, height) {
        let (key, span) = match image.map(|i| (&i.width, &i.height)) {
            Some((Some(w), h)) if h.as_ref().is_none_or(|h| w.get_ref().0 >= h.get_ref().0) => {
                ("image.width", w.span())
            }
            Some((_, Some(h))) => ("image.height", h.span()),
            _ => ("image", 0..0),
        };
        return Err(ctx.invalid(span, key, e.to_string()));
    }
    Ok((width, height))
}

/// The `[render]` table as a settings patch (`tolerance` refused beside the seed's
/// `interval_factor`), checked as the render will check it: a value out of range is an error
/// at its key, worded from the parameter table as every front end words it.
fn render_settings(ctx: &Ctx, render: RawRender) -> Result<SettingsPatch, LoadError> {
    let rule = match (&render.tolerance, &render.interval_factor) {
        (Some(t), Some(_)) => {
            return Err(ctx.invalid(
                t.span(),
                "render.tolerance",
                "either `tolerance` (the error-controlled rule) or `interval_factor` (the \
                 seed's fixed rule), not both",
            ));
        }
        (Some(t), None) => Some(RulePatch::ErrorControlled {
            tolerance: Some(t.get_ref().0),
        }),
        (None, Some(k)) => Some(RulePatch::Seed {
            interval_factor: Some(k.get_ref().0),
            paper_exact: false,
        }),
        (None, None) => None,
    };
    let patch = SettingsPatch {
        spp: render.spp.as_ref().map(|s| s.get_ref().0),
        aa: render.aa.as_ref().map(|s| s.get_ref().0),
        pixel_filter: render.pixel_filter,
        pixel_filter_width: render.pixel_filter_width.as_ref().map(|w| w.get_ref().0),
        rule,
        transparent: render.transparent.unwrap_or(false),
        integrator: render.integrator,
        max_bounces: render.max_bounces.as_ref().map(|s| *s.get_ref()),
        diffuse_bounces: render.diffuse_bounces.as_ref().map(|s| *s.get_ref()),
        glossy_bounces: render.glossy_bounces.as_ref().map(|s| *s.get_ref()),
        transmission_bounces: render.transmission_bounces.as_ref().map(|s| *s.get_ref()),
        clamp_indirect: render.clamp_indirect.as_ref().map(|s| s.get_ref().0),
        filter_glossy: render.filter_glossy.as_ref().map(|s| *s.get_ref()),
        light_tracing: render.light_tracing,
        reuse: render.reuse,
        ..Default::default()
    };
    if let Err(e) = patch.resolve() {
        let span = match e.param() {
            Param::Spp => render.spp.map(|s| s.span()),
            Param::Aa => render.aa.map(|s| s.span()),
            Param::PixelFilterWidth => render.pixel_filter_width.map(|s| s.span()),
            Param::Tolerance => render.tolerance.map(|s| s.span()),
            Param::IntervalFactor => render.interval_factor.map(|s| s.span()),
            Param::MaxBounces => render.max_bounces.map(|s| s.span()),
            Param::DiffuseBounces => render.diffuse_bounces.map(|s| s.span()),
            Param::GlossyBounces => render.glossy_bounces.map(|s| s.span()),
            Param::TransmissionBounces => render.transmission_bounces.map(|s| s.span()),
            Param::FilterGlossy => render.filter_glossy.as_ref().map(|s| s.span()),
            _ => None,
        };
        let at = ctx.at(span.unwrap_or(0..0));
        return Err(LoadError::invalid(at, e.message(Param::key_name)));
    }
    Ok(patch)
}

/// Loads a mesh file by its extension (`UnknownScene` when the extension is not a mesh's).
pub fn load_model(
    path: &Path,
    transform: &Transform,
    textures: &mut TextureCache,
) -> Result<model::Model, LoadError> {
    match extension(path).as_deref() {
        Some("obj") => super::obj::load(path, transform, textures),
        Some("gltf" | "glb") => super::gltf::load(path, transform, textures),
        _ => Err(LoadError::UnknownScene {
            name: shown(path),
            builtins: String::new(),
        }),
    }
}

/// A path's extension, lower-cased.
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}
