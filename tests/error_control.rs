//! The error-controlled adaptive rule (`render::refine`): it must be as close to the converged
//! image as dense at the same samples per site while tracing fewer rays, keep a defocused
//! highlight's disc and rim, and answer its tolerance.

use dofray::camera::{ApertureShape, Camera, CameraSpec, Focus, LensSpec};
use dofray::embree::Device;
use dofray::metrics::{Space, psnr};
use dofray::render::{
    Film, Mode, NoProgress, PathLimits, RenderSettings, RenderStats, SamplingRule, render,
};
use dofray::scene::{Background, Object, SceneDesc, World, builtin};
use dofray::shade::Material;
use glam::Vec3;

fn setup(desc: &SceneDesc) -> (World, Camera) {
    let device = Device::new().unwrap();
    let world = World::build(desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    (world, camera)
}

fn draw(world: &World, camera: &Camera, settings: RenderSettings) -> (Film, RenderStats) {
    render(world, camera, &settings, &NoProgress).unwrap()
}

/// The converged image: dense with every pixel (in focus or not) at `spp`, another seed.
fn reference(world: &World, camera: &Camera, spp: u32) -> Vec<[f32; 3]> {
    let settings = RenderSettings {
        mode: Mode::Dense,
        spp,
        aa: spp,
        seed: 99,
        ..Default::default()
    };
    draw(world, camera, settings).0.rgb()
}

#[test]
fn adaptive_is_as_close_to_the_reference_as_dense_with_fewer_rays() {
    let mut desc = builtin::paper();
    desc.camera.width = 160;
    desc.camera.height = 120;
    let (world, camera) = setup(&desc);
    let truth = reference(&world, &camera, 256);
    for spp in [16, 64] {
        let at = |mode| RenderSettings {
            mode,
            spp,
            ..Default::default()
        };
        let (dense, dense_stats) = draw(&world, &camera, at(Mode::Dense));
        let (adaptive, adaptive_stats) = draw(&world, &camera, at(Mode::Adaptive));
        let q = |f: &Film| psnr(&f.rgb(), &truth, 160, 120, Space::Srgb).unwrap();
        let (qd, qa) = (q(&dense), q(&adaptive));
        let ratio = adaptive_stats.rays.total() as f64 / dense_stats.rays.total() as f64;
        eprintln!(
            "{spp} spp: dense {qd:.2} dB, adaptive {qa:.2} dB with {:.0}% of its rays in {} rounds",
            100.0 * ratio,
            adaptive_stats.rounds
        );
        assert!(
            qa >= qd - 0.5,
            "{spp} spp: adaptive {qa} dB vs dense {qd} dB"
        );
        assert!(
            ratio < 0.75,
            "{spp} spp: adaptive traced {ratio:.2} of dense's rays"
        );
        assert!(adaptive_stats.rounds > 1, "it checked and refined");
    }
}

/// A small, very bright sphere far in front of the focus plane: its blur is a disc of the CoC's
/// diameter with a hard rim (not band-limited). The error-controlled rule must keep the
/// disc's shape and rim as well as dense does (the seed's rule at k = 0.4 rounds it off: 0.87
/// intersection over union).
#[test]
fn a_defocused_highlight_keeps_its_disc_and_rim() {
    let size = 96u32;
    let desc = SceneDesc {
        name: "highlight".into(),
        camera: CameraSpec {
            eye: Vec3::ZERO,
            look_at: Vec3::Z,
            up: Vec3::Y,
            vfov_deg: 30.0,
            width: size,
            height: size,
            lens: LensSpec::Aperture { radius: 0.8 },
            focus: Focus::Distance(10.0),
            aperture: ApertureShape::default(),
            real_lens: None,
        },
        materials: vec![
            Material {
                emission: Vec3::splat(100.0),
                ..Material::diffuse(Vec3::ZERO)
            },
            Material::diffuse(Vec3::splat(0.004)),
        ],
        objects: vec![
            Object::Sphere {
                center: Vec3::new(0.1, -0.05, 5.0),
                radius: 0.08,
                material: 0,
            },
            // An in-focus dim sphere beside it: sharp detail the disc must not smear.
            Object::Sphere {
                center: Vec3::new(-1.2, 0.8, 10.0),
                radius: 0.5,
                material: 1,
            },
        ],
        lights: vec![],
        ambient: Vec3::splat(0.4),
        background: Background::uniform(Vec3::ZERO),
        ..Default::default()
    };
    let (world, camera) = setup(&desc);
    let coc = camera.coc_px(5.0);
    assert!(coc > 25.0, "the disc is {coc} px across");
    let truth = reference(&world, &camera, 1024);
    // The disc: pixels at more than half the brightest pixel's luminance.
    let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let peak = truth.iter().map(|&c| luma(c)).fold(0.0, f32::max);
    let inside =
        |img: &[[f32; 3]]| -> Vec<bool> { img.iter().map(|&c| luma(c) > 0.5 * peak).collect() };
    let want = inside(&truth);
    let area = want.iter().filter(|&&b| b).count();
    let expected = std::f32::consts::PI * coc * coc / 4.0;
    assert!(
        (area as f32 - expected).abs() < 0.25 * expected,
        "reference disc {area} px vs {expected}"
    );
    // Intersection over union of the disc masks.
    let iou = |got: &[bool]| {
        let both = got.iter().zip(&want).filter(|&(&a, &b)| a && b).count();
        let any = got.iter().zip(&want).filter(|&(&a, &b)| a || b).count();
        both as f64 / any as f64
    };
    // The camera's rays alone: the error controller must find the rim itself (with light
    // tracing the lamp's disc comes from the light's side, and the sites need not).
    let settings = RenderSettings {
        mode: Mode::Adaptive,
        spp: 256,
        path: PathLimits {
            light_tracing: false,
            ..Default::default()
        },
        ..Default::default()
    };
    let (film, _) = draw(&world, &camera, settings.clone());
    let adaptive = iou(&inside(&film.rgb()));
    let (seed, _) = draw(
        &world,
        &camera,
        RenderSettings {
            rule: SamplingRule::Seed {
                interval_factor: 0.4,
                paper_exact: false,
            },
            ..settings.clone()
        },
    );
    let seed_iou = iou(&inside(&seed.rgb()));
    let (dense, _) = draw(
        &world,
        &camera,
        RenderSettings {
            mode: Mode::Dense,
            ..settings.clone()
        },
    );
    let dense_iou = iou(&inside(&dense.rgb()));
    eprintln!(
        "disc IoU: error-controlled {adaptive:.3}, dense {dense_iou:.3}, seed rule {seed_iou:.3}"
    );
    // As round as dense at the same samples per site (whose noise alone costs a few percent).
    assert!(
        adaptive > 0.93 && adaptive > dense_iou - 0.02,
        "error-controlled disc IoU {adaptive}, dense {dense_iou}"
    );
    // The rim stays hard: sites were traced densely along it.
    let w = size as usize;
    let traced = film.samples.iter().filter(|&&n| n > 0).count();
    let rim_sites = (0..w * w)
        .filter(|&p| {
            let (x, y) = (p % w, p / w);
            x + 1 < w && want[p] != want[p + 1] && film.samples[p] > 0 && y > 0
        })
        .count();
    let rim = (0..w * w)
        .filter(|&p| p % w + 1 < w && want[p] != want[p + 1])
        .count();
    assert!(
        rim_sites * 3 > rim && rim_sites * w * w > 2 * rim * traced,
        "{rim_sites} of {rim} rim pixels traced ({traced} of {} overall)",
        w * w
    );
}

#[test]
fn a_smaller_tolerance_traces_more_and_comes_closer() {
    let mut desc = builtin::paper();
    desc.camera.width = 120;
    desc.camera.height = 90;
    let (world, camera) = setup(&desc);
    let truth = reference(&world, &camera, 256);
    let mut last: Option<(u64, f64)> = None;
    for tolerance in [8.0, 2.0, 0.5] {
        let (film, stats) = draw(
            &world,
            &camera,
            RenderSettings {
                mode: Mode::Adaptive,
                spp: 64,
                rule: SamplingRule::ErrorControlled {
                    tolerance: Some(tolerance),
                },
                ..Default::default()
            },
        );
        let q = psnr(&film.rgb(), &truth, 120, 90, Space::Srgb).unwrap();
        eprintln!(
            "tolerance {tolerance}: {} sites, {q:.2} dB",
            stats.sample_sites
        );
        if let Some((sites, quality)) = last {
            assert!(
                stats.sample_sites > sites,
                "tolerance {tolerance}: {} sites",
                stats.sample_sites
            );
            assert!(q > quality, "tolerance {tolerance}: {q} dB");
        }
        last = Some((stats.sample_sites, q));
    }
}

#[test]
fn the_samples_map_records_what_was_traced() {
    let mut desc = builtin::paper();
    desc.camera.width = 100;
    desc.camera.height = 75;
    let (world, camera) = setup(&desc);
    // The direct integrator, whose in-focus sites take `aa` (4) and blurred ones up to 16.
    let settings = RenderSettings {
        integrator: dofray::render::Integrator::Direct,
        aa: 4,
        ..RenderSettings::default()
    };
    let (film, stats) = draw(&world, &camera, settings);
    let traced: u64 = film.samples.iter().map(|&n| u64::from(n)).sum();
    // Every sample is one primary ray (the depth pass adds one per pixel). Buckets refine
    // apart, so the sites on the column and row two buckets share may be traced by both: at
    // most 129 of every 64 x 64 pixels (3%).
    let counted = traced + 100 * 75;
    assert!(
        counted <= stats.rays.primary && stats.rays.primary <= counted + counted * 129 / 4096,
        "{counted} samples, {} primary rays",
        stats.rays.primary
    );
    assert!(film.samples.iter().all(|&n| n <= 16));
    assert!(film.samples.contains(&0), "some pixels were interpolated");
    assert!(film.samples.contains(&16) && film.samples.contains(&4));
    assert!(film.interval.iter().all(|i| i.is_power_of_two()));
}

#[test]
fn the_rule_decides_the_same_for_any_thread_count() {
    let mut desc = builtin::paper();
    desc.camera.width = 96;
    desc.camera.height = 72;
    let (world, camera) = setup(&desc);
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            draw(
                &world,
                &camera,
                RenderSettings {
                    spp: 64,
                    ..Default::default()
                },
            )
        })
    };
    let ((one, s1), (two, s2)) = (on(1), on(2));
    let bits = |f: &Film| -> Vec<u32> {
        f.color
            .iter()
            .flat_map(|c| c.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&one), bits(&two));
    assert_eq!((one.samples, one.interval), (two.samples, two.interval));
    assert_eq!((s1.rays, s1.rounds), (s2.rays, s2.rounds));
}

