//! Blur the depth pass cannot see.
//!
//! The depth pass sends one ray through each pixel centre, so a primitive whose sharp image
//! holds no pixel centre (a sub-pixel sphere, a wire, a distant glint) leaves no trace in the
//! CoC map. Defocused, it still spreads its light over a disc of its CoC, and sites chosen from
//! the CoC map alone step over that disc: alone on black, a bright sphere 0.6 px across blurred
//! to 24 px kept 9% of its energy in adaptive mode. This map bounds, per tile of
//! [`TILE`] x [`TILE`] pixels, the sharpest and the widest blur of any such primitive whose light
//! can reach the tile, from the scene's geometry (its bounds through the lens, not rays), so the
//! site rule treats the tile as if the depth pass had seen it there
//! ([`super::maps::Blur::with_unseen`]).
//!
//! **Which primitives.** A disc of radius sqrt(2) / 2 px always holds a pixel centre, so a
//! triangle whose projected incircle is at least that wide, or a sphere whose image is, is seen.
//! The others are bounded piece by piece: a long thin triangle (a wire, a sliver of a mesh) is
//! split until each piece's image fits in a tile, so each piece's blur range is local to it.
//! Primitives that light tracing takes from the camera ([`super::LightTraced`]) and primitives
//! not wholly in front of the lens (whose blur near the lens has no bound) are left out.
//!
//! The map depends only on the scene and the camera, so every region makes the same one.

use glam::Vec3;
use rayon::prelude::*;

use super::LightTraced;
use crate::camera::{BoxImage, Camera};
use crate::embree::Geometry;
use crate::limits::{MemoryError, try_vec};
use crate::scene::World;

/// Tile size of the map, pixels.
pub const TILE: usize = 8;
/// A disc of this radius (pixels) always holds a pixel centre.
const SEEN_RADIUS: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// The most halvings of one triangle (a piece per tile of a 2^16-tile-long sliver).
const MAX_SPLITS: u32 = 16;

/// Per tile, the sharpest and widest blur (CoC, pixels) of primitives the depth pass may miss.
#[derive(Debug, Clone)]
pub struct UnseenBlur {
    tiles_x: usize,
    tiles_y: usize,
    /// Smallest CoC reaching the tile; infinite where none does.
    sharpest: Vec<f32>,
    /// Largest CoC reaching the tile; 0 where none does.
    widest: Vec<f32>,
}

impl UnseenBlur {
    /// No unseen primitive anywhere in a `width` x `height` image.
    pub fn none(width: usize, height: usize) -> Result<Self, MemoryError> {
        let (tiles_x, tiles_y) = (width.div_ceil(TILE), height.div_ceil(TILE));
        Ok(Self {
            tiles_x,
            tiles_y,
            sharpest: try_vec(tiles_x * tiles_y, f32::INFINITY, "the unseen-blur map")?,
            widest: try_vec(tiles_x * tiles_y, 0.0, "the unseen-blur map")?,
        })
    }

