//! What the mesh loaders return, object transforms, and scenes made around a bare model file
//! (a framing camera, a default lens and light).

use std::path::Path;

use glam::{Affine3A, Mat3, Vec3};

use super::error::{LoadError, Location};
use super::{Background, MeshMaterials, Object, SceneDesc};
use crate::camera::{
    ApertureShape, CameraSpec, DEFAULT_HEIGHT, DEFAULT_VFOV, DEFAULT_WIDTH, Focus, LensSpec,
    Photographic,
};
use crate::embree::TriangleMesh;
use crate::shade::{Light, Material};

/// An affine transform for points, with the inverse transpose for normals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// The affine map of points (object to world).
    pub affine: Affine3A,
    /// Inverse transpose of the linear part: transforms normals.
    pub normal: Mat3,
    /// The transform mirrors (negative determinant): triangle winding is reversed.
    pub mirrors: bool,
}

impl Default for Transform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Transform {
    /// The identity: no change.
    pub const IDENTITY: Self = Self {
        affine: Affine3A::IDENTITY,
        normal: Mat3::IDENTITY,
        mirrors: false,
    };

    /// The transform of an affine matrix, or `None` if it is singular or not finite.
    pub fn new(affine: Affine3A) -> Option<Self> {
        let linear = Mat3::from(affine.matrix3);
        let det = linear.determinant();
        if !(det.is_finite() && det != 0.0 && affine.translation.is_finite()) {
            return None;
        }
        let normal = linear.inverse().transpose();
        normal.is_finite().then_some(Self {
            affine,
            normal,
            mirrors: det < 0.0,
        })
    }

    /// Scale, then rotate, then translate: `translate * rotate * scale`.
    pub fn from_srt(scale: Vec3, rotate: Mat3, translate: Vec3) -> Option<Self> {
        Self::new(Affine3A::from_mat3_translation(
            rotate * Mat3::from_diagonal(scale),
            translate,
        ))
    }

    /// `self` applied after `inner` (`self * inner`).
    pub fn after(&self, inner: &Transform) -> Option<Self> {
        Self::new(self.affine * inner.affine)
    }

    /// Transforms a point.
    pub fn point(&self, p: [f32; 3]) -> [f32; 3] {
        self.affine.transform_point3(Vec3::from(p)).to_array()
    }

    /// Transforms a normal by the inverse transpose and normalises it (zero if it degenerates).
    pub fn normal(&self, n: [f32; 3]) -> [f32; 3] {
        (self.normal * Vec3::from(n)).normalize_or_zero().to_array()
    }

    /// Whether the affine part is exactly the identity.
    pub fn is_identity(&self) -> bool {
        self.affine == Affine3A::IDENTITY
    }
}

/// Rotation by Euler angles in degrees about the fixed X, then Y, then Z axes
/// (`Rz * Ry * Rx`).
pub fn euler_xyz_deg(deg: Vec3) -> Mat3 {
    let r = deg * (std::f32::consts::PI / 180.0);
    Mat3::from_rotation_z(r.z) * Mat3::from_rotation_y(r.y) * Mat3::from_rotation_x(r.x)
}

/// A camera found in a model file (glTF), in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelCamera {
    /// Camera position, world space.
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit up direction (the camera's +y; may be zero if degenerate).
    pub up: Vec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub vfov_deg: f32,
    /// Width over height, if the file gives one.
    pub aspect: Option<f32>,
    /// The depth of field the file's custom properties give the camera (glTF has none).
    pub dof: CameraDof,
}

