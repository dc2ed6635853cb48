//! The safe Embree layer: analytic hits, packets versus single rays, threads, and bad input.

use dofray::embree::{
    Device, EMBREE_MAJOR, EmbreeError, ErrorCode, Geometry, GeometryId, Hit, LANES, PacketWidth,
    Ray, RayHint, RayPacket16, Scene, SceneBuilder, ShadowPacket16, Spheres, TriangleMesh,
    limited_isas,
};
use glam::Vec3;
use rayon::prelude::*;

/// One way Embree can trace on this machine: a device (unlimited, or limited to one ISA the
/// CPU has) and how 16-ray packets are handed to it.
struct Path {
    name: String,
    device: Device,
    width: PacketWidth,
}

/// Every kernel path Embree can take here: an unlimited device and one limited to each
/// narrower ISA this CPU has (so a machine with AVX-512 also runs the AVX2 and SSE kernels and
/// the ray-stream fallback of 16-wide calls), each with every packet width.
fn every_path() -> Vec<Path> {
    let mut devices = vec![("native".to_string(), Device::with_config("").unwrap())];
    for isa in limited_isas() {
        devices.push((
            isa.into(),
            Device::with_config(&format!("isa={isa}")).unwrap(),
        ));
    }
    let mut paths = Vec::new();
    for (isa, device) in devices {
        for width in [
            PacketWidth::Auto,
            PacketWidth::X16,
            PacketWidth::X8,
            PacketWidth::X4,
        ] {
            paths.push(Path {
                name: format!("isa {isa}, {width:?}"),
                device: device.clone(),
                width,
            });
        }
    }
    paths
}

impl Path {
    fn commit(&self, b: SceneBuilder) -> Scene {
        let mut scene = b.commit().unwrap();
        scene.set_packet_width(self.width);
        scene
    }
}

fn sphere_scene(path: &Path, center: Vec3, radius: f32) -> Scene {
    let mut b = SceneBuilder::new(&path.device).unwrap();
    b.add_spheres(Spheres::new([(center, radius)]).unwrap())
        .unwrap();
    path.commit(b)
}

