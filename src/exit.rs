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
//! [`classify`] walks an error's `source()` chain from the outside in and returns the kind of the
//! first error it recognises; `anyhow` context messages are skipped that way too.

use std::error::Error;

#[cfg(feature = "bench")]
use crate::bench::{BenchError, plot::PlotError};
use crate::camera::CameraError;
use crate::embree::{EmbreeError, ErrorCode};
use crate::limits::MemoryError;
use crate::output::OutputError;
use crate::overrides::OverrideError;
use crate::render::{RenderError, SettingError};
use crate::renderer::RendererError;
use crate::scene::{LoadError, SceneError};

/// Exit status of a successful run.
pub const OK: u8 = 0;
/// Exit status of an internal error (anything not classified otherwise).
pub const INTERNAL: u8 = 1;
/// Exit status of a usage error (bad flags or flag values). clap uses it too.
pub const USAGE: u8 = 2;
/// Exit status of an input (scene, model, texture) that cannot be read or is invalid.
pub const BAD_INPUT: u8 = 3;
/// Exit status of an output that cannot be written.
pub const IO: u8 = 4;
/// Exit status of a resource limit (memory, input size caps).
pub const RESOURCE_LIMIT: u8 = 5;

/// What kind of failure stopped a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// Bad command-line flags or values.
    Usage,
    /// A scene, model or texture that cannot be read or is invalid.
    BadInput,
    /// An output that cannot be written.
    Io,
    /// A resource limit: the image's buffers exceed the available memory, or an input exceeds
    /// a [`crate::scene::LoadOptions`] limit, or Embree ran out of memory.
    ResourceLimit,
    /// Stopped by a signal (its number).
    Interrupted(i32),
    /// Anything else.
    Internal,
}

impl ErrorKind {
    /// The process exit status for this kind (see the module documentation).
    pub fn exit_code(self) -> u8 {
        match self {
            Self::Usage => USAGE,
            Self::BadInput => BAD_INPUT,
            Self::Io => IO,
            Self::ResourceLimit => RESOURCE_LIMIT,
            Self::Interrupted(signal) => u8::try_from(128 + signal.clamp(0, 127)).unwrap_or(255),
            Self::Internal => INTERNAL,
        }
    }

    /// The kind's name in JSON error objects (`"bad_input"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Usage => "usage",
            Self::BadInput => "bad_input",
            Self::Io => "io",
            Self::ResourceLimit => "resource_limit",
            Self::Interrupted(_) => "interrupted",
            Self::Internal => "internal",
        }
    }
}

/// The version of the `--json` objects' layout (`schema_version`, docs/json.md). Raised when a
/// field is removed or changes meaning; new fields may appear within a version.
pub const SCHEMA_VERSION: u32 = 1;

/// The JSON error object `dofray --json` prints on stdout when it fails:
/// `{"schema_version": 1, "error": {"kind": ..., "message": ..., "exit_code": ...}}`.
pub fn json_error(kind: ErrorKind, message: &str) -> serde_json::Value {
    serde_json::json!({
        "schema_version": SCHEMA_VERSION,
        "error": error_object(kind, message),
    })
}

/// The `error` member of [`json_error`]: `kind`, `message` and `exit_code` (also a failed
/// job's entry in a run's summary).
pub fn error_object(kind: ErrorKind, message: &str) -> serde_json::Value {
    serde_json::json!({
        "kind": kind.name(),
        "message": message,
        "exit_code": kind.exit_code(),
    })
}

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

/// `error`'s message followed by those of its sources, `outer: inner: innermost` (what the
/// command line prints, for bindings that report a message).
pub fn full_message(error: &(dyn Error + 'static)) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        message.push_str(": ");
        message.push_str(&e.to_string());
        source = e.source();
    }
    message
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
        if let Some(kind) = kind_of(e) {
            return kind;
        }
        next = e.source();
    }
    ErrorKind::Internal
}

