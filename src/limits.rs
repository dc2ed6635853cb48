//! Resource guards: refuse work whose buffers would not fit in the memory this process may
//! use, with a message that says how much it would need and which limit stops it, instead of
//! being killed by the operating system (or aborted by the allocator) halfway through.
//!
//! The memory budget ([`MemoryBudget`]) is the least of every limit that applies to the
//! process ([`MemoryLimit`]): `MemAvailable` in `/proc/meminfo`; the address-space and data
//! limits (`ulimit -v`, `ulimit -d`: `Max address space` and `Max data size` in
//! `/proc/self/limits`) less what is already mapped (`VmSize`, `VmData` in
//! `/proc/self/status`); and the memory limit of the process's cgroup and its ancestors
//! (cgroup v2: `memory.max` less `memory.current`; cgroup v1: `memory.limit_in_bytes` or
//! `hierarchical_memory_limit` less `memory.usage_in_bytes`; page cache the kernel reclaims
//! first, `inactive_file` in `memory.stat`, does not count as used). Every reader parses the
//! text of its file, so each is tested on given text ([`SystemFiles::under`] reads a directory
//! standing in for `/`).
//!
//! Buffers sized by the image or by a mesh are also allocated fallibly ([`try_vec`],
//! [`try_collect`]): an allocation the system refuses despite the budget (another process took
//! the memory, the estimate was short) is a [`MemoryError::Allocation`], never an abort.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::error_kind::{ErrorKind, HasKind};

/// Bytes the renderer needs per image pixel at its peak, estimated with a small margin. The
/// film holds colour (12 B), alpha, depth, CoC, interval and sample count (4 B each); a render
/// keeps per-pixel estimates (mean, variance, sample count) and the blur, interval and site maps
/// beside it, and output conversion needs one more 8-bit or float image. Measured peak resident
/// memory grows by 99 (adaptive, PNG) to 117 (the seed's rule, EXR) bytes per pixel from
/// 1000 x 1000 to 2000 x 4000 (debug build, paper scene): 128 allows for that.
pub const BYTES_PER_PIXEL: u64 = 128;

/// The cap used when no limit can be read (no `/proc`).
pub const FALLBACK_LIMIT_BYTES: u64 = 16 << 30;

/// Limits at or beyond this many bytes (2^60, an exbibyte) mean "no limit": cgroup v1 writes
/// its unlimited value as 9223372036854771712, `/proc/self/limits` as `unlimited`.
const UNLIMITED: u64 = 1 << 60;

/// One limit on the memory this process may use, with the numbers it was read from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MemoryLimit {
    /// `MemAvailable` in `/proc/meminfo`: what the system can give without swapping.
    Available {
        /// Bytes available.
        available: u64,
    },
    /// The address-space limit (`RLIMIT_AS`, `ulimit -v`; its soft limit, which applies).
    AddressSpace {
        /// The limit in bytes.
        limit: u64,
        /// Address space the process has mapped already (`VmSize`).
        mapped: u64,
    },
    /// The data-segment limit (`RLIMIT_DATA`, `ulimit -d`), which bounds private writable
    /// memory (the heap and anonymous mappings) since Linux 4.7.
    Data {
        /// The limit in bytes.
        limit: u64,
        /// Private writable memory mapped already (`VmData`).
        mapped: u64,
    },
    /// A cgroup v2 `memory.max` (of the process's cgroup or an ancestor).
    CgroupV2 {
        /// The cgroup's directory (`/sys/fs/cgroup/...`).
        dir: PathBuf,
        /// `memory.max` in bytes.
        max: u64,
        /// `memory.current`, less the reclaimable page cache (`inactive_file`).
        used: u64,
    },
    /// A cgroup v1 memory limit (`memory.limit_in_bytes`, or a smaller
    /// `hierarchical_memory_limit` an ancestor sets).
    CgroupV1 {
        /// The cgroup's directory (`/sys/fs/cgroup/memory/...`).
        dir: PathBuf,
        /// The limit in bytes.
        limit: u64,
        /// `memory.usage_in_bytes`, less the reclaimable page cache (`total_inactive_file`).
        used: u64,
    },
    /// Nothing could be read: [`FALLBACK_LIMIT_BYTES`] is assumed.
    Fallback,
}

impl MemoryLimit {
    /// Bytes this limit leaves for new buffers.
    pub fn remaining(&self) -> u64 {
        match *self {
            Self::Available { available } => available,
            Self::AddressSpace { limit, mapped } | Self::Data { limit, mapped } => {
                limit.saturating_sub(mapped)
            }
            Self::CgroupV2 {
                max: limit, used, ..
            }
            | Self::CgroupV1 { limit, used, .. } => limit.saturating_sub(used),
            Self::Fallback => FALLBACK_LIMIT_BYTES,
        }
    }

