//! Progress on stderr: a bar on a terminal, a line every few seconds elsewhere (farm logs,
//! pipes), or nothing (`--progress`).

use std::io::IsTerminal;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dofray::render::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How progress is shown on stderr.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ProgressMode {
    /// A bar when stderr is a terminal, else plain lines; nothing with --quiet or --json.
    #[default]
    Auto,
    /// A bar that redraws itself (drawn only on a terminal).
    Bar,
    /// A line every few seconds and when a phase starts: for logs and pipes.
    Plain,
    /// Nothing.
    None,
}

impl ProgressMode {
    /// What is shown: `--quiet` silences everything; `auto` shows nothing with `--json`, a bar
    /// on a terminal and lines elsewhere.
    pub(crate) fn resolve(self, quiet: bool, json: bool) -> Self {
        match self {
            _ if quiet => Self::None,
            Self::Auto if json => Self::None,
            Self::Auto if std::io::stderr().is_terminal() => Self::Bar,
            Self::Auto => Self::Plain,
            mode => mode,
        }
    }
}

/// How often plain progress prints a line.
const PLAIN_INTERVAL: Duration = Duration::from_secs(5);

/// Progress shown as [`ProgressMode`] says ([`ProgressMode::resolve`]d first).
pub(crate) enum Bar {
    /// An indicatif bar on stderr.
    Drawn(ProgressBar),
    /// Lines on stderr.
    Plain(Plain),
    /// Nothing.
    Hidden,
}

impl Bar {
    pub(crate) fn new(mode: ProgressMode) -> Self {
        match mode {
            ProgressMode::Bar | ProgressMode::Auto => {
                let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(
                        "{msg:>9} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
                    )
                    .expect("valid template")
                    .progress_chars("=> "),
                );
                Self::Drawn(bar)
            }
            ProgressMode::Plain => Self::Plain(Plain::default()),
            ProgressMode::None => Self::Hidden,
        }
    }
}

impl Progress for Bar {
    fn start(&self, phase: &str, total: u64) {
        match self {
            Self::Drawn(bar) => {
                bar.reset();
                bar.set_length(total);
                bar.set_message(phase.to_string());
            }
            Self::Plain(p) => p.start(phase, total),
            Self::Hidden => {}
        }
    }
    fn advance(&self, units: u64) {
        match self {
            Self::Drawn(bar) => bar.inc(units),
            Self::Plain(p) => p.advance(units),
            Self::Hidden => {}
        }
    }
    fn finish(&self) {
        if let Self::Drawn(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// Plain progress: a line when a phase starts and at most every [`PLAIN_INTERVAL`] after.
#[derive(Default)]
pub(crate) struct Plain {
    done: AtomicU64,
    phase: Mutex<Option<Phase>>,
}

struct Phase {
    name: String,
    total: u64,
    started: Instant,
    printed: Instant,
}

impl Plain {
    fn start(&self, name: &str, total: u64) {
        self.done.store(0, Ordering::Relaxed);
        let now = Instant::now();
        let mut phase = self.phase.lock().unwrap_or_else(|e| e.into_inner());
        eprintln!("progress: {name}: 0%");
        *phase = Some(Phase {
            name: name.to_string(),
            total,
            started: now,
            printed: now,
        });
    }

    fn advance(&self, units: u64) {
        let done = self.done.fetch_add(units, Ordering::Relaxed) + units;
        // Workers never wait for the printer: one that finds it busy goes on.
        let Ok(mut guard) = self.phase.try_lock() else {
            return;
        };
        let Some(phase) = guard.as_mut() else {
            return;
        };
        let now = Instant::now();
        if now.duration_since(phase.printed) < PLAIN_INTERVAL || phase.total == 0 {
            return;
        }
        phase.printed = now;
        let fraction = (done as f64 / phase.total as f64).min(1.0);
        let elapsed = now.duration_since(phase.started).as_secs_f64();
        let left = if fraction > 0.0 {
            format!(
                ", about {:.0} s left",
                elapsed * (1.0 - fraction) / fraction
            )
        } else {
            String::new()
        };
        eprintln!(
            "progress: {}: {:.0}% after {elapsed:.0} s{left}",
            phase.name,
            100.0 * fraction
        );
    }
}