/// Depth of field given to a glTF camera as custom properties (glTF `extras` of the camera or
/// its node; Blender exports a camera's custom properties there with "Include > Custom
/// Properties"): glTF cameras have no aperture or focus of their own. Names and units are the
/// scene file's `[camera]` keys with a `dofray_` prefix: `dofray_f_number`,
/// `dofray_focus_distance` (scene units), `dofray_focal_length_mm`, `dofray_sensor_width_mm`,
/// `dofray_blades`, `dofray_blade_rotation` (degrees), `dofray_anamorphic`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CameraDof {
    /// The f-number (Blender's F-Stop); without it the camera is a pinhole.
    pub f_number: Option<f32>,
    /// Distance in focus along the view axis.
    pub focus_distance: Option<f32>,
    /// Focal length, mm (default: the one that keeps the glTF field of view on the sensor).
    pub focal_length_mm: Option<f32>,
    /// Sensor width, mm (default 36, Blender's).
    pub sensor_width_mm: Option<f32>,
    /// Diaphragm blades (0: round).
    pub blades: Option<u32>,
    /// Rotation of the blades, degrees.
    pub blade_rotation_deg: Option<f32>,
    /// Anamorphic ratio, aperture height over width.
    pub anamorphic: Option<f32>,
}

/// One mesh of a model with the model material it uses (`None`: the default material).
#[derive(Debug, Clone)]
pub struct ModelMesh {
    /// The triangles, in world space.
    pub mesh: TriangleMesh,
    /// Index into [`Model::materials`]; `None` for [`default_material`].
    pub material: Option<usize>,
}

/// What a mesh loader returns: meshes (already transformed), named materials, maybe a camera,
/// the file's lights (glTF KHR_lights_punctual, in world space and dofray's radiometric units)
/// and what the file uses that was ignored.
#[derive(Debug, Clone, Default)]
pub struct Model {
    /// The meshes, transformed into world space.
    pub meshes: Vec<ModelMesh>,
    /// The file's materials with their names; meshes refer to them by index.
    pub materials: Vec<(String, Material)>,
    /// The first perspective camera.
    pub camera: Option<ModelCamera>,
    /// When the file has no perspective camera but an orthographic one: that camera, named
    /// for messages (`camera 0 "Ortho" (node 2)`). dofray renders only perspective views.
    pub orthographic_camera: Option<String>,
    /// The file's lights, world space, radiometric units.
    pub lights: Vec<Light>,
    /// At most one line, naming the file and everything in it dofray ignored.
    pub warnings: Vec<String>,
}

impl Model {
    /// Triangles over all meshes.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.mesh.triangle_count()).sum()
    }
}

/// The material of surfaces that name none: light grey, matte.
pub fn default_material() -> Material {
    Material::diffuse(Vec3::splat(0.8))
}

/// Bounds of one object. They are infinite when the object reaches beyond the f32 range
/// (a sphere whose centre plus radius overflows).
pub fn object_bounds(o: &Object) -> (Vec3, Vec3) {
    match o {
        Object::Sphere { center, radius, .. } => (*center - *radius, *center + *radius),
        Object::Mesh { mesh, .. } => mesh.positions().iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(Vec3::from(*p)), hi.max(Vec3::from(*p))),
        ),
    }
}

/// Bounds of a set of objects (`None` if there are none). They are infinite when an object
/// reaches beyond the f32 range.
pub fn bounds(objects: &[Object]) -> Option<(Vec3, Vec3)> {
    let (lo, hi) = objects.iter().map(object_bounds).fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), (a, b)| (lo.min(a), hi.max(b)),
    );
    lo.cmple(hi).all().then_some((lo, hi))
}

/// A number for messages: plain when moderate (`2.5`), in exponent form when huge or tiny
/// (`3e38`).
pub fn short_number(v: f32) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e7).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A point for messages: `[3e38, 0, 1.5]`.
pub fn short_vec(v: Vec3) -> String {
    let [x, y, z] = v.to_array().map(short_number);
    format!("[{x}, {y}, {z}]")
}

/// [`frame`], or why bounds `(lo, hi)` cannot be framed: the camera distance they need (or
/// the bounds themselves) overflow f32, so no camera built from them could be finite.
pub fn frame_checked(
    lo: Vec3,
    hi: Vec3,
    vfov_deg: f32,
    aspect: f32,
) -> Result<(Vec3, Vec3), String> {
    let (eye, look_at) = frame(lo, hi, vfov_deg, aspect);
    let ok = eye.is_finite()
        && look_at.is_finite()
        && (look_at - eye).length_squared().is_finite()
        && (look_at - eye).length_squared() > 0.0;
    if ok {
        Ok((eye, look_at))
    } else {
        Err(format!(
            "the scene bounds are too large to frame: they span {} to {}, and a camera far \
             enough away to see them all would be beyond the range of 32-bit floats",
            short_vec(lo),
            short_vec(hi)
        ))
    }
}

