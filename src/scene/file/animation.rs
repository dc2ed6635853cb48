//! The `[animation]` table: keys, tracks and the check of every frame of the shot.

use std::ops::Range;

use glam::DVec3;
use toml::Spanned;

use super::Ctx;
use super::camera::{BEHIND, in_front, view_problem};
use super::raw::{RawAnimation, RawKey, dv3};
use crate::camera::{CameraSpec, Focus, LensSpec};
use crate::scene::animation::{Animation, FocusTrack, Interpolation, Key, Track, Tracks, Value};
use crate::scene::error::LoadError;
use crate::scene::model::short_vec;

/// The largest frame number (either sign) a scene may give.
const MAX_FRAME: i64 = 1_000_000_000;
/// The most frames a shot may have (every one is checked when the file is loaded).
const MAX_SHOT_FRAMES: i64 = 1_000_000;

/// Where one parameter's key is written: its frame, its `[[animation.key]]` index and the span
/// of its value.
struct Place {
    frame: i64,
    index: usize,
    span: Range<usize>,
}

/// The keys of one parameter and where they are written (in frame order).
type Places = Vec<(&'static str, Vec<Place>)>;

/// The keys' positions (`[x, y, z]`) by name.
const POINTS: [&str; 4] = ["eye", "look_at", "up", "focus_point"];
/// The keys' numbers by name.
const SCALARS: [&str; 5] = [
    "vfov",
    "focal_length_mm",
    "f_number",
    "aperture_radius",
    "focus_distance",
];

impl RawKey {
    /// Where position `name` is written in this key, and its value, if the key sets it.
    fn point(&self, name: &str) -> Option<(Range<usize>, DVec3)> {
        let v = match name {
            "eye" => &self.eye,
            "look_at" => &self.look_at,
            "up" => &self.up,
            "focus_point" => &self.focus_point,
            _ => return None,
        }
        .as_ref()?;
        Some((v.span(), dv3(*v.get_ref())))
    }

    /// Where number `name` is written in this key, and its value, if the key sets it.
    fn scalar(&self, name: &str) -> Option<(Range<usize>, f64)> {
        fn read<T>(v: &Option<Spanned<T>>, f: fn(&T) -> f32) -> Option<(Range<usize>, f64)> {
            v.as_ref().map(|v| (v.span(), f(v.get_ref()) as f64))
        }
        match name {
            "vfov" => read(&self.vfov, |v| v.0),
            "focal_length_mm" => read(&self.focal_length_mm, |v| v.0),
            "f_number" => read(&self.f_number, |v| v.0),
            "aperture_radius" => read(&self.aperture_radius, |v| v.0),
            "focus_distance" => read(&self.focus_distance, |v| v.0),
            _ => None,
        }
    }
}

/// Reads tracks from the keys, recording where each parameter's keys are.
struct TrackReader<'a> {
    ctx: &'a Ctx<'a>,
    keys: &'a [Spanned<RawKey>],
    /// The table's interpolation (for keys that give none).
    default: Interpolation,
    places: Places,
}

impl TrackReader<'_> {
    /// The track of position `name`, or None when no key sets it.
    fn point(&mut self, name: &'static str) -> Result<Option<Track<DVec3>>, LoadError> {
        self.track(name, |k| k.point(name))
    }

    /// The track of number `name`, interpolated as `space` of it, or None when no key sets it.
    fn scalar(
        &mut self,
        name: &'static str,
        space: fn(f64) -> f64,
    ) -> Result<Option<Track<f64>>, LoadError> {
        self.track(name, |k| k.scalar(name).map(|(span, v)| (span, space(v))))
    }

    /// The track of parameter `name` from the keys that set it (`value` reads it from a key,
    /// in the space it is interpolated in), or None when no key does.
    fn track<T: Value>(
        &mut self,
        name: &'static str,
        value: impl Fn(&RawKey) -> Option<(Range<usize>, T)>,
    ) -> Result<Option<Track<T>>, LoadError> {
        let (mut found, mut spots) = (Vec::new(), Vec::<Place>::new());
        for (index, k) in self.keys.iter().enumerate() {
            let k = k.get_ref();
            let Some((span, value)) = value(k) else {
                continue;
            };
            let frame = *k.frame.get_ref();
            if let Some(first) = spots.iter().find(|p| p.frame == frame) {
                return Err(self.ctx.invalid(
                    span,
                    format!("animation.key[{index}].{name}"),
                    format!(
                        "`{name}` is keyed twice at frame {frame} (animation.key[{}] keys it \
                         there too); a parameter has at most one key per frame",
                        first.index
                    ),
                ));
            }
            found.push(Key {
                frame,
                value,
                interpolation: k.interpolation.unwrap_or(self.default),
            });
            spots.push(Place { frame, index, span });
        }
        if !spots.is_empty() {
            spots.sort_by_key(|p| p.frame);
            self.places.push((name, spots));
        }
        // Frames are unique, so this fails only without keys.
        Ok(Track::new(found).ok())
    }
}

