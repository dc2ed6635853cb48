//! Scene descriptions (what to render) and the world built from them (Embree geometry plus
//! the materials and lights that shade its hits).

pub mod animation;
pub mod area_light;
pub mod builtin;
pub mod emitters;
pub mod error;
pub mod file;
pub mod gltf;
pub mod input;
pub mod light_tree;
mod mesh_input;
pub mod model;
pub mod obj;
pub mod stacking;
pub mod texture;
mod world;

pub use animation::{Animation, Interpolation};
pub use error::{LoadError, Location};
pub use input::LoadOptions;
pub use world::{SceneError, World};

use glam::Vec3;

use crate::camera::CameraSpec;
use crate::embree::TriangleMesh;
use crate::shade::{Light, Material};

/// Which material each triangle of a mesh uses.
#[derive(Debug, Clone)]
pub enum MeshMaterials {
    /// One material (an index into [`SceneDesc::materials`]) for every triangle.
    One(usize),
    /// A material index (into [`SceneDesc::materials`]) per triangle, in triangle order.
    PerTriangle(Vec<u32>),
}

/// One thing in the scene.
#[derive(Debug, Clone)]
pub enum Object {
    /// A sphere.
    Sphere {
        /// Centre, scene units.
        center: Vec3,
        /// Radius, scene units (> 0).
        radius: f32,
        /// Index into [`SceneDesc::materials`].
        material: usize,
    },
    /// A triangle mesh, in world space.
    Mesh {
        /// The triangles.
        mesh: TriangleMesh,
        /// Which material each triangle uses.
        materials: MeshMaterials,
    },
}

/// The world: the radiance arriving from every direction rays leave the scene in. Rays that hit
/// nothing see it, and the path tracer is lit by it (sampled by importance when it is a map).
/// A sky colour by direction (`horizon` at the horizon blending to `zenith` straight up), or
/// an equirectangular map.
#[derive(Debug, Clone)]
pub struct Background {
    /// Radiance towards the horizon (and below it), linear RGB.
    pub horizon: Vec3,
    /// Radiance straight up, linear RGB.
    pub zenith: Vec3,
    /// An environment map (Blender's Environment Texture), which replaces the sky when given.
    pub map: Option<std::sync::Arc<crate::shade::EnvironmentMap>>,
}

/// Equal colours, and the same map (by identity: maps are not compared texel by texel).
impl PartialEq for Background {
    fn eq(&self, other: &Self) -> bool {
        let same_map = match (&self.map, &other.map) {
            (None, None) => true,
            (Some(a), Some(b)) => std::sync::Arc::ptr_eq(a, b),
            _ => false,
        };
        self.horizon == other.horizon && self.zenith == other.zenith && same_map
    }
}

impl Background {
    /// The same radiance `c` (linear RGB) in every direction.
    pub fn uniform(c: Vec3) -> Self {
        Self {
            horizon: c,
            zenith: c,
            map: None,
        }
    }

    /// Radiance seen along unit direction `dir` (+y up): the map's, else `horizon` at and
    /// below the horizon, blending to `zenith` by the square root of `dir.y`.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match &self.map {
            Some(map) => map.radiance(dir),
            None => self.horizon.lerp(self.zenith, dir.y.clamp(0.0, 1.0).sqrt()),
        }
    }
}