/// An eye position that frames bounds `(lo, hi)` from the front-right-above (+Z is the front,
/// as in glTF), with vertical field of view `vfov_deg` and aspect `aspect` (width / height).
pub fn frame(lo: Vec3, hi: Vec3, vfov_deg: f32, aspect: f32) -> (Vec3, Vec3) {
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-3);
    let vertical = vfov_deg.to_radians() * 0.5;
    let horizontal = (vertical.tan() * aspect).atan();
    let half = vertical.min(horizontal);
    let distance = radius / half.sin() * 1.05;
    let dir = Vec3::new(0.45, 0.35, 1.0).normalize();
    (center + dir * distance, center)
}

/// A key light from above, behind and to the left of a camera looking along `forward`.
pub fn default_light(forward: Vec3) -> Light {
    let right = forward.cross(Vec3::Y).normalize_or(Vec3::X);
    let direction = (forward * 0.5 + right * 0.35 - Vec3::Y).normalize();
    Light::Directional {
        direction,
        irradiance: Vec3::splat(3.0),
        angle: 0.0,
    }
}

/// The sky of scenes that do not set one (the paper scene's).
pub fn default_background() -> Background {
    Background {
        horizon: Vec3::new(0.375, 0.41, 0.475),
        zenith: Vec3::new(0.15, 0.225, 0.4),
        map: None,
    }
}

/// The radiance of Blender's default world (its Background node's grey 0.05 at strength 1):
/// what a model that brings its own lights is lit by besides them.
pub const BLENDER_WORLD: f32 = 0.05;

/// Default aperture radius for a bare model, as a fraction of its bounds' diagonal.
pub const MODEL_APERTURE_FRACTION: f32 = 0.02;

/// A scene around a model file: the model's meshes and materials, the glTF camera if it has
/// one (else a view framing the model; a file whose only camera is orthographic is refused),
/// a small aperture focused on the bounds' centre, the file's lights (else one key light),
/// and Blender's default world (a model without lights: a key light, some ambient light and
/// the default sky).
pub fn model_scene(path: &Path, model: Model) -> Result<SceneDesc, LoadError> {
    if model.meshes.is_empty() {
        return Err(LoadError::Empty {
            path: path.to_path_buf(),
        });
    }
    let (materials, objects) = objects(model.meshes, model.materials);
    let (lo, hi) = bounds(&objects).ok_or_else(|| LoadError::Empty {
        path: path.to_path_buf(),
    })?;
    check_viewable(
        path,
        model.camera.as_ref(),
        &model.orthographic_camera,
        lo,
        hi,
    )?;
    let center = (lo + hi) * 0.5;
    let diagonal = (hi - lo).length().max(1e-3);
    let dof = model.camera.map(|c| c.dof);
    let View {
        eye,
        look_at,
        up,
        vfov_deg,
        size: (width, height),
    } = view(model.camera, lo, hi);
    // Focus on the bounds' centre when it is in front of the camera, else on the look-at point.
    let focus = if (center - eye).dot(look_at - eye) > 0.0 {
        center
    } else {
        look_at
    };
    let name = path
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    let (lens, focus, aperture, lens_guessed) = match dof {
        Some(dof) => model_lens(path, &dof, vfov_deg, (width, height), focus),
        None => {
            let radius = MODEL_APERTURE_FRACTION * diagonal;
            let warning = format!(
                "{}: no camera; dofray frames the model and guesses a lens: aperture radius \
                 {radius:.3} (2% of the model's size), focused on its centre {:.3} away. Give \
                 --f-number (or --aperture-radius) and --focus-distance (or --autofocus) to \
                 choose the depth of field",
                path.display(),
                (focus - eye).dot((look_at - eye).normalize_or_zero()),
            );
            (
                LensSpec::Aperture { radius },
                Focus::Point(focus),
                ApertureShape::default(),
                Some(warning),
            )
        }
    };
    let mut warnings = model.warnings;
    warnings.extend(lens_guessed.clone());
    Ok(SceneDesc {
        name,
        camera: CameraSpec {
            eye,
            look_at,
            up,
            vfov_deg,
            width,
            height,
            lens,
            focus,
            aperture,
            real_lens: None,
        },
        materials,
        objects,
        // A file with lights was lit by its artist: it gets those and Blender's default world
        // (uniform grey 0.05), as when it is imported into Blender. A file without gets a key
        // light and the default sky.
        ambient: Vec3::splat(if model.lights.is_empty() {
            0.15
        } else {
            BLENDER_WORLD
        }),
        background: if model.lights.is_empty() {
            default_background()
        } else {
            Background::uniform(Vec3::splat(BLENDER_WORLD))
        },
        lights: if model.lights.is_empty() {
            vec![default_light((look_at - eye).normalize_or(Vec3::NEG_Z))]
        } else {
            model.lights
        },
        warnings,
        lens_guessed,
        ..Default::default()
    })
}

