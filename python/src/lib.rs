//! `dofray._dofray`, the extension module behind the Python package `dofray` (python/dofray):
//! [`render`] loads a scene, applies keyword overrides and renders it on a thread of its own
//! while the calling thread, without the GIL, waits; every 50 ms it takes the GIL back to run
//! Python's signal handlers (Ctrl-C cancels the render and raises `KeyboardInterrupt`) and the
//! progress callback (an exception from it cancels the render and propagates). The result is a
//! [`Render`]: RGBA, depth and CoC as numpy arrays, the statistics as a dict.
//!
//! Errors are raised as `dofray.Error` (with a `kind` attribute: the name of
//! [`dofray::exit::ErrorKind`]) or, for bad arguments, `dofray.UsageError` (also a
//! `ValueError`); both are defined by the Python package.

use std::error::Error as StdError;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use dofray::embree::Device;
use dofray::exit::{ErrorKind, HasKind};
use dofray::limits::{MemoryError, try_copy};
use dofray::overrides::Overrides;
use dofray::params::Param;
use dofray::render::{CancelFlag, Film, Progress, RenderSettings, RenderStats, SettingsPatch};
use dofray::renderer::{Renderer, RendererError};
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3};
use pyo3::IntoPyObjectExt;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

mod jobs;
mod keywords;

use keywords::SceneKeywords;

/// How often the waiting thread takes the GIL to check for signals and report progress.
const POLL: Duration = Duration::from_millis(50);

/// A failure of the render thread, sent back to the Python thread (which raises it).
#[derive(Debug)]
struct Failure {
    kind: ErrorKind,
    message: String,
}

impl Failure {
    fn usage(message: String) -> Self {
        Self {
            kind: ErrorKind::Usage,
            message,
        }
    }

    /// The library's error: its kind and its message with its causes (`outer: inner`),
    /// overrides and settings named as the Python keywords are. Only errors with a kind: a new
    /// library error type does not compile here until it has one.
    fn from_error(error: &impl HasKind) -> Self {
        let kind = error.kind();
        let error: &(dyn StdError + 'static) = error;
        let message = error
            .downcast_ref::<RendererError>()
            .and_then(|e| e.param_message(Param::keyword_name))
            .unwrap_or_else(|| dofray::exit::full_message(error));
        Self { kind, message }
    }

    /// The Python exception: `dofray.UsageError` for usage errors, else `dofray.Error`, with
    /// `kind` set.
    fn into_pyerr(self, py: Python<'_>) -> PyErr {
        let class = if self.kind == ErrorKind::Usage {
            "UsageError"
        } else {
            "Error"
        };
        let made = (|| -> PyResult<PyErr> {
            let exception = py
                .import("dofray")?
                .getattr(class)?
                .call1((&self.message,))?;
            exception.setattr("kind", self.kind.name())?;
            Ok(PyErr::from_value(exception))
        })();
        // Only a broken installation (no `dofray` package around the module) gets here.
        made.unwrap_or_else(|e| e)
    }
}

/// What to render: the scene and the keyword overrides, checked for range by the library.
struct Job {
    scene: String,
    frame: Option<i64>,
    overrides: Overrides,
    settings: SettingsPatch,
    /// Worker threads of the render (None: all cores).
    threads: Option<usize>,
}

/// `threads` checked: 1 to [`dofray::limits::MAX_THREADS`], or None for all cores.
fn checked_threads(threads: Option<i64>) -> Result<Option<usize>, Failure> {
    let max = dofray::limits::MAX_THREADS;
    match threads {
        None => Ok(None),
        Some(n) if n >= 1 && n as u64 <= max as u64 => Ok(Some(n as usize)),
        Some(n) => Err(Failure {
            kind: ErrorKind::Usage,
            message: format!("threads must be 1 to {max} (or None: all cores), got {n}"),
        }),
    }
}

/// The Embree device, made once per process (making one starts Embree's thread pool).
static DEVICE: Mutex<Option<Device>> = Mutex::new(None);

fn device() -> Result<Device, Failure> {
    let mut device = DEVICE.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(d) = device.as_ref() {
        return Ok(d.clone());
    }
    let d = Device::new().map_err(|e| Failure::from_error(&e))?;
    *device = Some(d.clone());
    Ok(d)
}

/// The scene argument as the library takes it.
fn scene_name(scene: &Path) -> Result<String, Failure> {
    scene
        .to_str()
        .map(str::to_owned)
        .ok_or_else(|| Failure::usage(format!("scene path {} is not valid UTF-8", scene.display())))
}

/// Loads `scene` and builds it with `overrides`, and the render settings `settings` ask of it.
fn prepare(
    scene: &str,
    overrides: Overrides,
    settings: &SettingsPatch,
) -> Result<(Renderer, RenderSettings), Failure> {
    let fail = |e: RendererError| Failure::from_error(&e);
    let desc = dofray::scene::load(scene).map_err(|e| fail(e.into()))?;
    let renderer = Renderer::with_overrides(desc, overrides, &device()?).map_err(fail)?;
    let settings = renderer.settings(settings).map_err(fail)?;
    Ok((renderer, settings))
}

impl Job {
    /// Loads, builds and renders (on the calling thread), reporting to `progress`.
    fn run(self, progress: &Shared) -> Result<(Film, RenderStats), Failure> {
        let Job {
            scene,
            overrides,
            settings,
            frame,
            threads,
        } = self;
        let render = || {
            let (renderer, settings) = prepare(&scene, overrides, &settings)?;
            renderer
                .render_frame(frame, None, &settings, progress)
                .map_err(|e| Failure::from_error(&e))
        };
        // The workers start before the scene is loaded (`dofray::workers`).
        match threads {
            None => {
                dofray::workers::start_global();
                render()
            }
            // A pool of the caller's size for this render; the image is the same for any.
            Some(n) => dofray::workers::pool(Some(n))
                .map_err(|e| Failure {
                    kind: ErrorKind::ResourceLimit,
                    message: format!("cannot start {n} worker threads: {e}"),
                })?
                .install(render),
        }
    }
}

/// Progress shared by the render thread (which writes it) and the Python thread (which reads
/// it and may cancel).
#[derive(Default)]
struct Shared {
    cancel: CancelFlag,
    /// The current phase: its number (from 1; 0 before the first) and name.
    phase: Mutex<(u64, String)>,
    done: AtomicU64,
    total: AtomicU64,
}

impl Progress for Shared {
    fn start(&self, phase: &str, total: u64) {
        let mut current = self.phase.lock().unwrap_or_else(PoisonError::into_inner);
        current.0 += 1;
        current.1 = phase.to_owned();
        self.done.store(0, Ordering::Relaxed);
        self.total.store(total, Ordering::Relaxed);
    }