    /// The map of `world`'s primitives the depth pass (whose depths are `depth`) may miss,
    /// seen through `camera`, their light reaching `margin` pixels further (the pixel filter's
    /// reach). `light_traced` primitives are left out.
    pub fn of(
        world: &World,
        camera: &Camera,
        depth: &[f32],
        margin: f32,
        light_traced: &LightTraced,
    ) -> Result<Self, MemoryError> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let empty = Self::none(w, h)?;
        let probe = Probe {
            camera,
            depth,
            margin,
        };
        // One pass over every primitive of every geometry, so a scene of many small
        // geometries does not pay a map per geometry.
        let primitives =
            world
                .scene
                .geometries()
                .par_iter()
                .enumerate()
                .flat_map(|(g, geometry)| {
                    let count = match geometry {
                        Geometry::Mesh(m) => m.triangle_count(),
                        Geometry::Spheres(s) => s.len(),
                    };
                    (0..count as u32)
                        .into_par_iter()
                        .map(move |prim| (g as u32, geometry, prim))
                });
        let out = primitives
            .filter(|&(g, _, prim)| !light_traced.contains(g, prim))
            .fold(
                || empty.clone(),
                |mut map, (_, geometry, prim)| {
                    map.add_primitive(&probe, geometry, prim);
                    map
                },
            )
            .reduce(|| empty.clone(), Self::merged);
        Ok(out)
    }

    /// The smallest CoC of an unseen primitive whose light may reach pixel (x, y); infinite
    /// where none does.
    pub fn sharpest(&self, x: usize, y: usize) -> f32 {
        self.sharpest[self.tile(x, y)]
    }

    /// The largest CoC of an unseen primitive whose light may reach pixel (x, y); 0 where none
    /// does.
    pub fn widest(&self, x: usize, y: usize) -> f32 {
        self.widest[self.tile(x, y)]
    }

    fn tile(&self, x: usize, y: usize) -> usize {
        (y / TILE).min(self.tiles_y - 1) * self.tiles_x + (x / TILE).min(self.tiles_x - 1)
    }

    fn merged(mut self, other: Self) -> Self {
        for (a, b) in self.sharpest.iter_mut().zip(other.sharpest) {
            *a = a.min(b);
        }
        for (a, b) in self.widest.iter_mut().zip(other.widest) {
            *a = a.max(b);
        }
        self
    }

    fn add_primitive(&mut self, probe: &Probe, geometry: &Geometry, prim: u32) {
        let camera = probe.camera;
        match geometry {
            Geometry::Mesh(m) => {
                let corners =
                    m.indices()[prim as usize].map(|v| Vec3::from(m.positions()[v as usize]));
                if !triangle_seen(camera, corners) {
                    self.add_triangle(probe, corners, MAX_SPLITS);
                }
            }
            Geometry::Spheres(s) => {
                let (centre, r) = (s.center(prim), s.radius(prim));
                // The image of a sphere at distance d holds a disc of radius k r / d (more off
                // the axis, where the image stretches).
                let d = (centre - camera.eye).length();
                if camera.pixels_per_unit() * r < SEEN_RADIUS * d
                    && let Some(image) = camera.box_image(centre - r, centre + r)
                {
                    self.add_image(probe, &image);
                }
            }
        }
    }

    /// Adds triangle `t`, halved along its longest edge until its image fits in a tile.
    fn add_triangle(&mut self, probe: &Probe, t: [Vec3; 3], splits: u32) {
        let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
        let Some(image) = probe.camera.box_image(lo, hi) else {
            return;
        };
        let [x0, y0, x1, y1] = image.sharp;
        if splits == 0 || (x1 - x0).max(y1 - y0) <= TILE as f32 {
            self.add_image(probe, &image);
            return;
        }
        // Pieces whose light cannot reach the frame are dropped.
        if probe.reach_in_frame(&image).is_none() {
            return;
        }
        let longest = (0..3)
            .max_by(|&a, &b| {
                let edge = |i: usize| (t[(i + 1) % 3] - t[i]).length_squared();
                edge(a).total_cmp(&edge(b))
            })
            .unwrap_or(0);
        let (a, b, c) = (t[longest], t[(longest + 1) % 3], t[(longest + 2) % 3]);
        let mid = 0.5 * (a + b);
        self.add_triangle(probe, [a, mid, c], splits - 1);
        self.add_triangle(probe, [mid, b, c], splits - 1);
    }

    /// Marks the tiles the light of the box whose image is `image` may reach with its blur
    /// range, unless the depth pass saw a surface at its depths where it lies.
    fn add_image(&mut self, probe: &Probe, image: &BoxImage) {
        let camera = probe.camera;
        if probe.saw_surface_at(image) {
            return;
        }
        let Some([x0, y0, x1, y1]) = probe.reach_in_frame(image) else {
            return;
        };
        let tile = |v: f32, n: usize| ((v.max(0.0) as usize) / TILE).min(n - 1);
        let (tx0, tx1) = (tile(x0, self.tiles_x), tile(x1, self.tiles_x));
        let (ty0, ty1) = (tile(y0, self.tiles_y), tile(y1, self.tiles_y));
        let (sharpest, widest) = (image.min_coc(camera), image.max_coc(camera));
        for ty in ty0..=ty1 {
            for t in ty * self.tiles_x + tx0..=ty * self.tiles_x + tx1 {
                self.sharpest[t] = self.sharpest[t].min(sharpest);
                self.widest[t] = self.widest[t].max(widest);
            }
        }
    }
}

