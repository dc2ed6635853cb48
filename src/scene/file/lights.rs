//! The `[[lights]]`, the `[background]` and the ambient light.

use std::ops::Range;

use glam::{Vec2, Vec3};
use toml::Spanned;

use super::Ctx;
use super::raw::{Color, Finite, LightKind, RawBackground, RawLight, RawSize, RawWorld, v3};
use crate::camera::CameraSpec;
use crate::scene::Background;
use crate::scene::area_light::{AreaLight, AreaShape};
use crate::scene::error::LoadError;
use crate::scene::input::LoadOptions;
use crate::scene::model::{BLENDER_WORLD, default_background, default_light};
use crate::scene::texture::load_environment;
use crate::shade::Light;

/// One `[[lights]]` entry: a punctual light, or an area light (emissive geometry).
pub(super) enum FileLight {
    Punctual(Light),
    Area(AreaLight),
}

/// What a scene file's `[[lights]]` give: punctual lights, and area lights (with their index)
/// to add as geometry.
pub(super) struct FileLights {
    pub(super) lights: Vec<Light>,
    pub(super) areas: Vec<(usize, AreaLight)>,
}

/// The file's lights (punctual, and area lights to add as geometry), else the default key
/// light unless a model brings lights; plus the models' lights.
pub(super) fn lights(
    ctx: &Ctx,
    raw: Option<Vec<Spanned<RawLight>>>,
    model_lights: Vec<Light>,
    camera: &CameraSpec,
) -> Result<FileLights, LoadError> {
    let mut lights = Vec::new();
    let mut areas = Vec::new();
    match raw {
        None if model_lights.is_empty() => lights.push(default_light(
            (camera.look_at - camera.eye).normalize_or(Vec3::Z),
        )),
        None => {}
        Some(raw) => {
            for (i, l) in raw.into_iter().enumerate() {
                let span = l.span();
                match light(ctx, i, l)? {
                    FileLight::Punctual(l) => {
                        // The ranges the renderer checks, refused at the table that gave them.
                        crate::scene::world::check_light(i, &l).map_err(|e| {
                            ctx.invalid(span.clone(), format!("lights[{i}]"), e.to_string())
                        })?;
                        lights.push(l)
                    }
                    FileLight::Area(a) => areas.push((i, a)),
                }
            }
        }
    }
    lights.extend(model_lights);
    Ok(FileLights { lights, areas })
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
                        map: None,
                    }
                }
                _ => return Err(ctx.invalid(span, "background", "give either `color` (a uniform background) or `horizon` and `zenith`, not both")),
            }
        }
    })
}

/// The `[world]`: a uniform `color`, or an equirectangular `map`, times `strength`, the map
/// turned by `rotation` degrees about the up axis (Blender's world: Background colour and
/// strength, or an Environment Texture behind a Mapping node's Z rotation).
pub(super) fn world(
    ctx: &Ctx,
    raw: Spanned<RawWorld>,
    options: &LoadOptions,
) -> Result<Background, LoadError> {
    let span = raw.span();
    let w = raw.into_inner();
    let strength = w.strength.map_or(1.0, |s| s.0);
    match (w.map, w.color) {
        (Some(_), Some(_)) => Err(ctx.invalid(
            span,
            "world",
            "give either `color` (a uniform world) or `map` (an environment map), not both",
        )),
        (Some(map), None) => {
            let path = ctx.resolve(map.get_ref());
            let rotation = w.rotation.map_or(0.0, |r| r.0).to_radians();
            let map = load_environment(&path, strength, rotation, options)?;
            Ok(Background {
                map: Some(std::sync::Arc::new(map)),
                ..Background::uniform(Vec3::ZERO)
            })
        }
        (None, color) => {
            if w.rotation.is_some() {
                return Err(ctx.invalid(span, "world.rotation", "`rotation` turns a `map`"));
            }
            Ok(Background::uniform(
                color.map_or(Vec3::splat(BLENDER_WORLD), |c| c.0) * strength,
            ))
        }
    }
}

/// The `ambient` light (linear RGB).
pub(super) fn ambient(raw: Option<Color>) -> Vec3 {
    raw.map_or(Vec3::splat(0.1), |c| c.0)
}