/// The lens of a model's own camera: its `dof` properties, else a pinhole (glTF cameras carry
/// no depth of field, and blur nobody asked for is worse than none), with the warning that
/// says so. Focus: `dof`'s distance, else `focus` (the bounds' centre).
fn model_lens(
    path: &Path,
    dof: &CameraDof,
    vfov_deg: f32,
    (width, height): (u32, u32),
    focus: Vec3,
) -> (LensSpec, Focus, ApertureShape, Option<String>) {
    let focus = dof
        .focus_distance
        .map_or(Focus::Point(focus), Focus::Distance);
    let aperture = ApertureShape {
        blades: dof.blades.unwrap_or(0),
        rotation_deg: dof.blade_rotation_deg.unwrap_or(0.0),
        anamorphic: dof.anamorphic.unwrap_or(1.0),
    };
    let Some(n) = dof.f_number else {
        let warning = format!(
            "{}: its camera has no depth of field (glTF cameras carry none): rendering it \
             sharp, as a pinhole. For blur give --f-number and --focus-distance (or \
             --autofocus), set the camera's dofray_f_number and dofray_focus_distance custom \
             properties, or export with dofray's Blender add-on",
            path.display()
        );
        return (LensSpec::Pinhole, focus, aperture, Some(warning));
    };
    let lens = Photographic::keeping_vfov(
        n,
        dof.focal_length_mm,
        dof.sensor_width_mm,
        vfov_deg,
        (width, height),
    );
    (lens.spec(), focus, aperture, None)
}

/// The model's meshes as scene objects, and its materials with the default material last
/// (the one meshes that name none use).
fn objects(
    meshes: Vec<ModelMesh>,
    materials: Vec<(String, Material)>,
) -> (Vec<Material>, Vec<Object>) {
    let mut materials: Vec<Material> = materials.into_iter().map(|(_, m)| m).collect();
    let default = materials.len();
    materials.push(default_material());
    let objects = meshes
        .into_iter()
        .map(|m| Object::Mesh {
            mesh: m.mesh,
            materials: MeshMaterials::One(m.material.unwrap_or(default)),
        })
        .collect();
    (materials, objects)
}

