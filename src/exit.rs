//! Exit codes and error kinds: what the `dofray` command returns for each kind of failure, and
//! how a library error is classified, so the binary and library users agree.
//!
//! | code | kind | meaning |
//! |------|------|---------|
//! | 0 | | success |
//! | 1 | `internal` | anything else (a bug, a failed worker pool, a non-finite render) |
//! | 2 | `usage` | bad command-line flags or values (clap's own errors included) |
//! | 3 | `bad_input` | a scene, model or texture that cannot be read or is invalid |
//! | 4 | `io` | an output (image, AOV picture, bench directory, cache) cannot be written |
//! | 5 | `resource_limit` | an image too large for memory, an input beyond a `LoadOptions` limit |
//! | 128 + N | `interrupted` | SIGINT (130), SIGTERM (143) or SIGHUP (129) |
//!
//! # How an error gets its kind
//!
//! Each error type says its kind where it is defined, with an `impl` [`HasKind`] in its own
//! module; a composite error asks its source's `kind()`. [`ErrorKind`], [`HasKind`], the exit
//! codes and the JSON error objects live in [`crate::error_kind`] (re-exported here), which
//! imports nothing of dofray, so the layers depend on it, not on this module, which sits above
//! them all.
//!
//! [`classify`] takes an untyped error (an `anyhow` chain in the binary, a `dyn Error` in the
//! bindings), walks its `source()` chain from the outside in and returns the kind of the first
//! error it recognises (so `anyhow` context messages are skipped), else
//! [`ErrorKind::Internal`]. It recognises the types in one `classified!` list below, which
//! generates the downcasts. Forgetting a type does not compile:
//! - a listed type must implement [`HasKind`] (the downcast calls its `kind()`);
//! - [`HasKind`] requires a sealed marker trait that only that list implements, so a type with
//!   a kind must be listed (the compiler says so, naming the list);
//! - the job loop ([`crate::batch::Batch`]) and the C and Python bindings call `.kind()` on the
//!   typed errors they hold, so a new error type they receive needs a kind.
//!
//! For a listed type `e`, `classify(&e) == e.kind()`.

use std::error::Error;

pub use crate::error_kind::{
    BAD_INPUT, ErrorKind, HasKind, INTERNAL, IO, OK, RESOURCE_LIMIT, SCHEMA_VERSION, USAGE,
    error_object, full_message, json_error,
};

/// A usage error found after the command line was parsed: a flag's value out of range, flags
/// that contradict each other or the scene. Its message names the flag.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// An error of a given kind with its own message (for failures that have no typed error).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct KindError {
    /// What kind of failure this is (sets the exit code and the JSON `kind`).
    pub kind: ErrorKind,
    /// The whole message shown to the user.
    pub message: String,
}

impl HasKind for UsageError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

impl HasKind for KindError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

