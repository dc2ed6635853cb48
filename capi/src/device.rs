//! Devices.

use std::ffi::c_char;
use std::sync::atomic::{AtomicU64, Ordering};

use dofray::embree::Device;

use crate::args::{free, out_arg, put, str_arg};
use crate::status::{DofrayStatus, guard};

/// An Embree device: builds and traces scenes. Share one among all scenes and threads.
pub struct DofrayDevice {
    pub(crate) device: Device,
    /// Unique per device created here, so a scene knows whether its cached world is its.
    pub(crate) id: u64,
}

pub(crate) fn next_device_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Creates an Embree device. `config`: Embree's configuration string (such as
/// `"threads=2"` or `"isa=avx2"`); NULL or `""` takes it from the environment variable
/// `DOFRAY_EMBREE_CONFIG`, else Embree's defaults. The first call also starts dofray's
/// worker threads (one a core; `RAYON_NUM_THREADS` sets another count), before any scene
/// takes memory: a worker first started under an address-space limit the scene had used up
/// would abort the process.
///
/// # Safety
/// `config` is NULL or a NUL-terminated string; `out` is NULL or points to writable storage
/// for a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_device_new(
    config: *const c_char,
    out: *mut *mut DofrayDevice,
) -> DofrayStatus {
    guard(|| {
        // SAFETY: the function's contract.
        let out = unsafe { out_arg(out) }?;
        dofray::workers::start_global();
        let device = if config.is_null() {
            Device::new()?
        } else {
            // SAFETY: non-NULL, NUL-terminated by the function's contract.
            match unsafe { str_arg(config, "config") }? {
                "" => Device::new()?,
                config => Device::with_config(config)?,
            }
        };
        let id = next_device_id();
        // SAFETY: out was checked by out_arg.
        unsafe { put(out, DofrayDevice { device, id }) };
        Ok(())
    })
}

/// Frees a device (NULL: nothing). Scenes rendered on it keep what they need of it alive.
///
/// # Safety
/// `device` is NULL or a device from `dofray_device_new`, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dofray_device_free(device: *mut DofrayDevice) {
    // SAFETY: the function's contract.
    unsafe { free(device) }
}
