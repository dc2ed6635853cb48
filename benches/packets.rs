//! Throughput of 16-wide packets versus single rays for coherent thin-lens primary rays.
//!
//! The paper scene at 640x480 with 16 lens samples per pixel (aperture radius 0.2, focused on
//! the 4th sphere), one packet per pixel, every 4th pixel in x and y: 19200 packets, 307200 rays,
//! generated once outside the timed loop. Single-threaded. Criterion reports elements/s, which
//! are rays/s. `benches/cpp/run.sh` compares the same packet loop with C++ calling Embree.
//!
//! Run with `cargo bench --bench packets`.

#[path = "cpp/paper_rays.rs"]
mod paper_rays;

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dofray::embree::{Device, RayHint};
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

criterion_group!(benches, packets);
criterion_main!(benches);