/// The kind of this one error, if it is one dofray knows.
fn kind_of(e: &(dyn Error + 'static)) -> Option<ErrorKind> {
    if e.is::<UsageError>() {
        return Some(ErrorKind::Usage);
    }
    if let Some(e) = e.downcast_ref::<KindError>() {
        return Some(e.kind);
    }
    if e.is::<MemoryError>() {
        return Some(ErrorKind::ResourceLimit);
    }
    if e.is::<OverrideError>() || e.is::<SettingError>() {
        return Some(ErrorKind::Usage);
    }
    if let Some(e) = e.downcast_ref::<RendererError>() {
        return Some(renderer_kind(e));
    }
    if let Some(e) = e.downcast_ref::<LoadError>() {
        return Some(load_kind(e));
    }
    if let Some(e) = e.downcast_ref::<SceneError>() {
        return Some(scene_kind(e));
    }
    if e.is::<CameraError>() {
        return Some(ErrorKind::BadInput);
    }
    if let Some(e) = e.downcast_ref::<EmbreeError>() {
        return Some(embree_kind(e, ErrorKind::Internal));
    }
    if let Some(e) = e.downcast_ref::<RenderError>() {
        return Some(render_kind(e));
    }
    if let Some(e) = e.downcast_ref::<OutputError>() {
        return Some(output_kind(e));
    }
    if let Some(e) = e.downcast_ref::<crate::output::merge::MergeError>() {
        return Some(match e {
            crate::output::merge::MergeError::Output(e) => output_kind(e),
            crate::output::merge::MergeError::NoTiles
            | crate::output::merge::MergeError::OutputFormat { .. } => ErrorKind::Usage,
            _ => ErrorKind::BadInput,
        });
    }
    #[cfg(feature = "bench")]
    if let Some(kind) = bench_kind(e) {
        return Some(kind);
    }
    if let Some(e) = e.downcast_ref::<std::io::Error>() {
        return Some(match e.kind() {
            std::io::ErrorKind::OutOfMemory => ErrorKind::ResourceLimit,
            std::io::ErrorKind::Interrupted => ErrorKind::Interrupted(2),
            _ => ErrorKind::Io,
        });
    }
    None
}

/// The kind of a benchmark's error (only with the `bench` feature).
#[cfg(feature = "bench")]
fn bench_kind(e: &(dyn Error + 'static)) -> Option<ErrorKind> {
    if let Some(e) = e.downcast_ref::<BenchError>() {
        return Some(match e {
            BenchError::Render(e) => render_kind(e),
            BenchError::Metrics(_) => ErrorKind::Internal,
            BenchError::Cache { .. } | BenchError::CacheDir { .. } => ErrorKind::Io,
            _ => ErrorKind::Usage,
        });
    }
    if let Some(e) = e.downcast_ref::<PlotError>() {
        return Some(match e {
            PlotError::Output(e) => output_kind(e),
            PlotError::Draw { .. } => ErrorKind::Io,
        });
    }
    None
}

fn renderer_kind(e: &RendererError) -> ErrorKind {
    match e {
        RendererError::Load(e) => load_kind(e),
        RendererError::Scene { source, .. } => scene_kind(source),
        RendererError::Override(_) => ErrorKind::Usage,
        RendererError::Memory(_) => ErrorKind::ResourceLimit,
        // The caller asked for this camera.
        RendererError::Camera {
            overridden: true, ..
        } => ErrorKind::Usage,
        RendererError::Camera { .. } | RendererError::ScaledFocusPixelMisses { .. } => {
            ErrorKind::BadInput
        }
        RendererError::Render(e) => render_kind(e),
    }
}

fn scene_kind(e: &SceneError) -> ErrorKind {
    match e {
        SceneError::Embree(e) => embree_kind(e, ErrorKind::BadInput),
        _ => ErrorKind::BadInput,
    }
}

fn load_kind(e: &LoadError) -> ErrorKind {
    match e.root() {
        LoadError::TooLarge { .. } | LoadError::Limit { .. } => ErrorKind::ResourceLimit,
        _ => ErrorKind::BadInput,
    }
}

fn embree_kind(e: &EmbreeError, otherwise: ErrorKind) -> ErrorKind {
    match e {
        EmbreeError::Embree {
            code: ErrorCode::OutOfMemory,
            ..
        } => ErrorKind::ResourceLimit,
        EmbreeError::InvalidGeometry(_) => ErrorKind::BadInput,
        _ => otherwise,
    }
}

fn render_kind(e: &RenderError) -> ErrorKind {
    match e {
        RenderError::NonFinite { .. } => ErrorKind::Internal,
        // The caller stopped it, as SIGINT would.
        RenderError::Cancelled => ErrorKind::Interrupted(2),
        _ => ErrorKind::Usage,
    }
}

fn output_kind(e: &OutputError) -> ErrorKind {
    match e {
        // The value of -o or --aov-dir is wrong, not the file system.
        OutputError::UnknownExtension { .. } | OutputError::Collision { .. } => ErrorKind::Usage,
        _ => ErrorKind::Io,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

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

    #[test]
    fn typed_errors_are_classified_through_contexts() {
        let memory = crate::limits::check_image_memory_against(100, 100, 1, true).unwrap_err();
        let e = anyhow::Error::new(memory).context("outer");
        assert_eq!(classify(e.as_ref()), ErrorKind::ResourceLimit);
        let load = LoadError::Io {
            path: PathBuf::from("x.obj"),
            error: std::io::Error::from(std::io::ErrorKind::NotFound),
        };
        assert_eq!(classify(&load), ErrorKind::BadInput);
        let too_large = LoadError::TooLarge {
            path: PathBuf::from("x.obj"),
            limit: 1,
        };
        assert_eq!(classify(&too_large), ErrorKind::ResourceLimit);
        let write = OutputError::Io {
            path: PathBuf::from("o.png"),
            source: std::io::Error::from(std::io::ErrorKind::PermissionDenied),
        };
        assert_eq!(classify(&write), ErrorKind::Io);
        let ext = OutputError::UnknownExtension {
            path: PathBuf::from("o.jpg"),
        };
        assert_eq!(classify(&ext), ErrorKind::Usage);
        assert_eq!(
            classify(&RenderError::from(SettingError::Samples {
                param: crate::params::Param::Spp,
                value: 0
            })),
            ErrorKind::Usage
        );
        let e = anyhow::Error::new(UsageError("--x must be 1".into())).context("while parsing");
        assert_eq!(classify(e.as_ref()), ErrorKind::Usage);
        assert_eq!(
            classify(anyhow::anyhow!("something odd").as_ref()),
            ErrorKind::Internal
        );
    }
}
