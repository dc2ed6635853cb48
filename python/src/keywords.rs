//! The scene keywords of `render` and `render_jobs`: the scene overrides and render settings
//! they ask for, each named as the parameter table names it for Python.

use dofray::camera::RealLensSpec;
use dofray::overrides::Overrides;
use dofray::params::Param;
use dofray::render::{Integrator, Mode, RulePatch, SettingsPatch};
use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::Failure;

/// The scene keywords of `render`, and of `render_jobs` (in its `**overrides`).
#[derive(Default)]
pub(crate) struct SceneKeywords {
    pub(crate) width: Option<i64>,
    pub(crate) height: Option<i64>,
    pub(crate) f_number: Option<f32>,
    pub(crate) focal_length: Option<f32>,
    pub(crate) sensor_width: Option<f32>,
    pub(crate) focus_distance: Option<f32>,
    pub(crate) autofocus: Option<(i64, i64)>,
    pub(crate) aperture_radius: Option<f32>,
    pub(crate) blades: Option<i64>,
    pub(crate) lens: Option<std::path::PathBuf>,
    pub(crate) spp: Option<i64>,
    pub(crate) aa: Option<i64>,
    pub(crate) mode: Option<String>,
    pub(crate) tolerance: Option<f32>,
    pub(crate) seed: Option<u64>,
    pub(crate) exposure: Option<f32>,
    pub(crate) transparent: bool,
    pub(crate) integrator: Option<String>,
    pub(crate) light_tracing: Option<bool>,
    pub(crate) reuse: Option<bool>,
}

/// `value` as keyword `name` takes it, or a `TypeError` naming the keyword.
fn item<'py, T: FromPyObjectOwned<'py>>(name: &str, value: &Bound<'py, PyAny>) -> PyResult<T> {
    value.extract::<T>().map_err(|e| {
        let e: PyErr = e.into();
        PyTypeError::new_err(format!("render_jobs() keyword {name}: {e}"))
    })
}

impl SceneKeywords {
    /// The keywords of `overrides`; `None` leaves a value as the scene has it.
    pub(crate) fn from_dict(overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut k = Self::default();
        for (key, value) in overrides.into_iter().flat_map(|d| d.iter()) {
            let name: String = key.extract()?;
            if value.is_none() {
                continue;
            }
            let v = &value;
            match name.as_str() {
                "width" => k.width = item(&name, v)?,
                "height" => k.height = item(&name, v)?,
                "f_number" => k.f_number = item(&name, v)?,
                "focal_length" => k.focal_length = item(&name, v)?,
                "sensor_width" => k.sensor_width = item(&name, v)?,
                "focus_distance" => k.focus_distance = item(&name, v)?,
                "autofocus" => k.autofocus = item(&name, v)?,
                "aperture_radius" => k.aperture_radius = item(&name, v)?,
                "blades" => k.blades = item(&name, v)?,
                "lens" => k.lens = item(&name, v)?,
                "spp" => k.spp = item(&name, v)?,
                "aa" => k.aa = item(&name, v)?,
                "mode" => k.mode = item(&name, v)?,
                "tolerance" => k.tolerance = item(&name, v)?,
                "seed" => k.seed = item(&name, v)?,
                "exposure" => k.exposure = item(&name, v)?,
                "transparent" => k.transparent = item(&name, v)?,
                "integrator" => k.integrator = item(&name, v)?,
                "light_tracing" => k.light_tracing = item(&name, v)?,
                "reuse" => k.reuse = item(&name, v)?,
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "render_jobs() got an unexpected keyword argument '{name}'"
                    )));
                }
            }
        }
        Ok(k)
    }

    /// The scene overrides and render settings the keywords ask for, checked for range by the
    /// library when the scene is rendered.
    pub(crate) fn parts(self) -> Result<(Overrides, SettingsPatch), Failure> {
        let autofocus = match self.autofocus {
            Some((x, y)) => Some((
                to_u32("autofocus x", Some(x))?.unwrap_or(0),
                to_u32("autofocus y", Some(y))?.unwrap_or(0),
            )),
            None => None,
        };
        // A real lens's file is read here: its faults are bad input naming file and line.
        let real_lens = match &self.lens {
            Some(path) => Some(RealLensSpec::load(path).map_err(|e| Failure::from_error(&e))?),
            None => None,
        };
        let overrides = Overrides {
            width: to_u32(Param::Width.keyword_name(), self.width)?,
            height: to_u32(Param::Height.keyword_name(), self.height)?,
            f_number: self.f_number,
            focal_length_mm: self.focal_length,
            sensor_width_mm: self.sensor_width,
            focus_distance: self.focus_distance,
            autofocus,
            aperture_radius: self.aperture_radius,
            blades: to_u32(Param::Blades.keyword_name(), self.blades)?,
            real_lens,
            ..Default::default()
        };
        let settings = SettingsPatch {
            mode: to_mode(self.mode.as_deref())?,
            spp: to_u32(Param::Spp.keyword_name(), self.spp)?,
            aa: to_u32(Param::Aa.keyword_name(), self.aa)?,
            rule: (self.tolerance).map(|t| RulePatch::ErrorControlled { tolerance: Some(t) }),
            seed: self.seed,
            exposure: self.exposure,
            transparent: self.transparent,
            integrator: to_integrator(self.integrator.as_deref())?,
            light_tracing: self.light_tracing,
            reuse: self.reuse,
            ..Default::default()
        };
        Ok((overrides, settings))
    }
}

/// An integer keyword that must fit a `u32`.
pub(crate) fn to_u32(name: &str, value: Option<i64>) -> Result<Option<u32>, Failure> {
    value
        .map(|v| {
            u32::try_from(v).map_err(|_| {
                Failure::usage(format!(
                    "{name} must be an integer from 0 to {}, got {v}",
                    u32::MAX
                ))
            })
        })
        .transpose()
}

/// A sampling mode's name.
/// The `integrator` keyword: `"path"` or `"direct"`.
fn to_integrator(name: Option<&str>) -> Result<Option<Integrator>, Failure> {
    name.map(|n| {
        Integrator::from_name(n).ok_or_else(|| {
            Failure::usage(format!(
                "integrator must be \"path\" or \"direct\", got {n:?}"
            ))
        })
    })
    .transpose()
}

pub(crate) fn to_mode(mode: Option<&str>) -> Result<Option<Mode>, Failure> {
    mode.map(|m| {
        m.parse()
            .map_err(|e: dofray::render::UnknownMode| Failure::usage(e.to_string()))
    })
    .transpose()
}
