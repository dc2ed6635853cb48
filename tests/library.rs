//! dofray as a library: a scene built in code from the defaults, overrides, and settings.

use dofray::embree::Device;
use dofray::glam::Vec3;
use dofray::overrides::{OverrideError, Overrides, Param, SettingsOverrides};
use dofray::render::{NoProgress, SiteRule};
use dofray::renderer::{Renderer, RendererError};
use dofray::scene::{Object, SceneDesc};
use dofray::shade::{Light, Material};

fn sphere_scene() -> SceneDesc {
    SceneDesc {
        materials: vec![Material::diffuse(Vec3::new(0.8, 0.2, 0.2))],
        objects: vec![Object::Sphere {
            center: Vec3::ZERO,
            radius: 1.0,
            material: 0,
        }],
        lights: vec![Light::Point {
            position: Vec3::new(2.0, 4.0, 4.0),
            intensity: Vec3::splat(50.0),
        }],
        ..Default::default()
    }
}

#[test]
fn a_scene_from_the_defaults_renders_with_overrides() {
    let overrides = Overrides {
        width: Some(32),
        aperture_radius: Some(0.1),
        autofocus: Some((16, 12)),
        ..Default::default()
    };
    let r = Renderer::with_overrides(sphere_scene(), overrides, &Device::new().unwrap()).unwrap();
    // The height follows the default camera's 4:3 aspect.
    assert_eq!((r.desc().camera.width, r.desc().camera.height), (32, 24));
    let camera = r.camera(None).unwrap();
    assert!(
        (camera.focus_distance() - 4.0).abs() < 0.01,
        "{}",
        camera.focus_distance()
    );
    let settings = SettingsOverrides::default().settings(r.desc()).unwrap();
    assert_eq!(settings.rule, SiteRule::Error);
    let (film, _) = r.render(&settings, &NoProgress).unwrap();
    let centre = film.color[12 * 32 + 16];
    assert!(
        centre.x > centre.y,
        "the red sphere is in the middle: {centre}"
    );
}

#[test]
fn override_errors_name_the_field_and_classify_as_usage() {
    let overrides = Overrides {
        f_number: Some(-2.0),
        ..Default::default()
    };
    let e = Renderer::with_overrides(sphere_scene(), overrides, &Device::new().unwrap())
        .err()
        .unwrap();
    assert!(matches!(
        e,
        RendererError::Override(OverrideError::NotPositive {
            param: Param::FNumber,
            ..
        })
    ));
    assert_eq!(
        e.to_string(),
        "f_number must be a finite number > 0, got -2"
    );
    assert_eq!(dofray::exit::classify(&e).name(), "usage");
    let scene_interval = SceneDesc {
        interval_factor: Some(0.2),
        ..sphere_scene()
    };
    let settings = SettingsOverrides::default()
        .settings(&scene_interval)
        .unwrap();
    assert_eq!(
        (settings.rule, settings.interval_factor),
        (SiteRule::Seed, 0.2)
    );
    let flags = SettingsOverrides {
        tolerance: Some(0.5),
        ..Default::default()
    };
    let settings = flags.settings(&scene_interval).unwrap();
    assert_eq!(
        (settings.rule, settings.tolerance),
        (SiteRule::Error, Some(0.5))
    );
}
