//! What a lens ray costs to make: the thin lens's 16-wide `rays16` against each shipped real
//! lens's (traced element by element), for one 640x480 camera's film positions and lens
//! samples (4096 rays, 256 calls), single-threaded. Criterion reports elements/s (rays/s):
//! their ratio is the real lens's cost per ray relative to the thin lens. The cost of a
//! render adds tracing and shading on top of it (`dofray bench`).
//!
//! `real_lens_build` is what placing a real lens costs, once a camera (and again for every
//! focus distance of an animation): the exit pupil bounds, the traced blur table and the
//! chief rays, on the machine's threads.
//!
//! Run with `cargo bench --bench lenses`.

use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dofray::camera::{Camera, CameraSpec, Focus, LensSpec, Prescription, RealLensSpec};
use dofray::embree::LANES;

const CALLS: usize = 256;

fn spec() -> CameraSpec {
    CameraSpec {
        focus: Focus::Distance(3.0),
        lens: LensSpec::Photographic {
            focal_length_mm: 50.0,
            f_number: 2.0,
            sensor_width_mm: 36.0,
        },
        ..CameraSpec::default()
    }
}

/// Film positions and lens sample numbers spread over the frame and the lens.
fn samples() -> Vec<[[f32; LANES]; 4]> {
    let frac = |x: f32| x - x.floor();
    (0..CALLS)
        .map(|call| {
            let k = |lane: usize| (call * LANES + lane) as f32;
            [
                std::array::from_fn(|l| frac(k(l) * 0.618_034) * 640.0),
                std::array::from_fn(|l| frac(k(l) * 0.754_878) * 480.0),
                std::array::from_fn(|l| frac(k(l) * 0.569_840) * 2.0 - 1.0),
                std::array::from_fn(|l| frac(k(l) * 0.362_437) * 2.0 - 1.0),
            ]
        })
        .collect()
}

fn make_rays(camera: &Camera, samples: &[[[f32; LANES]; 4]]) -> f32 {
    let (mut origin, mut dir, mut weight) = ([[0.0; LANES]; 3], [[0.0; LANES]; 3], [0.0; LANES]);
    let mut sum = 0.0;
    for s in samples {
        camera.lens_rays16(
            (&s[0], &s[1]),
            (&s[2], &s[3]),
            &mut origin,
            &mut dir,
            &mut weight,
        );
        sum += dir[2][0] + weight[0];
    }
    sum
}

/// The camera of each shipped lens, wide open, with `spec()`'s focus and image size, on a
/// 36 mm film (the fisheye's image circle covers only a 24 mm one at 4:3).
fn real_lens_specs() -> Vec<(&'static str, CameraSpec)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("lenses");
    [
        ("double-gauss-50mm", 36.0),
        ("wide-22mm", 36.0),
        ("telephoto-250mm", 36.0),
        ("fisheye-10mm", 24.0),
    ]
    .map(|(name, sensor_width_mm)| {
        let p = Prescription::load(&dir.join(format!("{name}.dat"))).expect("lens file");
        let spec = CameraSpec {
            real_lens: Some(RealLensSpec {
                prescription: Arc::new(p),
                f_number: None,
                sensor_width_mm,
            }),
            ..spec()
        };
        (name, spec)
    })
    .into()
}

fn lenses(c: &mut Criterion) {
    let samples = samples();
    let mut group = c.benchmark_group("lens_rays_640x480");
    group.throughput(Throughput::Elements((CALLS * LANES) as u64));
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    let thin = spec().build(|_| None).expect("thin lens");
    group.bench_function("thin", |b| b.iter(|| make_rays(&thin, black_box(&samples))));
    for (name, spec) in real_lens_specs() {
        let camera = spec.build(|_| None).expect("real lens");
        group.bench_function(name, |b| b.iter(|| make_rays(&camera, black_box(&samples))));
    }
    group.finish();
}

fn lens_builds(c: &mut Criterion) {
    let mut group = c.benchmark_group("real_lens_build");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(5));
    for (name, spec) in real_lens_specs() {
        group.bench_function(name, |b| {
            b.iter(|| black_box(&spec).build(|_| None).expect("real lens"))
        });
    }
    group.finish();
}

criterion_group!(benches, lenses, lens_builds);
criterion_main!(benches);
