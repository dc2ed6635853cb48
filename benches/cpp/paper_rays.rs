//! The packet-tracing workload shared by `benches/packets.rs` (criterion) and
//! `examples/packet_loop.rs` (the Rust side of the C++ comparison in `benches/cpp/`).
//! `benches/cpp/packet_loop.cpp` is a line-by-line C++ port of this file: change both together.
//!
//! Workload: the `paper` scene at 640x480, every `STRIDE`-th pixel in x and y, `SPP` thin-lens
//! samples per pixel exactly as the renderer draws them (`PixelSampler` seeded with
//! (`SEED`, y * width + x), the lens's `lens_point`, `Camera::lens_ray` through the pixel centre).
//! One packet = the 16 lens samples of one pixel: coherent primary rays.
//!
//! Included with `#[path]` (Cargo does not build files under `benches/cpp/` on their own).

use dofray::camera::{Camera, Lens};
use dofray::embree::{Device, LANES, Ray, RayHint, RayPacket16, Scene, SceneBuilder, Spheres};
use dofray::sampler::PixelSampler;
use dofray::scene::{Object, builtin};
use glam::Vec2;

/// Trace every `STRIDE`-th pixel in x and y: 160 x 120 = 19200 pixels (packets) at 640x480.
pub const STRIDE: u32 = 4;
/// Lens samples per pixel: one full packet.
pub const SPP: u32 = LANES as u32;
/// The renderer's default image seed.
pub const SEED: u64 = 0;

/// The paper scene's geometry as `World::build` lays it out: meshes first (the ground quad is
/// geometry 0), then all spheres in one sphere-point geometry (geometry 1).
pub fn paper_scene(device: &Device) -> (Scene, Camera) {
    let desc = builtin::paper();
    let camera = desc
        .camera
        .build(|_| None)
        .expect("the paper camera is valid");
    let mut builder = SceneBuilder::new(device).expect("scene");
    let mut spheres = Vec::new();
    for object in &desc.objects {
        match object {
            Object::Sphere { center, radius, .. } => spheres.push((*center, *radius)),
            Object::Mesh { mesh, .. } => {
                builder.add_mesh(mesh.clone()).expect("ground mesh");
            }
        }
    }
    builder
        .add_spheres(Spheres::new(spheres).expect("spheres"))
        .expect("sphere geometry");
    (builder.commit().expect("commit"), camera)
}

/// The pre-generated rays: `SPP` consecutive rays per traced pixel, pixels in row-major order.
pub fn paper_rays(camera: &Camera) -> Vec<Ray> {
    let mut rays = Vec::new();
    for y in (0..camera.height).step_by(STRIDE as usize) {
        for x in (0..camera.width).step_by(STRIDE as usize) {
            let sampler = PixelSampler::new(SEED, u64::from(y * camera.width + x));
            let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
            for i in 0..SPP {
                let lens: Vec2 = camera.lens.lens_point(sampler.get(i));
                rays.push(camera.lens_ray(px, py, lens));
            }
        }
    }
    rays
}

/// FNV-1a over the bits of every ray's origin and direction: equal when two programs generated
/// bit-identical rays.
#[allow(dead_code)] // the example prints it; the bench does not
pub fn rays_hash(rays: &[Ray]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for r in rays {
        for v in [
            r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z,
        ] {
            h = (h ^ u64::from(v.to_bits())).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// What a pass over the rays found: the number of hits and the sum of their distances (in ray
/// order, in f64), so two implementations that trace the same rays print the same numbers.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Checksum {
    pub hits: u64,
    pub sum_t: f64,
}

impl Checksum {
    fn add(&mut self, t: Option<f32>) {
        if let Some(t) = t {
            self.hits += 1;
            self.sum_t += f64::from(t);
        }
    }
}

/// Traces the rays 16 at a time with `intersect16` (one packet per pixel), reusing one packet.
pub fn trace_packets(scene: &Scene, rays: &[Ray], hint: RayHint) -> Checksum {
    let mut packet = RayPacket16::new();
    let mut sum = Checksum::default();
    for chunk in rays.chunks(LANES) {
        packet.clear();
        for (lane, ray) in chunk.iter().enumerate() {
            packet.set(lane, ray);
        }
        scene.intersect16(&mut packet, hint);
        for lane in 0..chunk.len() {
            sum.add(packet.hit(lane).map(|h| h.t));
        }
    }
    sum
}

/// Traces the same rays one at a time with `intersect1`.
pub fn trace_single(scene: &Scene, rays: &[Ray]) -> Checksum {
    let mut sum = Checksum::default();
    for ray in rays {
        sum.add(scene.intersect1(ray).map(|h| h.t));
    }
    sum
}
