//! dofray as a library: a scene built in code from the defaults, overrides, and settings.

use dofray::embree::Device;
use dofray::glam::Vec3;
use dofray::overrides::{OverrideError, Overrides};
use dofray::params::Param;
use dofray::render::{NoProgress, RulePatch, SamplingRule, SettingsPatch};
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
    let settings = r.settings(&SettingsPatch::default()).unwrap();
    assert_eq!(
        settings.rule,
        SamplingRule::ErrorControlled { tolerance: None }
    );
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
    let scene_interval = SettingsPatch {
        rule: Some(RulePatch::Seed {
            interval_factor: Some(0.2),
            paper_exact: false,
        }),
        ..Default::default()
    };
    let settings = SettingsPatch::default()
        .over(&scene_interval)
        .resolve()
        .unwrap();
    assert_eq!(
        settings.rule,
        SamplingRule::Seed {
            interval_factor: 0.2,
            paper_exact: false
        }
    );
    // The flags' rule replaces the scene's.
    let flags = SettingsPatch {
        rule: Some(RulePatch::ErrorControlled {
            tolerance: Some(0.5),
        }),
        ..Default::default()
    };
    let settings = flags.over(&scene_interval).resolve().unwrap();
    assert_eq!(
        (settings.rule, settings.tolerance()),
        (
            SamplingRule::ErrorControlled {
                tolerance: Some(0.5)
            },
            Some(0.5)
        )
    );
    // Setting errors name the parameter as each front end does.
    let e = SettingsPatch {
        spp: Some(0),
        ..Default::default()
    }
    .resolve()
    .unwrap_err();
    assert_eq!(e.to_string(), "spp must be 1 to 65536, got 0");
    assert_eq!(e.message(Param::flag), "--spp must be 1 to 65536, got 0");
    assert_eq!(
        e.message(Param::setter_name),
        "dofray_scene_set_spp must be 1 to 65536, got 0"
    );
}