/// A complete description of what to render, independent of Embree.
///
/// ```rust
/// use dofray::camera::{CameraSpec, Focus, LensSpec};
/// use dofray::glam::Vec3;
/// use dofray::scene::{Object, SceneDesc};
/// use dofray::shade::{Light, Material};
/// use dofray::{embree::Device, render::NoProgress, renderer::Renderer};
///
/// let scene = SceneDesc {
///     camera: CameraSpec {
///         width: 64,
///         height: 48,
///         lens: LensSpec::Aperture { radius: 0.2 },
///         focus: Focus::Distance(5.0),
///         ..Default::default()
///     },
///     materials: vec![Material::diffuse(Vec3::new(0.8, 0.2, 0.2))],
///     objects: vec![Object::Sphere { center: Vec3::ZERO, radius: 1.0, material: 0 }],
///     lights: vec![Light::Point { position: Vec3::new(2.0, 4.0, 4.0), intensity: Vec3::splat(50.0) }],
///     ..Default::default()
/// };
/// let renderer = Renderer::new(scene, &Device::new()?)?;
/// let (film, _) = renderer.render(&renderer.settings(&Default::default())?, &NoProgress)?;
/// assert!(film.color[24 * 64 + 32].x > 0.0); // the lit sphere fills the centre
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct SceneDesc {
    /// The scene's name (its `name` key, else the file stem or the built-in's name), for reports.
    pub name: String,
    /// Camera placement and lens.
    pub camera: CameraSpec,
    /// The materials; objects refer to them by index.
    pub materials: Vec<Material>,
    /// What is in the scene (world space).
    pub objects: Vec<Object>,
    /// Lights that cast shadows.
    pub lights: Vec<Light>,
    /// Ambient light (linear RGB), unshadowed: adds albedo x ambient x (1 - mirror) to every
    /// hit.
    pub ambient: Vec3,
    /// What rays that hit nothing see.
    pub background: Background,
    /// The render settings the scene asks for (the command line's flags and the bindings'
    /// keywords go over them: [`crate::render::SettingsPatch::over`]).
    pub settings: crate::settings::SettingsPatch,
    /// What the files the scene was loaded from use but dofray ignores (glTF extensions it
    /// does not implement, light ranges, animations, ...): at most one line per file, naming
    /// the file. Empty for built-in scenes.
    pub warnings: Vec<String>,
    /// When the input gave no lens and dofray chose one (a bare model's): the warning that
    /// says so, also in `warnings`. Overrides that give a lens remove both
    /// ([`crate::overrides::Overrides::apply_scene`]).
    pub lens_guessed: Option<String>,
    /// The camera animation of a scene file's `[animation]` table (None for built-in scenes,
    /// bare models and files without one). `camera` is the `[camera]` table as written; apply
    /// the animation to a copy of it for each frame.
    pub animation: Option<Animation>,
    /// How PNG outputs show the colour (a scene file's `[view]`; plain sRGB by default): the
    /// view transform, look, exposure and gamma of Blender's colour management.
    pub view: crate::view::DisplayView,
}

/// An empty scene named "scene": the default [`CameraSpec`] (a pinhole at (0, 0, 5) looking
/// down -z at the origin, 640 x 480), no materials, objects or lights, ambient 0.1 (a scene
/// file's default), the default sky, and the render settings left to the renderer. Fill in
/// what it needs: `SceneDesc { materials, objects, lights, ..Default::default() }` (a scene
/// without objects does not build: [`SceneError::Empty`]).
impl Default for SceneDesc {
    fn default() -> Self {
        Self {
            name: "scene".into(),
            camera: CameraSpec::default(),
            materials: Vec::new(),
            objects: Vec::new(),
            lights: Vec::new(),
            ambient: Vec3::splat(0.1),
            background: model::default_background(),
            settings: Default::default(),
            warnings: Vec::new(),
            lens_guessed: None,
            animation: None,
            view: Default::default(),
        }
    }
}

/// Loads a scene: a built-in scene by name (see [`builtin::BUILTIN`]), a `.toml` scene file
/// (`docs/scene-format.md`), or a `.obj`, `.gltf` or `.glb` model, which gets the glTF camera if
/// it has one (else a view framing its bounds), a small aperture focused on the bounds' centre,
/// a key light and the default sky. Files are read with the default [`LoadOptions`] (limits
/// and path policy); see [`load_with`].
///
/// ```rust
/// let paper = dofray::scene::load("paper")?;
/// assert_eq!((paper.camera.width, paper.camera.height), (640, 480));
///
/// // A file that cannot be read is an error that names it.
/// let missing = dofray::scene::load("no/such/scene.toml").unwrap_err();
/// assert!(missing.to_string().contains("no/such/scene.toml"), "{missing}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn load(path_or_name: &str) -> Result<SceneDesc, LoadError> {
    load_with(path_or_name, &LoadOptions::default())
}

/// [`load`] with explicit limits and path policy.
pub fn load_with(path_or_name: &str, options: &LoadOptions) -> Result<SceneDesc, LoadError> {
    let path = std::path::Path::new(path_or_name);
    match file::extension(path).as_deref() {
        Some("toml") => file::load(path, options),
        Some("obj" | "gltf" | "glb") => {
            let mut textures = texture::TextureCache::new(*options);
            let model = file::load_model(path, &model::Transform::IDENTITY, &mut textures)?;
            model::model_scene(path, model)
        }
        _ => builtin::builtin(path_or_name).ok_or_else(|| LoadError::UnknownScene {
            name: path_or_name.to_string(),
            builtins: builtin::BUILTIN
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

/// The largest colour, albedo, specular or emission value a scene may give (and pattern scale, and
/// Blinn-Phong exponent): far beyond any real material, small enough that no sum of shading
/// terms can overflow f32.
pub const MAX_MATERIAL_VALUE: f32 = 1e6;
/// The largest light intensity (point) or irradiance (directional).
pub const MAX_LIGHT_VALUE: f32 = 1e12;