    fn advance(&self, units: u64) {
        self.done.fetch_add(units, Ordering::Relaxed);
    }

    fn cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }
}

impl Shared {
    /// (phase number, name, done, total), `done` at most `total`.
    fn snapshot(&self) -> (u64, String, u64, u64) {
        let current = self.phase.lock().unwrap_or_else(PoisonError::into_inner);
        let total = self.total.load(Ordering::Relaxed);
        let done = self.done.load(Ordering::Relaxed).min(total);
        (current.0, current.1.clone(), done, total)
    }
}

/// Calls `callback(phase, done, total)` when the progress moved since `last`.
fn report(
    py: Python<'_>,
    callback: Option<&Py<PyAny>>,
    shared: &Shared,
    last: &mut (u64, u64),
) -> PyResult<()> {
    let Some(callback) = callback else {
        return Ok(());
    };
    let (number, phase, done, total) = shared.snapshot();
    if number == 0 || (number, done) == *last {
        return Ok(());
    }
    *last = (number, done);
    callback.call1(py, (phase, done, total))?;
    Ok(())
}

/// The render thread's outcome (`Ok`), or the Python exception that stopped the wait.
type Outcome = PyResult<Result<(Film, RenderStats), Failure>>;

/// Runs `job` on a thread of its own, reporting its progress to `callback`.
fn run_job(py: Python<'_>, job: Job, callback: Option<Py<PyAny>>) -> Outcome {
    let shared = Shared::default();
    let mut last = (0, 0);
    run_detached(
        py,
        &shared.cancel,
        |_wake| job.run(&shared),
        |py| report(py, callback.as_ref(), &shared, &mut last),
    )
}

/// What the work thread of [`run_detached`] tells the waiting thread.
enum Message<T> {
    /// Poll now: there is news for the progress callback.
    Wake,
    /// The work's result.
    Done(Result<T, Failure>),
}