/// What deciding whether the depth pass saw a primitive takes.
struct Probe<'a> {
    camera: &'a Camera,
    /// The depth pass's depths (view axis; infinite for a miss).
    depth: &'a [f32],
    /// How much further than its blur a primitive's light reaches (the pixel filter).
    margin: f32,
}

impl Probe<'_> {
    /// Relative depth slack of [`Probe::saw_surface_at`].
    const SLACK: f32 = 0.02;

    /// The film rectangle the light of the box whose image is `image` can reach, if it
    /// overlaps the frame.
    fn reach_in_frame(&self, image: &BoxImage) -> Option<[f32; 4]> {
        let reach @ [x0, y0, x1, y1] = image.reach(self.camera, self.margin)?;
        let (w, h) = (self.camera.width as f32, self.camera.height as f32);
        (x1 >= 0.0 && y1 >= 0.0 && x0 < w && y0 < h).then_some(reach)
    }

    /// Whether a depth-pass ray within a pixel of the centre of `image` found a surface at the
    /// box's depths: then the box is part of a surface the CoC map holds there (a small
    /// triangle of a fine mesh, a sliver between larger ones), whose blur the site rule
    /// already reads. A sub-pixel object in front of or behind what the pass saw is unseen.
    fn saw_surface_at(&self, image: &BoxImage) -> bool {
        let (w, h) = (self.camera.width as i64, self.camera.height as i64);
        let cx = (0.5 * (image.sharp[0] + image.sharp[2])).floor() as i64;
        let cy = (0.5 * (image.sharp[1] + image.sharp[3])).floor() as i64;
        let (near, far) = (
            image.near * (1.0 - Self::SLACK),
            image.far * (1.0 + Self::SLACK),
        );
        (cy - 1..=cy + 1)
            .filter(|y| (0..h).contains(y))
            .flat_map(|y| (cx - 1..=cx + 1).map(move |x| (x, y)))
            .filter(|(x, _)| (0..w).contains(x))
            .any(|(x, y)| (near..=far).contains(&self.depth[(y * w + x) as usize]))
    }
}

