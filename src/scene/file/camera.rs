//! The `[camera]` table: view, lens and focus, and the checks of a view.

use std::ops::Range;

use glam::Vec3;
use toml::Spanned;

use super::Ctx;
use super::objects::{FromModel, Objects};
use super::raw::{RawCamera, V3, v3};
use crate::camera::{
    ApertureShape, CameraError, CameraSpec, DEFAULT_SENSOR_WIDTH_MM, DEFAULT_VFOV, Focus, LensSpec,
    Photographic, Prescription, RealLensSpec,
};
use crate::scene::Object;
use crate::scene::error::LoadError;
use crate::scene::model;

/// Where the camera stands and looks.
struct View {
    eye: Vec3,
    look_at: Vec3,
    up: Vec3,
}

/// The camera of a `width` x `height` image of `objects`: the `[camera]` table's (checked),
/// with the view of the model camera the objects bring, if any.
pub(super) fn camera(
    ctx: &Ctx,
    raw: Option<Spanned<RawCamera>>,
    width: u32,
    height: u32,
    objects: &Objects,
) -> Result<CameraSpec, LoadError> {
    let from_model = objects.camera.as_ref();
    let table = raw.as_ref().map_or(0..0, |r| r.span());
    if let (Some((_, _, key)), Some(raw)) = (from_model, &raw) {
        check_model_view(ctx, raw.get_ref(), key)?;
    }
    let raw = raw.map(Spanned::into_inner).unwrap_or_default();
    let vfov_deg = match from_model {
        Some((c, _, _)) => c.vfov_deg,
        None => raw.vfov.as_ref().map_or(DEFAULT_VFOV, |v| v.get_ref().0),
    };
    let view = view(ctx, &raw, vfov_deg, width, height, objects)?;
    check_view(ctx, &raw, &table, &view)?;
    let real_lens = real_lens(ctx, &raw)?;
    if real_lens.is_none() {
        check_lens_keys(ctx, &raw)?;
    }
    let lens = lens(&raw, from_model.is_some(), vfov_deg, width, height);
    let focus = focus(ctx, &raw, &table, width, height, &view)?;
    let blades = raw.blades.as_ref().map_or(0, |b| b.get_ref().0);
    if !ApertureShape::blades_ok(blades) {
        return Err(ctx.invalid(
            raw.blades.as_ref().map(|b| b.span()).unwrap_or(0..0),
            "camera.blades",
            "`blades` must be 0 (a circular aperture) or at least 3",
        ));
    }
    let spec = CameraSpec {
        eye: view.eye,
        look_at: view.look_at,
        up: view.up,
        vfov_deg,
        width,
        height,
        lens,
        focus,
        aperture: ApertureShape {
            blades,
            rotation_deg: raw.blade_rotation.as_ref().map_or(0.0, |r| r.get_ref().0),
            anamorphic: raw.anamorphic.as_ref().map_or(1.0, |a| a.get_ref().0),
        },
        real_lens,
    };
    check_built(ctx, &raw, &table, &spec)?;
    Ok(spec)
}

