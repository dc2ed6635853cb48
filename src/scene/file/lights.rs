//! The `[[lights]]`, the `[background]` and the ambient light.

use std::ops::Range;

use glam::Vec3;
use toml::Spanned;

use super::Ctx;
use super::raw::{Color, Finite, LightKind, RawBackground, RawLight, v3};
use crate::camera::CameraSpec;
use crate::scene::Background;
use crate::scene::error::LoadError;
use crate::scene::model::{default_background, default_light};
use crate::shade::Light;

/// The file's lights, else the default key light unless a model brings lights; plus the
/// models' lights.
pub(super) fn lights(
    ctx: &Ctx,
    raw: Option<Vec<Spanned<RawLight>>>,
    model_lights: Vec<Light>,
    camera: &CameraSpec,
) -> Result<Vec<Light>, LoadError> {
    let mut lights: Vec<Light> = match raw {
        None if model_lights.is_empty() => vec![default_light(
            (camera.look_at - camera.eye).normalize_or(Vec3::Z),
        )],
        None => Vec::new(),
        Some(lights) => lights
            .into_iter()
            .enumerate()
            .map(|(i, l)| light(ctx, i, l))
            .collect::<Result<_, _>>()?,
    };
    lights.extend(model_lights);
    Ok(lights)
}

/// The `[background]`: a uniform `color`, or a sky from `horizon` to `zenith`.
pub(super) fn background(
    ctx: &Ctx,
    raw: Option<Spanned<RawBackground>>,
) -> Result<Background, LoadError> {
    Ok(match raw {
        None => default_background(),
        Some(b) => {
            let span = b.span();
            let b = b.into_inner();
            match (b.color, b.horizon, b.zenith) {
                (Some(c), None, None) => Background::uniform(c.0),
                (None, h, z) => {
                    let d = default_background();
                    Background {
                        horizon: h.map_or(d.horizon, |c| c.0),
                        zenith: z.map_or(d.zenith, |c| c.0),
                    }
                }
                _ => return Err(ctx.invalid(span, "background", "give either `color` (a uniform background) or `horizon` and `zenith`, not both")),
            }
        }
    })
}

/// The `ambient` light (linear RGB).
pub(super) fn ambient(raw: Option<Color>) -> Vec3 {
    raw.map_or(Vec3::splat(0.1), |c| c.0)
}

/// One `[[lights]]` table.
fn light(ctx: &Ctx, i: usize, l: Spanned<RawLight>) -> Result<Light, LoadError> {
    let span = l.span();
    let l = l.into_inner();
    let key = format!("lights[{i}]");
    if l.kind != LightKind::Spot {
        let cone = [
            ("inner_angle", l.inner_angle.is_some()),
            ("outer_angle", l.outer_angle.is_some()),
        ];
        refuse(ctx, &span, &key, cone, "belongs to spot lights")?;
    }
    match l.kind {
        LightKind::Spot => spot(ctx, &key, span, l),
        LightKind::Point => point(ctx, &key, span, l),
        LightKind::Directional => directional(ctx, &key, span, l),
    }
}

fn spot(ctx: &Ctx, key: &str, span: Range<usize>, l: RawLight) -> Result<Light, LoadError> {
    if l.irradiance.is_some() {
        return Err(ctx.invalid(span, format!("{key}.irradiance"), "`irradiance` belongs to directional lights; a spot light takes `position`, `direction`, `intensity`, `inner_angle` and `outer_angle`"));
    }
    let position = l
        .position
        .ok_or_else(|| ctx.invalid(span.clone(), key, "a spot light needs `position`"))?;
    let direction = l.direction.ok_or_else(|| {
        ctx.invalid(
            span.clone(),
            key,
            "a spot light needs `direction` (the way it shines)",
        )
    })?;
    let d = v3(*direction.get_ref());
    if d.length_squared() == 0.0 || !d.normalize().is_finite() {
        return Err(ctx.invalid(
            direction.span(),
            format!("{key}.direction"),
            "the direction must not be zero",
        ));
    }
    let angle = |a: &Option<Spanned<Finite>>, default: f32| {
        a.as_ref()
            .map_or((default, span.clone()), |a| (a.get_ref().0, a.span()))
    };
    let (outer, outer_span) = angle(&l.outer_angle, 45.0);
    let (inner, inner_span) = angle(&l.inner_angle, 0.0);
    if !(outer > 0.0 && outer <= 90.0) {
        return Err(ctx.invalid(
            outer_span,
            format!("{key}.outer_angle"),
            "the outer cone angle (degrees from the axis) must be > 0 and at most 90",
        ));
    }
    if !(inner >= 0.0 && inner <= outer) {
        return Err(ctx.invalid(
            inner_span,
            format!("{key}.inner_angle"),
            format!(
                "the inner cone angle (degrees from the axis) must be from 0 to \
                 outer_angle ({outer})"
            ),
        ));
    }
    Ok(Light::Spot {
        position: v3(position),
        direction: d.normalize(),
        intensity: l.intensity.map_or(Vec3::splat(100.0), |c| c.0),
        inner_angle: inner.to_radians(),
        outer_angle: outer.to_radians(),
    })
}

fn point(ctx: &Ctx, key: &str, span: Range<usize>, l: RawLight) -> Result<Light, LoadError> {
    let directional = [
        ("direction", l.direction.is_some()),
        ("irradiance", l.irradiance.is_some()),
    ];
    refuse(
        ctx,
        &span,
        key,
        directional,
        "belongs to directional lights; a point light takes `position` and `intensity`",
    )?;
    let position = l
        .position
        .ok_or_else(|| ctx.invalid(span, key, "a point light needs `position`"))?;
    Ok(Light::Point {
        position: v3(position),
        intensity: l.intensity.map_or(Vec3::splat(100.0), |c| c.0),
    })
}

fn directional(ctx: &Ctx, key: &str, span: Range<usize>, l: RawLight) -> Result<Light, LoadError> {
    let point = [
        ("position", l.position.is_some()),
        ("intensity", l.intensity.is_some()),
    ];
    refuse(
        ctx,
        &span,
        key,
        point,
        "belongs to point lights; a directional light takes `direction` and `irradiance`",
    )?;
    let direction = l
        .direction
        .ok_or_else(|| ctx.invalid(span.clone(), key, "a directional light needs `direction`"))?;
    let d = v3(*direction.get_ref());
    if d.length_squared() == 0.0 {
        return Err(ctx.invalid(
            direction.span(),
            format!("{key}.direction"),
            "the direction must not be zero",
        ));
    }
    Ok(Light::Directional {
        direction: d,
        irradiance: l.irradiance.map_or(Vec3::ONE, |c| c.0),
    })
}

/// Refuses the first of `keys` that is set: it is a key that "`{k}` `belongs`" (to another
/// kind of light).
fn refuse(
    ctx: &Ctx,
    span: &Range<usize>,
    key: &str,
    keys: [(&str, bool); 2],
    belongs: &str,
) -> Result<(), LoadError> {
    for (k, set) in keys {
        if set {
            return Err(ctx.invalid(
                span.clone(),
                format!("{key}.{k}"),
                format!("`{k}` {belongs}"),
            ));
        }
    }
    Ok(())
}
