//! Every parameter a user sets, and what each front end calls it: one table.
//!
//! The library's errors about a value name its [`Param`] ([`crate::overrides::OverrideError`],
//! [`crate::render::SettingError`]); each front end words the name its own way through
//! `message(name)`: the command line by [`Param::flag`], a scene file by [`Param::key`] (with
//! the file and line), Python by [`Param::keyword`], C by [`Param::setter`]. The checks and
//! their wording stay in one place; only the name differs.
//!
//! ```rust
//! use dofray::params::Param;
//!
//! assert_eq!(Param::FNumber.flag(), "--f-number");
//! assert_eq!(Param::FNumber.key(), Some("camera.f_number"));
//! assert_eq!(Param::FocalLength.keyword(), Some("focal_length"));
//! assert_eq!(Param::Spp.setter(), Some("dofray_scene_set_spp"));
//! ```

/// A user-settable parameter: a scene override or a render setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// Image width in pixels.
    Width,
    /// Image height in pixels.
    Height,
    /// Aperture radius in scene units.
    ApertureRadius,
    /// A photographic lens's f-number.
    FNumber,
    /// A photographic lens's focal length in mm.
    FocalLength,
    /// A photographic lens's sensor width in mm.
    SensorWidth,
    /// The seed's lens: the sharp range in scene units.
    SharpRange,
    /// The seed's lens: the blur in pixels at the sharp range's ends.
    Spread,
    /// Focus distance along the view axis.
    FocusDistance,
    /// Autofocus on the surface seen through a pixel.
    Autofocus,
    /// Aperture blades (0: circular).
    Blades,
    /// Rotation of a polygonal aperture in degrees.
    BladeRotation,
    /// Anamorphic ratio: aperture height over width.
    Anamorphic,
    /// The lights.
    Lights,
    /// Ambient light level.
    Ambient,
    /// Where sample sites are placed ([`crate::render::Mode`]).
    Mode,
    /// Samples per sample site that blur reaches.
    Spp,
    /// Samples per in-focus sample site (anti-aliasing).
    Aa,
    /// The pixel filter's shape.
    PixelFilter,
    /// The pixel filter's width in pixels.
    PixelFilterWidth,
    /// The error-controlled rule's tolerance.
    Tolerance,
    /// The seed rule's interval factor k.
    IntervalFactor,
    /// The seed rule per pixel, as the paper has it.
    PaperExact,
    /// A transparent background.
    Transparent,
    /// Exposure in stops.
    Exposure,
    /// The random seed of the samples.
    Seed,
    /// The weighting of lens samples.
    LensFilter,
    /// The largest sample interval (a library setting only).
    MaxInterval,
    /// How light is carried (path or direct).
    Integrator,
    /// Most bounces of any kind.
    MaxBounces,
    /// Most diffuse bounces.
    DiffuseBounces,
    /// Most glossy bounces.
    GlossyBounces,
    /// Most transmission bounces.
    TransmissionBounces,
    /// Clamp on indirect samples.
    ClampIndirect,
    /// The glossy filter (Cycles' Filter Glossy).
    FilterGlossy,
    /// Light tracing of small emitters, and of lamps' glossy highlights, seen through the lens.
    LightTracing,
    /// Sample reuse across adaptive sites.
    Reuse,
}

/// What each front end calls a [`Param`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Names {
    /// The Rust field's name (`f_number`).
    pub field: &'static str,
    /// The command line's flag (`--f-number`), if it has one.
    pub flag: Option<&'static str>,
    /// The scene file's key, `section.key` (`camera.f_number`).
    pub key: Option<&'static str>,
    /// The Python keyword of `dofray.render` (`f_number`).
    pub keyword: Option<&'static str>,
    /// The C function that sets it (`dofray_scene_set_f_number`).
    pub setter: Option<&'static str>,
}

/// One row of the table.
const fn row(
    field: &'static str,
    flag: Option<&'static str>,
    key: Option<&'static str>,
    keyword: Option<&'static str>,
    setter: Option<&'static str>,
) -> Names {
    Names {
        field,
        flag,
        key,
        keyword,
        setter,
    }
}

