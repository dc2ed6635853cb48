//! Camera and lens animation: keyed tracks of the camera's parameters, interpolated per frame
//! (the `[animation]` table of a scene file, `docs/scene-format.md`).
//!
//! Every animated parameter is a track of its own: a list of keys (frame, value, and how
//! the segment that starts at the key runs to the next one), so a key need not set every
//! parameter. Before a track's first key and after its last, the track holds that key's value.
//! Some parameters are interpolated in another space than their own units, as a camera
//! operator's controls are: the focus distance in dioptres (1 / distance, as a focus ring
//! turns; `inf` is 0 dioptres), the f-number in stops (its logarithm, as an aperture ring
//! clicks). The rest (positions, field of view, focal length, aperture radius) interpolate in
//! their own units.

use std::ops::{Add, Mul, RangeInclusive, Sub};

use glam::DVec3;
use serde::Deserialize;

use crate::camera::{CameraSpec, Focus, LensSpec};

/// How a track runs from one key to the next (set on the key the segment starts at).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// A straight line: constant velocity between the keys.
    Linear,
    /// A Catmull-Rom spline through the keys (non-uniform: the tangent at a key is the slope of
    /// the parabola through it and its two neighbours, by frame number), flat at a track's
    /// first and last key, so a track of two keys eases in and out without overshooting.
    /// Between keys of more than two, the curve may overshoot a little, as every
    /// Catmull-Rom spline does.
    #[default]
    Smooth,
    /// Smoothstep (3u² - 2u³) from one key to the next: zero velocity at every key.
    Ease,
    /// Hold the key's value until the next key's frame (a cut).
    Constant,
}

/// What a track's values must support to be interpolated: `f64` and `DVec3`.
pub(crate) trait Value:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<f64, Output = Self>
{
    /// The zero velocity.
    const ZERO: Self;
}

impl Value for f64 {
    const ZERO: Self = 0.0;
}

impl Value for DVec3 {
    const ZERO: Self = DVec3::ZERO;
}

/// One key of a track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Key<T> {
    pub frame: i64,
    pub value: T,
    /// How the segment from this key to the next one runs.
    pub interpolation: Interpolation,
}

/// The keys of one parameter, in frame order, at most one per frame, at least one.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Track<T> {
    keys: Vec<Key<T>>,
}

impl<T: Value> Track<T> {
    /// A track from keys in any order; `Err(frame)` names a frame with two keys, `Err(None)`
    /// says there are no keys.
    pub fn new(mut keys: Vec<Key<T>>) -> Result<Self, Option<i64>> {
        keys.sort_by_key(|k| k.frame);
        if let Some(w) = keys.windows(2).find(|w| w[0].frame == w[1].frame) {
            return Err(Some(w[0].frame));
        }
        if keys.is_empty() {
            return Err(None);
        }
        Ok(Self { keys })
    }

    /// The value at `frame` (sub-frames interpolate too).
    pub fn at(&self, frame: f64) -> T {
        let keys = &self.keys;
        let (first, last) = (&keys[0], &keys[keys.len() - 1]);
        // Hold before the first key and after the last (NaN holds the first).
        if frame.is_nan() || frame <= first.frame as f64 {
            return first.value;
        }
        if frame >= last.frame as f64 {
            return last.value;
        }
        // The segment [i, i + 1] containing the frame.
        let i = keys.partition_point(|k| k.frame as f64 <= frame) - 1;
        let (a, b) = (&keys[i], &keys[i + 1]);
        let span = (b.frame - a.frame) as f64;
        let u = (frame - a.frame as f64) / span;
        let delta = b.value - a.value;
        match a.interpolation {
            Interpolation::Constant => a.value,
            Interpolation::Linear => a.value + delta * u,
            Interpolation::Ease => a.value + delta * (u * u * (3.0 - 2.0 * u)),
            Interpolation::Smooth => {
                // Cubic Hermite with tangents scaled from per frame to per segment.
                let (m0, m1) = (self.tangent(i) * span, self.tangent(i + 1) * span);
                let (u2, u3) = (u * u, u * u * u);
                a.value * (2.0 * u3 - 3.0 * u2 + 1.0)
                    + m0 * (u3 - 2.0 * u2 + u)
                    + b.value * (3.0 * u2 - 2.0 * u3)
                    + m1 * (u3 - u2)
            }
        }
    }

    /// The smooth curve's velocity (value per frame) at key `i`: zero at the track's ends,
    /// else non-uniform Catmull-Rom's, the slope at key i of the parabola through keys i - 1,
    /// i and i + 1 (Barry and Goldman's pyramid with frame numbers as knots gives the same).
    fn tangent(&self, i: usize) -> T {
        if i == 0 || i + 1 >= self.keys.len() {
            return T::ZERO;
        }
        let (p, k, n) = (&self.keys[i - 1], &self.keys[i], &self.keys[i + 1]);
        let (h0, h1) = ((k.frame - p.frame) as f64, (n.frame - k.frame) as f64);
        let slope0 = (k.value - p.value) * (1.0 / h0);
        let slope1 = (n.value - k.value) * (1.0 / h1);
        (slope0 * h1 + slope1 * h0) * (1.0 / (h0 + h1))
    }
}

