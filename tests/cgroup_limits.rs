//! Issue 28: a real cgroup memory limit, the kind Slurm and Kubernetes set, rather than a
//! faked `/sys` tree (`limits.rs`'s unit tests cover the parsing). The test makes a child
//! memory cgroup (v1 `memory.limit_in_bytes`, else v2 `memory.max`), runs `dofray` inside it,
//! and checks two things. An image the limit cannot hold is refused with exit 5, naming the
//! cgroup. An image the guard admits renders to the end, and the kernel's OOM killer is not
//! needed.
//!
//! Making a cgroup needs root and a writable cgroup hierarchy with the memory controller. The
//! CI machines have both (cgroup v1). Where neither exists, the test says so on stdout and
//! checks nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dofray::render::reuse::RECORDS_HELD;

use crate::scratch::Scratch;

/// The cgroup's limit: 320 MiB.
const LIMIT: u64 = 320 << 20;

/// A child memory cgroup with a limit, removed on drop.
struct Cgroup {
    dir: PathBuf,
}

impl Cgroup {
    /// A new cgroup `tag` limited to `bytes`, v1 or v2, or why none can be made.
    fn new(bytes: u64, tag: &str) -> Result<Self, String> {
        let name = format!("dofray-test-{}-{tag}", std::process::id());
        let v1 = Path::new("/sys/fs/cgroup/memory");
        let v2 = Path::new("/sys/fs/cgroup");
        let (dir, limit_file) = if v1.join("memory.limit_in_bytes").exists() {
            (v1.join(&name), "memory.limit_in_bytes")
        } else if std::fs::read_to_string(v2.join("cgroup.subtree_control"))
            .is_ok_and(|c| c.split_whitespace().any(|c| c == "memory"))
        {
            (v2.join(&name), "memory.max")
        } else {
            return Err("no cgroup v1 memory hierarchy, nor cgroup v2 with memory".into());
        };
        std::fs::create_dir(&dir).map_err(|e| format!("cannot make {}: {e}", dir.display()))?;
        let cgroup = Self { dir };
        std::fs::write(cgroup.dir.join(limit_file), bytes.to_string())
            .map_err(|e| format!("cannot set {limit_file}: {e}"))?;
        Ok(cgroup)
    }

    /// `dofray args...` run inside the cgroup (the shell moves itself in, then execs).
    fn dofray(&self, args: &[&str]) -> Output {
        let procs = self.dir.join("cgroup.procs");
        Command::new("sh")
            .arg("-c")
            .arg(format!(
                "echo $$ > '{}' && exec \"$0\" \"$@\"",
                procs.display()
            ))
            .arg(env!("CARGO_BIN_EXE_dofray"))
            .args(args)
            .output()
            .expect("sh runs")
    }
}

impl Drop for Cgroup {
    fn drop(&mut self) {
        // Empty once its processes have exited; the kernel may take a moment to notice.
        for _ in 0..50 {
            if std::fs::remove_dir(&self.dir).is_ok() {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

/// A cgroup limited to [`LIMIT`], or None (saying why) where none can be made.
fn cgroup(tag: &str) -> Option<Cgroup> {
    Cgroup::new(LIMIT, tag)
        .map_err(|why| println!("not run: {why}"))
        .ok()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn a_real_cgroup_limit_refuses_what_cannot_fit_and_admits_what_can() {
    let Some(cgroup) = cgroup("images") else {
        return;
    };
    let dir = Scratch::new("cgroup");

    // 20000 x 20000 needs about 48 GiB of buffers: refused before anything is allocated.
    let out = dir.join("big.png");
    let refused = cgroup.dofray(&[
        "render",
        "--width",
        "20000",
        "--height",
        "20000",
        "--json",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    let stdout = text(&refused.stdout);
    assert_eq!(
        refused.status.code(),
        Some(5),
        "{stdout}{}",
        text(&refused.stderr)
    );
    assert!(stdout.contains("\"resource_limit\""), "{stdout}");
    assert!(stdout.contains("cgroup memory limit"), "{stdout}");
    assert!(!out.exists(), "nothing is written");

    // About 60% of the limit by the guard's estimate (128 B a pixel): admitted, and it must
    // then fit for real, or the OOM killer ends it with SIGKILL (no exit code).
    let out = dir.join("fits.exr");
    let admitted = cgroup.dofray(&[
        "render",
        "--width",
        "1400",
        "--height",
        "1050",
        "--mode",
        "pinhole",
        "--aa",
        "1",
        "--json",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(
        admitted.status.code(),
        Some(0),
        "{:?}: {}{}",
        admitted.status,
        text(&admitted.stdout),
        text(&admitted.stderr)
    );
    assert!(std::fs::metadata(&out).unwrap().len() > 0);

    // A million emissive triangles: the mesh fits, the emitters' light tree (about 280 bytes
    // an emitter) does not. No allocation fails under a cgroup (the OOM killer ends the
    // process instead), so this is refused from the budget before the tree is built (or, on
    // a machine with less left, before the OBJ is parsed): exit 5, never SIGKILL.
    let model = crate::memory_limits::emissive_grid(&dir, 707);
    let out = dir.join("emissive.png");
    let args = ["--spp", "1", "--width", "32", "--threads", "1"];
    assert_refused(&cgroup, &model, &args, &out, "out of memory");
    drop(cgroup);
}

/// `dofray render scene args... --quiet -o out` in `cgroup` exits 5 (not killed), its message
/// naming `what` and the cgroup's limit, and writes nothing.
fn assert_refused(cgroup: &Cgroup, scene: &Path, args: &[&str], out: &Path, what: &str) {
    let mut all = vec!["render", scene.to_str().unwrap()];
    all.extend(args);
    all.extend(["--quiet", "-o", out.to_str().unwrap()]);
    let refused = cgroup.dofray(&all);
    let err = text(&refused.stderr);
    assert_eq!(
        refused.status.code(),
        Some(5),
        "{:?}: {err}",
        refused.status
    );
    assert!(
        err.contains(what) && err.contains("cgroup memory limit"),
        "{err}"
    );
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn samples_kept_for_reuse_that_outgrow_a_cgroup_are_refused_not_killed() {
    let Some(cgroup) = cgroup("reuse") else {
        return;
    };
    let dir = Scratch::new("cgroup-reuse");
    // Sample reuse keeps every blurred site's samples for a few rows of buckets: a plane just
    // out of focus at 64 spp holds about 400 MB of them at 600 x 600 (46 MB of buffers). Each
    // bucket asks the budget for room first, so the render is refused, never killed (the
    // build before was killed in both cases below).
    let plane = dir.join("plane.obj");
    std::fs::write(
        &plane,
        "v -10 -10 0\nv 10 -10 0\nv 10 10 0\nv -10 10 0\nf 1 2 3\nf 1 3 4\n",
    )
    .unwrap();
    let out = dir.join("plane.png");
    // Many rows of buckets; then one frame-wide row of them, refined in one step (each
    // bucket sees the largest that the others before it held).
    for (width, height) in [("600", "600"), ("8000", "128")] {
        let args = ["--focus-distance", "38", "--spp", "64"];
        let args = [&args[..], &["--width", width, "--height", height]].concat();
        assert_refused(&cgroup, &plane, &args, &out, RECORDS_HELD);
    }
    drop(cgroup);
}