impl Param {
    /// Every parameter.
    pub const ALL: [Param; 37] = [
        Self::Width,
        Self::Height,
        Self::ApertureRadius,
        Self::FNumber,
        Self::FocalLength,
        Self::SensorWidth,
        Self::SharpRange,
        Self::Spread,
        Self::FocusDistance,
        Self::Autofocus,
        Self::Blades,
        Self::BladeRotation,
        Self::Anamorphic,
        Self::Lights,
        Self::Ambient,
        Self::Mode,
        Self::Spp,
        Self::Aa,
        Self::PixelFilter,
        Self::PixelFilterWidth,
        Self::Tolerance,
        Self::IntervalFactor,
        Self::PaperExact,
        Self::Transparent,
        Self::Exposure,
        Self::Seed,
        Self::LensFilter,
        Self::MaxInterval,
        Self::Integrator,
        Self::MaxBounces,
        Self::DiffuseBounces,
        Self::GlossyBounces,
        Self::TransmissionBounces,
        Self::ClampIndirect,
        Self::FilterGlossy,
        Self::LightTracing,
        Self::Reuse,
    ];

    /// The table: the parameter's name in each front end.
    #[rustfmt::skip]
    pub const fn names(self) -> Names {
        match self {
            Self::Width => row("width", Some("--width"), Some("image.width"), Some("width"), Some("dofray_scene_set_size")),
            Self::Height => row("height", Some("--height"), Some("image.height"), Some("height"), Some("dofray_scene_set_size")),
            Self::ApertureRadius => row("aperture_radius", Some("--aperture-radius"), Some("camera.aperture_radius"), Some("aperture_radius"), Some("dofray_scene_set_aperture_radius")),
            Self::FNumber => row("f_number", Some("--f-number"), Some("camera.f_number"), Some("f_number"), Some("dofray_scene_set_f_number")),
            Self::FocalLength => row("focal_length_mm", Some("--focal-length"), Some("camera.focal_length_mm"), Some("focal_length"), Some("dofray_scene_set_focal_length_mm")),
            Self::SensorWidth => row("sensor_width_mm", Some("--sensor-width"), Some("camera.sensor_width_mm"), Some("sensor_width"), None),
            Self::SharpRange => row("sharp_range", Some("--sharp-range"), Some("camera.sharp_range"), None, None),
            Self::Spread => row("spread", Some("--spread"), Some("camera.spread"), None, None),
            Self::FocusDistance => row("focus_distance", Some("--focus-distance"), Some("camera.focus_distance"), Some("focus_distance"), Some("dofray_scene_set_focus_distance")),
            Self::Autofocus => row("autofocus", Some("--autofocus"), Some("camera.focus_pixel"), Some("autofocus"), Some("dofray_scene_set_autofocus")),
            Self::Blades => row("blades", Some("--blades"), Some("camera.blades"), Some("blades"), None),
            Self::BladeRotation => row("blade_rotation_deg", Some("--blade-rotation"), Some("camera.blade_rotation"), None, None),
            Self::Anamorphic => row("anamorphic", Some("--anamorphic"), Some("camera.anamorphic"), None, None),
            Self::Lights => row("lights", Some("--light"), Some("lights"), None, None),
            Self::Ambient => row("ambient", Some("--ambient"), Some("ambient"), None, None),
            Self::Mode => row("mode", Some("--mode"), None, Some("mode"), Some("dofray_scene_set_mode")),
            Self::Spp => row("spp", Some("--spp"), Some("render.spp"), Some("spp"), Some("dofray_scene_set_spp")),
            Self::Aa => row("aa", Some("--aa"), Some("render.aa"), Some("aa"), Some("dofray_scene_set_aa")),
            Self::PixelFilter => row("pixel_filter", Some("--pixel-filter"), Some("render.pixel_filter"), None, None),
            Self::PixelFilterWidth => row("pixel_filter_width", Some("--pixel-filter-width"), Some("render.pixel_filter_width"), None, None),
            Self::Tolerance => row("tolerance", Some("--tolerance"), Some("render.tolerance"), Some("tolerance"), Some("dofray_scene_set_tolerance")),
            Self::IntervalFactor => row("interval_factor", Some("--interval-factor"), Some("render.interval_factor"), None, None),
            Self::PaperExact => row("paper_exact", Some("--paper-exact"), None, None, None),
            Self::Transparent => row("transparent", Some("--transparent"), Some("render.transparent"), Some("transparent"), Some("dofray_scene_set_transparent")),
            Self::Exposure => row("exposure", Some("--exposure"), None, Some("exposure"), Some("dofray_scene_set_exposure")),
            Self::Seed => row("seed", Some("--seed"), None, Some("seed"), Some("dofray_scene_set_seed")),
            Self::LensFilter => row("lens_filter", Some("--filter"), None, None, None),
            Self::MaxInterval => row("max_interval", None, None, None, None),
            Self::Integrator => row("integrator", Some("--integrator"), Some("render.integrator"), Some("integrator"), None),
            Self::MaxBounces => row("max_bounces", Some("--max-bounces"), Some("render.max_bounces"), None, None),
            Self::DiffuseBounces => row("diffuse_bounces", Some("--diffuse-bounces"), Some("render.diffuse_bounces"), None, None),
            Self::GlossyBounces => row("glossy_bounces", Some("--glossy-bounces"), Some("render.glossy_bounces"), None, None),
            Self::TransmissionBounces => row("transmission_bounces", Some("--transmission-bounces"), Some("render.transmission_bounces"), None, None),
            Self::ClampIndirect => row("clamp_indirect", Some("--clamp-indirect"), Some("render.clamp_indirect"), None, None),
            Self::FilterGlossy => row("filter_glossy", Some("--filter-glossy"), Some("render.filter_glossy"), None, None),
            Self::LightTracing => row("light_tracing", Some("--light-tracing"), Some("render.light_tracing"), Some("light_tracing"), None),
            Self::Reuse => row("reuse", Some("--reuse"), Some("render.reuse"), Some("reuse"), None),
        }
    }

