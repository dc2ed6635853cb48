//! The Embree device and the typed errors it reports.

use std::collections::HashMap;
use std::ffi::{CStr, CString, c_char, c_void};
use std::fmt;
use std::sync::{Arc, Mutex};
use std::thread::{self, ThreadId};

use super::sys;
use crate::error_kind::{ErrorKind, HasKind};

/// Embree's error codes (`RTCError`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    /// `RTC_ERROR_UNKNOWN`.
    Unknown,
    /// `RTC_ERROR_INVALID_ARGUMENT`.
    InvalidArgument,
    /// `RTC_ERROR_INVALID_OPERATION`.
    InvalidOperation,
    /// `RTC_ERROR_OUT_OF_MEMORY`.
    OutOfMemory,
    /// `RTC_ERROR_UNSUPPORTED_CPU`: the CPU lacks an instruction set Embree was built for.
    UnsupportedCpu,
    /// `RTC_ERROR_CANCELLED`: a progress monitor cancelled the operation.
    Cancelled,
    /// A code this version of dofray does not know.
    Other(u32),
}

impl ErrorCode {
    fn from_raw(code: sys::RTCError) -> Self {
        match code {
            sys::RTC_ERROR_UNKNOWN => Self::Unknown,
            sys::RTC_ERROR_INVALID_ARGUMENT => Self::InvalidArgument,
            sys::RTC_ERROR_INVALID_OPERATION => Self::InvalidOperation,
            sys::RTC_ERROR_OUT_OF_MEMORY => Self::OutOfMemory,
            sys::RTC_ERROR_UNSUPPORTED_CPU => Self::UnsupportedCpu,
            sys::RTC_ERROR_CANCELLED => Self::Cancelled,
            other => Self::Other(other),
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Unknown => f.write_str("RTC_ERROR_UNKNOWN"),
            Self::InvalidArgument => f.write_str("RTC_ERROR_INVALID_ARGUMENT"),
            Self::InvalidOperation => f.write_str("RTC_ERROR_INVALID_OPERATION"),
            Self::OutOfMemory => f.write_str("RTC_ERROR_OUT_OF_MEMORY"),
            Self::UnsupportedCpu => f.write_str("RTC_ERROR_UNSUPPORTED_CPU"),
            Self::Cancelled => f.write_str("RTC_ERROR_CANCELLED"),
            Self::Other(c) => write!(f, "RTC error {c}"),
        }
    }
}

/// Everything that can go wrong in the Embree layer.
#[derive(Debug, thiserror::Error)]
pub enum EmbreeError {
    /// Embree itself reported an error (through its error callback or `rtcGetDeviceError`).
    #[error("Embree reported {code}: {message}")]
    Embree {
        /// The error code.
        code: ErrorCode,
        /// The call that failed, with Embree's own message when it gave one.
        message: String,
    },
    /// Geometry data was rejected before it reached Embree.
    #[error("invalid geometry: {0}")]
    InvalidGeometry(String),
    /// A device configuration string that cannot be passed to Embree.
    #[error("invalid Embree device config {config:?}: {reason}")]
    InvalidConfig {
        /// The configuration string.
        config: String,
        /// Why it was refused.
        reason: String,
    },
}

/// A result whose error defaults to [`EmbreeError`].
pub type Result<T, E = EmbreeError> = std::result::Result<T, E>;

/// Per thread, the first error Embree reported through the callback since that thread last
/// took it.
///
/// Embree calls the error callback on the thread whose API call failed (errors inside its own
/// build tasks are re-raised in the thread that called `rtcCommitScene`), and keeps the sticky
/// code behind `rtcGetDeviceError` per thread too. Keying by thread keeps the error of one
/// thread's scene build from being reported by another thread building a scene on the same
/// device at the same time. An entry is left behind only by a thread that got an error and
/// never checked, which every wrapper call does. (Were Embree ever to call the callback from a
/// worker thread instead, that error would be filed under the worker and not reach the caller;
/// Embree 3.13 and 4.3 do not.)
type ErrorSlot = Mutex<HashMap<ThreadId, (ErrorCode, String)>>;

