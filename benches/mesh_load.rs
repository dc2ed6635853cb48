//! Large meshes: loading a 1-million-triangle OBJ and building its BVH, and what it costs in
//! memory: the mesh's own buffers against the process's resident set (VmRSS) after each step
//! and at its peak (VmHWM), which includes the parser's temporary buffers.
//!
//! The mesh is a 708 x 707-quad height-field grid (1,001,112 triangles, 501,972 vertices),
//! written once as OBJ text to a temporary file. Run with `cargo bench --bench mesh_load`.

use std::hint::black_box;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use dofray::embree::Device;
use dofray::limits::Bytes;
use dofray::scene::{self, MeshMaterials, Object, SceneDesc, World};

const QUADS_X: usize = 708;
const QUADS_Z: usize = 707;

/// Writes the grid as OBJ (positions and triangles) and returns its path.
fn write_grid(dir: &Path) -> PathBuf {
    let path = dir.join(format!("dofray-grid-{}.obj", std::process::id()));
    let file = std::fs::File::create(&path).unwrap();
    let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
    writeln!(
        w,
        "# {QUADS_X}x{QUADS_Z}-quad grid for dofray's mesh_load bench"
    )
    .unwrap();
    for j in 0..=QUADS_Z {
        for i in 0..=QUADS_X {
            let (x, z) = (
                i as f32 / QUADS_X as f32 * 20.0 - 10.0,
                j as f32 / QUADS_Z as f32 * 20.0,
            );
            let y = 0.3 * (x * 1.7).sin() * (z * 1.3).cos();
            writeln!(w, "v {x:.5} {y:.5} {z:.5}").unwrap();
        }
    }
    let v = |i: usize, j: usize| j * (QUADS_X + 1) + i + 1;
    for j in 0..QUADS_Z {
        for i in 0..QUADS_X {
            let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            writeln!(w, "f {a} {b} {c}\nf {a} {c} {d}").unwrap();
        }
    }
    w.flush().unwrap();
    path
}

/// A `/proc/self/status` field in bytes (VmRSS: resident now; VmHWM: peak resident).
fn status_bytes(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    let kib: u64 = line[field.len() + 1..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    Some(kib * 1024)
}

fn mesh_stats(desc: &SceneDesc) -> (usize, usize) {
    desc.objects
        .iter()
        .filter_map(|o| match o {
            Object::Mesh { mesh, materials } => {
                let ids = match materials {
                    MeshMaterials::One(_) => 0,
                    MeshMaterials::PerTriangle(v) => v.capacity() * 4,
                };
                Some((mesh.triangle_count(), mesh.heap_bytes() + ids))
            }
            Object::Sphere { .. } => None,
        })
        .fold((0, 0), |(t, b), (t2, b2)| (t + t2, b + b2))
}

/// Resets the process's peak resident set (VmHWM) to its current size, so the next peak read
/// is this measurement's (Linux 4.0+; without it VmHWM is the peak since the process began).
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// One measured load + build, with memory, printed before the criterion runs.
fn report(path: &Path, device: &Device) {
    let peak_reset = reset_peak();
    let rss0 = status_bytes("VmRSS:").unwrap_or(0);
    let t0 = Instant::now();
    let desc = scene::load(path.to_str().unwrap()).unwrap();
    let load = t0.elapsed();
    let rss_loaded = status_bytes("VmRSS:").unwrap_or(0);
    let peak_loaded = status_bytes("VmHWM:").unwrap_or(0);
    let t1 = Instant::now();
    let world = World::build(&desc, device).unwrap();
    let build = t1.elapsed();
    let rss_built = status_bytes("VmRSS:").unwrap_or(0);
    let peak = status_bytes("VmHWM:").unwrap_or(0);
    let (triangles, mesh_bytes) = mesh_stats(&desc);
    let file = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    eprintln!("mesh_load: {triangles} triangles, OBJ file {}", Bytes(file));
    eprintln!(
        "mesh_load: OBJ load {:.2} s, BVH build (World::build) {:.2} s, total {:.2} s",
        load.as_secs_f64(),
        build.as_secs_f64(),
        (load + build).as_secs_f64()
    );
    eprintln!(
        "mesh_load: TriangleMesh::heap_bytes {} ({:.1} B/triangle)",
        Bytes(mesh_bytes as u64),
        mesh_bytes as f64 / triangles as f64,
    );
    eprintln!(
        "mesh_load: RSS before {}, after load {} (+{}), after BVH build {} (+{}; Embree's BVH {})",
        Bytes(rss0),
        Bytes(rss_loaded),
        Bytes(rss_loaded.saturating_sub(rss0)),
        Bytes(rss_built),
        Bytes(rss_built.saturating_sub(rss0)),
        Bytes(rss_built.saturating_sub(rss_loaded)),
    );
    eprintln!(
        "mesh_load: peak RSS (VmHWM{}) during load {} (+{} over before), during load + BVH \
         build {} (+{})",
        if peak_reset {
            ", reset before loading"
        } else {
            " since the process began"
        },
        Bytes(peak_loaded),
        Bytes(peak_loaded.saturating_sub(rss0)),
        Bytes(peak),
        Bytes(peak.saturating_sub(rss0)),
    );
    drop(world);
    drop(desc);
}

fn benches(c: &mut Criterion) {
    // Removed when the bench ends, however it ends.
    let dir = tempfile::tempdir().unwrap();
    let path = write_grid(dir.path());
    let device = Device::new().unwrap();
    report(&path, &device);

    let mut g = c.benchmark_group("1M-triangle OBJ");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(10));
    g.bench_function("load", |b| {
        b.iter(|| black_box(scene::load(path.to_str().unwrap()).unwrap()))
    });
    g.bench_function("load + BVH build", |b| {
        b.iter(|| {
            let desc = scene::load(path.to_str().unwrap()).unwrap();
            black_box(World::build(&desc, &device).unwrap())
        })
    });
    g.finish();
}

criterion_group!(mesh_load, benches);
criterion_main!(mesh_load);
