//! The one place that knows whether dofray was built against Embree 3 or Embree 4.
//!
//! Embree 3 passes an `RTCIntersectContext` to every query; Embree 4 passes optional
//! `RTCIntersectArguments` / `RTCOccludedArguments` instead. Both initialise them with inline
//! `rtcInit*` helpers that bindgen cannot see, so they are re-done here field by field.
//! Embree 4 also keeps the text of the last error per thread (`rtcGetDeviceLastErrorMessage`),
//! which is the only way to learn why `rtcNewDevice` failed; Embree 3 has no such call.
//! Everything else dofray uses has the same name and layout in both versions.

use super::packet::{Mask4, Mask8, Mask16};
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

/// Generates one packet query (`rtcIntersect{4,8,16}` / `rtcOccluded{4,8,16}`) over both
/// Embree versions' signatures.
macro_rules! packet_query {
    ($name:ident, $rtc:ident, $Mask:ty, $Data:ty, $args:ident) => {
        /// # Safety
        /// `scene` must be a live, committed Embree scene. (The mask and the packet are aligned
        /// by their types as Embree requires for this width.)
        pub(super) unsafe fn $name(
            valid: &$Mask,
            scene: sys::RTCScene,
            data: &mut $Data,
            coherent: bool,
        ) {
            #[cfg(embree3)]
            {
                let mut ctx = context(coherent);
                // SAFETY: the caller guarantees a committed scene; the mask and packet types
                // are aligned for this width, and Embree reads exactly that many lanes of each.
                unsafe { sys::$rtc(valid.0.as_ptr(), scene, &mut ctx, data) }
            }
            #[cfg(embree4)]
            {
                let mut args = $args(coherent);
                // SAFETY: the caller guarantees a committed scene; the mask and packet types
                // are aligned for this width, and Embree reads exactly that many lanes of each.
                unsafe { sys::$rtc(valid.0.as_ptr(), scene, data, &mut args) }
            }
        }
    };
}

packet_query!(
    intersect16,
    rtcIntersect16,
    Mask16,
    sys::RTCRayHit16,
    intersect_args
);
packet_query!(
    intersect8,
    rtcIntersect8,
    Mask8,
    sys::RTCRayHit8,
    intersect_args
);
packet_query!(
    intersect4,
    rtcIntersect4,
    Mask4,
    sys::RTCRayHit4,
    intersect_args
);
packet_query!(
    occluded16,
    rtcOccluded16,
    Mask16,
    sys::RTCRay16,
    occluded_args
);
packet_query!(occluded8, rtcOccluded8, Mask8, sys::RTCRay8, occluded_args);
packet_query!(occluded4, rtcOccluded4, Mask4, sys::RTCRay4, occluded_args);