/// The keys of `name`, if it is animated.
fn keys_of<'a>(places: &'a Places, name: &str) -> Option<&'a [Place]> {
    places
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, p)| p.as_slice())
}

/// The `[animation]` table: its tracks, checked against the camera's lens, and every frame of
/// the shot checked for a valid view. `focus_on_look_at`: the camera's focus is its `look_at`
/// by default (no focus key in `[camera]`), so without focus keys it follows an animated
/// `look_at`.
pub(super) fn animation(
    ctx: &Ctx,
    raw: Spanned<RawAnimation>,
    camera: &CameraSpec,
    focus_on_look_at: bool,
) -> Result<Animation, LoadError> {
    let table = raw.span();
    let raw = raw.into_inner();
    check_keys(ctx, &raw)?;
    let (frame_start, frame_end) = shot(ctx, &raw, &table)?;

    let mut read = TrackReader {
        ctx,
        keys: &raw.key,
        default: raw.interpolation.unwrap_or_default(),
        places: Places::new(),
    };
    let same = |v: f64| v;
    let tracks = Tracks {
        eye: read.point("eye")?,
        look_at: read.point("look_at")?,
        up: read.point("up")?,
        vfov: read.scalar("vfov", same)?,
        focal_length_mm: read.scalar("focal_length_mm", same)?,
        ln_f_number: read.scalar("f_number", f64::ln)?,
        aperture_radius: read.scalar("aperture_radius", same)?,
        focus: None,
    };
    // Focus distances in dioptres (inf is 0).
    let dioptres = read.scalar("focus_distance", |d| 1.0 / d)?;
    let focus_point = read.point("focus_point")?;
    let places = read.places;
    if camera.real_lens.is_some() {
        check_real_lens_keys(ctx, &places)?;
    } else {
        check_lens_keys(ctx, &camera.lens, &places)?;
    }
    check_focus_keys(ctx, &places)?;
    let focus = match (dioptres, focus_point) {
        (Some(d), _) => Some(FocusTrack::Dioptres(d)),
        (None, Some(p)) => Some(FocusTrack::Point(p)),
        (None, None) if focus_on_look_at => tracks.look_at.clone().map(FocusTrack::Point),
        (None, None) => None,
    };
    let animation = Animation {
        fps: raw.fps.map_or(24.0, |f| f.0),
        frame_start,
        frame_end,
        tracks: Tracks { focus, ..tracks },
    };
    check_frames(ctx, &animation, camera, &places, table)?;
    Ok(animation)
}

/// A key's frame number (`v`, at `key`), if in range.
fn frame(ctx: &Ctx, v: &Spanned<i64>, key: String) -> Result<i64, LoadError> {
    // A range test, not abs(): abs(i64::MIN) overflows.
    if (-MAX_FRAME..=MAX_FRAME).contains(v.get_ref()) {
        Ok(*v.get_ref())
    } else {
        Err(ctx.invalid(
            v.span(),
            key,
            "a frame number from -1000000000 to 1000000000",
        ))
    }
}