/// A quad at z = 2 from (0,0) to (1,1), as two triangles.
fn quad_scene(path: &Path) -> Scene {
    let mut b = SceneBuilder::new(&path.device).unwrap();
    let mesh = TriangleMesh::new(
        vec![
            [0.0, 0.0, 2.0],
            [1.0, 0.0, 2.0],
            [1.0, 1.0, 2.0],
            [0.0, 1.0, 2.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap();
    b.add_mesh(mesh).unwrap();
    path.commit(b)
}

/// Several spheres over a ground mesh: enough structure for random rays to hit and miss.
fn mixed_scene(path: &Path) -> Scene {
    let mut b = SceneBuilder::new(&path.device).unwrap();
    let spheres = (0..5).map(|i| {
        let i = i as f32;
        (Vec3::new(-1.6 + 0.8 * i, 0.5, -1.0 + 2.5 * i), 0.5)
    });
    b.add_spheres(Spheres::new(spheres).unwrap()).unwrap();
    let ground = TriangleMesh::new(
        vec![
            [-30.0, 0.0, -26.0],
            [30.0, 0.0, -26.0],
            [30.0, 0.0, 34.0],
            [-30.0, 0.0, 34.0],
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap();
    b.add_mesh(ground).unwrap();
    path.commit(b)
}

/// Deterministic xorshift so the "random" rays are the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn ray(&mut self) -> Ray {
        let origin = Vec3::new(self.next() * 4.0 - 2.0, self.next() * 2.0 + 0.2, -6.0);
        let target = Vec3::new(self.next() * 8.0 - 4.0, self.next() * 1.5 - 0.5, 10.0);
        Ray::new(origin, (target - origin).normalize())
    }
}

#[test]
fn ray_hits_sphere_at_analytic_distance_with_right_normal() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let center = Vec3::new(0.3, -0.2, 5.0);
        let radius = 0.75;
        let scene = sphere_scene(&path, center, radius);
        let origin = Vec3::new(0.1, 0.0, -1.0);
        let dir = Vec3::new(0.02, -0.03, 1.0).normalize();
        // Solve |o + t d - c|^2 = r^2 in f64 for the expected near root.
        let oc = (origin - center).as_dvec3();
        let d = dir.as_dvec3();
        let b = oc.dot(d);
        let c = oc.length_squared() - (radius as f64).powi(2);
        let t_expected = -b - (b * b - c).sqrt();

        let hit = scene
            .intersect1(&Ray::new(origin, dir))
            .expect("ray must hit");
        assert!(
            (hit.t as f64 - t_expected).abs() < 1e-4,
            "t = {}, expected {t_expected}",
            hit.t
        );
        assert_eq!(hit.geometry, GeometryId(0));
        assert_eq!(hit.prim, 0);
        let p = origin + dir * hit.t;
        let expected_normal = (p - center).normalize();
        assert!(
            hit.ng.normalize().dot(expected_normal) > 0.9999,
            "normal {:?}",
            hit.ng
        );
        assert!(matches!(scene.geometry(hit.geometry), Geometry::Spheres(_)));

        // A ray passing beside the sphere (closest approach 1.0 > radius) misses.
        let beside = Ray::new(Vec3::new(center.x + 1.0, center.y, -1.0), Vec3::Z);
        assert!(scene.intersect1(&beside).is_none());
        assert!(!scene.occluded1(&beside));
    }
}

#[test]
fn triangle_hits_report_primitive_and_barycentrics() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let scene = quad_scene(&path);
        // Point (0.7, 0.2) is in triangle 0 (0,1,2): p = a + u (b - a) + v (c - a) gives u = 0.5, v = 0.2.
        let hit = scene
            .intersect1(&Ray::new(Vec3::new(0.7, 0.2, 0.0), Vec3::Z))
            .expect("hit");
        assert_eq!(hit.prim, 0);
        assert!((hit.t - 2.0).abs() < 1e-5);
        assert!(
            (hit.u - 0.5).abs() < 1e-5 && (hit.v - 0.2).abs() < 1e-5,
            "{hit:?}"
        );
        // Point (0.2, 0.7) is in triangle 1 (0,2,3): u = 0.2, v = 0.5.
        let hit = scene
            .intersect1(&Ray::new(Vec3::new(0.2, 0.7, 0.0), Vec3::Z))
            .expect("hit");
        assert_eq!(hit.prim, 1);
        assert!(
            (hit.u - 0.2).abs() < 1e-5 && (hit.v - 0.5).abs() < 1e-5,
            "{hit:?}"
        );
        // Outside the quad.
        assert!(
            scene
                .intersect1(&Ray::new(Vec3::new(1.2, 0.5, 0.0), Vec3::Z))
                .is_none()
        );
    }
}

