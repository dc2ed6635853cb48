//! The Rust side of the FFI-overhead comparison: the same loop as `benches/cpp/packet_loop.cpp`
//! (run both with `benches/cpp/run.sh`). Traces the paper scene's coherent thin-lens rays
//! (16 lens samples per pixel, every 4th pixel of 640x480) through the safe wrapper, with
//! `intersect16` and with 16 x `intersect1`, single-threaded, and prints one line per mode:
//!
//! `packet_loop lang=rust embree=3 mode=intersect16 rays=307200 rays_hash=... hits=... sum_t=...
//! reps=15 median_mrays=... best_mrays=...`
//!
//! Usage: `cargo run --release --example packet_loop [REPS] [EMBREE_CONFIG]`

#[path = "../benches/cpp/paper_rays.rs"]
mod paper_rays;

use std::hint::black_box;
use std::time::Instant;

use dofray::bench::median;
use dofray::embree::{Device, EMBREE_MAJOR, RayHint};
use paper_rays::{Checksum, paper_rays, paper_scene, rays_hash, trace_packets, trace_single};

fn main() {
    let mut args = std::env::args().skip(1);
    let reps: usize = args
        .next()
        .map(|s| s.parse().expect("REPS must be a positive integer"))
        .unwrap_or(15)
        .max(1);
    let config = args.next().unwrap_or_default();
    let device = Device::with_config(&config).expect("Embree device");
    let (scene, camera) = paper_scene(&device);
    let rays = paper_rays(&camera);
    let hash = rays_hash(&rays);

    let modes: [(&str, &dyn Fn() -> Checksum); 2] = [
        ("intersect16", &|| {
            trace_packets(&scene, black_box(&rays), RayHint::Coherent)
        }),
        ("intersect1", &|| trace_single(&scene, black_box(&rays))),
    ];
    // Warm up, take the checksums, then interleave the modes pass by pass so that both see the
    // same machine load (this box is shared and noisy).
    let checks: Vec<Checksum> = modes.iter().map(|(_, run)| black_box(run())).collect();
    let mut mrays = vec![Vec::with_capacity(reps); modes.len()];
    for _ in 0..reps {
        for (m, (name, run)) in modes.iter().enumerate() {
            let start = Instant::now();
            let c = black_box(run());
            let secs = start.elapsed().as_secs_f64();
            assert_eq!(c, checks[m], "{name}: a repetition traced different hits");
            mrays[m].push(rays.len() as f64 / secs / 1e6);
        }
    }
    for (m, (name, _)) in modes.iter().enumerate() {
        let best = mrays[m].iter().copied().fold(0.0, f64::max);
        println!(
            "packet_loop lang=rust embree={EMBREE_MAJOR} mode={name} rays={} rays_hash={hash:016x} \
             hits={} sum_t={:.6} reps={reps} median_mrays={:.3} best_mrays={best:.3}",
            rays.len(),
            checks[m].hits,
            checks[m].sum_t,
            median(mrays[m].clone()),
        );
    }
}