/// Refuses keys at frames out of range and keys that set nothing.
fn check_keys(ctx: &Ctx, raw: &RawAnimation) -> Result<(), LoadError> {
    for (i, k) in raw.key.iter().enumerate() {
        let key = k.get_ref();
        frame(ctx, &key.frame, format!("animation.key[{i}].frame"))?;
        let sets = POINTS.iter().any(|n| key.point(n).is_some())
            || SCALARS.iter().any(|n| key.scalar(n).is_some());
        if !sets {
            return Err(ctx.invalid(
                k.span(),
                format!("animation.key[{i}]"),
                "a key sets no parameter: give at least one of eye, look_at, up, vfov, \
                 focal_length_mm, f_number, aperture_radius, focus_distance, focus_point",
            ));
        }
    }
    Ok(())
}

/// The shot's first and last frames: `frame_start` and `frame_end`, else the keys' first
/// and last.
fn shot(ctx: &Ctx, raw: &RawAnimation, table: &Range<usize>) -> Result<(i64, i64), LoadError> {
    let key_frames = || raw.key.iter().map(|k| *k.get_ref().frame.get_ref());
    let range_end = |v: &Option<Spanned<i64>>, key: &str, default: Option<i64>| match v {
        Some(v) => frame(ctx, v, format!("animation.{key}")),
        None => default.ok_or_else(|| {
            ctx.invalid(
                table.clone(),
                format!("animation.{key}"),
                "an animation without keys needs `frame_start` and `frame_end`",
            )
        }),
    };
    let frame_start = range_end(&raw.frame_start, "frame_start", key_frames().min())?;
    let frame_end = range_end(&raw.frame_end, "frame_end", key_frames().max())?;
    let frames = frame_end - frame_start + 1;
    if !(1..=MAX_SHOT_FRAMES).contains(&frames) {
        let span = raw
            .frame_end
            .as_ref()
            .or(raw.frame_start.as_ref())
            .map_or(table.clone(), |s| s.span());
        let message = if frames < 1 {
            format!("`frame_end` ({frame_end}) must be at least `frame_start` ({frame_start})")
        } else {
            format!(
                "the shot from frame {frame_start} to {frame_end} has {frames} frames; a shot \
                 has at most {MAX_SHOT_FRAMES}"
            )
        };
        return Err(ctx.invalid(span, "animation.frame_end", message));
    }
    Ok((frame_start, frame_end))
}

/// The first (lowest-index) key of `name`, if it is animated.
fn first_key<'a>(places: &'a Places, name: &str) -> Option<&'a Place> {
    let spots = keys_of(places, name)?;
    spots.iter().min_by_key(|p| p.index)
}

/// Refuses keys that animate a lens when the `[camera]` has a real lens (a prescription):
/// only its focus and the view are animated.
fn check_real_lens_keys(ctx: &Ctx, places: &Places) -> Result<(), LoadError> {
    for name in ["vfov", "focal_length_mm", "f_number", "aperture_radius"] {
        if let Some(p) = first_key(places, name) {
            return Err(ctx.invalid(
                p.span.clone(),
                format!("animation.key[{}].{name}", p.index),
                format!("`{name}` cannot be animated with a real lens (`camera.lens`): keys may move the view and the focus"),
            ));
        }
    }
    Ok(())
}

/// Refuses keys that animate another lens than the `[camera]`'s.
fn check_lens_keys(ctx: &Ctx, lens_spec: &LensSpec, places: &Places) -> Result<(), LoadError> {
    let lens_conflict = |name: &str, message: String| match first_key(places, name) {
        Some(p) => Err(ctx.invalid(
            p.span.clone(),
            format!("animation.key[{}].{name}", p.index),
            message,
        )),
        None => Ok(()),
    };
    let lens = match lens_spec {
        LensSpec::Pinhole => "a pinhole (no lens key, or `aperture_radius = 0`)",
        LensSpec::Aperture { .. } => "an aperture radius (`aperture_radius`)",
        LensSpec::Photographic { .. } => "photographic (`f_number`)",
        LensSpec::Seed { .. } => "the seed's (`sharp_range` and `spread`)",
    };
    if !matches!(lens_spec, LensSpec::Photographic { .. }) {
        for name in ["f_number", "focal_length_mm"] {
            lens_conflict(
                name,
                format!(
                    "`{name}` animates a photographic lens, but the [camera] lens is {lens}; \
                     give `f_number` in [camera]{}",
                    if matches!(lens_spec, LensSpec::Seed { .. }) {
                        ""
                    } else {
                        " or animate `aperture_radius`"
                    }
                ),
            )?;
        }
    } else {
        lens_conflict(
            "vfov",
            "a photographic lens (`f_number` in [camera]) sets the field of view from \
             focal_length_mm and sensor_width_mm; animate `focal_length_mm` instead of `vfov`"
                .into(),
        )?;
    }
    if !matches!(lens_spec, LensSpec::Aperture { .. } | LensSpec::Pinhole) {
        lens_conflict(
            "aperture_radius",
            format!(
                "`aperture_radius` animates an aperture-radius lens (or a pinhole), but the \
                 [camera] lens is {lens}{}",
                if matches!(lens_spec, LensSpec::Photographic { .. }) {
                    "; animate `f_number` instead"
                } else {
                    ""
                }
            ),
        )?;
    }
    Ok(())
}

