//! Temporary files that never outlive the process, and the atomic write built on them.
//!
//! Every file dofray writes is first written to a hidden temporary file next to its target,
//! `.{name}.tmp-{pid}-{n}`, and renamed over the target once complete. Each temporary file is
//! listed in a process-wide registry while it exists: dropping a [`TempFile`] removes it, and
//! [`remove_all_for_exit`] removes every listed file for a process that is about to exit (the
//! `dofray` command calls it on SIGINT, SIGTERM and SIGHUP before exiting with 128 + the
//! signal's number), so an interrupted render or write leaves nothing behind. A process killed outright
//! (SIGKILL, a power cut) cannot clean up: the next write to the same target removes the
//! temporary files of that target whose process no longer exists.

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};

use super::OutputError;

/// The temporary files that exist right now. [`remove_all_for_exit`] takes this lock and never
/// releases it (the process exits), so no temporary file can appear after its clean-up.
static REGISTRY: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn registry() -> MutexGuard<'static, Vec<PathBuf>> {
    // The list stays valid even if a thread panicked while holding the lock.
    REGISTRY.lock().unwrap_or_else(|e| e.into_inner())
}

/// The directory `path` would be written into ("." for a bare file name).
pub(crate) fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Removes `.{name}.tmp-{pid}-{n}` files in `dir` left by processes that no longer exist
/// (`/proc/{pid}` is gone; where `/proc` is missing nothing is removed). Only this target's own
/// temporary names are touched; a file whose process is alive (or whose name does not parse)
/// is left alone. Failures are ignored: sweeping is a courtesy, never a reason not to write.
fn sweep_stale(dir: &Path, name: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let prefix = format!(".{name}.tmp-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(rest) = file_name.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        let Some((pid, n)) = rest.split_once('-') else {
            continue;
        };
        let (Ok(pid), Ok(_)) = (pid.parse::<u32>(), n.parse::<u64>()) else {
            continue;
        };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// A registered hidden temporary file next to a target; removed on drop unless persisted.
#[derive(Debug)]
pub struct TempFile {
    path: PathBuf,
    target: PathBuf,
    file: File,
}

impl TempFile {
    /// Creates a fresh temporary file in `target`'s directory, `.{name}.tmp-{pid}-{n}`.
    /// `target` is used as given: resolve symbolic links first (see [`super::resolve_target`]).
    pub fn create(target: &Path) -> std::io::Result<Self> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".to_owned());
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        sweep_stale(parent_dir(target), &name);
        let path = parent_dir(target).join(format!(".{name}.tmp-{}-{n}", std::process::id()));
        // Created and listed under the lock, so a signal sees every file that exists.
        let mut list = registry();
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)?;
        list.push(path.clone());
        drop(list);
        Ok(Self {
            path,
            target: target.to_path_buf(),
            file,
        })
    }

    /// The temporary file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The open temporary file, for writing.
    pub fn file(&mut self) -> &mut File {
        &mut self.file
    }

    /// Flushes the file to disk and renames it over the target (the file is closed when
    /// `self` drops, after the rename: fine on Unix, where renaming an open file is allowed).
    pub fn persist(self) -> std::io::Result<()> {
        self.file.sync_all()?;
        std::fs::rename(&self.path, &self.target)?;
        unregister(&self.path);
        Ok(())
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if unregister(&self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Removes `path` from the registry; whether it was listed.
fn unregister(path: &Path) -> bool {
    let mut list = registry();
    match list.iter().position(|p| p == path) {
        Some(i) => {
            list.swap_remove(i);
            true
        }
        None => false,
    }
}

/// Runs `write` on a temporary file next to `target` (already resolved), then syncs it and
/// renames it over `target`. On any error the temporary file is removed and `target` is left
/// untouched. Errors name `shown`, the path the caller was given.
pub(crate) fn write_atomic(
    shown: &Path,
    target: &Path,
    write: impl FnOnce(&mut File) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    let io_err = |source| OutputError::Io {
        path: shown.to_path_buf(),
        source,
    };
    let mut tmp = TempFile::create(target).map_err(io_err)?;
    write(tmp.file())?;
    tmp.persist().map_err(io_err)
}

/// Removes every temporary file that exists now, for a process about to exit (on a signal):
/// returns the paths it removed. The registry's lock is taken and never released, so no
/// temporary file can appear after the clean-up (a thread that tries to create one waits
/// until the process exits). Safe to call from any thread, e.g. one that waits for signals;
/// the caller then exits without unwinding (`_exit`).
pub fn remove_all_for_exit() -> Vec<PathBuf> {
    let list = registry();
    let removed = list
        .iter()
        .filter(|path| std::fs::remove_file(path).is_ok())
        .cloned()
        .collect();
    std::mem::forget(list);
    removed
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write as _;

    #[test]
    fn temp_files_are_listed_while_they_exist_and_removed_on_drop() {
        let dir = tempfile::Builder::new()
            .prefix("dofray-atomic-")
            .tempdir()
            .unwrap();
        let target = dir.path().join("t.png");
        let mut tmp = TempFile::create(&target).unwrap();
        let path = tmp.path().to_path_buf();
        assert!(path.is_file());
        assert!(registry().contains(&path));
        tmp.file().write_all(b"x").unwrap();
        drop(tmp);
        assert!(!path.exists() && !registry().contains(&path));

        let mut tmp = TempFile::create(&target).unwrap();
        let path = tmp.path().to_path_buf();
        tmp.file().write_all(b"done").unwrap();
        tmp.persist().unwrap();
        assert!(!path.exists() && !registry().contains(&path));
        assert_eq!(std::fs::read(&target).unwrap(), b"done");
        dir.close().unwrap();
    }
}