/// Builds the camera as a render would (autofocus answered with any depth: the scene is not
/// built yet) so that a value every key accepts alone but the lens cannot use together (a
/// focal length too long for any field of view, an aperture too large for the lens to stay
/// in range) is refused here, at the key that gave it, instead of later without a place.
fn check_built(
    ctx: &Ctx,
    raw: &RawCamera,
    table: &Range<usize>,
    spec: &CameraSpec,
) -> Result<(), LoadError> {
    let error = match spec.build(|_| Some(1.0)) {
        Ok(_) => return Ok(()),
        // Where the autofocus pixel lands depends on the final image size and the scene.
        Err(CameraError::FocusPixelOutside { .. } | CameraError::FocusPixelMisses { .. }) => {
            return Ok(());
        }
        Err(e) => e,
    };
    let name = match &error {
        CameraError::Invalid { name, .. } => *name,
        _ => "",
    };
    fn at<T>(key: &Option<Spanned<T>>) -> Option<Range<usize>> {
        key.as_ref().map(Spanned::span)
    }
    // The key that gave the value, by the name the check uses; for a derived aperture, the
    // first of the keys it is derived from.
    let keys = [
        ("eye", at(&raw.eye)),
        ("look_at", at(&raw.look_at)),
        ("up", at(&raw.up)),
        ("vfov", at(&raw.vfov)),
        ("focal_length_mm", at(&raw.focal_length_mm)),
        ("sensor_width_mm", at(&raw.sensor_width_mm)),
        ("aperture_radius", at(&raw.aperture_radius)),
        ("f_number", at(&raw.f_number)),
        ("sharp_range", at(&raw.sharp_range)),
        ("spread", at(&raw.spread)),
        ("anamorphic", at(&raw.anamorphic)),
        ("blade_rotation", at(&raw.blade_rotation)),
        ("blades", at(&raw.blades)),
        ("lens", at(&raw.lens)),
    ];
    let candidates: &[&str] = match name {
        "eye" => &["eye"],
        "look_at" => &["look_at"],
        "up" => &["up"],
        "vfov_deg" => &["vfov", "focal_length_mm", "sensor_width_mm"],
        "focal_length_mm" => &["focal_length_mm", "vfov"],
        "sensor_width_mm" => &["sensor_width_mm"],
        "f_number" => &["f_number"],
        "sharp_range" => &["sharp_range"],
        "spread" => &["spread"],
        "anamorphic ratio" => &["anamorphic"],
        "aperture rotation" => &["blade_rotation"],
        "aperture blades" => &["blades"],
        "lens" | "focus distance" if raw.lens.is_some() => &["lens"],
        _ => &[
            "aperture_radius",
            "f_number",
            "sharp_range",
            "spread",
            "anamorphic",
            "eye",
        ],
    };
    let found = candidates.iter().find_map(|c| {
        keys.iter()
            .find_map(|(k, span)| (k == c).then(|| span.clone()).flatten().map(|s| (k, s)))
    });
    Err(match found {
        Some((key, span)) => ctx.invalid(span, format!("camera.{key}"), error.to_string()),
        None => ctx.invalid(table.clone(), "camera", error.to_string()),
    })
}

/// The `lens` key's prescription with the keys a real lens takes (`f_number` stops it
/// down, `sensor_width_mm` sizes the film); the thin lens's keys are refused beside it.
fn real_lens(ctx: &Ctx, raw: &RawCamera) -> Result<Option<RealLensSpec>, LoadError> {
    let Some(file) = &raw.lens else {
        return Ok(None);
    };
    let thin = [
        ("vfov", raw.vfov.as_ref().map(Spanned::span)),
        (
            "focal_length_mm",
            raw.focal_length_mm.as_ref().map(Spanned::span),
        ),
        (
            "aperture_radius",
            raw.aperture_radius.as_ref().map(Spanned::span),
        ),
        ("sharp_range", raw.sharp_range.as_ref().map(Spanned::span)),
        ("spread", raw.spread.as_ref().map(Spanned::span)),
        ("blades", raw.blades.as_ref().map(Spanned::span)),
        (
            "blade_rotation",
            raw.blade_rotation.as_ref().map(Spanned::span),
        ),
        ("anamorphic", raw.anamorphic.as_ref().map(Spanned::span)),
    ];
    if let Some((key, Some(span))) = thin.into_iter().find(|(_, s)| s.is_some()) {
        return Err(ctx.invalid(
            span,
            format!("camera.{key}"),
            format!("`{key}` describes the thin lens; with `lens` (a real lens's prescription) the lens gives its own focal length, field of view and round stop: remove `{key}`"),
        ));
    }
    let path = ctx.resolve(file.get_ref());
    let prescription = Prescription::load(&path).map_err(|e| {
        LoadError::from(e).referenced(ctx.at_key(file.span(), "camera.lens"), "lens")
    })?;
    Ok(Some(RealLensSpec {
        prescription: std::sync::Arc::new(prescription),
        f_number: raw.f_number.as_ref().map(|f| f.get_ref().0),
        sensor_width_mm: raw
            .sensor_width_mm
            .as_ref()
            .map_or(DEFAULT_SENSOR_WIDTH_MM, |s| s.get_ref().0),
    }))
}