/// The focus track: a distance (keyed in scene units or `inf`, interpolated in dioptres) or a
/// point in focus.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum FocusTrack {
    /// Dioptres: 1 / focus distance (0 = focused at infinity).
    Dioptres(Track<f64>),
    Point(Track<DVec3>),
}

/// Every animated parameter (None: not animated). Scalars are stored in the space they are
/// interpolated in (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Tracks {
    pub eye: Option<Track<DVec3>>,
    pub look_at: Option<Track<DVec3>>,
    pub up: Option<Track<DVec3>>,
    /// Degrees.
    pub vfov: Option<Track<f64>>,
    /// Millimetres.
    pub focal_length_mm: Option<Track<f64>>,
    /// ln(f-number): interpolated in stops.
    pub ln_f_number: Option<Track<f64>>,
    /// Scene units.
    pub aperture_radius: Option<Track<f64>>,
    pub focus: Option<FocusTrack>,
}

/// A camera animation: the frame range and rate of a shot, and keyed tracks of the camera's
/// view (`eye`, `look_at`, `up`, `vfov`), lens (`focal_length_mm`, `f_number`,
/// `aperture_radius`) and focus (`focus_distance` or `focus_point`).
///
/// Made by the scene file loader from an `[animation]` table (which checks that the tracks
/// fit the camera's lens and that every frame of the range has a valid view); see
/// `docs/scene-format.md`. A still render uses the scene's `[camera]` as written; to render
/// frame `f`, [`Animation::apply`] it to a copy of that camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    /// Frames per second (finite, > 0): how frame numbers map to time for whoever plays the
    /// frames back (the camera does not depend on it).
    pub fps: f32,
    /// The first frame of the shot.
    pub frame_start: i64,
    /// The last frame of the shot (>= `frame_start`).
    pub frame_end: i64,
    pub(crate) tracks: Tracks,
}

impl Animation {
    /// Sets every animated camera and lens parameter of `camera` to its value at `frame` (an
    /// f64, so sub-frames, for motion blur say, interpolate too; the shot's frames are the
    /// integers of [`Animation::frames`]). Parameters that are not animated keep `camera`'s
    /// values. An animated focus replaces the camera's focus (a distance, point or autofocus
    /// pixel). Lens tracks apply only to the kind of lens they were checked against: the
    /// f-number and focal length to a photographic lens, the aperture radius to an
    /// aperture-radius lens or a pinhole (which then becomes an aperture of that radius), the
    /// field of view to any lens but a photographic one; a track that does not fit `camera`'s
    /// lens (say the command line replaced the lens) is skipped.
    ///
    /// The values are not validated here ([`CameraSpec::build`] does that): a spline through
    /// more than two keys can overshoot, and a focus distance that would overshoot beyond
    /// infinity stays at infinity, a radius below 0 at 0.
    pub fn apply(&self, camera: &mut CameraSpec, frame: f64) {
        let t = &self.tracks;
        if let Some(eye) = &t.eye {
            camera.eye = eye.at(frame).as_vec3();
        }
        if let Some(look_at) = &t.look_at {
            camera.look_at = look_at.at(frame).as_vec3();
        }
        if let Some(up) = &t.up {
            camera.up = up.at(frame).as_vec3();
        }
        match &mut camera.lens {
            LensSpec::Photographic {
                focal_length_mm,
                f_number,
                ..
            } => {
                if let Some(track) = &t.focal_length_mm {
                    *focal_length_mm = track.at(frame) as f32;
                }
                if let Some(track) = &t.ln_f_number {
                    *f_number = track.at(frame).exp() as f32;
                }
            }
            lens @ (LensSpec::Aperture { .. } | LensSpec::Pinhole) => {
                if let Some(track) = &t.aperture_radius {
                    let radius = track.at(frame).max(0.0) as f32;
                    *lens = if radius > 0.0 {
                        LensSpec::Aperture { radius }
                    } else {
                        LensSpec::Pinhole
                    };
                }
            }
            LensSpec::Seed { .. } => {}
        }
        if !matches!(camera.lens, LensSpec::Photographic { .. }) {
            if let Some(vfov) = &t.vfov {
                camera.vfov_deg = vfov.at(frame) as f32;
            }
        }
        match &t.focus {
            None => {}
            Some(FocusTrack::Dioptres(track)) => {
                // Dioptres beyond 0 (a spline overshooting infinity) stay at infinity.
                camera.focus = Focus::Distance((1.0 / track.at(frame).max(0.0)) as f32);
            }
            Some(FocusTrack::Point(track)) => {
                camera.focus = Focus::Point(track.at(frame).as_vec3())
            }
        }
    }

    /// The shot's frames: `frame_start..=frame_end`.
    pub fn frames(&self) -> RangeInclusive<i64> {
        self.frame_start..=self.frame_end
    }

