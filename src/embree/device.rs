//! The Embree device and the typed errors it reports.

use std::ffi::{CStr, CString, c_char, c_void};
use std::fmt;
use std::sync::{Arc, Mutex};

use super::sys;

/// Embree's error codes (`RTCError`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    Unknown,
    InvalidArgument,
    InvalidOperation,
    OutOfMemory,
    UnsupportedCpu,
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
    Embree { code: ErrorCode, message: String },
    /// Geometry data was rejected before it reached Embree.
    #[error("invalid geometry: {0}")]
    InvalidGeometry(String),
    /// A device configuration string that cannot be passed to Embree.
    #[error("invalid Embree device config {config:?}: {reason}")]
    InvalidConfig { config: String, reason: String },
}

pub type Result<T, E = EmbreeError> = std::result::Result<T, E>;

/// The first error Embree reported through the callback since it was last taken.
type ErrorSlot = Mutex<Option<(ErrorCode, String)>>;

struct DeviceInner {
    raw: sys::RTCDevice,
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
        if let Ok(mut first) = slot.lock() {
            first.get_or_insert((ErrorCode::from_raw(code), text));
        }
    });
}

impl Device {
    /// A device with Embree's default configuration.
    pub fn new() -> Result<Self> {
        Self::with_config("")
    }

    /// A device with an Embree configuration string such as `"threads=2,verbose=0"`.
    pub fn with_config(config: &str) -> Result<Self> {
        let c_config = CString::new(config).map_err(|_| EmbreeError::InvalidConfig {
            config: config.to_string(),
            reason: "contains a NUL byte".into(),
        })?;
        // SAFETY: c_config is a valid NUL-terminated string for the duration of the call.
        let raw = unsafe { sys::rtcNewDevice(c_config.as_ptr()) };
        if raw.is_null() {
            // SAFETY: rtcGetDeviceError accepts NULL and returns the error of the failed rtcNewDevice.
            let code = unsafe { sys::rtcGetDeviceError(std::ptr::null_mut()) };
            return Err(EmbreeError::Embree {
                code: ErrorCode::from_raw(code),
                message: format!("rtcNewDevice rejected the config {config:?}"),
            });
        }
        let errors: Box<ErrorSlot> = Box::new(Mutex::new(None));
        let user = &*errors as *const ErrorSlot as *mut c_void;
        // SAFETY: raw is a live device; the callback never unwinds and `user` stays valid until
        // rtcReleaseDevice in Drop, after which Embree no longer calls it.
        unsafe { sys::rtcSetDeviceErrorFunction(raw, Some(error_callback), user) };
        Ok(Device(Arc::new(DeviceInner { raw, errors })))
    }

    pub(super) fn raw(&self) -> sys::RTCDevice {
        self.0.raw
    }

    /// Turns any error Embree reported since the last check into an `Err`.
    pub(super) fn check(&self, what: &str) -> Result<()> {
        let reported = self.0.errors.lock().ok().and_then(|mut slot| slot.take());
        // SAFETY: raw is a live device. This also clears Embree's own sticky error code.
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
