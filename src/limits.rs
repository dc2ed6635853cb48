//! Resource guards: refuse work whose buffers would not fit in memory, with a message that says
//! how much it would need, instead of being killed by the operating system halfway through.

use std::fmt;

use crate::error_kind::{ErrorKind, HasKind};

/// Bytes the renderer needs per image pixel, estimated with a safety margin. The film holds
/// colour (12 B), depth, CoC, interval and sample count (4 B each); the render modes make about
/// three more full-size temporary copies of the colour and the maps, and output conversion
/// needs one more 8-bit or float image: about 80 bytes per pixel in all.
pub const BYTES_PER_PIXEL: u64 = 80;

/// The cap used when the available memory cannot be read (no `/proc/meminfo`).
pub const FALLBACK_LIMIT_BYTES: u64 = 16 << 30;

/// An image too large for the memory there is.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "a {width}x{height} image needs about {} for its render buffers, but only {} is {}; \
     choose a smaller --width/--height",
    Bytes(*needed), Bytes(*available), if *measured { "available" } else { "allowed (the available memory could not be read)" }
)]
pub struct MemoryError {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Estimated bytes the render buffers need (128-bit: exact for every u32 size, never
    /// saturated).
    pub needed: u128,
    /// Bytes available (MemAvailable), or the fallback cap.
    pub available: u64,
    /// Whether `available` was read from the system (false: the fallback cap).
    pub measured: bool,
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
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_meminfo(&text)
}

/// The `MemAvailable` line of a `/proc/meminfo` text, in bytes.
pub fn parse_meminfo(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut words = line["MemAvailable:".len()..].split_whitespace();
    let value: u64 = words.next()?.parse().ok()?;
    let scale = match words.next() {
        Some("kB") | Some("KB") | Some("kiB") => 1024,
        None => 1,
        Some(_) => return None,
    };
    value.checked_mul(scale)
}

/// Refuses an image size whose render buffers would exceed the available memory
/// (`MemAvailable`, else [`FALLBACK_LIMIT_BYTES`]).
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
/// would need more than the available memory (`MemAvailable` in `/proc/meminfo`, else
/// [`FALLBACK_LIMIT_BYTES`]).
pub fn check_image_memory(width: u32, height: u32) -> Result<(), MemoryError> {
    match available_memory() {
        Some(available) => check_image_memory_against(width, height, available, true),
        None => check_image_memory_against(width, height, FALLBACK_LIMIT_BYTES, false),
    }
}

/// [`check_image_memory`] against a given budget (for tests and for callers with their own).
pub fn check_image_memory_against(
    width: u32,
    height: u32,
    available: u64,
    measured: bool,
) -> Result<(), MemoryError> {
    let needed = image_memory_bytes(width, height);
    if needed > available as u128 {
        Err(MemoryError {
            width,
            height,
            needed,
            available,
            measured,
        })
    } else {
        Ok(())
    }
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
    }

    #[test]
    fn sizes_beyond_the_budget_are_refused_with_the_need() {
        assert!(check_image_memory_against(640, 480, 1 << 30, true).is_ok());
        let e = check_image_memory_against(100_000, 100_000, 1 << 30, true).unwrap_err();
        assert_eq!(e.needed, 100_000 * 100_000 * BYTES_PER_PIXEL as u128);
        let msg = e.to_string();
        assert!(
            msg.contains("100000x100000") && msg.contains("745.1 GiB"),
            "{msg}"
        );
        assert!(msg.contains("1.0 GiB"), "{msg}");
        assert_eq!(Bytes(512u64).to_string(), "512 B");
    }

    #[test]
    fn the_real_check_accepts_small_and_refuses_absurd_sizes() {
        assert!(check_image_memory(64, 48).is_ok());
        let e = check_image_memory(u32::MAX, u32::MAX).unwrap_err();
        // 4294967295^2 x 80 bytes = 1.47e21 bytes = 1.2 ZiB, more than u64 holds: not saturated.
        assert_eq!(e.needed, 1_475_739_525_209_569_362_000);
        assert!(e.to_string().contains("1.2 ZiB"), "{e}");
    }
}