    /// The animated parameters, by their scene-file key names (`eye`, `look_at`, `up`, `vfov`,
    /// `focal_length_mm`, `f_number`, `aperture_radius`, and `focus_distance` or
    /// `focus_point`), in that order. `focus_point` is among them also when the focus follows
    /// an animated `look_at` (a scene whose `[camera]` gives no focus key, so the focus is on
    /// `look_at`, and whose animation keys no focus).
    pub fn parameters(&self) -> Vec<&'static str> {
        let t = &self.tracks;
        [
            ("eye", t.eye.is_some()),
            ("look_at", t.look_at.is_some()),
            ("up", t.up.is_some()),
            ("vfov", t.vfov.is_some()),
            ("focal_length_mm", t.focal_length_mm.is_some()),
            ("f_number", t.ln_f_number.is_some()),
            ("aperture_radius", t.aperture_radius.is_some()),
            (
                "focus_distance",
                matches!(t.focus, Some(FocusTrack::Dioptres(_))),
            ),
            ("focus_point", matches!(t.focus, Some(FocusTrack::Point(_)))),
        ]
        .into_iter()
        .filter_map(|(name, animated)| animated.then_some(name))
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn track(keys: &[(i64, f64, Interpolation)]) -> Track<f64> {
        Track::new(
            keys.iter()
                .map(|&(frame, value, interpolation)| Key {
                    frame,
                    value,
                    interpolation,
                })
                .collect(),
        )
        .unwrap()
    }

    use Interpolation::*;

    #[test]
    fn keys_are_sorted_and_unique() {
        let t = track(&[(10, 1.0, Linear), (0, 0.0, Linear)]);
        assert_eq!(t.at(5.0), 0.5);
        let dup = Track::new(vec![
            Key {
                frame: 3,
                value: 0.0,
                interpolation: Linear,
            };
            2
        ]);
        assert_eq!(dup, Err(Some(3)));
        assert_eq!(Track::<f64>::new(vec![]), Err(None));
    }

    #[test]
    fn linear_and_constant_and_hold() {
        let t = track(&[(0, 2.0, Linear), (4, 8.0, Constant), (8, 0.0, Linear)]);
        assert_eq!(t.at(2.0), 5.0);
        assert_eq!(t.at(1.0), 3.5);
        assert_eq!(t.at(4.0), 8.0);
        assert_eq!(t.at(7.999), 8.0);
        assert_eq!(t.at(8.0), 0.0);
        assert_eq!(t.at(-100.0), 2.0);
        assert_eq!(t.at(100.0), 0.0);
        assert_eq!(t.at(f64::NAN), 2.0);
    }

    #[test]
    fn ease_is_flat_at_keys_and_monotone() {
        let t = track(&[(0, 1.0, Ease), (10, 3.0, Ease), (30, -1.0, Ease)]);
        let h = 1e-4;
        for key in [0.0, 10.0, 30.0] {
            let v = (t.at(key + h) - t.at(key - h)) / (2.0 * h);
            assert!(v.abs() < 1e-3, "velocity {v} at {key}");
        }
        let mut prev = t.at(0.0);
        for i in 1..=100 {
            let x = t.at(i as f64 * 0.1);
            assert!(x >= prev);
            prev = x;
        }
        assert_eq!(t.at(5.0), 2.0);
    }

    #[test]
    fn smooth_passes_through_keys_with_parabola_tangents() {
        // Non-uniform spacing: keys on a parabola are reproduced in the interior tangent.
        let f = |x: f64| 0.5 * x * x - x + 3.0;
        let frames = [0i64, 2, 7, 8, 20];
        let t = track(&frames.map(|x| (x, f(x as f64), Smooth)));
        for x in frames {
            assert!((t.at(x as f64) - f(x as f64)).abs() < 1e-12);
        }
        for (i, &x) in frames.iter().enumerate().take(4).skip(1) {
            assert!((t.tangent(i) - (x as f64 - 1.0)).abs() < 1e-9);
        }
        assert_eq!(t.tangent(0), 0.0);
        assert_eq!(t.tangent(4), 0.0);
        // Two keys: eases in and out, within the keys.
        let two = track(&[(0, 1.0, Smooth), (10, 5.0, Smooth)]);
        for i in 0..=100 {
            let v = two.at(i as f64 * 0.1);
            assert!((1.0..=5.0).contains(&v));
        }
        assert!((two.at(0.01) - 1.0).abs() < 1e-4);
        assert_eq!(two.at(5.0), 3.0);
    }

    #[test]
    fn vectors_interpolate_per_component() {
        let t = Track::new(vec![
            Key {
                frame: 1,
                value: DVec3::new(0.0, 1.0, 5.0),
                interpolation: Linear,
            },
            Key {
                frame: 3,
                value: DVec3::new(2.0, 1.0, 3.0),
                interpolation: Linear,
            },
        ])
        .unwrap();
        assert_eq!(t.at(2.0), DVec3::new(1.0, 1.0, 4.0));
    }
}