struct DeviceInner {
    raw: sys::RTCDevice,
    config: String,
    /// Boxed so its address, handed to Embree as the callback's user pointer, never moves.
    errors: Box<ErrorSlot>,
}

// SAFETY: an RTCDevice is thread-safe: Embree allows calls on one device from any thread, and the
// error slot is behind a Mutex.
unsafe impl Send for DeviceInner {}
// SAFETY: as above; `&DeviceInner` only reads the handle or locks the Mutex.
unsafe impl Sync for DeviceInner {}

impl Drop for DeviceInner {
    fn drop(&mut self) {
        // SAFETY: raw came from rtcNewDevice and this is its last owner on the Rust side; every
        // Scene holds an Arc to this, so no scene of ours outlives the callback's user pointer.
        unsafe { sys::rtcReleaseDevice(self.raw) }
    }
}

/// An Embree device. Cheap to clone; scenes keep their device alive.
///
/// Several threads may build scenes on one device at once: errors are recorded per thread, as
/// Embree itself records them, so each builder sees only the errors of its own calls.
#[derive(Clone)]
pub struct Device(Arc<DeviceInner>);

impl fmt::Debug for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Device(embree {})", super::version::EMBREE_MAJOR)
    }
}

/// Embree calls this on errors. It must not unwind: any panic is caught and dropped.
unsafe extern "C" fn error_callback(
    user: *mut c_void,
    code: sys::RTCError,
    message: *const c_char,
) {
    let _ = std::panic::catch_unwind(|| {
        let text = if message.is_null() {
            String::new()
        } else {
            // SAFETY: Embree passes a NUL-terminated string valid for the duration of the call.
            unsafe { CStr::from_ptr(message) }
                .to_string_lossy()
                .into_owned()
        };
        // SAFETY: user is the ErrorSlot boxed in DeviceInner, alive as long as the device.
        let slot = unsafe { &*(user as *const ErrorSlot) };
        if let Ok(mut errors) = slot.lock() {
            errors
                .entry(thread::current().id())
                .or_insert((ErrorCode::from_raw(code), text));
        }
    });
}

/// The environment variable whose value [`Device::new`] passes to Embree as its device
/// configuration, for example `isa=avx2` to pin Embree's kernels for a whole run, or
/// `threads=4`.
pub const CONFIG_ENV: &str = "DOFRAY_EMBREE_CONFIG";

/// The Embree configuration from [`CONFIG_ENV`] (empty when it is unset or not UTF-8).
pub fn env_config() -> String {
    std::env::var(CONFIG_ENV).unwrap_or_default()
}

/// The `isa=` values (Embree's device configuration) that limit Embree to an instruction set
/// this CPU supports and that is narrower than its widest: `sse4.2`, `avx`, `avx2`, in that
/// order. A device without an `isa=` limit uses the widest (AVX-512 where the CPU has it), so
/// these plus an unlimited device exercise every kernel family Embree can run here.
pub fn limited_isas() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        let has = [
            ("sse4.2", std::arch::is_x86_feature_detected!("sse4.2")),
            ("avx", std::arch::is_x86_feature_detected!("avx")),
            (
                "avx2",
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma"),
            ),
        ];
        has.iter()
            .take_while(|(_, ok)| *ok)
            .map(|(isa, _)| *isa)
            .collect()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        Vec::new()
    }
}

impl Device {
    /// A device configured from the environment: the value of `DOFRAY_EMBREE_CONFIG` (see
    /// [`CONFIG_ENV`]), else Embree's defaults.
    pub fn new() -> Result<Self> {
        Self::with_config(&env_config())
    }

    /// A device configured from the environment (as [`Device::new`]) whose thread pool, used
    /// to build BVHs, has at most `threads` threads (Embree's `threads=` option).
    pub fn with_threads(threads: usize) -> Result<Self> {
        let env = env_config();
        let sep = if env.trim().is_empty() { "" } else { "," };
        Self::with_config(&format!("{env}{sep}threads={threads}"))
    }