#[test]
fn mesh_normals_and_uvs_interpolate() {
    let mesh = TriangleMesh::new(
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap()
    .with_normals(vec![[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    .unwrap()
    .with_uvs(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    .unwrap();
    let uv = mesh.uv(0, 0.25, 0.5).unwrap();
    assert!((uv.x - 0.25).abs() < 1e-6 && (uv.y - 0.5).abs() < 1e-6);
    let n = mesh.shading_normal(0, 0.0, 1.0).unwrap();
    assert!((n - Vec3::Y).length() < 1e-6, "normalised on input: {n:?}");
    assert_eq!(mesh.face_normal(0).normalize(), Vec3::Z);
}

/// Through the public API: an inactive lane's ray (including `tfar`, which a hit would shorten)
/// is left as it was, although tracing the ray it held before would hit. (`embree::scene`'s unit tests check that no
/// hit field of an inactive lane is written either; `hit()` cannot show that, as it returns
/// `None` for inactive lanes whatever they hold.)
#[test]
fn partial_mask_leaves_inactive_lanes_untouched() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let scene = mixed_scene(&path);
        let mut rng = Rng(7);
        let mut packet = RayPacket16::new();
        let rays: Vec<Ray> = (0..LANES).map(|_| rng.ray()).collect();
        for (lane, ray) in rays.iter().enumerate() {
            packet.set(lane, ray);
        }
        for lane in (0..LANES).filter(|l| l % 3 == 1) {
            packet.set_inactive(lane);
        }
        assert_eq!(packet.active_count(), 11);
        // Deactivated lanes hold an empty segment, so no path of Embree's traces them.
        let idle: Vec<Ray> = (0..LANES).map(|lane| packet.ray(lane)).collect();
        scene.intersect16(&mut packet, RayHint::Coherent);
        let (mut hits, mut inactive_would_hit) = (0, 0);
        for (lane, ray) in rays.iter().enumerate() {
            if lane % 3 == 1 {
                assert_eq!(
                    packet.ray(lane),
                    idle[lane],
                    "inactive lane {lane} was written"
                );
                assert!(idle[lane].tnear > idle[lane].tfar, "{:?}", idle[lane]);
                assert!(!packet.is_active(lane) && packet.hit(lane).is_none());
                if scene.intersect1(ray).is_some() {
                    inactive_would_hit += 1;
                }
            } else {
                assert_eq!(
                    packet.hit(lane).is_some(),
                    scene.intersect1(ray).is_some(),
                    "active lane {lane}"
                );
                if packet.hit(lane).is_some() {
                    hits += 1;
                }
            }
        }
        assert!(hits > 0, "the active lanes should hit something");
        assert!(
            inactive_would_hit > 0,
            "some inactive lane's ray must hit, or leaving its tfar alone proves nothing"
        );
    }
}

/// The packet and single-ray paths must report the same hit: distance, ids, barycentrics and
/// geometric normal (up to float rounding).
fn assert_same_hit(single: &Hit, wide: &Hit, what: &str) {
    assert_eq!(
        (single.geometry, single.prim),
        (wide.geometry, wide.prim),
        "{what}"
    );
    let close = |a: f32, b: f32, scale: f32| (a - b).abs() <= 1e-4 * scale.max(1.0);
    assert!(
        close(single.t, wide.t, single.t),
        "{what}: t {single:?} vs {wide:?}"
    );
    assert!(
        close(single.u, wide.u, 1.0) && close(single.v, wide.v, 1.0),
        "{what}: u, v {single:?} vs {wide:?}"
    );
    let scale = single.ng.length();
    assert!(
        scale > 0.0 && (single.ng - wide.ng).length() <= 1e-4 * scale,
        "{what}: Ng {single:?} vs {wide:?}"
    );
}

#[test]
fn intersect16_agrees_with_intersect1_and_occluded16() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let scene = mixed_scene(&path);
        for hint in [RayHint::Coherent, RayHint::Incoherent] {
            let mut rng = Rng(12345);
            let mut packet = RayPacket16::new();
            let mut shadow = ShadowPacket16::new();
            let (mut hits, mut misses, mut triangle_hits) = (0, 0, 0);
            for _ in 0..64 {
                let rays: Vec<Ray> = (0..LANES).map(|_| rng.ray()).collect();
                for (lane, ray) in rays.iter().enumerate() {
                    packet.set(lane, ray);
                    shadow.set(lane, ray);
                }
                scene.intersect16(&mut packet, hint);
                scene.occluded16(&mut shadow, hint);
                for (lane, ray) in rays.iter().enumerate() {
                    let single = scene.intersect1(ray);
                    let wide = packet.hit(lane);
                    match (single, wide) {
                        (Some(s), Some(w)) => {
                            hits += 1;
                            if matches!(scene.geometry(s.geometry), Geometry::Mesh(_)) {
                                triangle_hits += 1;
                            }
                            assert_same_hit(&s, &w, &format!("{hint:?} lane {lane}"));
                        }
                        (None, None) => misses += 1,
                        other => {
                            panic!("{hint:?} lane {lane}: single and packet disagree: {other:?}")
                        }
                    }
                    assert_eq!(
                        shadow.occluded(lane),
                        wide.is_some(),
                        "{hint:?} lane {lane}"
                    );
                    assert_eq!(scene.occluded1(ray), wide.is_some(), "{hint:?} lane {lane}");
                }
            }
            assert!(
                hits > 100 && misses > 20 && triangle_hits > 20 && hits - triangle_hits > 20,
                "{hint:?}: {hits} hits ({triangle_hits} on triangles), {misses} misses"
            );
        }
    }
}

#[test]
fn occlusion_respects_the_segment() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let scene = sphere_scene(&path, Vec3::new(0.0, 0.0, 5.0), 1.0);
        // The sphere's front is at t = 4: a segment ending before it is not occluded.
        assert!(!scene.occluded1(&Ray::segment(Vec3::ZERO, Vec3::Z, 0.0, 3.9)));
        assert!(scene.occluded1(&Ray::segment(Vec3::ZERO, Vec3::Z, 0.0, 4.1)));
    }
}

