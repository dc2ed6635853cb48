//! Cancellation through `Progress::cancelled`: every mode stops with `RenderError::Cancelled`.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use dofray::embree::Device;
use dofray::overrides::Overrides;
use dofray::render::{CancelFlag, Mode, Progress, RenderError, RenderSettings, SamplingRule};
use dofray::renderer::{Renderer, RendererError};

/// Cancels after the first unit of work of `phase` ("depth", or the mode's own phase).
struct CancelIn {
    phase: &'static str,
    current: Mutex<String>,
    flag: AtomicBool,
}

impl CancelIn {
    fn new(phase: &'static str) -> Self {
        Self {
            phase,
            current: Mutex::new(String::new()),
            flag: AtomicBool::new(false),
        }
    }
}

impl Progress for CancelIn {
    fn start(&self, phase: &str, _total: u64) {
        *self.current.lock().unwrap() = phase.to_string();
    }
    fn advance(&self, _units: u64) {
        let current = self.current.lock().unwrap();
        if self.phase == "mode" && *current != "depth" || *current == self.phase {
            self.flag.store(true, Ordering::Relaxed);
        }
    }
    fn cancelled(&self) -> bool {
        self.flag.load(Ordering::Relaxed)
    }
}

fn renderer() -> Renderer {
    let desc = dofray::scene::load("paper").unwrap();
    let overrides = Overrides {
        width: Some(160),
        height: Some(120),
        ..Default::default()
    };
    Renderer::with_overrides(desc, overrides, &Device::new().unwrap()).unwrap()
}

fn settings() -> Vec<RenderSettings> {
    let of = |mode, rule| RenderSettings {
        mode,
        rule,
        ..Default::default()
    };
    vec![
        of(
            Mode::Pinhole,
            SamplingRule::ErrorControlled { tolerance: None },
        ),
        of(
            Mode::Dense,
            SamplingRule::ErrorControlled { tolerance: None },
        ),
        of(
            Mode::Adaptive,
            SamplingRule::ErrorControlled { tolerance: None },
        ),
        of(
            Mode::Adaptive,
            SamplingRule::Seed {
                interval_factor: 0.4,
                paper_exact: false,
            },
        ),
    ]
}

fn assert_cancelled(result: Result<impl Sized, RendererError>, what: &str) {
    match result {
        Err(RendererError::Render(RenderError::Cancelled)) => {}
        Err(e) => panic!("{what}: expected a cancelled render, got {e}"),
        Ok(_) => panic!("{what}: expected a cancelled render, got an image"),
    }
}

#[test]
fn every_mode_stops_when_cancelled_in_the_depth_pass_or_its_own_phase() {
    let r = renderer();
    for s in settings() {
        for phase in ["depth", "mode"] {
            let progress = CancelIn::new(phase);
            let what = format!("{:?} {:?} cancelled in {phase}", s.mode, s.rule);
            assert_cancelled(r.render(&s, &progress), &what);
        }
    }
}

#[test]
fn a_cancel_flag_stops_a_render_and_classifies_as_interrupted() {
    let r = renderer();
    let flag = CancelFlag::new();
    flag.cancel();
    let wrapped = flag.with(&dofray::render::NoProgress);
    for s in settings() {
        assert_cancelled(r.render(&s, &flag), "a cancelled flag");
        assert_cancelled(r.render(&s, &wrapped), "a wrapped cancelled flag");
    }
    let e = r.render(&RenderSettings::default(), &flag).unwrap_err();
    let kind = dofray::exit::classify(&e);
    assert_eq!((kind.name(), kind.exit_code()), ("interrupted", 130));
    // Not cancelled: the same renderer still renders.
    let (film, _) = r
        .render(&RenderSettings::default(), &CancelFlag::new())
        .unwrap();
    assert_eq!((film.width, film.height), (160, 120));
}