/// What a caught panic's payload says (`"(no message)"` when it is not a string).
pub fn panic_text(payload: &(dyn std::any::Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(no message)")
}

/// The kind of `error`: that of the outermost error in its `source()` chain that is recognised,
/// else [`ErrorKind::Internal`].
pub fn classify(error: &(dyn Error + 'static)) -> ErrorKind {
    let mut next = Some(error);
    while let Some(e) = next {
        if let Some(kind) = CLASSIFIED.iter().find_map(|kind_of| kind_of(e)) {
            return kind;
        }
        next = e.source();
    }
    ErrorKind::Internal
}

/// `e`'s kind if it is a `T`.
fn kind_as<T: HasKind>(e: &(dyn Error + 'static)) -> Option<ErrorKind> {
    e.downcast_ref::<T>().map(T::kind)
}

/// The errors [`classify`] recognises: every type with a [`HasKind`] impl, each once (an entry
/// may carry a `#[cfg(...)]`). Generates `CLASSIFIED` (one downcast per type) and the sealed
/// marker impls [`HasKind`] requires.
macro_rules! classified {
    ($($(#[$attr:meta])* $ty:ty),+ $(,)?) => {
        $($(#[$attr])* impl crate::error_kind::sealed::Listed for $ty {})+

        /// One downcast per classified type.
        const CLASSIFIED: &[fn(&(dyn Error + 'static)) -> Option<ErrorKind>] =
            &[$($(#[$attr])* kind_as::<$ty>),+];

        /// The classified types, for the tests to check they construct each.
        #[cfg(test)]
        fn classified_types() -> Vec<(std::any::TypeId, &'static str)> {
            vec![$($(#[$attr])* (std::any::TypeId::of::<$ty>(), stringify!($ty))),+]
        }
    };
}

classified! {
    std::io::Error,
    UsageError,
    KindError,
    crate::limits::MemoryError,
    crate::overrides::OverrideError,
    crate::renderer::RendererError,
    crate::scene::LoadError,
    crate::scene::SceneError,
    crate::camera::CameraError,
    crate::camera::LensFileError,
    crate::embree::EmbreeError,
    crate::render::RenderError,
    crate::render::RegionError,
    crate::settings::UnknownMode,
    crate::settings::SettingError,
    crate::output::OutputError,
    crate::output::CompressionError,
    crate::view::ViewError,
    crate::output::merge::MergeError,
    crate::batch::FrameSpecError,
    crate::batch::FrameSelectError,
    crate::batch::RequestError,
    crate::batch::JobError,
    crate::batch::PatternError,
    crate::batch::ShardError,
    crate::metrics::MetricsError,
    #[cfg(feature = "bench")]
    crate::bench::BenchError,
    #[cfg(feature = "bench")]
    crate::bench::plot::PlotError,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::RequestError;
    use crate::batch::{FrameSelectError, FrameSpecError, JobError, PatternError, ShardError};
    #[cfg(feature = "bench")]
    use crate::bench::{BenchError, plot::PlotError};
    use crate::camera::CameraError;
    use crate::embree::{EmbreeError, ErrorCode};
    use crate::metrics::MetricsError;
    use crate::output::merge::MergeError;
    use crate::output::{CompressionError, OutputError};
    use crate::overrides::OverrideError;
    use crate::params::Param;
    use crate::render::{RegionError, RenderError};
    use crate::renderer::RendererError;
    use crate::scene::{LoadError, Location, SceneError};
    use crate::settings::{SettingError, UnknownMode};
    use crate::view::ViewError;
    use std::any::TypeId;
    use std::path::PathBuf;

    // Every listed type has a kind (the list's downcasts need it too; this says it first).
    const _: fn() = || {
        fn has_kind<T: HasKind>() {}
        has_kind::<std::io::Error>();
        has_kind::<UsageError>();
        has_kind::<KindError>();
        has_kind::<crate::limits::MemoryError>();
        has_kind::<OverrideError>();
        has_kind::<RendererError>();
        has_kind::<LoadError>();
        has_kind::<SceneError>();
        has_kind::<CameraError>();
        has_kind::<crate::camera::LensFileError>();
        has_kind::<EmbreeError>();
        has_kind::<RenderError>();
        has_kind::<RegionError>();
        has_kind::<UnknownMode>();
        has_kind::<SettingError>();
        has_kind::<OutputError>();
        has_kind::<CompressionError>();
        has_kind::<ViewError>();
        has_kind::<MergeError>();
        has_kind::<FrameSpecError>();
        has_kind::<FrameSelectError>();
        has_kind::<RequestError>();
        has_kind::<JobError>();
        has_kind::<PatternError>();
        has_kind::<ShardError>();
        has_kind::<MetricsError>();
        #[cfg(feature = "bench")]
        has_kind::<BenchError>();
        #[cfg(feature = "bench")]
        has_kind::<PlotError>();
    };

    #[test]
    fn codes_are_distinct_and_documented() {
        let kinds = [
            ErrorKind::Usage,
            ErrorKind::BadInput,
            ErrorKind::Io,
            ErrorKind::ResourceLimit,
            ErrorKind::Internal,
        ];
        let codes: Vec<u8> = kinds.iter().map(|k| k.exit_code()).collect();
        assert_eq!(codes, [2, 3, 4, 5, 1]);
        assert_eq!(ErrorKind::Interrupted(2).exit_code(), 130);
        assert_eq!(ErrorKind::Interrupted(15).exit_code(), 143);
        assert_eq!(ErrorKind::Interrupted(1).exit_code(), 129);
        assert_eq!(ErrorKind::BadInput.name(), "bad_input");
    }

    /// An error, its type and the kind it must have.
    struct Case {
        error: anyhow::Error,
        own: ErrorKind,
        ty: TypeId,
        expected: ErrorKind,
    }

    fn case<E: HasKind + Send + Sync>(error: E, expected: ErrorKind) -> Case {
        Case {
            own: error.kind(),
            ty: TypeId::of::<E>(),
            error: anyhow::Error::new(error),
            expected,
        }
    }

    fn io(kind: std::io::ErrorKind) -> std::io::Error {
        std::io::Error::from(kind)
    }

    fn path() -> PathBuf {
        PathBuf::from("x.png")
    }

    fn too_large() -> LoadError {
        LoadError::TooLarge {
            path: path(),
            limit: 1,
        }
    }

    fn embree(code: ErrorCode) -> EmbreeError {
        EmbreeError::Embree {
            code,
            message: "rtcCommitScene".into(),
        }
    }

    fn camera_error() -> CameraError {
        CameraError::FocusPixelMisses { x: 1, y: 2 }
    }

    fn output_io() -> OutputError {
        OutputError::Io {
            path: path(),
            source: io(std::io::ErrorKind::PermissionDenied),
        }
    }

    fn unknown_extension() -> OutputError {
        OutputError::UnknownExtension { path: path() }
    }

    fn zero_spp() -> SettingError {
        SettingError::Samples {
            param: Param::Spp,
            value: 0,
        }
    }

    fn metrics_error() -> MetricsError {
        MetricsError::Empty {
            width: 0,
            height: 0,
        }
    }

    /// One error (or more, for composites) of every classified type, with its kind as the
    /// command line's exit codes and tests/cli.rs expect it.
    fn cases() -> Vec<Case> {
        use ErrorKind::*;
        let memory = crate::limits::check_image_memory_against(
            100,
            100,
            &crate::limits::MemoryLimit::Available { available: 1 },
        )
        .unwrap_err();
        let override_error = || OverrideError::ZeroSize(Param::Width);
        let renderer_camera = |overridden| RendererError::Camera {
            source: camera_error(),
            overridden,
        };
        let cases = vec![
            case(io(std::io::ErrorKind::NotFound), Io),
            case(io(std::io::ErrorKind::OutOfMemory), ResourceLimit),
            case(io(std::io::ErrorKind::Interrupted), Interrupted(2)),
            case(UsageError("--x".into()), Usage),
            case(
                KindError {
                    kind: Io,
                    message: "exists".into(),
                },
                Io,
            ),
            case(memory.clone(), ResourceLimit),
            case(override_error(), Usage),
            case(RendererError::from(override_error()), Usage),
            case(RendererError::from(memory), ResourceLimit),
            case(RendererError::from(too_large()), ResourceLimit),
            case(
                RendererError::Scene {
                    name: "paper".into(),
                    source: SceneError::Empty,
                },
                BadInput,
            ),
            case(renderer_camera(true), Usage),
            case(renderer_camera(false), BadInput),
            case(
                RendererError::ScaledFocusPixelMisses {
                    x0: 0,
                    y0: 0,
                    w0: 1,
                    h0: 1,
                    x: 0,
                    y: 0,
                    width: 2,
                    height: 2,
                },
                BadInput,
            ),
            case(RendererError::from(RenderError::Cancelled), Interrupted(2)),
            case(
                LoadError::Io {
                    path: path(),
                    error: io(std::io::ErrorKind::NotFound),
                },
                BadInput,
            ),
            case(too_large(), ResourceLimit),
            case(
                LoadError::Referenced {
                    at: Location::file(&path()),
                    what: "texture",
                    cause: Box::new(too_large()),
                },
                ResourceLimit,
            ),
            case(SceneError::Empty, BadInput),
            case(
                SceneError::from(embree(ErrorCode::OutOfMemory)),
                ResourceLimit,
            ),
            case(SceneError::from(embree(ErrorCode::Unknown)), BadInput),
            // What Embree's build passes on when the system refuses it a thread (seen under
            // `ulimit -v 400000`) is a resource limit, not the scene's fault.
            case(
                SceneError::from(EmbreeError::Embree {
                    code: ErrorCode::Unknown,
                    message: "rtcCommitScene: pthread_create has failed: Resource temporarily \
                              unavailable"
                        .into(),
                }),
                ResourceLimit,
            ),
            case(
                SceneError::from(crate::limits::MemoryError::allocation("the light tree", 1)),
                ResourceLimit,
            ),
            case(camera_error(), BadInput),
            case(
                crate::camera::LensFileError::Invalid {
                    path: path(),
                    line: 3,
                    message: "x".into(),
                },
                BadInput,
            ),
            case(embree(ErrorCode::OutOfMemory), ResourceLimit),
            case(EmbreeError::InvalidGeometry("NaN".into()), BadInput),
            case(embree(ErrorCode::UnsupportedCpu), Internal),
            case(RenderError::from(zero_spp()), Usage),
            case(zero_spp(), Usage),
            case(RenderError::Cancelled, Interrupted(2)),
            case(RegionError::Syntax("1,2".into()), Usage),
            case(UnknownMode("fast".into()), Usage),
            case(unknown_extension(), Usage),
            case(output_io(), Io),
            case(
                CompressionError::Unknown {
                    name: "lzma".into(),
                },
                Usage,
            ),
            case(ViewError::Filmic, Usage),
            case(MergeError::NoTiles, Usage),
            case(
                MergeError::Read {
                    path: path(),
                    message: "truncated".into(),
                },
                BadInput,
            ),
            case(MergeError::from(output_io()), Io),
            case(FrameSpecError::Empty, Usage),
            case(FrameSelectError::NoStart, Usage),
            case(FrameSelectError::List(FrameSpecError::Empty), Usage),
            case(RequestError::from(FrameSelectError::NoStart), Usage),
            case(JobError::Exists { path: path() }, Io),
            case(JobError::from(output_io()), Io),
            case(JobError::from(renderer_camera(true)), Usage),
            case(JobError::from(RenderError::Cancelled), Interrupted(2)),
            case(PatternError::Mixed { path: path() }, Usage),
            case(ShardError::ZeroCount { index: 0 }, Usage),
            case(metrics_error(), Internal),
        ];
        #[cfg(feature = "bench")]
        let cases: Vec<Case> = cases.into_iter().chain(bench_cases()).collect();
        cases
    }

    #[cfg(feature = "bench")]
    fn bench_cases() -> Vec<Case> {
        use ErrorKind::*;
        vec![
            case(BenchError::ZeroRepeat, Usage),
            case(BenchError::from(RenderError::from(zero_spp())), Usage),
            case(BenchError::from(metrics_error()), Internal),
            case(
                BenchError::Cache {
                    path: path(),
                    error: io(std::io::ErrorKind::PermissionDenied),
                },
                Io,
            ),
            case(
                PlotError::Draw {
                    path: path(),
                    message: "font".into(),
                },
                Io,
            ),
            case(PlotError::from(unknown_extension()), Usage),
        ]
    }

    #[test]
    fn every_classified_type_has_its_kind() {
        let cases = cases();
        for c in &cases {
            assert_eq!(c.own, c.expected, "{:?}", c.error);
            assert_eq!(classify(c.error.as_ref()), c.expected, "{:?}", c.error);
        }
        for (ty, name) in classified_types() {
            assert!(cases.iter().any(|c| c.ty == ty), "no case for {name}");
        }
        assert_eq!(CLASSIFIED.len(), classified_types().len());
    }

    #[test]
    fn typed_errors_are_classified_through_contexts() {
        for c in cases() {
            let e = c.error.context("while rendering").context("job 1");
            assert_eq!(classify(e.as_ref()), c.expected, "{e:#}");
        }
        let e = anyhow::Error::new(UsageError("--x must be 1".into())).context("while parsing");
        assert_eq!(classify(e.as_ref()), ErrorKind::Usage);
        assert_eq!(
            classify(anyhow::anyhow!("something odd").as_ref()),
            ErrorKind::Internal
        );
    }
}