    /// The limit's name, for JSON and tests: `available`, `address_space`, `data`,
    /// `cgroup_v2`, `cgroup_v1` or `fallback`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Available { .. } => "available",
            Self::AddressSpace { .. } => "address_space",
            Self::Data { .. } => "data",
            Self::CgroupV2 { .. } => "cgroup_v2",
            Self::CgroupV1 { .. } => "cgroup_v1",
            Self::Fallback => "fallback",
        }
    }
}

/// What follows "only N" in messages: the verb and the limit, with its numbers.
impl fmt::Display for MemoryLimit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Available { .. } => write!(f, "is available (MemAvailable)"),
            Self::AddressSpace { limit, mapped } => write!(
                f,
                "is left under the process's address-space limit (RLIMIT_AS, ulimit -v) of {}, \
                 {} of which is mapped already",
                Bytes(*limit),
                Bytes(*mapped)
            ),
            Self::Data { limit, mapped } => write!(
                f,
                "is left under the process's data limit (RLIMIT_DATA, ulimit -d) of {}, {} of \
                 which is in use already",
                Bytes(*limit),
                Bytes(*mapped)
            ),
            Self::CgroupV2 { dir, max, used } => write!(
                f,
                "is left under the cgroup memory limit of {} ({}/memory.max), {} of which is \
                 in use",
                Bytes(*max),
                dir.display(),
                Bytes(*used)
            ),
            Self::CgroupV1 { dir, limit, used } => write!(
                f,
                "is left under the cgroup memory limit of {} ({}), {} of which is in use",
                Bytes(*limit),
                dir.display(),
                Bytes(*used)
            ),
            Self::Fallback => write!(f, "is allowed (the available memory could not be read)"),
        }
    }
}

/// Every memory limit that applies to the process; the budget is the least of them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct MemoryBudget {
    /// The limits found (empty: none could be read).
    pub limits: Vec<MemoryLimit>,
}

impl MemoryBudget {
    /// The limits of this process now ([`SystemFiles::live`]).
    pub fn read() -> Self {
        SystemFiles::live().memory_budget()
    }

    /// The limit that leaves the least ([`MemoryLimit::Fallback`] when none was found).
    pub fn binding(&self) -> MemoryLimit {
        self.limits
            .iter()
            .min_by_key(|l| l.remaining())
            .cloned()
            .unwrap_or(MemoryLimit::Fallback)
    }

    /// Bytes left for new buffers: the least any limit leaves.
    pub fn bytes(&self) -> u64 {
        self.binding().remaining()
    }
}

/// The memory a render (or a load) could not have.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MemoryError {
    /// An image whose render buffers would not fit: refused before anything is allocated.
    #[error(
        "a {width}x{height} image needs about {} for its render buffers, but only {} {limit}; \
         choose a smaller --width/--height",
        Bytes(*needed), Bytes(limit.remaining())
    )]
    Image {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Estimated bytes the render buffers need (128-bit: exact for every u32 size, never
        /// saturated).
        needed: u128,
        /// The limit that leaves the least.
        limit: MemoryLimit,
    },
    /// A buffer the system refused to allocate.
    #[error(
        "out of memory: {} for {what} could not be allocated; {} {limit}",
        Bytes(*bytes), Bytes(limit.remaining())
    )]
    Allocation {
        /// What the buffer was for ("the film's colour").
        what: &'static str,
        /// Its size in bytes.
        bytes: u128,
        /// The limit that left the least when it failed.
        limit: MemoryLimit,
    },
}

impl MemoryError {
    /// The bytes that were needed (the image's estimate, or the refused buffer).
    pub fn needed(&self) -> u128 {
        match self {
            Self::Image { needed, .. } => *needed,
            Self::Allocation { bytes, .. } => *bytes,
        }
    }

    /// The limit that left the least.
    pub fn limit(&self) -> &MemoryLimit {
        match self {
            Self::Image { limit, .. } | Self::Allocation { limit, .. } => limit,
        }
    }

    /// A failed allocation of `bytes` for `what`, with the budget read now.
    pub fn allocation(what: &'static str, bytes: u128) -> Self {
        Self::Allocation {
            what,
            bytes,
            limit: MemoryBudget::read().binding(),
        }
    }
}

/// A byte count for people: "1.5 GiB".
#[derive(Debug, Clone, Copy)]
pub struct Bytes<T = u64>(pub T);

impl<T: Copy + Into<u128>> fmt::Display for Bytes<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const UNITS: [&str; 9] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB", "ZiB", "YiB"];
        let bytes: u128 = self.0.into();
        let mut v = bytes as f64;
        let mut unit = 0;
        while v >= 1024.0 && unit + 1 < UNITS.len() {
            v /= 1024.0;
            unit += 1;
        }
        if unit == 0 {
            write!(f, "{bytes} B")
        } else {
            write!(f, "{v:.1} {}", UNITS[unit])
        }
    }
}

/// Estimated bytes the render buffers of a `width` x `height` image need.
pub fn image_memory_bytes(width: u32, height: u32) -> u128 {
    width as u128 * height as u128 * BYTES_PER_PIXEL as u128
}

