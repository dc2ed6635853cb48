//! Area lights (Blender's rectangle, disk and sphere lights) as what they physically are:
//! emissive geometry, which the path tracer samples like any emissive mesh or sphere, soft
//! shadows included. Their power is given in watts, as in Blender, and turned into the
//! radiance Cycles gives them: `P / (pi A)` from the front of a rectangle or disk of area A
//! (one-sided Lambertian emitters), `P / (4 pi^2 r^2)` from a sphere of radius r.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::Object;
use crate::embree::{EmbreeError, TriangleMesh};
use crate::shade::{LightObject, Material};

/// Segments of the polygon a disk light is made of (its radiance is set from the polygon's
/// own area, so the power is exact).
pub const DISK_SEGMENTS: usize = 64;

/// The shape of an area light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AreaShape {
    /// A rectangle: `size.x` along the light's right axis, `size.y` along its up axis.
    Rect {
        /// Width and height, scene units.
        size: Vec2,
    },
    /// A disk of radius `radius` (Blender's disk `size` is its diameter).
    Disk {
        /// Radius, scene units.
        radius: f32,
    },
    /// A sphere of radius `radius`, emitting in every direction.
    Sphere {
        /// Radius, scene units.
        radius: f32,
    },
}

/// An area light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaLight {
    /// Its shape.
    pub shape: AreaShape,
    /// Centre, scene units.
    pub position: Vec3,
    /// The way a rectangle or disk emits (its front's normal; need not be unit length).
    pub direction: Vec3,
    /// Which way a rectangle's height runs (projected onto its plane; another axis is used when
    /// it is parallel to `direction`).
    pub up: Vec3,
    /// Radiant power (W) per colour channel: Blender's colour times its power.
    pub power: Vec3,
    /// Camera rays see it (Blender's lights hide from them by default; every other ray sees a
    /// light, and none is shadowed by one: [`LightObject`]).
    pub visible_to_camera: bool,
}

impl AreaLight {
    /// The light's emitting area (for a disk, the polygon's).
    pub fn area(&self) -> f32 {
        match self.shape {
            AreaShape::Rect { size } => size.x * size.y,
            AreaShape::Disk { radius } => {
                let n = DISK_SEGMENTS as f32;
                0.5 * n * radius * radius * (2.0 * PI / n).sin()
            }
            AreaShape::Sphere { radius } => 4.0 * PI * radius * radius,
        }
    }

    /// The radiance it emits (W / m^2 / sr): its power over pi times its area (a sphere's
    /// whole surface emits, a rectangle's or disk's front only).
    pub fn radiance(&self) -> Vec3 {
        self.power / (PI * self.area())
    }

    /// The emissive material: black, emitting [`AreaLight::radiance`], one-sided unless a
    /// sphere, and a light object (no shadow, a back rays pass through).
    pub fn material(&self) -> Material {
        Material {
            emission: self.radiance(),
            one_sided: !matches!(self.shape, AreaShape::Sphere { .. }),
            light: Some(LightObject {
                camera: self.visible_to_camera,
            }),
            ..Material::diffuse(Vec3::ZERO)
        }
    }

    /// The geometry, using material `material`; an error when it is degenerate (zero size or
    /// direction, or not finite).
    pub fn object(&self, material: usize) -> Result<Object, EmbreeError> {
        let (center, n) = (self.position, self.direction.normalize_or_zero());
        let (right, up) = frame(n, self.up);
        let corners: Vec<Vec3> = match self.shape {
            AreaShape::Sphere { radius } => {
                return Ok(Object::Sphere {
                    center,
                    radius,
                    material,
                });
            }
            AreaShape::Rect { size } => {
                let (a, b) = (right * (0.5 * size.x), up * (0.5 * size.y));
                vec![
                    center - a - b,
                    center + a - b,
                    center + a + b,
                    center - a + b,
                ]
            }
            AreaShape::Disk { radius } => (0..DISK_SEGMENTS)
                .map(|i| {
                    let phi = 2.0 * PI * i as f32 / DISK_SEGMENTS as f32;
                    center + (right * phi.cos() + up * phi.sin()) * radius
                })
                .collect(),
        };
        // A fan from the first corner; counter-clockwise about `n`, so the front faces `n`.
        let indices = (1..corners.len() as u32 - 1)
            .map(|i| [0, i, i + 1])
            .collect();
        let mesh = TriangleMesh::new(corners.iter().map(|c| c.to_array()).collect(), indices)?;
        Ok(Object::Mesh {
            mesh,
            materials: super::MeshMaterials::One(material),
        })
    }
}

/// Right and up axes of a plane facing unit `n`, up as close to `up` as the plane allows.
fn frame(n: Vec3, up: Vec3) -> (Vec3, Vec3) {
    let up = up - n * n.dot(up);
    let up = if up.length_squared() > 1e-12 {
        up.normalize()
    } else {
        let (t, _) = crate::shade::basis(n);
        t
    };
    (up.cross(n), up)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_becomes_radiance_over_pi_times_area() {
        let rect = AreaLight {
            shape: AreaShape::Rect {
                size: Vec2::new(2.0, 0.5),
            },
            position: Vec3::ZERO,
            direction: Vec3::NEG_Y,
            up: Vec3::Z,
            power: Vec3::splat(100.0),
            visible_to_camera: true,
        };
        assert!((rect.radiance().x - 100.0 / PI).abs() < 1e-4);
        let sphere = AreaLight {
            shape: AreaShape::Sphere { radius: 0.5 },
            ..rect
        };
        // 4 pi^2 r^2 L = P.
        let l = sphere.radiance().x;
        assert!((4.0 * PI * PI * 0.25 * l - 100.0).abs() < 1e-3, "{l}");
    }

    #[test]
    fn a_rect_faces_its_direction_with_its_size() {
        let light = AreaLight {
            shape: AreaShape::Rect {
                size: Vec2::new(2.0, 1.0),
            },
            position: Vec3::new(0.0, 3.0, 0.0),
            direction: Vec3::NEG_Y,
            up: Vec3::Z,
            power: Vec3::ONE,
            visible_to_camera: true,
        };
        let Object::Mesh { mesh, .. } = light.object(0).unwrap() else {
            panic!("a rect is a mesh")
        };
        for t in 0..mesh.triangle_count() as u32 {
            let n = mesh.face_normal(t);
            assert!(n.normalize().dot(Vec3::NEG_Y) > 0.999, "{n}");
        }
        let area: f32 = (0..2).map(|t| 0.5 * mesh.face_normal(t).length()).sum();
        assert!((area - 2.0).abs() < 1e-5);
        // Height along z (up), width along x.
        let zs = mesh
            .positions()
            .iter()
            .map(|p| p[2].abs())
            .fold(0.0, f32::max);
        assert!((zs - 0.5).abs() < 1e-6);
    }

    #[test]
    fn a_disk_is_a_fan_of_its_polygon_area() {
        let light = AreaLight {
            shape: AreaShape::Disk { radius: 1.0 },
            position: Vec3::ZERO,
            direction: Vec3::X,
            up: Vec3::Y,
            power: Vec3::ONE,
            visible_to_camera: true,
        };
        let Object::Mesh { mesh, .. } = light.object(0).unwrap() else {
            panic!("a disk is a mesh")
        };
        let area: f32 = (0..mesh.triangle_count() as u32)
            .map(|t| 0.5 * mesh.face_normal(t).length())
            .sum();
        assert!((area - light.area()).abs() < 1e-4);
        assert!((light.area() - PI).abs() < 0.01);
    }
}