#[test]
fn threads_see_the_same_hits() {
    for path in every_path() {
        // The last path printed is the one that failed.
        eprintln!("{}", path.name);
        let scene = mixed_scene(&path);
        let mut rng = Rng(99);
        let rays: Vec<Ray> = (0..4096).map(|_| rng.ray()).collect();
        let trace = |chunk: &[Ray]| {
            let mut packet = RayPacket16::new();
            let mut out = Vec::with_capacity(chunk.len());
            packet.clear();
            for (lane, ray) in chunk.iter().enumerate() {
                packet.set(lane, ray);
            }
            scene.intersect16(&mut packet, RayHint::Incoherent);
            for lane in 0..chunk.len() {
                out.push(
                    packet
                        .hit(lane)
                        .map(|h| (h.geometry, h.prim, h.t.to_bits())),
                );
            }
            out
        };
        let serial: Vec<_> = rays.chunks(LANES).flat_map(trace).collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let parallel: Vec<_> =
            pool.install(|| rays.par_chunks(LANES).flat_map_iter(trace).collect());
        assert_eq!(serial, parallel);
    }
}

#[test]
fn bounds_cover_the_geometry() {
    let scene = sphere_scene(&every_path()[0], Vec3::new(1.0, 2.0, 3.0), 0.5);
    let (lo, hi) = scene.bounds();
    assert!(lo.x <= 0.5 && lo.y <= 1.5 && lo.z <= 2.5, "{lo:?}");
    assert!(hi.x >= 1.5 && hi.y >= 2.5 && hi.z >= 3.5, "{hi:?}");
    assert!((hi - lo).max_element() < 1.5);
}

#[test]
fn invalid_device_config_is_an_error() {
    // Embree ignores options it does not know (`nonsense_option=3` makes a device) but fails
    // rtcNewDevice on a malformed value, with RTC_ERROR_UNKNOWN on both Embree 3 and 4.
    let err = Device::with_config("threads=notanumber").unwrap_err();
    let EmbreeError::Embree { code, message } = &err else {
        panic!("expected Embree's own error, got {err}");
    };
    assert_eq!(*code, ErrorCode::Unknown, "{err}");
    assert!(message.contains("threads=notanumber"), "{message:?}");
    if EMBREE_MAJOR >= 4 {
        // Embree 4 says why (rtcGetDeviceLastErrorMessage); Embree 3 gives only the code.
        assert!(message.contains("integer expected"), "{message:?}");
    }
    assert!(matches!(
        Device::with_config("bad\0config"),
        Err(EmbreeError::InvalidConfig { .. })
    ));
    assert!(Device::with_config("verbose=0").is_ok());
}

#[test]
fn out_of_range_index_is_an_error() {
    let err = TriangleMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 3]],
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("triangle 0") && text.contains("3 vertices"),
        "{text}"
    );
}

#[test]
fn non_finite_geometry_is_an_error() {
    let err = TriangleMesh::new(
        vec![[0.0; 3], [1.0, f32::NAN, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap_err();
    assert!(err.to_string().contains("vertex 1"), "{err}");
    assert!(Spheres::new([(Vec3::new(0.0, f32::INFINITY, 0.0), 1.0)]).is_err());
    assert!(Spheres::new([(Vec3::ZERO, 0.0)]).is_err());
    assert!(Spheres::new([(Vec3::ZERO, -1.0)]).is_err());
    assert!(Spheres::new([(Vec3::ZERO, f32::NAN)]).is_err());
    assert!(TriangleMesh::new(vec![[0.0; 3]], vec![]).is_err());
    let mesh = TriangleMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    assert!(mesh.clone().with_normals(vec![[0.0, 0.0, 1.0]]).is_err());
    assert!(mesh.with_uvs(vec![[0.0, f32::NAN]; 3]).is_err());
}