/// Runs `work` on a thread of its own; the calling thread waits without the GIL, taking it
/// every [`POLL`] (or when `work` calls the wake function it is given) for signals and
/// `poll` (the progress callback), and once more at the end. When either raises, `cancel` is
/// cancelled and the exception returned once `work` stopped.
fn run_detached<T: Send>(
    py: Python<'_>,
    cancel: &CancelFlag,
    work: impl FnOnce(&(dyn Fn() + Sync)) -> Result<T, Failure> + Send,
    mut poll: impl FnMut(Python<'_>) -> PyResult<()> + Send,
) -> PyResult<Result<T, Failure>> {
    py.detach(|| {
        std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel();
            scope.spawn(move || {
                let wake = || {
                    let _ = tx.send(Message::Wake);
                };
                let result = catch_unwind(AssertUnwindSafe(|| work(&wake)));
                let result = result.unwrap_or_else(|panic| {
                    let what = dofray::exit::panic_text(&*panic);
                    Err(Failure {
                        kind: ErrorKind::Internal,
                        message: format!("internal error in dofray: {what}"),
                    })
                });
                // The receiver waits for this message unless it is gone, which it is not.
                let _ = tx.send(Message::Done(result));
            });
            loop {
                match rx.recv_timeout(POLL) {
                    Ok(Message::Done(result)) => {
                        // The last progress (done = total) before the result.
                        Python::attach(&mut poll)?;
                        return Ok(result);
                    }
                    Ok(Message::Wake) | Err(RecvTimeoutError::Timeout) => {
                        let polled = Python::attach(|py| {
                            py.check_signals()?;
                            poll(py)
                        });
                        if let Err(e) = polled {
                            cancel.cancel();
                            // The render stops within a row's or a round's time.
                            while let Ok(Message::Wake) = rx.recv() {}
                            return Err(e);
                        }
                    }
                    Err(RecvTimeoutError::Disconnected) => {
                        return Ok(Err(Failure {
                            kind: ErrorKind::Internal,
                            message: "internal error in dofray: the render thread stopped \
                                      without a result"
                                .into(),
                        }));
                    }
                }
            }
        })
    })
}

/// A JSON value (the statistics) as Python objects.
fn json_to_py<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    match value {
        Value::Null => Ok(py.None().into_bound(py)),
        Value::Bool(b) => b.into_bound_py_any(py),
        Value::Number(n) => {
            if let Some(i) = n.as_u64() {
                i.into_bound_py_any(py)
            } else if let Some(i) = n.as_i64() {
                i.into_bound_py_any(py)
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_bound_py_any(py)
            }
        }
        Value::String(s) => s.into_bound_py_any(py),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            Ok(list.into_any())
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, json_to_py(py, v)?)?;
            }
            Ok(dict.into_any())
        }
    }
}

/// The statistics dict: `RenderStats` as `dofray --json` has it, `rays` with its `total`,
/// and `mrays_per_s`.
fn stats_dict<'py>(py: Python<'py>, stats: &RenderStats) -> PyResult<Bound<'py, PyDict>> {
    let mut value = serde_json::to_value(stats).map_err(|e| {
        Failure {
            kind: ErrorKind::Internal,
            message: format!("internal error in dofray: statistics: {e}"),
        }
        .into_pyerr(py)
    })?;
    if let Some(map) = value.as_object_mut() {
        if let Some(rays) = map.get_mut("rays").and_then(|r| r.as_object_mut()) {
            rays.insert("total".into(), stats.rays.total().into());
        }
        map.insert("mrays_per_s".into(), stats.mrays_per_s().into());
    }
    Ok(json_to_py(py, &value)?.cast_into::<PyDict>()?)
}

/// A finished render: `rgba` (height, width, 4) float32 linear RGB with alpha (premultiplied
/// when rendered with `transparent=True`, else alpha is 1), `depth` (height, width) float32
/// distance along the view axis (inf where nothing was hit), `coc` (height, width) float32
/// circle-of-confusion diameter in pixels, `stats` a dict, and `save(path)`.
#[pyclass(frozen, module = "dofray")]
struct Render {
    /// (height, width, 4) float32: linear RGB and alpha.
    #[pyo3(get)]
    rgba: Py<PyArray3<f32>>,
    /// (height, width) float32: distance along the view axis, inf where nothing was hit.
    #[pyo3(get)]
    depth: Py<PyArray2<f32>>,
    /// (height, width) float32: circle-of-confusion diameter in pixels.
    #[pyo3(get)]
    coc: Py<PyArray2<f32>>,
    /// The render's statistics (rays, seconds, mrays_per_s, sample_sites, ...).
    #[pyo3(get)]
    stats: Py<PyDict>,
    film: Film,
}

#[pymethods]
impl Render {
    /// Image width in pixels.
    #[getter]
    fn width(&self) -> usize {
        self.film.width
    }

    /// Image height in pixels.
    #[getter]
    fn height(&self) -> usize {
        self.film.height
    }