/// `MemAvailable` from `/proc/meminfo`, in bytes, if it can be read.
pub fn available_memory() -> Option<u64> {
    SystemFiles::live()
        .read("/proc/meminfo")
        .and_then(|t| parse_meminfo(&t))
}

/// A `kB` (or unitless) value after `key` on its line of a `/proc` text (`/proc/meminfo`,
/// `/proc/self/status`), in bytes.
fn parse_kib_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find_map(|l| l.strip_prefix(key))?;
    let mut words = line.strip_prefix(':')?.split_whitespace();
    let value: u64 = words.next()?.parse().ok()?;
    let scale = match words.next() {
        Some("kB") | Some("KB") | Some("kiB") => 1024,
        None => 1,
        Some(_) => return None,
    };
    value.checked_mul(scale)
}

/// The `MemAvailable` line of a `/proc/meminfo` text, in bytes.
pub fn parse_meminfo(text: &str) -> Option<u64> {
    parse_kib_field(text, "MemAvailable")
}

/// A `/proc/self/status` field (`VmSize`, `VmData`), in bytes.
pub fn parse_status_field(text: &str, key: &str) -> Option<u64> {
    parse_kib_field(text, key)
}

/// The soft limit of a resource in a `/proc/self/limits` text (`"Max address space"`, `"Max
/// data size"`), in its units: `Some(None)` when it is `unlimited`, `None` when the line is
/// missing or unreadable.
pub fn parse_proc_limit(text: &str, name: &str) -> Option<Option<u64>> {
    let rest = text.lines().find_map(|l| l.strip_prefix(name))?;
    // Names are padded with spaces; the next word starts the soft limit.
    if !rest.starts_with(' ') {
        return None;
    }
    match rest.split_whitespace().next()? {
        "unlimited" => Some(None),
        n => Some(Some(n.parse().ok()?)),
    }
}

/// A cgroup memory value (`memory.max`, `memory.current`, `memory.limit_in_bytes`, ...):
/// `Some(None)` for `max` or a value of 2^60 or more (no limit).
pub fn parse_cgroup_value(text: &str) -> Option<Option<u64>> {
    match text.trim() {
        "max" => Some(None),
        n => {
            let v: u64 = n.parse().ok()?;
            Some((v < UNLIMITED).then_some(v))
        }
    }
}

/// A `key value` line of a cgroup `memory.stat` text.
pub fn parse_memory_stat(text: &str, key: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let mut words = l.split_whitespace();
        (words.next()? == key).then(|| words.next()?.parse().ok())?
    })
}

/// The process's cgroups from a `/proc/self/cgroup` text: the cgroup v2 path (the `0::` line)
/// and the cgroup v1 path of the `memory` controller, each if present.
pub fn parse_proc_cgroup(text: &str) -> (Option<String>, Option<String>) {
    let (mut v2, mut v1) = (None, None);
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        if id == "0" && controllers.is_empty() {
            v2 = Some(path.to_string());
        } else if controllers.split(',').any(|c| c == "memory") {
            v1 = Some(path.to_string());
        }
    }
    (v2, v1)
}

/// A cgroup file system mount from `/proc/self/mountinfo`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CgroupMount {
    /// Version 2 (`cgroup2`), else 1 with the memory controller.
    pub v2: bool,
    /// The cgroup mounted there, in the hierarchy (`/` for the whole of it).
    pub root: String,
    /// Where it is mounted.
    pub mount_point: PathBuf,
}