#[test]
fn path_traced_in_focus_sites_take_samples_by_their_neighbours_noise() {
    // With the path tracer an in-focus site carries light noise: after 16 samples it takes
    // up to `spp` in proportion to its neighbours' noise (render::allocation), so the
    // background (no noise at all) keeps 16 and the lit spheres take more; the image stays
    // as close to the converged one as dense's with the same spp.
    let mut desc = builtin::paper();
    desc.camera.width = 100;
    desc.camera.height = 75;
    desc.camera.lens = LensSpec::Pinhole;
    let (world, camera) = setup(&desc);
    let spp = 64;
    let at = |mode| RenderSettings {
        mode,
        spp,
        aa: spp,
        ..RenderSettings::default()
    };
    let (film, stats) = draw(&world, &camera, at(Mode::Adaptive));
    let (dense, dense_stats) = draw(&world, &camera, at(Mode::Dense));
    assert!(film.coc.iter().all(|&c| c < 0.5), "a pinhole: all in focus");
    assert!(
        film.samples.iter().all(|&n| (16..=spp).contains(&n)),
        "every pixel a site with 16 to {spp} samples"
    );
    let count = |f: &dyn Fn(u32) -> bool| film.samples.iter().filter(|&&n| f(n)).count();
    let (few, all) = (count(&|n| n == 16), count(&|n| n == spp));
    let between = film.samples.len() - few - all;
    eprintln!("16: {few}, {spp}: {all}, between: {between} pixels");
    assert!(
        few > 0 && all > 0 && between > 0,
        "{few} / {between} / {all}"
    );
    // The empty background (depth infinite) has no noise: it keeps its first samples.
    let background: Vec<u32> = (film.depth.iter().zip(&film.samples))
        .filter(|&(&d, _)| !d.is_finite())
        .map(|(_, &n)| n)
        .collect();
    let at_16 = background.iter().filter(|&&n| n == 16).count();
    assert!(
        at_16 * 10 >= background.len() * 9,
        "{at_16} of {}",
        background.len()
    );
    // Fewer samples, the same error as dense (within 0.5 dB) against the converged image.
    let truth = reference(&world, &camera, 512);
    let q = |f: &Film| psnr(&f.rgb(), &truth, 100, 75, Space::Srgb).unwrap();
    let (qa, qd) = (q(&film), q(&dense));
    let samples = film.samples.iter().map(|&n| u64::from(n)).sum::<u64>();
    eprintln!(
        "adaptive {qa:.2} dB with {samples} samples ({} rays), dense {qd:.2} dB ({} rays)",
        stats.rays.total(),
        dense_stats.rays.total()
    );
    assert!(
        samples * 10 < 100 * 75 * u64::from(spp) * 8,
        "{samples} samples"
    );
    assert!(qa > qd - 0.5, "adaptive {qa:.2} dB, dense {qd:.2} dB");
}