    /// The widest ray packet Embree's kernels on this device trace natively (16 with
    /// AVX-512, 8 with AVX or AVX2, 4 with SSE), or 1 when it has no packet kernels. Narrower
    /// than the CPU's widest when the device's `isa=` limits it.
    pub fn native_packet_width(&self) -> u32 {
        let supported = |property| {
            // SAFETY: live device; querying a device property has no other effect.
            unsafe { sys::rtcGetDeviceProperty(self.0.raw, property) != 0 }
        };
        if supported(sys::RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) {
            16
        } else if supported(sys::RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) {
            8
        } else if supported(sys::RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED) {
            4
        } else {
            1
        }
    }

    /// Embree's version as `major.minor.patch`.
    pub fn embree_version(&self) -> String {
        let get = |property| {
            // SAFETY: live device; querying a device property has no other effect.
            unsafe { sys::rtcGetDeviceProperty(self.0.raw, property) }
        };
        format!(
            "{}.{}.{}",
            get(sys::RTC_DEVICE_PROPERTY_VERSION_MAJOR),
            get(sys::RTC_DEVICE_PROPERTY_VERSION_MINOR),
            get(sys::RTC_DEVICE_PROPERTY_VERSION_PATCH)
        )
    }

    /// A device with an Embree configuration string such as `"threads=2,verbose=0"`.
    ///
    /// ```rust
    /// use dofray::embree::Device;
    ///
    /// // SSE4.2 kernels only, as on a CPU without AVX (test the narrow code paths).
    /// let device = Device::with_config("isa=sse4.2,threads=1")?;
    /// assert_eq!(device.native_packet_width(), 4);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// A config Embree rejects (say `threads=notanumber`; Embree ignores unknown options) is an
    /// [`EmbreeError::Embree`] with Embree's code. Its message quotes Embree's reason on Embree 4;
    /// Embree 3 gives a failed `rtcNewDevice` no text, only the code.
    pub fn with_config(config: &str) -> Result<Self> {
        let c_config = CString::new(config).map_err(|_| EmbreeError::InvalidConfig {
            config: config.to_string(),
            reason: "contains a NUL byte".into(),
        })?;
        // SAFETY: c_config is a valid NUL-terminated string for the duration of the call.
        let raw = unsafe { sys::rtcNewDevice(c_config.as_ptr()) };
        if raw.is_null() {
            // SAFETY: rtcGetDeviceError accepts NULL and returns (and clears) this thread's error,
            // which the failed rtcNewDevice set.
            let code = unsafe { sys::rtcGetDeviceError(std::ptr::null_mut()) };
            let message = match super::version::new_device_error_message() {
                Some(reason) => format!("rtcNewDevice rejected the config {config:?}: {reason}"),
                None => format!(
                    "rtcNewDevice rejected the config {config:?} (Embree {} gives no reason)",
                    super::version::EMBREE_MAJOR
                ),
            };
            return Err(EmbreeError::Embree {
                code: ErrorCode::from_raw(code),
                message,
            });
        }
        let errors: Box<ErrorSlot> = Box::new(Mutex::new(HashMap::new()));
        let user = &*errors as *const ErrorSlot as *mut c_void;
        // SAFETY: raw is a live device; the callback never unwinds and `user` stays valid until
        // rtcReleaseDevice in Drop, after which Embree no longer calls it.
        unsafe { sys::rtcSetDeviceErrorFunction(raw, Some(error_callback), user) };
        Ok(Device(Arc::new(DeviceInner {
            raw,
            config: config.to_string(),
            errors,
        })))
    }

    /// The configuration string the device was created with.
    pub fn config(&self) -> &str {
        &self.0.config
    }

    pub(super) fn raw(&self) -> sys::RTCDevice {
        self.0.raw
    }

    /// Turns any error Embree reported to this thread since its last check into an `Err`.
    /// Errors of other threads' calls on the same device stay with those threads.
    pub(super) fn check(&self, what: &str) -> Result<()> {
        let reported = self
            .0
            .errors
            .lock()
            .ok()
            .and_then(|mut errors| errors.remove(&thread::current().id()));
        // SAFETY: raw is a live device. This also clears Embree's own sticky error code, which
        // Embree keeps per thread.
        let code = unsafe { sys::rtcGetDeviceError(self.0.raw) };
        match reported {
            Some((code, message)) => Err(EmbreeError::Embree {
                code,
                message: format!("{what}: {message}"),
            }),
            None if code != sys::RTC_ERROR_NONE => Err(EmbreeError::Embree {
                code: ErrorCode::from_raw(code),
                message: what.to_string(),
            }),
            None => Ok(()),
        }
    }
}