/// `\040`-style octal escapes of mountinfo fields (spaces, tabs, newlines, backslashes).
fn unescape_mountinfo(field: &str) -> String {
    let bytes = field.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let octal = bytes
            .get(i + 1..i + 4)
            .filter(|d| d.iter().all(|b| (b'0'..=b'7').contains(b)));
        match (bytes[i], octal) {
            (b'\\', Some(d)) => {
                let v = d.iter().fold(0u32, |v, b| v * 8 + u32::from(b - b'0'));
                out.push(v as u8);
                i += 4;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The cgroup v2 mounts and the cgroup v1 mounts with the memory controller in a
/// `/proc/self/mountinfo` text (`id parent dev root mount-point options [tags] - type source
/// super-options`).
pub fn parse_mountinfo(text: &str) -> Vec<CgroupMount> {
    text.lines()
        .filter_map(|line| {
            let (head, tail) = line.split_once(" - ")?;
            let head: Vec<&str> = head.split(' ').collect();
            let mut tail = tail.split(' ');
            let (fstype, _source, options) = (tail.next()?, tail.next()?, tail.next()?);
            let v2 = match fstype {
                "cgroup2" => true,
                "cgroup" if options.split(',').any(|o| o == "memory") => false,
                _ => return None,
            };
            Some(CgroupMount {
                v2,
                root: unescape_mountinfo(head.get(3)?),
                mount_point: PathBuf::from(unescape_mountinfo(head.get(4)?)),
            })
        })
        .collect()
}

/// The directory of cgroup `path` under `mount` (`None` if the mount does not hold it).
fn cgroup_dir(mount: &CgroupMount, path: &str) -> Option<PathBuf> {
    let relative = Path::new(path).strip_prefix(&mount.root).ok()?;
    Some(mount.mount_point.join(relative))
}

/// Where the memory limits are read from: the live system's `/proc` and `/sys`, or (for
/// tests) a directory standing in for `/`.
#[derive(Debug, Clone)]
pub struct SystemFiles {
    root: PathBuf,
}

impl SystemFiles {
    /// This process's own files.
    pub fn live() -> Self {
        Self {
            root: PathBuf::from("/"),
        }
    }

    /// The files under `root` in place of `/` (`root/proc/self/limits`, ...).
    pub fn under(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The text of the file at absolute path `path`, if it can be read.
    fn read(&self, path: impl AsRef<Path>) -> Option<String> {
        let path = path.as_ref();
        let path = path.strip_prefix("/").unwrap_or(path);
        std::fs::read_to_string(self.root.join(path)).ok()
    }

    /// Every memory limit that applies (see the module documentation).
    pub fn memory_budget(&self) -> MemoryBudget {
        let mut limits = Vec::new();
        if let Some(available) = self.read("/proc/meminfo").and_then(|t| parse_meminfo(&t)) {
            limits.push(MemoryLimit::Available { available });
        }
        limits.extend(self.rlimits());
        limits.extend(self.cgroup_limits());
        MemoryBudget { limits }
    }

    /// The address-space and data limits, when set, with what is mapped under each.
    fn rlimits(&self) -> Vec<MemoryLimit> {
        let (Some(limits), status) = (
            self.read("/proc/self/limits"),
            self.read("/proc/self/status"),
        ) else {
            return Vec::new();
        };
        let status = status.unwrap_or_default();
        let mut out = Vec::new();
        let mapped = |key| parse_status_field(&status, key).unwrap_or(0);
        if let Some(Some(limit)) = parse_proc_limit(&limits, "Max address space") {
            out.push(MemoryLimit::AddressSpace {
                limit,
                mapped: mapped("VmSize"),
            });
        }
        if let Some(Some(limit)) = parse_proc_limit(&limits, "Max data size") {
            out.push(MemoryLimit::Data {
                limit,
                mapped: mapped("VmData"),
            });
        }
        out
    }

    /// The memory limits of the process's cgroup and its ancestors (v2: every level up to the
    /// mount; v1: the cgroup's own limit and its hierarchical one).
    fn cgroup_limits(&self) -> Vec<MemoryLimit> {
        let Some(cgroup) = self.read("/proc/self/cgroup") else {
            return Vec::new();
        };
        let (v2_path, v1_path) = parse_proc_cgroup(&cgroup);
        let mut mounts = self
            .read("/proc/self/mountinfo")
            .map(|t| parse_mountinfo(&t))
            .unwrap_or_default();
        // Without mountinfo, the usual places.
        for (v2, point) in [(true, "/sys/fs/cgroup"), (false, "/sys/fs/cgroup/memory")] {
            if !mounts.iter().any(|m| m.v2 == v2) {
                mounts.push(CgroupMount {
                    v2,
                    root: "/".into(),
                    mount_point: point.into(),
                });
            }
        }
        let mut out = Vec::new();
        if let Some(path) = v2_path {
            for mount in mounts.iter().filter(|m| m.v2) {
                if let Some(dir) = cgroup_dir(mount, &path) {
                    out.extend(self.cgroup_v2(&dir, &mount.mount_point));
                    break;
                }
            }
        }
        if let Some(path) = v1_path {
            for mount in mounts.iter().filter(|m| !m.v2) {
                if let Some(dir) = cgroup_dir(mount, &path) {
                    out.extend(self.cgroup_v1(&dir));
                    break;
                }
            }
        }
        out
    }

    /// The least `memory.max - memory.current` of `dir` and its ancestors up to `top`.
    fn cgroup_v2(&self, dir: &Path, top: &Path) -> Option<MemoryLimit> {
        let mut least: Option<MemoryLimit> = None;
        for level in dir.ancestors().take_while(|d| d.starts_with(top)) {
            let Some(Some(max)) = self
                .read(level.join("memory.max"))
                .and_then(|t| parse_cgroup_value(&t))
            else {
                continue;
            };
            let current = self
                .read(level.join("memory.current"))
                .and_then(|t| parse_cgroup_value(&t).flatten())
                .unwrap_or(0);
            let reclaimable = self
                .read(level.join("memory.stat"))
                .and_then(|t| parse_memory_stat(&t, "inactive_file"))
                .unwrap_or(0);
            let limit = MemoryLimit::CgroupV2 {
                dir: level.to_path_buf(),
                max,
                used: current.saturating_sub(reclaimable),
            };
            if least
                .as_ref()
                .is_none_or(|l| limit.remaining() < l.remaining())
            {
                least = Some(limit);
            }
        }
        least
    }

    /// `dir`'s limit (the smaller of `memory.limit_in_bytes` and the hierarchical limit in
    /// `memory.stat`) less its usage.
    fn cgroup_v1(&self, dir: &Path) -> Option<MemoryLimit> {
        let stat = self.read(dir.join("memory.stat")).unwrap_or_default();
        let own = self
            .read(dir.join("memory.limit_in_bytes"))
            .and_then(|t| parse_cgroup_value(&t).flatten());
        let hierarchical =
            parse_memory_stat(&stat, "hierarchical_memory_limit").filter(|&v| v < UNLIMITED);
        let limit = own.into_iter().chain(hierarchical).min()?;
        let usage = self
            .read(dir.join("memory.usage_in_bytes"))
            .and_then(|t| parse_cgroup_value(&t).flatten())
            .unwrap_or(0);
        let reclaimable = parse_memory_stat(&stat, "total_inactive_file")
            .or_else(|| parse_memory_stat(&stat, "inactive_file"))
            .unwrap_or(0);
        Some(MemoryLimit::CgroupV1 {
            dir: dir.to_path_buf(),
            limit,
            used: usage.saturating_sub(reclaimable),
        })
    }
}

/// The number of threads this process has now (Linux: `Threads:` in `/proc/self/status`), or
/// `None` where that cannot be read. With `--threads N` that is at most 2N + 1: N render
/// workers, Embree's BVH builders (the main thread and N - 1 workers, idle while the render
/// runs) and the command line's signal listener (which only waits, see `output::atomic`).
pub fn process_threads() -> Option<usize> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|line| line.strip_prefix("Threads:"))
        .and_then(|n| n.trim().parse().ok())
}

/// The largest coordinate magnitude accepted anywhere in a scene (camera, lens, geometry after
/// its transform, lights), in scene units. Every ray dofray makes then starts within a few times
/// this of the origin, far inside the range Embree accepts (about 1.8e19), and f32 positions
/// this large are already 1e8 apart, so nothing meaningful is lost.
pub const MAX_COORDINATE: f32 = 1e15;

/// The most worker threads `--threads` accepts: far more than any machine's cores, few enough
/// that a typo cannot ask the system for thousands of threads.
pub const MAX_THREADS: usize = 1024;

/// Refuses a `width` x `height` image whose render buffers ([`BYTES_PER_PIXEL`] per pixel)
/// would need more than the memory budget ([`MemoryBudget::read`]: the least of
/// `MemAvailable`, the address-space and data limits and the cgroup limits; else
/// [`FALLBACK_LIMIT_BYTES`]).
pub fn check_image_memory(width: u32, height: u32) -> Result<(), MemoryError> {
    check_image_memory_against(width, height, &MemoryBudget::read().binding())
}

/// [`check_image_memory`] against a given limit (for tests and for callers with their own).
pub fn check_image_memory_against(
    width: u32,
    height: u32,
    limit: &MemoryLimit,
) -> Result<(), MemoryError> {
    let needed = image_memory_bytes(width, height);
    if needed > limit.remaining() as u128 {
        Err(MemoryError::Image {
            width,
            height,
            needed,
            limit: limit.clone(),
        })
    } else {
        Ok(())
    }
}

/// Refuses `bytes` for `what` when the memory budget ([`MemoryBudget::read`]) leaves less:
/// for memory that third-party code allocates infallibly, or that a cgroup would grant and
/// then reclaim with its OOM killer, so nothing could fail later with an error.
pub fn check_budget(what: &'static str, bytes: u128) -> Result<(), MemoryError> {
    let limit = MemoryBudget::read().binding();
    if bytes > u128::from(limit.remaining()) {
        return Err(MemoryError::Allocation { what, bytes, limit });
    }
    Ok(())
}

/// An empty vector with room for exactly `n` elements, or [`MemoryError::Allocation`] (naming
/// `what`) when the allocator refuses, instead of aborting the process.
pub fn try_with_capacity<T>(n: usize, what: &'static str) -> Result<Vec<T>, MemoryError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| MemoryError::allocation(what, n as u128 * size_of::<T>() as u128))?;
    Ok(v)
}

/// `n` copies of `value` ([`vec!`]), allocated fallibly ([`try_with_capacity`]).
pub fn try_vec<T: Clone>(n: usize, value: T, what: &'static str) -> Result<Vec<T>, MemoryError> {
    let mut v = try_with_capacity(n, what)?;
    v.resize(n, value);
    Ok(v)
}

/// The items of `iter` ([`Iterator::collect`]), whose count is known, allocated fallibly
/// ([`try_with_capacity`]).
pub fn try_collect<I>(iter: I, what: &'static str) -> Result<Vec<I::Item>, MemoryError>
where
    I: IntoIterator,
    I::IntoIter: ExactSizeIterator,
{
    let iter = iter.into_iter();
    let mut v = try_with_capacity(iter.len(), what)?;
    v.extend(iter);
    Ok(v)
}

/// A copy of `src` ([`<[T]>::to_vec`]), allocated fallibly ([`try_with_capacity`]).
pub fn try_copy<T: Clone>(src: &[T], what: &'static str) -> Result<Vec<T>, MemoryError> {
    let mut v = try_with_capacity(src.len(), what)?;
    v.extend_from_slice(src);
    Ok(v)
}

impl HasKind for MemoryError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::ResourceLimit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meminfo_is_parsed_in_kib() {
        let text = "MemTotal:       16310060 kB\nMemFree:  100 kB\nMemAvailable:    8000000 kB\n";
        assert_eq!(parse_meminfo(text), Some(8_000_000 * 1024));
        assert_eq!(parse_meminfo("MemTotal: 5 kB\n"), None);
        assert_eq!(parse_meminfo("MemAvailable: lots kB\n"), None);
        assert_eq!(parse_meminfo("MemAvailableX: 5 kB\n"), None);
    }

    /// `/proc/self/limits` as Linux 6.1 writes it, with `ulimit -v 3000000 -d unlimited`.
    const LIMITS: &str = "\
Limit                     Soft Limit           Hard Limit           Units     
Max cpu time              unlimited            unlimited            seconds   
Max file size             unlimited            unlimited            bytes     
Max data size             unlimited            unlimited            bytes     
Max stack size            8388608              unlimited            bytes     
Max core file size        0                    unlimited            bytes     
Max resident set          unlimited            unlimited            bytes     
Max processes             96551                96551                processes 
Max open files            20000                20000                files     
Max locked memory         8388608              8388608              bytes     
Max address space         3072000000           unlimited            bytes     
Max file locks            unlimited            unlimited            locks     
";

    #[test]
    fn rlimits_are_read_from_proc_self_limits() {
        // The soft limit, the one that applies; `unlimited` is no limit; a missing line None.
        assert_eq!(
            parse_proc_limit(LIMITS, "Max address space"),
            Some(Some(3_072_000_000))
        );
        assert_eq!(parse_proc_limit(LIMITS, "Max data size"), Some(None));
        assert_eq!(
            parse_proc_limit(LIMITS, "Max stack size"),
            Some(Some(8388608))
        );
        assert_eq!(parse_proc_limit(LIMITS, "Max msgqueue size"), None);
        assert_eq!(
            parse_proc_limit("Max address spaceX 5 5 bytes", "Max address space"),
            None
        );
        assert_eq!(
            parse_proc_limit("Max address space  many", "Max address space"),
            None
        );
        let status =
            "Name:\tdofray\nVmPeak:\t  300000 kB\nVmSize:\t  262144 kB\nVmData:\t   1024 kB\n";
        assert_eq!(parse_status_field(status, "VmSize"), Some(256 << 20));
        assert_eq!(parse_status_field(status, "VmData"), Some(1 << 20));
        assert_eq!(parse_status_field(status, "VmRSS"), None);
    }

    #[test]
    fn cgroup_files_are_parsed() {
        assert_eq!(parse_cgroup_value("max\n"), Some(None));
        assert_eq!(parse_cgroup_value("2147483648\n"), Some(Some(2 << 30)));
        // cgroup v1's "unlimited" (PAGE_COUNTER_MAX pages).
        assert_eq!(parse_cgroup_value("9223372036854771712\n"), Some(None));
        assert_eq!(parse_cgroup_value("lots"), None);
        let stat = "anon 100\nfile 5000\ninactive_file 4096\nhierarchical_memory_limit 1024\n";
        assert_eq!(parse_memory_stat(stat, "inactive_file"), Some(4096));
        assert_eq!(parse_memory_stat(stat, "file"), Some(5000));
        assert_eq!(parse_memory_stat(stat, "active_file"), None);
        // A hybrid system: v1 controllers and the unified hierarchy.
        let cgroup = "12:pids:/user.slice\n4:memory:/process_api/abc\n1:name=systemd:/x\n0::/user.slice/u.scope\n";
        assert_eq!(
            parse_proc_cgroup(cgroup),
            (
                Some("/user.slice/u.scope".into()),
                Some("/process_api/abc".into())
            )
        );
        assert_eq!(parse_proc_cgroup("0::/\n"), (Some("/".into()), None));
        assert_eq!(
            parse_proc_cgroup("3:cpu,memory:/a\n"),
            (None, Some("/a".into()))
        );
    }

    #[test]
    fn cgroup_mounts_are_found_in_mountinfo() {
        let text = "\
24 30 0:22 / /sys rw,nosuid - sysfs sysfs rw
31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755
35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory
36 31 0:33 / /sys/fs/cgroup/cpu rw,relatime - cgroup cgroup rw,cpu
41 31 0:38 /docker/abc /sys/fs/cgroup/uni\\040fied rw,relatime shared:9 - cgroup2 cgroup2 rw
";
        let mounts = parse_mountinfo(text);
        assert_eq!(
            mounts,
            vec![
                CgroupMount {
                    v2: false,
                    root: "/".into(),
                    mount_point: "/sys/fs/cgroup/memory".into()
                },
                CgroupMount {
                    v2: true,
                    root: "/docker/abc".into(),
                    mount_point: "/sys/fs/cgroup/uni fied".into()
                },
            ]
        );
        // A cgroup path is relative to the mount's root.
        assert_eq!(
            cgroup_dir(&mounts[1], "/docker/abc/inner"),
            Some("/sys/fs/cgroup/uni fied/inner".into())
        );
        assert_eq!(cgroup_dir(&mounts[1], "/other"), None);
        assert_eq!(
            cgroup_dir(&mounts[0], "/"),
            Some("/sys/fs/cgroup/memory".into())
        );
    }

    /// A directory standing in for `/`, with `files` (absolute path, text) written into it;
    /// removed when it is dropped.
    fn fake_root(name: &str, files: &[(&str, &str)]) -> tempfile::TempDir {
        let root = tempfile::Builder::new()
            .prefix(&format!("dofray-limits-{name}-"))
            .tempdir()
            .unwrap();
        for (path, text) in files {
            let path = root.path().join(path.trim_start_matches('/'));
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        }
        root
    }

    const MEMINFO: &str = "MemTotal: 32000000 kB\nMemAvailable: 16000000 kB\n";

    #[test]
    fn the_budget_is_the_least_limit_cgroup_v2_counting_ancestors() {
        let root = fake_root(
            "v2",
            &[
                ("/proc/meminfo", MEMINFO),
                ("/proc/self/limits", LIMITS),
                (
                    "/proc/self/status",
                    "VmSize:\t 1000000 kB\nVmData:\t 1000 kB\n",
                ),
                ("/proc/self/cgroup", "0::/jobs/render\n"),
                (
                    "/proc/self/mountinfo",
                    "41 31 0:38 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n",
                ),
                // The job's own cgroup has no limit; its parent allows 1 GiB, of which 600 MiB
                // are used but 200 MiB are reclaimable page cache.
                ("/sys/fs/cgroup/jobs/render/memory.max", "max\n"),
                ("/sys/fs/cgroup/jobs/render/memory.current", "104857600\n"),
                ("/sys/fs/cgroup/jobs/memory.max", "1073741824\n"),
                ("/sys/fs/cgroup/jobs/memory.current", "629145600\n"),
                (
                    "/sys/fs/cgroup/jobs/memory.stat",
                    "anon 1\ninactive_file 209715200\n",
                ),
            ],
        );
        let budget = SystemFiles::under(root.path()).memory_budget();
        assert_eq!(budget.limits.len(), 3, "{budget:?}");
        assert_eq!(
            budget.limits[1],
            MemoryLimit::AddressSpace {
                limit: 3_072_000_000,
                mapped: 1_024_000_000
            }
        );
        let cgroup = MemoryLimit::CgroupV2 {
            dir: "/sys/fs/cgroup/jobs".into(),
            max: 1 << 30,
            used: 400 << 20,
        };
        assert_eq!(budget.binding(), cgroup);
        assert_eq!(budget.bytes(), 624 << 20);
        let e = check_image_memory_against(4000, 3000, &budget.binding()).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("4000x3000")
                && m.contains("1.4 GiB")
                && m.contains("only 624.0 MiB is left under the cgroup memory limit of 1.0 GiB")
                && m.contains("/sys/fs/cgroup/jobs/memory.max")
                && m.contains("400.0 MiB of which is in use"),
            "{m}"
        );
    }

    #[test]
    fn the_address_space_limit_counts_what_is_mapped() {
        let root = fake_root(
            "as",
            &[
                ("/proc/meminfo", MEMINFO),
                ("/proc/self/limits", LIMITS),
                (
                    "/proc/self/status",
                    "VmSize:\t 2000000 kB\nVmData:\t 1000 kB\n",
                ),
                // cgroup v2 at the root: no memory.max there.
                ("/proc/self/cgroup", "0::/\n"),
                (
                    "/proc/self/mountinfo",
                    "41 31 0:38 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n",
                ),
                ("/sys/fs/cgroup/memory.current", "5\n"),
            ],
        );
        let budget = SystemFiles::under(root.path()).memory_budget();
        assert_eq!(budget.limits.len(), 2, "{budget:?}");
        assert_eq!(budget.bytes(), 3_072_000_000 - 2_048_000_000);
        let e = check_image_memory_against(1, 200_000_000, &budget.binding()).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("1x200000000 image needs about 23.8 GiB")
                && m.contains("only 976.6 MiB is left under the process's address-space limit")
                && m.contains("ulimit -v")
                && m.contains("of 2.9 GiB, 1.9 GiB of which is mapped already"),
            "{m}"
        );
        assert_eq!(e.limit().name(), "address_space");
    }

    #[test]
    fn cgroup_v1_takes_the_smaller_of_its_own_and_the_hierarchical_limit() {
        let dir = "/sys/fs/cgroup/memory/process_api/abc";
        let files = |limit: &'static str| {
            vec![
                ("/proc/self/cgroup", "4:memory:/process_api/abc\n0::/\n"),
                (
                    "/proc/self/mountinfo",
                    "35 31 0:32 / /sys/fs/cgroup/memory rw - cgroup cgroup rw,memory\n",
                ),
                (
                    "/sys/fs/cgroup/memory/process_api/abc/memory.limit_in_bytes",
                    limit,
                ),
                (
                    "/sys/fs/cgroup/memory/process_api/abc/memory.usage_in_bytes",
                    "300000000\n",
                ),
                (
                    "/sys/fs/cgroup/memory/process_api/abc/memory.stat",
                    "cache 1\ninactive_file 5\nhierarchical_memory_limit 2000000000\ntotal_inactive_file 100000000\n",
                ),
            ]
        };
        let root = fake_root("v1", &files("9223372036854771712\n"));
        let budget = SystemFiles::under(root.path()).memory_budget();
        let want = |limit| MemoryLimit::CgroupV1 {
            dir: dir.into(),
            limit,
            used: 200_000_000,
        };
        assert_eq!(budget.limits, vec![want(2_000_000_000)]);
        let root = fake_root("v1-own", &files("1000000000\n"));
        let budget = SystemFiles::under(root.path()).memory_budget();
        assert_eq!(budget.limits, vec![want(1_000_000_000)]);
        assert_eq!(budget.bytes(), 800_000_000);
        // Unlimited everywhere: no cgroup limit.
        let root = fake_root("v1-none", &files("9223372036854771712\n")[..4]);
        assert_eq!(
            SystemFiles::under(root.path()).memory_budget().limits,
            vec![]
        );
        // Nothing readable at all: the fallback cap.
        assert_eq!(
            SystemFiles::under(root.path()).memory_budget().bytes(),
            FALLBACK_LIMIT_BYTES
        );
    }

    #[test]
    fn the_live_budget_is_read() {
        let budget = MemoryBudget::read();
        assert!(
            budget.limits.iter().any(|l| l.name() == "available"),
            "{budget:?}"
        );
        assert!(budget.bytes() > 0);
    }

    #[test]
    fn sizes_beyond_the_budget_are_refused_with_the_need() {
        let gib = MemoryLimit::Available { available: 1 << 30 };
        assert!(check_image_memory_against(640, 480, &gib).is_ok());
        let e = check_image_memory_against(100_000, 100_000, &gib).unwrap_err();
        assert_eq!(e.needed(), 100_000 * 100_000 * BYTES_PER_PIXEL as u128);
        let msg = e.to_string();
        assert!(
            msg.contains("100000x100000") && msg.contains("1.2 TiB"),
            "{msg}"
        );
        assert!(
            msg.contains("only 1.0 GiB is available (MemAvailable)"),
            "{msg}"
        );
        assert_eq!(Bytes(512u64).to_string(), "512 B");
        let e = check_image_memory_against(100, 100, &MemoryLimit::Fallback).map(|_| ());
        assert!(e.is_ok());
    }

    #[test]
    fn the_real_check_accepts_small_and_refuses_absurd_sizes() {
        assert!(check_image_memory(64, 48).is_ok());
        let e = check_image_memory(u32::MAX, u32::MAX).unwrap_err();
        // 4294967295^2 x 128 bytes = 2.36e21 bytes = 2.0 ZiB, more than u64 holds: not saturated.
        assert_eq!(e.needed(), 2_361_183_240_335_310_979_200);
        assert!(e.to_string().contains("2.0 ZiB"), "{e}");
    }

    #[test]
    fn allocations_the_system_refuses_are_errors_not_aborts() {
        // More than the address space holds: the allocator refuses (no abort).
        let e = try_vec(isize::MAX as usize / 2, 0u8, "a test buffer").unwrap_err();
        assert!(matches!(
            e,
            MemoryError::Allocation {
                what: "a test buffer",
                ..
            }
        ));
        let m = e.to_string();
        assert!(
            m.starts_with("out of memory: 4.0 EiB for a test buffer could not be allocated; "),
            "{m}"
        );
        // A size whose bytes overflow usize.
        assert!(try_with_capacity::<u64>(usize::MAX / 2, "x").is_err());
        assert_eq!(try_vec(3, 7u32, "x").unwrap(), vec![7, 7, 7]);
        assert_eq!(
            try_collect([1, 2].iter().map(|v| v * 2), "x").unwrap(),
            vec![2, 4]
        );
        assert_eq!(try_copy(&[1u8, 2], "x").unwrap(), vec![1, 2]);
    }
}