/// Refuses a model no camera can be made for: one whose only camera is orthographic, and
/// bounds `(lo, hi)` too large for f32 to frame (without a camera) or to size the aperture and
/// focus (with one).
fn check_viewable(
    path: &Path,
    camera: Option<&ModelCamera>,
    orthographic: &Option<String>,
    lo: Vec3,
    hi: Vec3,
) -> Result<(), LoadError> {
    let too_large = |message: String| LoadError::Geometry {
        at: Location::file(path),
        message: format!("{message}; scale the model down (a scene file can, with `scale`)"),
    };
    if camera.is_none()
        && let Some(ortho) = orthographic
    {
        return Err(LoadError::Gltf {
            at: Location::file(path),
            message: format!(
                "its only camera, {ortho}, is orthographic, and dofray renders perspective \
                 (thin-lens) views only; add a perspective camera to the file, or include the \
                 model in a TOML scene, which frames it (or takes `[camera]` eye and look_at)"
            ),
        });
    }
    match camera {
        None => {
            frame_checked(
                lo,
                hi,
                DEFAULT_VFOV,
                DEFAULT_WIDTH as f32 / DEFAULT_HEIGHT as f32,
            )
            .map_err(too_large)?;
        }
        Some(_) if !(hi - lo).length().is_finite() => {
            return Err(too_large(format!(
                "the scene bounds are too large: they span {} to {}, beyond the range of \
                 32-bit floats",
                short_vec(lo),
                short_vec(hi)
            )));
        }
        Some(_) => {}
    }
    Ok(())
}

/// Where a bare model is seen from, and the image's size (width, height).
struct View {
    eye: Vec3,
    look_at: Vec3,
    up: Vec3,
    vfov_deg: f32,
    size: (u32, u32),
}

/// The model's own camera looking at the depth of the bounds' centre (with its aspect, when
/// usable), else the default view framing bounds `(lo, hi)`.
fn view(camera: Option<ModelCamera>, lo: Vec3, hi: Vec3) -> View {
    let center = (lo + hi) * 0.5;
    let (mut width, mut height) = (DEFAULT_WIDTH, DEFAULT_HEIGHT);
    let (eye, look_at, up, vfov_deg) = match camera {
        Some(c) => {
            if let Some(aspect) = c.aspect.filter(|a| a.is_finite() && *a > 0.05 && *a < 20.0) {
                width = DEFAULT_WIDTH;
                height = ((DEFAULT_WIDTH as f32 / aspect).round() as u32).max(1);
            }
            let along = (center - c.eye).dot(c.forward);
            // An up along the view direction would give no image plane.
            let up = if c.up.cross(c.forward).length_squared() > 1e-6 {
                c.up
            } else {
                Vec3::Y
            };
            (c.eye, c.eye + c.forward * along.max(1e-3), up, c.vfov_deg)
        }
        None => {
            let (eye, look_at) = frame(lo, hi, DEFAULT_VFOV, width as f32 / height as f32);
            (eye, look_at, Vec3::Y, DEFAULT_VFOV)
        }
    };
    if width == 0 || height == 0 {
        (width, height) = (DEFAULT_WIDTH, DEFAULT_HEIGHT);
    }
    View {
        eye,
        look_at,
        up,
        vfov_deg,
        size: (width, height),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_use_the_inverse_transpose() {
        let t = Transform::from_srt(Vec3::new(2.0, 1.0, 1.0), Mat3::IDENTITY, Vec3::ZERO).unwrap();
        // A 45-degree surface stretched along x gets a normal tilted towards x less.
        let n = Vec3::from(t.normal([1.0, 1.0, 0.0]));
        assert!(
            (n - Vec3::new(0.5, 1.0, 0.0).normalize()).length() < 1e-6,
            "{n}"
        );
        assert!(
            Transform::from_srt(Vec3::new(0.0, 1.0, 1.0), Mat3::IDENTITY, Vec3::ZERO).is_none()
        );
        let m = Transform::from_srt(Vec3::new(-1.0, 1.0, 1.0), Mat3::IDENTITY, Vec3::ZERO).unwrap();
        assert!(m.mirrors);
    }

    #[test]
    fn euler_rotates_x_then_y_then_z() {
        let r = euler_xyz_deg(Vec3::new(90.0, 90.0, 0.0));
        // X first takes +Y to +Z, then Y takes +Z to +X.
        assert!((r * Vec3::Y - Vec3::X).length() < 1e-6);
    }

    #[test]
    fn framing_sees_the_whole_bounds() {
        let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let (eye, look_at) = frame(lo, hi, 40.0, 4.0 / 3.0);
        assert_eq!(look_at, Vec3::ZERO);
        let d = eye.length();
        assert!(d * (20f32).to_radians().sin() >= 3f32.sqrt(), "{d}");
    }
}