impl EmbreeError {
    /// Out of memory is a resource limit and rejected geometry bad input; anything else is
    /// `otherwise` (what the caller was doing decides).
    pub fn kind_or(&self, otherwise: ErrorKind) -> ErrorKind {
        match self {
            Self::Embree {
                code: ErrorCode::OutOfMemory,
                ..
            } => ErrorKind::ResourceLimit,
            Self::Embree {
                code: ErrorCode::Unknown,
                message,
            } if refused_resource(message) => ErrorKind::ResourceLimit,
            Self::InvalidGeometry(_) => ErrorKind::BadInput,
            _ => otherwise,
        }
    }
}

/// Whether an `RTC_ERROR_UNKNOWN`'s message is the system refusing a thread or memory: Embree
/// passes on what its build threw that way (under `ulimit -v 400000`, for example:
/// "rtcCommitScene: pthread_create has failed: Resource temporarily unavailable").
fn refused_resource(message: &str) -> bool {
    [
        "pthread_create",
        "Resource temporarily unavailable",
        "bad_alloc",
        "out of memory",
    ]
    .iter()
    .any(|m| message.contains(m))
}

impl HasKind for EmbreeError {
    fn kind(&self) -> ErrorKind {
        self.kind_or(ErrorKind::Internal)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Barrier;

    use super::*;

    /// Makes Embree report an error to the calling thread: an unknown geometry type.
    fn provoke_error(device: &Device) {
        // SAFETY: live device; Embree rejects the type, returns NULL and creates nothing.
        let geom = unsafe { sys::rtcNewGeometry(device.raw(), 9999) };
        assert!(geom.is_null());
    }

    #[test]
    fn errors_are_reported_to_the_thread_whose_call_failed() {
        let device = Device::new().unwrap();
        let barrier = Barrier::new(2);
        thread::scope(|s| {
            let failing = s.spawn(|| {
                provoke_error(&device);
                barrier.wait(); // the error is recorded
                barrier.wait(); // the other thread has checked
                device.check("bad rtcNewGeometry")
            });
            barrier.wait();
            let other = device.check("another thread's call");
            barrier.wait();
            assert!(other.is_ok(), "got the other thread's error: {other:?}");
            match failing.join().unwrap() {
                Err(EmbreeError::Embree { code, message }) => {
                    assert_eq!(code, ErrorCode::Unknown, "{message}");
                    assert!(message.contains("invalid geometry type"), "{message:?}");
                }
                other => panic!("the failing thread should see its error: {other:?}"),
            }
        });
        assert!(device.0.errors.lock().unwrap().is_empty());
    }

    #[test]
    fn only_the_first_error_since_the_last_check_is_kept() {
        let device = Device::new().unwrap();
        provoke_error(&device);
        let data = [0u32; 16];
        // SAFETY: live device; Embree rejects the misaligned buffer (RTC_ERROR_INVALID_OPERATION)
        // before keeping the pointer, and the geometry is released once.
        unsafe {
            let geom = sys::rtcNewGeometry(device.raw(), sys::RTC_GEOMETRY_TYPE_TRIANGLE);
            sys::rtcSetSharedGeometryBuffer(
                geom,
                sys::RTC_BUFFER_TYPE_VERTEX,
                0,
                sys::RTC_FORMAT_FLOAT3,
                data.as_ptr().cast::<u8>().add(1).cast(),
                0,
                12,
                3,
            );
            sys::rtcReleaseGeometry(geom);
        }
        let err = device.check("two bad calls").unwrap_err();
        assert!(
            matches!(
                &err,
                EmbreeError::Embree {
                    code: ErrorCode::Unknown,
                    ..
                }
            ),
            "{err}"
        );
        assert!(device.check("next").is_ok());
    }
}
