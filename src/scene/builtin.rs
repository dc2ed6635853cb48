//! Scenes built into dofray. `paper` is the seed's canonical scene and the default.

use glam::Vec3;

use crate::camera::{ApertureShape, CameraSpec, Focus, LensSpec};
use crate::embree::TriangleMesh;
use crate::shade::{Light, Material, Pattern, Texture};

use super::{Background, MeshMaterials, Object, SceneDesc};

/// Names and one-line descriptions of the built-in scenes.
pub const BUILTIN: &[(&str, &str)] = &[(
    "paper",
    "the seed's scene: five textured spheres on a checkered ground, focused on the 4th (default)",
)];

/// A built-in scene by name.
pub fn builtin(name: &str) -> Option<SceneDesc> {
    match name {
        "paper" => Some(paper()),
        _ => None,
    }
}

/// Centre of the paper scene's sphere `i` (0 = front).
pub fn paper_sphere_center(i: usize) -> Vec3 {
    let i = i as f32;
    Vec3::new(-1.6 + 0.8 * i, 0.5, -1.0 + 2.5 * i)
}

/// The canonical scene of DESIGN.md: five spheres of radius 0.5 with different high-frequency
/// textures at equal spacing, a 60 x 60 m ground with a 1 m checker, a point light with
/// shadows, and a thin lens of radius 0.2 focused on the plane through the 4th sphere's centre.
pub fn paper() -> SceneDesc {
    let eye = Vec3::new(0.0, 1.2, -6.0);
    let look_at = Vec3::new(0.0, 0.5, 4.0);
    let proc = |pattern, a: [f32; 3], b: [f32; 3], scale| Material {
        base_color: Texture::Procedural {
            pattern,
            a: Vec3::from(a),
            b: Vec3::from(b),
            scale,
        },
        roughness: 0.45,
        ior: 1.5,
        ..Material::diffuse(Vec3::ZERO)
    };
    let materials = vec![
        proc(Pattern::Checker, [0.85, 0.1, 0.08], [0.95, 0.9, 0.8], 12.0),
        proc(Pattern::Stripes, [0.1, 0.25, 0.8], [0.9, 0.85, 0.2], 16.0),
        proc(Pattern::Grid, [0.95, 0.95, 0.95], [0.05, 0.45, 0.1], 10.0),
        proc(Pattern::Dots, [0.9, 0.55, 0.1], [0.15, 0.05, 0.3], 12.0),
        proc(Pattern::Marble, [0.9, 0.88, 0.82], [0.25, 0.2, 0.35], 2.0),
        Material {
            base_color: Texture::Procedural {
                pattern: Pattern::Checker,
                a: Vec3::splat(0.8),
                b: Vec3::splat(0.12),
                scale: 1.0,
            },
            ior: 1.5,
            ..Material::diffuse(Vec3::ZERO)
        },
    ];
    let mut objects: Vec<Object> = (0..5)
        .map(|i| Object::Sphere {
            center: paper_sphere_center(i),
            radius: 0.5,
            material: i,
        })
        .collect();
    // Ground quad at y = 0, 60 x 60 m around (0, 0, 4); UVs in metres for a 1 m checker. It is
    // flat, so Embree's geometric normal serves for shading (no per-vertex normals).
    let (cx, cz, h) = (0.0f32, 4.0f32, 30.0f32);
    let corners = [
        [cx - h, cz - h],
        [cx + h, cz - h],
        [cx + h, cz + h],
        [cx - h, cz + h],
    ];
    let ground = TriangleMesh::new(
        corners.iter().map(|&[x, z]| [x, 0.0, z]).collect(),
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .and_then(|m| m.with_uvs(corners.to_vec()))
    .expect("the built-in ground quad is valid");
    objects.push(Object::Mesh {
        mesh: ground,
        materials: MeshMaterials::One(5),
    });
    // Focus on the plane through the 4th sphere's centre, measured along the view axis.
    let forward = (look_at - eye).normalize();
    let focus_distance = (paper_sphere_center(3) - eye).dot(forward);
    SceneDesc {
        name: "paper".into(),
        camera: CameraSpec {
            eye,
            look_at,
            up: Vec3::Y,
            vfov_deg: 40.0,
            width: 640,
            height: 480,
            lens: LensSpec::Aperture { radius: 0.2 },
            focus: Focus::Distance(focus_distance),
            aperture: ApertureShape::default(),
            real_lens: None,
        },
        materials,
        objects,
        lights: vec![Light::Point {
            position: Vec3::new(-4.0, 8.0, -4.0),
            intensity: Vec3::splat(345.6),
        }],
        ambient: Vec3::splat(0.12),
        background: Background {
            horizon: Vec3::new(0.375, 0.41, 0.475),
            zenith: Vec3::new(0.15, 0.225, 0.4),
            map: None,
        },
        ..Default::default()
    }
}