/// One `[[lights]]` table.
fn light(ctx: &Ctx, i: usize, l: Spanned<RawLight>) -> Result<FileLight, LoadError> {
    let span = l.span();
    let l = l.into_inner();
    let key = format!("lights[{i}]");
    if matches!(
        l.kind,
        LightKind::Rect | LightKind::Disk | LightKind::Sphere
    ) {
        return area(ctx, &key, span, l).map(FileLight::Area);
    }
    let area_keys = [
        ("size", l.size.is_some()),
        ("radius", l.radius.is_some() && l.kind != LightKind::Spot),
        ("power", l.power.is_some()),
        ("up", l.up.is_some()),
        ("visible_to_camera", l.visible_to_camera.is_some()),
    ];
    let area_only = "belongs to area lights (type \"rect\", \"disk\" or \"sphere\"; `radius` to spot lights too)";
    refuse(ctx, &span, &key, &area_keys, area_only)?;
    if l.kind != LightKind::Spot {
        let cone = [
            ("inner_angle", l.inner_angle.is_some()),
            ("outer_angle", l.outer_angle.is_some()),
        ];
        refuse(ctx, &span, &key, &cone, "belongs to spot lights")?;
    }
    if l.kind != LightKind::Directional {
        let sun = [("angle", l.angle.is_some())];
        refuse(
            ctx,
            &span,
            &key,
            &sun,
            "belongs to directional lights (the sun's angle)",
        )?;
    }
    let color = l.color.map_or(Vec3::ONE, |c| c.0);
    let light = match l.kind {
        LightKind::Spot => spot(ctx, &key, span, l),
        LightKind::Point => point(ctx, &key, span, l),
        _ => directional(ctx, &key, span, l),
    }?;
    Ok(FileLight::Punctual(light.tinted(color)))
}

/// A `rect`, `disk` or `sphere` light: `position`, `power` (watts, as Blender's) times
/// `color`, `size` or `radius`, for flat ones the `direction` they face and `up`, and whether
/// camera rays see it.
fn area(ctx: &Ctx, key: &str, span: Range<usize>, l: RawLight) -> Result<AreaLight, LoadError> {
    let punctual = [
        ("intensity", l.intensity.is_some()),
        ("irradiance", l.irradiance.is_some()),
        ("inner_angle", l.inner_angle.is_some()),
        ("outer_angle", l.outer_angle.is_some()),
        ("angle", l.angle.is_some()),
    ];
    let not_area =
        "belongs to point, spot and directional lights; an area light takes `power` (watts)";
    refuse(ctx, &span, key, &punctual, not_area)?;
    let position = l
        .position
        .ok_or_else(|| ctx.invalid(span.clone(), key, "an area light needs `position`"))?;
    let needs = |what: &str| ctx.invalid(span.clone(), key, what.to_string());
    let shape = match l.kind {
        LightKind::Rect => AreaShape::Rect {
            size: match l.size {
                Some(RawSize::Square(s)) => Vec2::splat(s.0),
                Some(RawSize::Sides([w, h])) => Vec2::new(w.0, h.0),
                None => {
                    return Err(needs(
                        "a rect light needs `size` (a number or [width, height])",
                    ));
                }
            },
        },
        LightKind::Disk => match l.size {
            Some(RawSize::Square(d)) => AreaShape::Disk { radius: 0.5 * d.0 },
            _ => return Err(needs("a disk light needs `size` (its diameter, a number)")),
        },
        _ => AreaShape::Sphere {
            radius: l
                .radius
                .ok_or_else(|| needs("a sphere light needs `radius`"))?
                .0,
        },
    };
    let direction = match (&l.direction, l.kind) {
        (Some(d), _) if v3(*d.get_ref()).normalize_or_zero() == Vec3::ZERO => {
            return Err(ctx.invalid(
                d.span(),
                format!("{key}.direction"),
                "the direction must not be zero",
            ));
        }
        (Some(d), _) => v3(*d.get_ref()),
        (None, LightKind::Sphere) => Vec3::NEG_Y,
        (None, _) => {
            return Err(needs(
                "a rect or disk light needs `direction` (the way it faces)",
            ));
        }
    };
    let power = l.power.map_or(100.0, |p| p.get_ref().0);
    Ok(AreaLight {
        shape,
        position: v3(position),
        direction,
        up: l.up.map_or(Vec3::Y, v3),
        power: l.color.map_or(Vec3::ONE, |c| c.0) * power,
        visible_to_camera: l.visible_to_camera.unwrap_or(true),
    })
}

fn spot(ctx: &Ctx, key: &str, span: Range<usize>, l: RawLight) -> Result<Light, LoadError> {
    if l.irradiance.is_some() {
        return Err(ctx.invalid(span, format!("{key}.irradiance"), "`irradiance` belongs to directional lights; a spot light takes `position`, `direction`, `intensity`, `inner_angle`, `outer_angle` and `radius`"));
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
        radius: l.radius.map_or(0.0, |r| r.0),
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
        &directional,
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
        &point,
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
    let angle = match l.angle {
        Some(a) if !(0.0..=180.0).contains(&a.get_ref().0) => {
            return Err(ctx.invalid(
                a.span(),
                format!("{key}.angle"),
                "the sun's angle (its angular diameter, degrees) must be from 0 to 180",
            ));
        }
        Some(a) => a.get_ref().0.to_radians(),
        None => 0.0,
    };
    Ok(Light::Directional {
        direction: d,
        irradiance: l.irradiance.map_or(Vec3::ONE, |c| c.0),
        angle,
    })
}

/// Refuses the first of `keys` that is set: it is a key that "`{k}` `belongs`" (to another
/// kind of light).
fn refuse(
    ctx: &Ctx,
    span: &Range<usize>,
    key: &str,
    keys: &[(&str, bool)],
    belongs: &str,
) -> Result<(), LoadError> {
    for &(k, set) in keys {
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
