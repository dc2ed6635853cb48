//! What every output records about how it was made: key-value text written into EXR header
//! attributes and PNG text chunks, so a shot can be traced back to its settings.

use std::path::Path;

use crate::camera::Camera;
use crate::render::{Mode, RenderSettings, RenderStats, SamplingRule};

/// Ordered `(key, value)` pairs. Keys are ASCII (PNG keywords: 1 to 79 Latin-1 characters);
/// values are any text.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Metadata {
    entries: Vec<(String, String)>,
}

impl Metadata {
    /// No entries.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one entry (a key given twice is written twice; readers keep the last).
    pub fn push(&mut self, key: impl Into<String>, value: impl ToString) {
        self.entries.push((key.into(), value.to_string()));
    }

    /// The entries in the order they were added (duplicate keys included).
    pub fn iter(&self) -> impl Iterator<Item = (&str, &str)> {
        self.entries.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// The value of the last entry with `key`, if any.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.iter()
            .filter(|(k, _)| *k == key)
            .map(|(_, v)| v)
            .last()
    }

    /// The settings of one render: dofray's and Embree's versions, the mode and its sampling,
    /// the lens and focus, the filters, the scene (`scene_file`, when it is a file, is
    /// hashed so a changed file is noticed) and what the render cost.
    pub fn for_render(
        scene_name: &str,
        scene_file: Option<&Path>,
        camera: &Camera,
        settings: &RenderSettings,
        stats: &RenderStats,
        embree_version: &str,
    ) -> Self {
        let mut m = Self::new();
        m.push("Software", format!("dofray {}", env!("CARGO_PKG_VERSION")));
        m.push("dofray:version", env!("CARGO_PKG_VERSION"));
        m.push("dofray:commit", crate::GIT_COMMIT);
        m.push("dofray:embree", embree_version);
        m.push("dofray:scene", scene_name);
        if let Some(path) = scene_file {
            m.push("dofray:scene_file", path.display());
            if let Ok(bytes) = std::fs::read(path) {
                m.push("dofray:scene_fnv1a64", format!("{:016x}", fnv1a64(&bytes)));
            }
        }
        m.push("dofray:mode", settings.mode.name());
        if settings.mode == Mode::Adaptive {
            m.push("dofray:rule", settings.rule.site_rule().name());
            match (settings.rule, settings.tolerance()) {
                (_, Some(tolerance)) => m.push("dofray:tolerance", tolerance),
                (
                    SamplingRule::Seed {
                        interval_factor,
                        paper_exact,
                    },
                    _,
                ) => {
                    m.push("dofray:interval_factor", interval_factor);
                    m.push("dofray:paper_exact", paper_exact);
                }
                (SamplingRule::ErrorControlled { .. }, None) => {}
            }
        }
        m.push("dofray:spp", settings.spp);
        m.push("dofray:aa", settings.aa);
        m.push("dofray:seed", settings.seed);
        m.push("dofray:transparent", settings.transparent);
        m.push("dofray:exposure", settings.exposure);
        m.push(
            "dofray:pixel_filter",
            format!(
                "{:?} {} px",
                settings.pixel_filter.kind, settings.pixel_filter.width
            ),
        );
        m.push("dofray:lens_filter", format!("{:?}", settings.filter));
        m.push("dofray:aperture_radius", camera.aperture_radius());
        m.push("dofray:focus_distance", camera.focus_distance());
        m.push("dofray:width", camera.width);
        m.push("dofray:height", camera.height);
        m.push("dofray:seconds", format!("{:.3}", stats.seconds));
        m.push("dofray:rays", stats.rays.total());
        m
    }
}

/// FNV-1a, 64 bits: a stable hash (std's hasher may change between releases), fed bytes or,
/// through `fmt::Write`, formatted text.
pub struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    /// Feeds `bytes` into the hash.
    pub fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }

    /// The hash of everything fed so far (does not reset it).
    pub fn finish(&self) -> u64 {
        self.0
    }
}

impl std::fmt::Write for Fnv1a {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.update(s.as_bytes());
        Ok(())
    }
}

/// [`Fnv1a`] of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv1a::default();
    h.update(bytes);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_keep_their_order_and_the_last_value_wins() {
        let mut m = Metadata::new();
        m.push("a", 1);
        m.push("b", "two");
        m.push("a", 3.5);
        assert_eq!(m.get("a"), Some("3.5"));
        assert_eq!(m.get("c"), None);
        let keys: Vec<&str> = m.iter().map(|(k, _)| k).collect();
        assert_eq!(keys, ["a", "b", "a"]);
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_ne!(fnv1a64(b"scene a"), fnv1a64(b"scene b"));
    }
}
