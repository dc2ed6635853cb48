//! Throughput of 16-wide packets versus single rays for coherent thin-lens primary rays, and of
//! each way of handing a 16-ray packet to Embree (`PacketWidth`) on each ISA.
//!
//! The paper scene at 640x480 with 16 lens samples per pixel (aperture radius 0.2, focused on
//! the 4th sphere), one packet per pixel, every 4th pixel in x and y: 19200 packets, 307200 rays,
//! generated once outside the timed loop. Shadow rays go from each lens ray's hit towards the
//! scene's light, in the same packets. Single-threaded. Criterion reports elements/s, which are
//! rays/s. `benches/cpp/run.sh` compares the same packet loop with C++ calling Embree.
//!
//! Run with `cargo bench --bench packets` (`-- width` for the packet-width groups alone).

#[path = "cpp/paper_rays.rs"]
mod paper_rays;

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dofray::embree::{Device, LANES, PacketWidth, Ray, RayHint, Scene, ShadowPacket16};
use glam::Vec3;
use paper_rays::{paper_rays, paper_scene, trace_packets, trace_single};

fn packets(c: &mut Criterion) {
    let device = Device::new().expect("Embree device");
    let (scene, camera) = paper_scene(&device);
    let rays = paper_rays(&camera);
    // Both paths must see the same hits, or the comparison means nothing.
    let packet_sum = trace_packets(&scene, &rays, RayHint::Coherent);
    let single_sum = trace_single(&scene, &rays);
    assert_eq!(packet_sum.hits, single_sum.hits);
    assert!((packet_sum.sum_t - single_sum.sum_t).abs() <= 1e-6 * single_sum.sum_t);

    let mut group = c.benchmark_group("paper_640x480_16spp");
    group.throughput(Throughput::Elements(rays.len() as u64));
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(4));
    group.bench_function("intersect16_coherent", |b| {
        b.iter(|| trace_packets(&scene, black_box(&rays), RayHint::Coherent))
    });
    group.bench_function("intersect16_incoherent", |b| {
        b.iter(|| trace_packets(&scene, black_box(&rays), RayHint::Incoherent))
    });
    group.bench_function("16x_intersect1", |b| {
        b.iter(|| trace_single(&scene, black_box(&rays)))
    });
    group.finish();
}

/// Shadow rays from the hit of every lens ray towards the paper scene's point light, in the
/// lens rays' order (a pixel's 16 stay together); misses keep an empty segment.
fn shadow_rays(scene: &Scene, rays: &[Ray]) -> Vec<Ray> {
    let light = Vec3::new(-4.0, 8.0, -4.0);
    rays.iter()
        .map(|ray| match scene.intersect1(ray) {
            Some(hit) => {
                let p = ray.at(hit.t) + hit.ng.normalize() * 1e-3;
                let d = light - p;
                Ray::segment(p, d.normalize(), 0.0, d.length() * 0.999)
            }
            None => Ray::segment(Vec3::ZERO, Vec3::Z, 1.0, 0.0),
        })
        .collect()
}

fn trace_shadows(scene: &Scene, rays: &[Ray]) -> usize {
    let mut packet = ShadowPacket16::new();
    let mut blocked = 0;
    for chunk in rays.chunks(LANES) {
        packet.clear();
        for (lane, ray) in chunk.iter().enumerate() {
            packet.set(lane, ray);
        }
        scene.occluded16(&mut packet, RayHint::Coherent);
        blocked += (0..chunk.len()).filter(|&l| packet.occluded(l)).count();
    }
    blocked
}

/// `intersect16` and `occluded16` with each packet width, on the native device and on ones
/// limited to AVX2 and SSE4.2 (where a 16-wide call goes through Embree's ray-stream fallback).
fn widths(c: &mut Criterion) {
    for config in ["", "isa=avx2", "isa=sse4.2"] {
        let device = Device::with_config(config).expect("Embree device");
        let (mut scene, camera) = paper_scene(&device);
        let rays = paper_rays(&camera);
        let shadows = shadow_rays(&scene, &rays);
        let isa = config.strip_prefix("isa=").unwrap_or("native");
        let mut group = c.benchmark_group(format!("width_{isa}"));
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.sample_size(10);
        group.warm_up_time(Duration::from_millis(500));
        group.measurement_time(Duration::from_secs(3));
        let mut reference = None;
        for width in [PacketWidth::X16, PacketWidth::X8, PacketWidth::X4] {
            scene.set_packet_width(width);
            // Every width must find the same hits and the same occlusions.
            let check = (
                trace_packets(&scene, &rays, RayHint::Coherent),
                trace_shadows(&scene, &shadows),
            );
            assert_eq!(*reference.get_or_insert(check), check, "{isa} {width:?}");
            let name = format!("{width:?}").to_lowercase();
            group.bench_function(format!("intersect_{name}"), |b| {
                b.iter(|| trace_packets(&scene, black_box(&rays), RayHint::Coherent))
            });
            group.bench_function(format!("occluded_{name}"), |b| {
                b.iter(|| trace_shadows(&scene, black_box(&shadows)))
            });
        }
        group.finish();
    }
}

criterion_group!(benches, packets, widths);
criterion_main!(benches);
