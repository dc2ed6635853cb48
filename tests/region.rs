//! Regions and tiles: any window of the image renders to the same pixels, bit for bit, as the
//! whole frame, in every mode and under both adaptive rules, so tiles rendered apart (on
//! other machines) assemble into exactly the full render.

use dofray::camera::{ApertureShape, Camera};
use dofray::embree::Device;
use dofray::render::{
    Film, Mode, NoProgress, Region, RenderSettings, SamplingRule, render, render_region,
};
use dofray::scene::{World, builtin};

fn paper(width: u32, height: u32) -> (World, Camera) {
    paper_through(width, height, ApertureShape::default())
}

/// [`paper`] through `aperture`.
fn paper_through(width: u32, height: u32, aperture: ApertureShape) -> (World, Camera) {
    let mut desc = builtin::paper();
    desc.camera.width = width;
    desc.camera.height = height;
    desc.camera.aperture = aperture;
    let device = Device::new().unwrap();
    let world = World::build(&desc, &device).unwrap();
    let camera = desc.camera.build(|_| None).unwrap();
    (world, camera)
}

fn settings() -> Vec<(&'static str, RenderSettings)> {
    let base = RenderSettings {
        seed: 5,
        ..Default::default()
    };
    vec![
        ("adaptive, error rule", base.clone()),
        (
            "adaptive, error rule, transparent, tight",
            RenderSettings {
                transparent: true,
                rule: SamplingRule::ErrorControlled {
                    tolerance: Some(0.5),
                },
                spp: 32,
                ..base.clone()
            },
        ),
        (
            "adaptive, seed rule",
            RenderSettings {
                rule: SamplingRule::Seed {
                    interval_factor: 0.4,
                    paper_exact: false,
                },
                ..base.clone()
            },
        ),
        (
            "adaptive, paper exact",
            RenderSettings {
                rule: SamplingRule::Seed {
                    interval_factor: 0.4,
                    paper_exact: true,
                },
                ..base.clone()
            },
        ),
        (
            "dense",
            RenderSettings {
                mode: Mode::Dense,
                ..base.clone()
            },
        ),
        (
            "pinhole",
            RenderSettings {
                mode: Mode::Pinhole,
                ..base
            },
        ),
    ]
}

/// Every buffer of `tile` equals the same window of `full`, bit for bit.
fn assert_window(full: &Film, tile: &Film, r: &Region, what: &str) {
    assert_eq!(
        (tile.width, tile.height),
        (r.width() as usize, r.height() as usize)
    );
    for y in 0..tile.height {
        for x in 0..tile.width {
            let (p, q) = (
                (y + r.y0 as usize) * full.width + x + r.x0 as usize,
                y * tile.width + x,
            );
            let same = full.color[p].to_array().map(f32::to_bits)
                == tile.color[q].to_array().map(f32::to_bits)
                && full.alpha[p].to_bits() == tile.alpha[q].to_bits()
                && full.depth[p].to_bits() == tile.depth[q].to_bits()
                && full.coc[p].to_bits() == tile.coc[q].to_bits()
                && full.interval[p] == tile.interval[q]
                && full.samples[p] == tile.samples[q];
            assert!(
                same,
                "{what}: region {r}, pixel ({}, {}): full {:?} a {} n {} i {}, region {:?} a {} n {} i {}",
                x + r.x0 as usize,
                y + r.y0 as usize,
                full.color[p],
                full.alpha[p],
                full.samples[p],
                full.interval[p],
                tile.color[q],
                tile.alpha[q],
                tile.samples[q],
                tile.interval[q],
            );
        }
    }
}

#[test]
fn regions_render_the_same_pixels_as_the_whole_frame() {
    // 200 x 150: buckets of 64 leave partial ones at the right and bottom.
    let (world, camera) = paper(200, 150);
    let regions = [
        "0,0,200,150",
        "0,0,64,64",
        "37,21,131,99",
        "63,63,65,65",
        "199,149,200,150",
        "128,0,200,150",
        "5,70,190,71",
    ]
    .map(|s| s.parse::<Region>().unwrap());
    for (what, s) in settings() {
        let (full, full_stats) = render(&world, &camera, &s, &NoProgress).unwrap();
        for r in &regions {
            let (tile, stats) = render_region(&world, &camera, &s, r, &NoProgress).unwrap();
            assert_window(&full, &tile, r, what);
            assert!(stats.rays.total() <= full_stats.rays.total() || r.width() == 200);
        }
    }
}

/// Also through five blades stretched 1.4 times, whose lending kernel's rows are worked out
/// by whichever thread first needs them.
#[test]
fn a_tile_grid_reassembles_into_the_full_render_at_any_thread_count() {
    let bladed = ApertureShape {
        blades: 5,
        rotation_deg: 10.0,
        anamorphic: 1.4,
    };
    let round = settings().into_iter().take(3);
    let cases = (round.map(|c| (c, ApertureShape::default())))
        .chain(settings().into_iter().take(1).map(|c| (c, bladed)));
    for ((what, s), aperture) in cases {
        let what = &format!("{what}, {aperture:?}");
        let (world, camera) = paper_through(160, 120, aperture);
        let (full, _) = render(&world, &camera, &s, &NoProgress).unwrap();
        let tiles = Region::grid(160, 120, 3, 2).unwrap();
        for (i, r) in tiles.iter().enumerate() {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1 + i % 2)
                .build()
                .unwrap();
            let (tile, _) = pool
                .install(|| render_region(&world, &camera, &s, r, &NoProgress))
                .unwrap();
            assert_window(&full, &tile, r, what);
        }
    }
}

#[test]
fn a_region_costs_less_than_the_frame() {
    // With sample reuse a region also refines the buckets its lending windows read (up to
    // 4 x 2 buckets and one more each way, see `refine::lending`) and those around them:
    // here a 4 x 4 grid's last tile (3 x 2 of the 10 x 8 buckets) refines 8 x 4 of them.
    let (width, height) = (640, 512);
    let (world, camera) = paper(width, height);
    let s = RenderSettings {
        spp: 16,
        ..RenderSettings::default()
    };
    let (_, full) = render(&world, &camera, &s, &NoProgress).unwrap();
    let tile = Region::grid(width, height, 4, 4).unwrap()[15];
    let (_, part) = render_region(&world, &camera, &s, &tile, &NoProgress).unwrap();
    // The depth pass is the whole frame's; the rest is the tile's, its closure's and the
    // buckets' its sites borrow from.
    let depth_rays = u64::from(width * height);
    let shaded = |n: u64| n - depth_rays;
    assert!(
        shaded(part.rays.primary) < shaded(full.rays.primary) / 2,
        "{} of {}",
        part.rays.primary,
        full.rays.primary
    );
    assert!(part.sample_sites < full.sample_sites);
}

#[test]
fn regions_outside_the_image_are_refused() {
    let (world, camera) = paper(64, 48);
    let s = RenderSettings::default();
    for r in ["0,0,65,48", "0,40,64,49"] {
        let r: Region = r.parse().unwrap();
        let err = render_region(&world, &camera, &s, &r, &NoProgress).unwrap_err();
        assert!(err.to_string().contains("beyond the 64x48 image"), "{err}");
    }
}
