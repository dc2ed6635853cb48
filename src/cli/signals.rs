//! SIGINT, SIGTERM and SIGHUP: remove the temporary files of unfinished outputs, say so, and
//! exit with 128 + the signal's number (130, 143, 129).

use std::io::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// Whether an interrupted run also prints its error as a `--json` object on stdout.
static JSON_ON_SIGNAL: AtomicBool = AtomicBool::new(false);

/// The signal handlers could not be installed (an internal error: no typed source, so it is
/// not mistaken for an output's I/O error).
#[derive(Debug, thiserror::Error)]
#[error("cannot install the SIGINT/SIGTERM handlers: {0}")]
pub(crate) struct SignalsError(std::io::Error);

/// Installs (once per process) handlers for SIGINT, SIGTERM and SIGHUP that remove every
/// temporary file that exists, print `error: interrupted by SIG...` on stderr (and, with
/// `json`, the same error as a `--json` error object on stdout) and exit with status 128 + the
/// signal's number (SIGINT 130, SIGTERM 143, SIGHUP 129).
#[cfg(unix)]
pub(crate) fn clean_up_on_signals(json: bool) -> Result<(), SignalsError> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

    JSON_ON_SIGNAL.store(json, Ordering::SeqCst);
    static INSTALLED: Mutex<bool> = Mutex::new(false);
    let mut installed = INSTALLED.lock().unwrap_or_else(|e| e.into_inner());
    if *installed {
        return Ok(());
    }
    let mut signals =
        signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]).map_err(SignalsError)?;
    std::thread::Builder::new()
        .name("dofray-signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                exit_on_signal(signal);
            }
        })
        .map_err(SignalsError)?;
    *installed = true;
    Ok(())
}

/// Without Unix signals there is nothing to install; temporary files are still removed on
/// every error.
#[cfg(not(unix))]
pub(crate) fn clean_up_on_signals(json: bool) -> Result<(), SignalsError> {
    JSON_ON_SIGNAL.store(json, Ordering::SeqCst);
    Ok(())
}

/// Removes every temporary file (no new one can appear meanwhile) and exits with 128 + `signal`.
#[cfg(unix)]
fn exit_on_signal(signal: i32) -> ! {
    let mut message = format!(
        "interrupted by {}",
        signal_hook::low_level::signal_name(signal).unwrap_or("a signal")
    );
    for path in dofray::output::remove_all_for_exit() {
        message.push_str(&format!("; removed the unfinished {}", path.display()));
    }
    if JSON_ON_SIGNAL.load(Ordering::SeqCst) {
        let error =
            dofray::exit::json_error(dofray::exit::ErrorKind::Interrupted(signal), &message);
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{error}").and_then(|()| out.flush());
    }
    let _ = writeln!(std::io::stderr(), "error: {message}");
    // _exit: no atexit handlers or static destructors run while worker threads still trace.
    signal_hook::low_level::exit(128 + signal)
}
