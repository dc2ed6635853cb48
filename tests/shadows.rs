//! TEMPORARY experiment.
use dofray::embree::{Device, Ray, SceneBuilder, Spheres, TriangleMesh};
use glam::Vec3;

fn probe(device: &Device, c: Vec3, r: f32, eye: Vec3, light: Vec3, spread: f32) {
    let mut b = SceneBuilder::new(device).unwrap();
    b.add_spheres(Spheres::new([(c, r)]).unwrap()).unwrap();
    let scene = b.commit().unwrap();
    let (mut below_max, mut n) = (0.0f64, 0);
    let mut max_t = 0.0f32;
    let mut acne_old = 0;
    let mut need_max = 0.0f32;
    let mut need_p = Vec3::ZERO;
    // aim at points of the sphere's top cap
    let top = c + Vec3::Y * r;
    for i in 0..150 {
        for j in 0..150 {
            let target = top
                + Vec3::new(
                    (i as f32 / 149.0 - 0.5) * spread,
                    0.0,
                    (j as f32 / 149.0 - 0.5) * spread,
                );
            let dir = (target - eye).normalize();
            let Some(hit) = scene.intersect1(&Ray::new(eye, dir)) else {
                continue;
            };
            n += 1;
            max_t = max_t.max(hit.t);
            let p = eye + dir * hit.t;
            let below = (p.as_dvec3() - c.as_dvec3()).length() - r as f64;
            below_max = below_max.max(-below);
            let nrm = ((p - c) / r).normalize();
            if nrm.dot(light - p) <= 0.0 {
                continue;
            }
            let to_l = (light - p).normalize();
            let dist = (light - p).length();
            let shadow = |eps: f32| {
                let o = p + nrm * eps;
                scene.occluded1(&Ray::segment(o, to_l, 0.0, dist * (1.0 - 1e-4) - eps))
            };
            if shadow(1e-4 * (1.0 + p.abs().max_element())) {
                acne_old += 1;
            }
            let mut e = 1e-9f32;
            while shadow(e) && e < 1.0 {
                e *= 1.1;
            }
            if e > need_max {
                need_max = e;
                need_p = p;
            }
        }
    }
    let scale = c.abs().max_element() + r;
    eprintln!(
        "c={c} r={r} eye={eye}: {n} hits, max t {max_t:.3e}; max below {below_max:.2e} \
         ({:.1} ulp(|c|+r)); old-eps self-hits {acne_old}; needed eps {need_max:.2e} \
         = {:.2} ulp(|c|+r) = {:.2e} (|c|+r) at p={need_p}",
        below_max / ulp(scale) as f64,
        need_max / ulp(scale),
        need_max / scale,
    );
}

fn ulp(x: f32) -> f32 {
    f32::from_bits(x.to_bits() + 1) - x
}

#[test]
#[ignore]
fn experiment() {
    let device = Device::new().unwrap();
    let l = Vec3::new(2.0, 8.0, -3.0);
    for &r in &[10.0f32, 100.0, 1000.0, 1e4, 1e5] {
        probe(
            &device,
            Vec3::new(0.0, -r, 0.0),
            r,
            Vec3::new(0.0, 1.5, -6.0),
            l,
            4.0,
        );
    }
    // small spheres far from the origin
    for &(c, r) in &[
        (Vec3::new(100.0, 0.0, 0.0), 1.0f32),
        (Vec3::new(1000.0, 0.0, 0.0), 1.0),
        (Vec3::new(1000.0, 0.0, 0.0), 0.01),
        (Vec3::new(0.0, 0.0, 0.0), 0.01),
    ] {
        probe(
            &device,
            c,
            r,
            c + Vec3::new(0.0, 1.5, -6.0) * r,
            c + l * r,
            1.5 * r,
        );
    }
    // small sphere, far camera (large t)
    for &d in &[10.0f32, 1000.0, 1e4] {
        probe(
            &device,
            Vec3::ZERO,
            0.01,
            Vec3::new(0.0, 0.25, -1.0) * d,
            l,
            0.015,
        );
        probe(
            &device,
            Vec3::ZERO,
            1.0,
            Vec3::new(0.0, 0.25, -1.0) * d,
            l * 10.0,
            1.5,
        );
    }
}