/// Refuses keys of both `focus_distance` and `focus_point`, at the later one.
fn check_focus_keys(ctx: &Ctx, places: &Places) -> Result<(), LoadError> {
    if let (Some(d), Some(p)) = (
        first_key(places, "focus_distance"),
        first_key(places, "focus_point"),
    ) {
        let ((later, name), other) = if d.index > p.index {
            ((d, "focus_distance"), p)
        } else {
            ((p, "focus_point"), d)
        };
        return Err(ctx.invalid(
            later.span.clone(),
            format!("animation.key[{}].{name}", later.index),
            format!(
                "`focus_distance` and `focus_point` are both keyed (animation.key[{}] keys the \
                 other); animate one of them",
                other.index
            ),
        ));
    }
    Ok(())
}

/// Checks the camera of every frame of the shot: a valid view, the point in focus in front,
/// and whatever [`CameraSpec::build`] checks; the first bad frame is reported at the key of
/// the parameter most likely to blame that is animated (the last of its keys at or before the
/// frame, else its first), else at the `[animation]` table.
fn check_frames(
    ctx: &Ctx,
    animation: &Animation,
    camera: &CameraSpec,
    places: &Places,
    table: Range<usize>,
) -> Result<(), LoadError> {
    for frame in animation.frames() {
        let mut c = camera.clone();
        animation.apply(&mut c, frame as f64);
        let (suspects, message): (&[&str], String) =
            if let Some((key, message)) = view_problem(c.eye, c.look_at, c.up) {
                let suspects: &[&str] = if key == "up" {
                    &["up", "eye", "look_at"]
                } else {
                    &["look_at", "eye"]
                };
                let shown = format!(
                    "{message} (eye {}, look_at {}, up {})",
                    short_vec(c.eye),
                    short_vec(c.look_at),
                    short_vec(c.up)
                );
                (suspects, shown)
            } else if matches!(c.focus, Focus::Point(p) if !in_front(c.eye, c.look_at, p)) {
                (&["focus_point", "eye", "look_at"], BEHIND.into())
            } else {
                match c.build(|_| Some(1.0)) {
                    Ok(_) => continue,
                    Err(e) => {
                        let suspects: &[&str] = match &e {
                            crate::camera::CameraError::Invalid { name, .. } => match *name {
                                "vfov_deg" => &["vfov", "focal_length_mm"],
                                "focal_length_mm" => &["focal_length_mm"],
                                "f_number" => &["f_number"],
                                "aperture radius" => {
                                    &["aperture_radius", "f_number", "focal_length_mm", "eye"]
                                }
                                "focus distance" => &["focus_distance", "focus_point"],
                                _ => &["eye", "look_at", "up"],
                            },
                            _ => &[],
                        };
                        (suspects, e.to_string())
                    }
                }
            };
        let (span, key) = suspects
            .iter()
            .find_map(|&name| {
                let spots = keys_of(places, name)?;
                let p = spots
                    .iter()
                    .rev()
                    .find(|p| p.frame <= frame)
                    .unwrap_or(&spots[0]);
                Some((p.span.clone(), format!("animation.key[{}].{name}", p.index)))
            })
            .unwrap_or((table, "animation".into()));
        return Err(ctx.invalid(span, key, format!("at frame {frame}: {message}")));
    }
    Ok(())
}
