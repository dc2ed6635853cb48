// Scratch quality probe (not committed): PSNR vs reference for dense and adaptive.
use dofray::camera::LensSpec;
use dofray::metrics::{self, Space};
use dofray::render::{self, Mode, NoProgress, RenderSettings, SiteRule};
use std::io::Write;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let scene = &a[0];
    let (w, h): (u32, u32) = (a[1].parse().unwrap(), a[2].parse().unwrap());
    let spps: Vec<u32> = a[3].split(',').map(|s| s.parse().unwrap()).collect();
    let aperture: Option<f32> = std::env::var("APERTURE").ok().map(|s| s.parse().unwrap());
    let tol: Option<f32> = std::env::var("TOL").ok().map(|s| s.parse().unwrap());
    let mut desc = dofray::scene::load_with(scene, &Default::default()).unwrap();
    desc.camera.width = w;
    desc.camera.height = h;
    if let Some(r) = aperture {
        desc.camera.lens = LensSpec::Aperture { radius: r };
    }
    let device = dofray::embree::Device::new().unwrap();
    let world = dofray::scene::World::build(&desc, &device).unwrap();
    let fwd = (desc.camera.look_at - desc.camera.eye).normalize_or_zero();
    let camera = desc
        .camera
        .build(|ray| {
            world
                .scene
                .intersect1(ray)
                .map(|hit| (ray.at(hit.t) - ray.origin).dot(fwd))
        })
        .unwrap();
    let refspp: u32 = std::env::var("REFSPP")
        .ok()
        .map(|s| s.parse().unwrap())
        .unwrap_or(1024);
    let key = format!(
        "/tmp/probe-ref-{}-{w}x{h}-{:?}-{refspp}.bin",
        desc.name, aperture
    );
    let reference: Vec<[f32; 3]> = if let Ok(b) = std::fs::read(&key) {
        b.chunks_exact(12)
            .map(|c| [0, 1, 2].map(|i| f32::from_le_bytes(c[i * 4..i * 4 + 4].try_into().unwrap())))
            .collect()
    } else {
        let s = RenderSettings {
            mode: Mode::Dense,
            spp: refspp,
            aa: refspp,
            seed: 777,
            ..Default::default()
        };
        let (f, st) = render::render(&world, &camera, &s, &NoProgress).unwrap();
        eprintln!("reference {:.1}s", st.seconds);
        let rgb = f.rgb();
        let mut file = std::fs::File::create(&key).unwrap();
        for p in &rgb {
            for v in p {
                file.write_all(&v.to_le_bytes()).unwrap();
            }
        }
        rgb
    };
    let out = std::env::var("OUT").ok();
    for &spp in &spps {
        for (name, mode, rule) in [
            ("dense", Mode::Dense, SiteRule::Error),
            ("adaptive", Mode::Adaptive, SiteRule::Error),
            ("seed-k0.4", Mode::Adaptive, SiteRule::Seed),
        ] {
            let s = RenderSettings {
                mode,
                spp,
                rule,
                tolerance: tol,
                ..Default::default()
            };
            let mut best = f64::INFINITY;
            let mut film = None;
            let mut stats = None;
            for _ in 0..3 {
                let (f, st) = render::render(&world, &camera, &s, &NoProgress).unwrap();
                best = best.min(st.seconds);
                film = Some(f);
                stats = Some(st);
            }
            let f = film.unwrap();
            let st = stats.unwrap();
            let p =
                metrics::psnr(&f.rgb(), &reference, w as usize, h as usize, Space::Srgb).unwrap();
            let samples: u64 = f.samples.iter().map(|&n| n as u64).sum();
            println!(
                "{:>5} {name:>10}: {p:6.2} dB  {best:7.3}s  rays {:>10}  sites {:>7}  samples {:>9} rounds {}",
                spp,
                st.rays.total(),
                st.sample_sites,
                samples,
                st.rounds
            );
            if let Some(dir) = &out {
                dofray::output::write_film(
                    &std::path::Path::new(dir).join(format!("{}-{name}-{spp}.png", desc.name)),
                    &f,
                )
                .unwrap();
            }
        }
    }
}