fn probe_mesh(
    device: &Device,
    h: f32,
    tilt_deg: f32,
    shift: Vec3,
    eye: Vec3,
    light: Vec3,
    spread: f32,
) {
    let rot = glam::Quat::from_rotation_z(tilt_deg.to_radians());
    let corners = [[-h, -h], [h, -h], [h, h], [-h, h]];
    let pos: Vec<[f32; 3]> = corners
        .iter()
        .map(|&[x, z]| (rot * Vec3::new(x, 0.0, z) + shift).to_array())
        .collect();
    let nrm = rot * Vec3::Y;
    let mesh = TriangleMesh::new(pos.clone(), vec![[0, 2, 1], [0, 3, 2]]).unwrap();
    let mut b = SceneBuilder::new(device).unwrap();
    b.add_mesh(mesh).unwrap();
    let scene = b.commit().unwrap();
    let (eye, light) = (shift + rot * eye, shift + rot * light);
    let mut need_max = 0.0f32;
    let mut acne_old = 0;
    let mut n = 0;
    let mut max_t = 0.0f32;
    let mut need_p = Vec3::ZERO;
    for i in 0..150 {
        for j in 0..150 {
            let target = shift
                + rot
                    * Vec3::new(
                        (i as f32 / 149.0 - 0.5) * spread,
                        0.0,
                        (j as f32 / 149.0 - 0.5) * spread,
                    );
            let dir = (target - eye).normalize();
            let Some(hit) = scene.intersect1(&Ray::new(eye, dir)) else {
                continue;
            };
            n += 1;
            max_t = max_t.max(hit.t);
            let p = eye + dir * hit.t;
            let to_l = (light - p).normalize();
            let dist = (light - p).length();
            let shadow = |eps: f32| {
                let o = p + nrm * eps;
                scene.occluded1(&Ray::segment(o, to_l, 0.0, dist * (1.0 - 1e-4) - eps))
            };
            if shadow(1e-4 * (1.0 + p.abs().max_element())) {
                acne_old += 1;
            }
            let mut e = 1e-9f32;
            while shadow(e) && e < 1.0 {
                e *= 1.1;
            }
            if e > need_max {
                need_max = e;
                need_p = p;
            }
        }
    }
    let vmax = pos
        .iter()
        .map(|v| Vec3::from(*v).abs().max_element())
        .fold(0.0, f32::max);
    eprintln!(
        "mesh h={h} tilt={tilt_deg} shift={shift}: {n} hits, max t {max_t:.2e}; old-eps self-hits {acne_old}; needed eps {need_max:.2e} = {:.2e} vmax = {:.2e} max(|p|,t) at {need_p}",
        need_max / vmax,
        need_max / need_p.abs().max_element().max(max_t)
    );
}

#[test]
#[ignore]
fn experiment_mesh() {
    let device = Device::new().unwrap();
    let l = Vec3::new(2.0, 8.0, -3.0);
    let e = Vec3::new(0.0, 1.5, -6.0);
    for &h in &[30.0f32, 1000.0, 1e4] {
        for &tilt in &[0.0f32, 7.0] {
            probe_mesh(&device, h, tilt, Vec3::ZERO, e, l, 4.0);
        }
    }
    probe_mesh(&device, 1.0, 7.0, Vec3::new(1000.0, 0.0, 0.0), e, l, 1.5);
    probe_mesh(&device, 1.0, 7.0, Vec3::ZERO, e * 1000.0, l, 1.5);
    probe_mesh(&device, 0.01, 7.0, Vec3::ZERO, e * 0.01, l * 0.01, 0.015);
}