/// Whether the image of triangle `t` through the lens centre surely holds a pixel centre (its
/// incircle is at least [`SEEN_RADIUS`] wide). False for triangles not wholly in front.
fn triangle_seen(camera: &Camera, t: [Vec3; 3]) -> bool {
    let (Some(a), Some(b), Some(c)) = (
        camera.project(t[0]),
        camera.project(t[1]),
        camera.project(t[2]),
    ) else {
        return false;
    };
    let area2 = (b - a).perp_dot(c - a).abs();
    let perimeter = (b - a).length() + (c - b).length() + (a - c).length();
    // Inradius = 2 area / perimeter = area2 / perimeter.
    area2 >= SEEN_RADIUS * perimeter
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::embree::{Device, TriangleMesh};
    use crate::scene::{MeshMaterials, Object, SceneDesc};
    use crate::shade::Material;

    const SIZE: u32 = 64;

    fn camera() -> Camera {
        crate::camera::footprint::test_camera(SIZE)
    }

    /// The map of `objects` where the depth pass saw `depth` everywhere.
    fn map(objects: Vec<Object>, depth: f32) -> UnseenBlur {
        let desc = SceneDesc {
            materials: vec![Material::diffuse(Vec3::splat(0.5))],
            objects,
            ..Default::default()
        };
        let world = World::build(&desc, &Device::new().unwrap()).unwrap();
        let depths = vec![depth; (SIZE * SIZE) as usize];
        UnseenBlur::of(&world, &camera(), &depths, 1.5, &LightTraced::none()).unwrap()
    }

    fn marked(m: &UnseenBlur) -> usize {
        m.sharpest.iter().filter(|c| c.is_finite()).count()
    }

    #[test]
    fn a_sub_pixel_sphere_is_bounded_by_its_blur() {
        let sphere = |z: f32| Object::Sphere {
            center: Vec3::new(0.0, 0.0, z),
            radius: 0.002 * z,
            material: 0,
        };
        let c = camera();
        let m = map(vec![sphere(10.0)], f32::INFINITY);
        let (centre, coc) = (SIZE as usize / 2, c.coc_px(10.0));
        assert!((m.sharpest(centre, centre) / coc - 1.0).abs() < 0.01);
        assert!((m.widest(centre, centre) / coc - 1.0).abs() < 0.01);
        // Its light reaches CoC / 2 plus the filter's 1.5 px, no further than a tile beyond.
        let reach = (0.5 * coc + 1.5) as usize;
        let tiles = (2 * reach).div_ceil(TILE) + 1;
        assert!(marked(&m) <= tiles * tiles, "{} tiles", marked(&m));
        assert!(m.sharpest(0, 0).is_infinite());
        // Where the depth pass found a surface at its depth it is part of that surface.
        assert_eq!(marked(&map(vec![sphere(10.0)], 10.0)), 0);
        // A sphere the depth pass cannot miss is left to it.
        let big = Object::Sphere {
            center: Vec3::new(0.0, 0.0, 10.0),
            radius: 0.2,
            material: 0,
        };
        assert_eq!(marked(&map(vec![big], f32::INFINITY)), 0);
    }

    #[test]
    fn a_wire_marks_the_tiles_along_it_and_a_fine_mesh_none() {
        // A wire across the frame at depth 5 (in focus), from the top right (the image's x
        // axis is the world's -x here) to the bottom left.
        let wire = TriangleMesh::new(
            vec![[-3.0, 3.0, 5.0], [3.0, -3.0, 5.0], [3.0, -2.995, 5.0]],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let m = map(
            vec![Object::Mesh {
                mesh: wire,
                materials: MeshMaterials::One(0),
            }],
            f32::INFINITY,
        );
        let last = SIZE as usize - 1;
        assert_eq!(m.sharpest(last, 0), 0.0);
        assert_eq!(m.sharpest(last / 2, last / 2), 0.0);
        assert_eq!(m.sharpest(0, last), 0.0);
        // Off the diagonal: not its whole bounding box.
        assert!(m.sharpest(0, 0).is_infinite() && m.sharpest(last, last).is_infinite());
        // A wall of 0.02-unit squares at depth 10 (0.2 px each), which the depth pass saw.
        let n = 200;
        let step = 4.0 / n as f32;
        let positions = (0..=n)
            .flat_map(|j| {
                (0..=n).map(move |i| [i as f32 * step - 2.0, j as f32 * step - 2.0, 10.0])
            })
            .collect();
        let at = |i: u32, j: u32| j * (n + 1) + i;
        let indices = (0..n)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .flat_map(|(i, j)| {
                [
                    [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                    [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                ]
            })
            .collect();
        let fine = TriangleMesh::new(positions, indices).unwrap();
        let mesh = Object::Mesh {
            mesh: fine,
            materials: MeshMaterials::One(0),
        };
        assert_eq!(marked(&map(vec![mesh], 10.0)), 0);
    }
}
