//! Criterion benches of the renderer's parts: lens sampling, interval-map construction,
//! interpolation, and whole renders of the paper scene at 320x240 in dense and adaptive mode.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dofray::camera::{Camera, Lens};
use dofray::embree::Device;
use dofray::render::{Mode, NoProgress, RenderSettings, SamplingRule, interpolate, maps, render};
use dofray::sampler::PixelSampler;
use dofray::scene::{World, builtin};

fn paper(width: u32, height: u32) -> (World, Camera) {
    let mut desc = builtin::paper();
    desc.camera.width = width;
    desc.camera.height = height;
    let world = World::build(&desc, &Device::new().unwrap()).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    (world, camera)
}

fn benches(c: &mut Criterion) {
    let (world, camera) = paper(320, 240);
    let (w, h) = (320usize, 240usize);

    let mut g = c.benchmark_group("lens sampling");
    g.throughput(Throughput::Elements(16 * 1024));
    g.bench_function("16 samples x 1024 pixels", |b| {
        b.iter(|| {
            let mut acc = glam::Vec2::ZERO;
            for pixel in 0..1024u64 {
                let s = PixelSampler::new(7, pixel);
                for i in 0..16 {
                    acc += camera.lens.lens_point(s.get(i));
                }
            }
            black_box(acc)
        })
    });
    g.finish();

    let pinhole = RenderSettings {
        mode: Mode::Pinhole,
        ..Default::default()
    };
    let (film, _) = render(&world, &camera, &pinhole, &NoProgress).unwrap();
    let mut g = c.benchmark_group("maps 320x240");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.bench_function("blur reach", |b| {
        b.iter(|| black_box(maps::blurred(&film.coc, w, h)))
    });
    g.bench_function("interval map (conservative)", |b| {
        b.iter(|| black_box(maps::interval_map(&film.coc, w, h, 0.4, false, 64)))
    });
    let interval = maps::interval_map(&film.coc, w, h, 0.4, false, 64).unwrap();
    let sites = maps::site_mask(&interval, w, h).unwrap();
    g.bench_function("site mask", |b| {
        b.iter(|| black_box(maps::site_mask(&interval, w, h)))
    });
    g.bench_function("interpolation", |b| {
        let mut color: Vec<glam::Vec4> = film.color.iter().map(|c| c.extend(1.0)).collect();
        b.iter(|| interpolate::interpolate(black_box(&mut color), &interval, &sites, w, h))
    });
    g.finish();

    let mut g = c.benchmark_group("render paper 320x240");
    g.sample_size(10).measurement_time(Duration::from_secs(4));
    for (name, mode, k) in [
        ("dense", Mode::Dense, 0.4),
        ("adaptive k0.4", Mode::Adaptive, 0.4),
        ("adaptive k0.2", Mode::Adaptive, 0.2),
    ] {
        // The seed's fixed rule at k (dense ignores it).
        let settings = RenderSettings {
            mode,
            rule: SamplingRule::Seed {
                interval_factor: k,
                paper_exact: false,
            },
            ..Default::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| black_box(render(&world, &camera, &settings, &NoProgress).unwrap()))
        });
    }
    g.finish();
}

criterion_group! {
    name = renderer;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    targets = benches
}
criterion_main!(renderer);