/// Refuses view keys when the view comes from the model of object `key`.
fn check_model_view(ctx: &Ctx, raw: &RawCamera, key: &str) -> Result<(), LoadError> {
    for (k, span) in [
        ("eye", raw.eye.as_ref().map(|s| s.span())),
        ("look_at", raw.look_at.as_ref().map(|s| s.span())),
        ("up", raw.up.as_ref().map(|s| s.span())),
        ("vfov", raw.vfov.as_ref().map(|s| s.span())),
    ] {
        if let Some(span) = span {
            return Err(ctx.invalid(
                span,
                format!("camera.{k}"),
                format!(
                    "the camera's view comes from the model of {key} (`camera = true`); \
                     remove `{k}` (lens and focus keys still apply)"
                ),
            ));
        }
    }
    Ok(())
}

/// The view: the model's camera, else `eye` and `look_at` as given, the missing ones framing
/// the objects.
fn view(
    ctx: &Ctx,
    raw: &RawCamera,
    vfov_deg: f32,
    width: u32,
    height: u32,
    objects: &Objects,
) -> Result<View, LoadError> {
    let up = raw.up.as_ref().map_or(Vec3::Y, |u| v3(*u.get_ref()));
    let spanned = |v: &Spanned<V3>| v3(*v.get_ref());
    Ok(match (&objects.camera, &raw.eye, &raw.look_at) {
        (Some(from_model), _, _) => model_view(from_model, &objects.list, up),
        (None, Some(e), Some(l)) => View {
            eye: spanned(e),
            look_at: spanned(l),
            up,
        },
        (None, e, l) => {
            let (lo, hi) =
                model::bounds(&objects.list).unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
            let aspect = width as f32 / height as f32;
            let (fe, fl) = model::frame(lo, hi, vfov_deg, aspect);
            let framed = match e {
                None => model::frame_checked(lo, hi, vfov_deg, aspect).map(|_| ()),
                Some(_) if !fl.is_finite() => Err(format!(
                    "the scene bounds are too large to aim at: they span {} to {}, and their \
                     centre is beyond the range of 32-bit floats",
                    model::short_vec(lo),
                    model::short_vec(hi)
                )),
                Some(_) => Ok(()),
            };
            if let Err(message) = framed {
                return Err(unframed(ctx, objects, message));
            }
            View {
                eye: e.as_ref().map_or(fe, spanned),
                look_at: l.as_ref().map_or(fl, spanned),
                up,
            }
        }
    })
}

/// The model's camera, looking as far as the objects' centre lies along its view (the
/// default focus); its `up` unless that is parallel to the view.
fn model_view(from_model: &FromModel, objects: &[Object], up: Vec3) -> View {
    let (c, _, _) = from_model;
    let center = model::bounds(objects).map_or(c.eye + c.forward, |(lo, hi)| (lo + hi) * 0.5);
    let along = (center - c.eye).dot(c.forward);
    let along = if along.is_finite() {
        along.max(1e-3)
    } else {
        1.0
    };
    View {
        eye: c.eye,
        look_at: c.eye + c.forward * along,
        up: if c.up.cross(c.forward).length_squared() > 1e-6 {
            c.up
        } else {
            up
        },
    }
}

/// The objects cannot be framed (`message` says why): the error points at the object reaching
/// farthest from the origin.
fn unframed(ctx: &Ctx, objects: &Objects, message: String) -> LoadError {
    let reach = |o: &Object| {
        let (lo, hi) = model::object_bounds(o);
        lo.abs().max(hi.abs()).max_element()
    };
    let list = &objects.list;
    let far = (0..list.len())
        .max_by(|&a, &b| reach(&list[a]).total_cmp(&reach(&list[b])))
        .unwrap_or(0);
    let (span, key) = objects
        .origins
        .get(far)
        .cloned()
        .unwrap_or((0..0, "camera".into()));
    ctx.invalid(
        span,
        key,
        format!("{message}; give `eye` and `look_at` in [camera], or make the objects smaller"),
    )
}

