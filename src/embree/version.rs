//! The one place that knows whether dofray was built against Embree 3 or Embree 4.
//!
//! Embree 3 passes an `RTCIntersectContext` to every query; Embree 4 passes optional
//! `RTCIntersectArguments` / `RTCOccludedArguments` instead. Both initialise them with inline
//! `rtcInit*` helpers that bindgen cannot see, so they are re-done here field by field.
//! Embree 4 also keeps the text of the last error per thread (`rtcGetDeviceLastErrorMessage`),
//! which is the only way to learn why `rtcNewDevice` failed; Embree 3 has no such call.
//! Everything else dofray uses has the same name and layout in both versions.

use super::packet::Mask16;
use super::sys;

/// Embree's major version this build links against.
#[cfg(embree3)]
pub const EMBREE_MAJOR: u32 = 3;
/// Embree's major version this build links against.
#[cfg(embree4)]
pub const EMBREE_MAJOR: u32 = 4;

/// Why the last `rtcNewDevice` on this thread failed, in Embree's words, or `None` when Embree
/// cannot say. Call it only after `rtcNewDevice` returned NULL: the text is not cleared, so at
/// any other time it may describe an older error.
#[cfg(embree4)]
pub(super) fn new_device_error_message() -> Option<String> {
    // SAFETY: rtcGetDeviceLastErrorMessage accepts NULL (the thread's error state, which a failed
    // rtcNewDevice sets) and returns NULL or a NUL-terminated string that stays valid until the
    // next error on this thread; it is copied before anything else can call into Embree here.
    let text = unsafe { sys::rtcGetDeviceLastErrorMessage(std::ptr::null_mut()) };
    if text.is_null() {
        return None;
    }
    // SAFETY: non-null, NUL-terminated and alive for this statement, as above.
    let text = unsafe { std::ffi::CStr::from_ptr(text) }.to_string_lossy();
    let text = text.trim();
    (!text.is_empty()).then(|| text.to_string())
}

/// Why the last `rtcNewDevice` on this thread failed, in Embree's words, or `None` when Embree
/// cannot say. Embree 3 never can: `rtcGetDeviceError(NULL)` gives only the error code, and the
/// error callback, which carries the text, can only be set on a device that exists.
#[cfg(embree3)]
pub(super) fn new_device_error_message() -> Option<String> {
    None
}

// `..Default::default()` zeroes whatever fields this build's header adds beyond the three every
// Embree 3.13 has (`instStackSize` when RTC_MAX_INSTANCE_LEVEL_COUNT > 1), as
// rtcInitIntersectContext does; with the default header it updates nothing.
#[cfg(embree3)]
#[allow(clippy::needless_update)]
fn context(coherent: bool) -> sys::RTCIntersectContext {
    // Mirrors rtcInitIntersectContext.
    sys::RTCIntersectContext {
        flags: if coherent {
            sys::RTC_INTERSECT_CONTEXT_FLAG_COHERENT
        } else {
            sys::RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT
        },
        filter: None,
        instID: [sys::RTC_INVALID_GEOMETRY_ID; sys::RTC_MAX_INSTANCE_LEVEL_COUNT as usize],
        ..Default::default()
    }
}

#[cfg(embree4)]
fn query_flags(coherent: bool) -> sys::RTCRayQueryFlags {
    if coherent {
        sys::RTC_RAY_QUERY_FLAG_COHERENT
    } else {
        sys::RTC_RAY_QUERY_FLAG_INCOHERENT
    }
}

#[cfg(embree4)]
fn intersect_args(coherent: bool) -> sys::RTCIntersectArguments {
    // Mirrors rtcInitIntersectArguments: everything null/zero except flags and the feature mask.
    // A null context makes Embree use its default (rtcInitRayQueryContext) context.
    sys::RTCIntersectArguments {
        flags: query_flags(coherent),
        feature_mask: sys::RTC_FEATURE_FLAG_ALL,
        ..Default::default()
    }
}

#[cfg(embree4)]
fn occluded_args(coherent: bool) -> sys::RTCOccludedArguments {
    // Mirrors rtcInitOccludedArguments.
    sys::RTCOccludedArguments {
        flags: query_flags(coherent),
        feature_mask: sys::RTC_FEATURE_FLAG_ALL,
        ..Default::default()
    }
}

/// # Safety
/// `scene` must be a live, committed Embree scene.
pub(super) unsafe fn intersect1(scene: sys::RTCScene, rayhit: &mut sys::RTCRayHit, coherent: bool) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: the caller guarantees a committed scene; ctx and rayhit are valid for the call.
        unsafe { sys::rtcIntersect1(scene, &mut ctx, rayhit) }
    }
    #[cfg(embree4)]
    {
        let mut args = intersect_args(coherent);
        // SAFETY: the caller guarantees a committed scene; args and rayhit are valid for the call.
        unsafe { sys::rtcIntersect1(scene, rayhit, &mut args) }
    }
}

/// # Safety
/// `scene` must be a live, committed Embree scene.
pub(super) unsafe fn occluded1(scene: sys::RTCScene, ray: &mut sys::RTCRay, coherent: bool) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: as in intersect1.
        unsafe { sys::rtcOccluded1(scene, &mut ctx, ray) }
    }
    #[cfg(embree4)]
    {
        let mut args = occluded_args(coherent);
        // SAFETY: as in intersect1.
        unsafe { sys::rtcOccluded1(scene, ray, &mut args) }
    }
}

/// # Safety
/// `scene` must be a live, committed Embree scene. (`valid` and `rayhit` are 64-byte aligned
/// by their types, as rtcIntersect16 requires.)
pub(super) unsafe fn intersect16(
    valid: &Mask16,
    scene: sys::RTCScene,
    rayhit: &mut sys::RTCRayHit16,
    coherent: bool,
) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: the caller guarantees a committed scene; the mask and packet types are 64-byte
        // aligned and Embree reads 16 lanes of each.
        unsafe { sys::rtcIntersect16(valid.0.as_ptr(), scene, &mut ctx, rayhit) }
    }
    #[cfg(embree4)]
    {
        let mut args = intersect_args(coherent);
        // SAFETY: the caller guarantees a committed scene; the mask and packet types are 64-byte
        // aligned and Embree reads 16 lanes of each.
        unsafe { sys::rtcIntersect16(valid.0.as_ptr(), scene, rayhit, &mut args) }
    }
}

/// # Safety
/// `scene` must be a live, committed Embree scene. (`valid` and `ray` are 64-byte aligned by
/// their types, as rtcOccluded16 requires.)
pub(super) unsafe fn occluded16(
    valid: &Mask16,
    scene: sys::RTCScene,
    ray: &mut sys::RTCRay16,
    coherent: bool,
) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: the caller guarantees a committed scene; the mask and packet types are 64-byte
        // aligned and Embree reads 16 lanes of each.
        unsafe { sys::rtcOccluded16(valid.0.as_ptr(), scene, &mut ctx, ray) }
    }
    #[cfg(embree4)]
    {
        let mut args = occluded_args(coherent);
        // SAFETY: the caller guarantees a committed scene; the mask and packet types are 64-byte
        // aligned and Embree reads 16 lanes of each.
        unsafe { sys::rtcOccluded16(valid.0.as_ptr(), scene, ray, &mut args) }
    }
}