    /// The Rust field's name (`f_number`).
    pub const fn field(self) -> &'static str {
        self.names().field
    }

    /// The command line's flag (`--f-number`); the field's name for a library-only setting.
    pub fn flag(self) -> &'static str {
        self.names().flag.unwrap_or(self.field())
    }

    /// The scene file's key (`camera.f_number`), if a scene file can set it.
    pub const fn key(self) -> Option<&'static str> {
        self.names().key
    }

    /// The keyword of Python's `dofray.render` (`focal_length`), if it has one.
    pub const fn keyword(self) -> Option<&'static str> {
        self.names().keyword
    }

    /// The C function that sets it (`dofray_scene_set_f_number`), if there is one.
    pub const fn setter(self) -> Option<&'static str> {
        self.names().setter
    }

    /// How a scene file names it: its key, else its field.
    pub fn key_name(self) -> &'static str {
        self.key().unwrap_or(self.field())
    }

    /// How Python names it: its keyword, else its field.
    pub fn keyword_name(self) -> &'static str {
        self.keyword().unwrap_or(self.field())
    }

    /// How C names it: its setter, else its field.
    pub fn setter_name(self) -> &'static str {
        self.setter().unwrap_or(self.field())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_is_unique_within_its_front_end() {
        let mut seen = std::collections::HashSet::new();
        for p in Param::ALL {
            let n = p.names();
            assert!(seen.insert(("field", n.field)), "{p:?}");
            assert!(seen.insert(("flag", p.flag())), "{p:?}");
            if let Some(k) = n.key {
                assert!(seen.insert(("key", k)), "{p:?}");
            }
            if let Some(k) = n.keyword {
                assert!(seen.insert(("keyword", k)), "{p:?}");
            }
        }
    }

    /// The table's C setters are the header's, its Python keywords `dofray.render`'s.
    #[test]
    fn the_bindings_have_the_names_the_table_gives() {
        let header = include_str!("../include/dofray.h");
        let python = include_str!("../python/src/lib.rs");
        let start = python.find("signature = (").expect("render's signature");
        let signature = &python[start..start + python[start..].find("))]").expect("its end")];
        for p in Param::ALL {
            if let Some(setter) = p.setter() {
                assert!(header.contains(&format!("{setter}(")), "{p:?}: {setter}");
            }
            if let Some(keyword) = p.keyword() {
                let given = format!(" {keyword}=");
                assert!(signature.contains(&given), "{p:?}: {keyword}");
            }
        }
    }
}
