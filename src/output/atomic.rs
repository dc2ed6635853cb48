//! Temporary files that never outlive the process, and the atomic write built on them.
//!
//! Every file dofray writes is first written to a hidden temporary file next to its target,
//! `.{name}.tmp-{pid}-{n}`, and renamed over the target once complete. Each temporary file is
//! listed in a process-wide registry while it exists: dropping a [`TempFile`] removes it, and
//! [`clean_up_on_signals`] installs handlers for SIGINT, SIGTERM and SIGHUP that remove every
//! listed file and exit with the conventional status (128 + the signal's number: 130, 143,
//! 129), so an interrupted render or write leaves nothing behind. A process killed outright
//! (SIGKILL, a power cut) cannot clean up: the next write to the same target removes the
//! temporary files of that target whose process no longer exists.

use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};

use super::OutputError;

/// The temporary files that exist right now. The signal thread takes this lock and never
/// releases it (it exits the process), so no temporary file can appear after its clean-up.
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

/// Whether an interrupted run also prints its error as a `--json` object on stdout.
static JSON_ON_SIGNAL: AtomicBool = AtomicBool::new(false);

/// Installs (once per process) handlers for SIGINT, SIGTERM and SIGHUP that remove every
/// temporary file that exists, print `error: interrupted by SIG...` on stderr (and, with
/// `json`, the same error as a `--json` error object on stdout: [`crate::exit::json_error`])
/// and exit with status 128 + the signal's number (SIGINT 130, SIGTERM 143, SIGHUP 129).
#[cfg(unix)]
pub fn clean_up_on_signals(json: bool) -> Result<(), OutputError> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

    JSON_ON_SIGNAL.store(json, Ordering::SeqCst);
    static INSTALLED: Mutex<bool> = Mutex::new(false);
    let mut installed = INSTALLED.lock().unwrap_or_else(|e| e.into_inner());
    if *installed {
        return Ok(());
    }
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])
        .map_err(OutputError::Signals)?;
    std::thread::Builder::new()
        .name("dofray-signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                exit_on_signal(signal);
            }
        })
        .map_err(OutputError::Signals)?;
    *installed = true;
    Ok(())
}

/// Without Unix signals there is nothing to install; temporary files are still removed on
/// every error.
#[cfg(not(unix))]
pub fn clean_up_on_signals(json: bool) -> Result<(), OutputError> {
    JSON_ON_SIGNAL.store(json, Ordering::SeqCst);
    Ok(())
}

/// Removes every temporary file and exits with 128 + `signal`, holding the registry's lock so
/// no new temporary file can appear meanwhile.
#[cfg(unix)]
fn exit_on_signal(signal: i32) -> ! {
    let list = registry();
    let mut message = format!(
        "interrupted by {}",
        signal_hook::low_level::signal_name(signal).unwrap_or("a signal")
    );
    for path in list.iter() {
        if std::fs::remove_file(path).is_ok() {
            message.push_str(&format!("; removed the unfinished {}", path.display()));
        }
    }
    if JSON_ON_SIGNAL.load(Ordering::SeqCst) {
        let error = crate::exit::json_error(crate::exit::ErrorKind::Interrupted(signal), &message);
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{error}").and_then(|()| out.flush());
    }
    let _ = writeln!(std::io::stderr(), "error: {message}");
    // _exit: no atexit handlers or static destructors run while worker threads still trace.
    signal_hook::low_level::exit(128 + signal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temp_files_are_listed_while_they_exist_and_removed_on_drop() {
        let dir = std::env::temp_dir().join(format!("dofray-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("t.png");
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
        std::fs::remove_dir_all(dir).unwrap();
    }
}
