//! The one place that knows whether dofray was built against Embree 3 or Embree 4.
//!
//! Embree 3 passes an `RTCIntersectContext` to every query; Embree 4 passes optional
//! `RTCIntersectArguments` / `RTCOccludedArguments` instead. Both initialise them with inline
//! `rtcInit*` helpers that bindgen cannot see, so they are re-done here field by field.
//! Everything else dofray uses has the same name and layout in both versions.

use super::sys;

/// Embree's major version this build links against.
#[cfg(embree3)]
pub const EMBREE_MAJOR: u32 = 3;
/// Embree's major version this build links against.
#[cfg(embree4)]
pub const EMBREE_MAJOR: u32 = 4;

#[cfg(embree3)]
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
/// `scene` must be a live, committed Embree scene; `valid` and `rayhit` are 64-byte aligned.
pub(super) unsafe fn intersect16(
    valid: &[i32; 16],
    scene: sys::RTCScene,
    rayhit: &mut sys::RTCRayHit16,
    coherent: bool,
) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: the caller guarantees a committed scene and aligned packets.
        unsafe { sys::rtcIntersect16(valid.as_ptr(), scene, &mut ctx, rayhit) }
    }
    #[cfg(embree4)]
    {
        let mut args = intersect_args(coherent);
        // SAFETY: the caller guarantees a committed scene and aligned packets.
        unsafe { sys::rtcIntersect16(valid.as_ptr(), scene, rayhit, &mut args) }
    }
}

/// # Safety
/// `scene` must be a live, committed Embree scene; `valid` and `ray` are 64-byte aligned.
pub(super) unsafe fn occluded16(
    valid: &[i32; 16],
    scene: sys::RTCScene,
    ray: &mut sys::RTCRay16,
    coherent: bool,
) {
    #[cfg(embree3)]
    {
        let mut ctx = context(coherent);
        // SAFETY: the caller guarantees a committed scene and aligned packets.
        unsafe { sys::rtcOccluded16(valid.as_ptr(), scene, &mut ctx, ray) }
    }
    #[cfg(embree4)]
    {
        let mut args = occluded_args(coherent);
        // SAFETY: the caller guarantees a committed scene and aligned packets.
        unsafe { sys::rtcOccluded16(valid.as_ptr(), scene, ray, &mut args) }
    }
}