    /// Writes the image as rendered to `path`: PNG (8-bit sRGB) or OpenEXR (linear half
    /// float RGBA, with the depth and CoC layers) by the extension, as `dofray render -o`.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| dofray::output::write_film(&path, &self.film))
            .map_err(|e| Failure::from_error(&e).into_pyerr(py))
    }

    fn __repr__(&self) -> String {
        format!("<dofray.Render {}x{}>", self.film.width, self.film.height)
    }
}

impl Render {
    fn new(py: Python<'_>, film: Film, stats: &RenderStats) -> PyResult<Self> {
        // An ImportError if numpy is missing (the numpy crate would panic).
        py.import("numpy")?;
        let (w, h) = (film.width, film.height);
        let memory = |e: MemoryError| Failure::from_error(&e).into_pyerr(py);
        let rgba = film.try_rgba_interleaved().map_err(memory)?;
        let shape = |e: numpy::ndarray::ShapeError| {
            Failure {
                kind: ErrorKind::Internal,
                message: format!("internal error in dofray: film shape: {e}"),
            }
            .into_pyerr(py)
        };
        let rgba = Array3::from_shape_vec((h, w, 4), rgba).map_err(shape)?;
        let depth = try_copy(&film.depth, "the depth array").map_err(memory)?;
        let depth = Array2::from_shape_vec((h, w), depth).map_err(shape)?;
        let coc = try_copy(&film.coc, "the CoC array").map_err(memory)?;
        let coc = Array2::from_shape_vec((h, w), coc).map_err(shape)?;
        Ok(Self {
            rgba: rgba.into_pyarray(py).unbind(),
            depth: depth.into_pyarray(py).unbind(),
            coc: coc.into_pyarray(py).unbind(),
            stats: stats_dict(py, stats)?.unbind(),
            film,
        })
    }
}

/// Renders `scene` (a built-in name such as "paper", or a .toml, .obj, .gltf or .glb path)
/// with the given overrides; see the Python package's `dofray.render` for the keywords.
#[pyfunction]
#[pyo3(signature = (
    scene, *, width=None, height=None, f_number=None, focal_length=None, sensor_width=None,
    focus_distance=None, autofocus=None, aperture_radius=None, blades=None, lens=None, spp=None, aa=None,
    mode=None, tolerance=None, seed=None, exposure=None, transparent=false, integrator=None,
    light_tracing=None, reuse=None, frame=None, threads=None, progress=None
))]
#[allow(clippy::too_many_arguments)]
fn render(
    py: Python<'_>,
    scene: PathBuf,
    width: Option<i64>,
    height: Option<i64>,
    f_number: Option<f32>,
    focal_length: Option<f32>,
    sensor_width: Option<f32>,
    focus_distance: Option<f32>,
    autofocus: Option<(i64, i64)>,
    aperture_radius: Option<f32>,
    blades: Option<i64>,
    lens: Option<PathBuf>,
    spp: Option<i64>,
    aa: Option<i64>,
    mode: Option<&str>,
    tolerance: Option<f32>,
    seed: Option<u64>,
    exposure: Option<f32>,
    transparent: bool,
    integrator: Option<&str>,
    light_tracing: Option<bool>,
    reuse: Option<bool>,
    frame: Option<i64>,
    threads: Option<i64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Render> {
    if let Some(callback) = &progress
        && !callback.bind(py).is_callable()
    {
        return Err(pyo3::exceptions::PyTypeError::new_err(
            "progress must be callable (phase, done, total)",
        ));
    }
    let keywords = SceneKeywords {
        width,
        height,
        f_number,
        focal_length,
        sensor_width,
        focus_distance,
        autofocus,
        aperture_radius,
        blades,
        lens,
        spp,
        aa,
        mode: mode.map(str::to_owned),
        tolerance,
        seed,
        exposure,
        transparent,
        integrator: integrator.map(str::to_owned),
        light_tracing,
        reuse,
    };
    let job = (|| -> Result<Job, Failure> {
        let (overrides, settings) = keywords.parts()?;
        Ok(Job {
            scene: scene_name(&scene)?,
            frame,
            overrides,
            settings,
            threads: checked_threads(threads)?,
        })
    })()
    .map_err(|f| f.into_pyerr(py))?;
    match run_job(py, job, progress)? {
        Err(failure) => Err(failure.into_pyerr(py)),
        Ok((film, stats)) => Render::new(py, film, &stats),
    }
}

/// The extension module.
#[pymodule]
fn _dofray(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::render_jobs, m)?)?;
    m.add_class::<Render>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