/// Where a problem of the whole camera is shown: at `up`, else `vfov`, else the table.
fn camera_span(raw: &RawCamera, table: &Range<usize>) -> Range<usize> {
    [
        raw.up.as_ref().map(|u| u.span()),
        raw.vfov.as_ref().map(|v| v.span()),
    ]
    .into_iter()
    .flatten()
    .next()
    .unwrap_or(table.clone())
}

/// Refuses a view without a direction or an up.
fn check_view(
    ctx: &Ctx,
    raw: &RawCamera,
    table: &Range<usize>,
    view: &View,
) -> Result<(), LoadError> {
    match view_problem(view.eye, view.look_at, view.up) {
        None => Ok(()),
        Some(("up", message)) => {
            let span = raw
                .up
                .as_ref()
                .map_or(camera_span(raw, table), |u| u.span());
            Err(ctx.invalid(span, "camera.up", message))
        }
        Some((_, message)) => {
            let (span, key) = match (&raw.look_at, &raw.eye) {
                (Some(l), _) => (l.span(), "camera.look_at"),
                (None, Some(e)) => (e.span(), "camera.eye"),
                (None, None) => (camera_span(raw, table), "camera.look_at"),
            };
            Err(ctx.invalid(span, key, message))
        }
    }
}

/// The keys of `keys` the table gives, with the spans of their values, in order.
fn given(keys: [(&'static str, Option<Range<usize>>); 3]) -> Vec<(&'static str, Range<usize>)> {
    keys.into_iter()
        .filter_map(|(k, s)| s.map(|s| (k, s)))
        .collect()
}

/// Refuses more than one lens parameterisation, and keys that belong to another.
fn check_lens_keys(ctx: &Ctx, raw: &RawCamera) -> Result<(), LoadError> {
    let lenses = given([
        (
            "aperture_radius",
            raw.aperture_radius.as_ref().map(|s| s.span()),
        ),
        ("f_number", raw.f_number.as_ref().map(|s| s.span())),
        ("sharp_range", raw.sharp_range.as_ref().map(|s| s.span())),
    ]);
    if lenses.len() > 1 {
        return Err(ctx.invalid(lenses[1].1.clone(), format!("camera.{}", lenses[1].0), format!("`{}` and `{}` both set the lens; give one of aperture_radius, f_number (photographic) or sharp_range + spread (the seed's)", lenses[0].0, lenses[1].0)));
    }
    if raw.f_number.is_none() {
        for (k, s) in [
            ("focal_length_mm", &raw.focal_length_mm),
            ("sensor_width_mm", &raw.sensor_width_mm),
        ] {
            if let Some(s) = s {
                return Err(ctx.invalid(
                    s.span(),
                    format!("camera.{k}"),
                    format!("`{k}` describes a photographic lens and needs `f_number`"),
                ));
            }
        }
    } else if let Some(v) = &raw.vfov {
        return Err(ctx.invalid(v.span(), "camera.vfov", "a photographic lens (`f_number`) sets the field of view from focal_length_mm and sensor_width_mm; remove `vfov`"));
    }
    if raw.sharp_range.is_some() != raw.spread.is_some() {
        let (k, s) = match (&raw.sharp_range, &raw.spread) {
            (Some(s), _) => ("sharp_range", s.span()),
            (_, Some(s)) => ("spread", s.span()),
            _ => unreachable!(),
        };
        return Err(ctx.invalid(
            s,
            format!("camera.{k}"),
            "the seed's lens needs both `sharp_range` (scene units) and `spread` (pixels)",
        ));
    }
    Ok(())
}

/// The lens the (checked) keys give. With a model's camera (`model_view`), a photographic
/// lens without `focal_length_mm` keeps the model's field of view (`vfov_deg` at `width` x
/// `height`).
fn lens(raw: &RawCamera, model_view: bool, vfov_deg: f32, width: u32, height: u32) -> LensSpec {
    if let Some(r) = &raw.aperture_radius {
        if r.get_ref().0 == 0.0 {
            LensSpec::Pinhole
        } else {
            LensSpec::Aperture {
                radius: r.get_ref().0,
            }
        }
    } else if let Some(n) = &raw.f_number {
        let n = n.get_ref().0;
        let sensor_width_mm = raw.sensor_width_mm.as_ref().map(|s| s.get_ref().0);
        let focal_length_mm = raw.focal_length_mm.as_ref().map(|f| f.get_ref().0);
        // With a model's camera, the focal length that keeps its field of view on this sensor.
        if model_view {
            Photographic::keeping_vfov(
                n,
                focal_length_mm,
                sensor_width_mm,
                vfov_deg,
                (width, height),
            )
        } else {
            Photographic::new(n, focal_length_mm, sensor_width_mm)
        }
        .spec()
    } else if let (Some(r), Some(s)) = (&raw.sharp_range, &raw.spread) {
        LensSpec::Seed {
            sharp_range: r.get_ref().0,
            spread: s.get_ref().0,
        }
    } else {
        LensSpec::Pinhole
    }
}

/// The focus: at most one way, on `look_at` without a focus key, a point in front.
fn focus(
    ctx: &Ctx,
    raw: &RawCamera,
    table: &Range<usize>,
    width: u32,
    height: u32,
    view: &View,
) -> Result<Focus, LoadError> {
    let focuses = given([
        (
            "focus_distance",
            raw.focus_distance.as_ref().map(|s| s.span()),
        ),
        ("focus_point", raw.focus_point.as_ref().map(|s| s.span())),
        ("focus_pixel", raw.focus_pixel.as_ref().map(|s| s.span())),
    ]);
    if focuses.len() > 1 {
        return Err(ctx.invalid(
            focuses[1].1.clone(),
            format!("camera.{}", focuses[1].0),
            format!(
                "`{}` and `{}` both set the focus; give one",
                focuses[0].0, focuses[1].0
            ),
        ));
    }
    let focus = if let Some(d) = &raw.focus_distance {
        Focus::Distance(d.get_ref().0)
    } else if let Some(p) = &raw.focus_point {
        let p = v3(*p.get_ref());
        Focus::Point(p)
    } else if let Some(px) = &raw.focus_pixel {
        let [x, y] = *px.get_ref();
        if x.0 >= width || y.0 >= height {
            return Err(ctx.invalid(px.span(), "camera.focus_pixel", format!("pixel ({}, {}) is outside the {width}x{height} image (x < width, y < height, counted from the top left)", x.0, y.0)));
        }
        Focus::Pixel { x: x.0, y: y.0 }
    } else {
        Focus::Point(view.look_at)
    };
    if let Focus::Point(p) = focus {
        if !in_front(view.eye, view.look_at, p) {
            let span = raw
                .focus_point
                .as_ref()
                .map_or(camera_span(raw, table), |s| s.span());
            return Err(ctx.invalid(span, "camera.focus_point", BEHIND));
        }
    }
    Ok(focus)
}

/// What is wrong with a view, if anything: the key to blame (`look_at` or `up`) and why.
pub(super) fn view_problem(
    eye: Vec3,
    look_at: Vec3,
    up: Vec3,
) -> Option<(&'static str, &'static str)> {
    let view = (look_at - eye).length_squared();
    if view == 0.0 {
        Some(("look_at", "`look_at` must differ from `eye`"))
    } else if !view.is_finite() {
        Some((
            "look_at",
            "`eye` and `look_at` are too far apart: the distance between them is beyond the \
             range of 32-bit floats",
        ))
    } else if (look_at - eye).cross(up).length_squared() <= 1e-12 * view * up.length_squared() {
        Some((
            "up",
            "`up` must not be zero or parallel to the view direction (eye to look_at)",
        ))
    } else {
        None
    }
}

/// Whether the point `p` is in front of a camera at `eye` looking at `look_at`.
pub(super) fn in_front(eye: Vec3, look_at: Vec3, p: Vec3) -> bool {
    (p - eye).dot(look_at - eye) > 0.0
}

pub(super) const BEHIND: &str = "the point in focus must be in front of the camera";
