//! Khronos PBR Neutral (Khronos Group, 2024), as Blender 4.2 applies it: scene-linear Rec.709
//! encoded in log2 from 2^-9 to 2^10, a 57^3 LUT baked from the published formula, sampled
//! tetrahedrally, then the sRGB curve (colour space "Khronos PBR Neutral sRGB").

use super::lut::Lut3;

const STOPS: (f64, f64) = (-9.0, 10.0);

pub(super) struct PbrNeutral {
    lut: Lut3,
}

impl PbrNeutral {
    pub(super) fn new() -> Self {
        let lut = Lut3::bake(57, |enc| {
            neutral(enc.map(|e| (e * (STOPS.1 - STOPS.0) + STOPS.0).exp2()))
        });
        Self { lut }
    }

    /// Linear Rec.709 to display-linear Rec.709 in `[0, 1]`.
    pub(super) fn apply(&self, rgb: [f32; 3]) -> [f32; 3] {
        let (lo, hi) = (STOPS.0 as f32, STOPS.1 as f32);
        let enc = rgb.map(|v| (v.max(f32::MIN_POSITIVE).log2() - lo) / (hi - lo));
        self.lut.sample(enc)
    }
}

/// The Khronos PBR Neutral tone mapper on linear Rec.709: a small black offset, identity up
/// to 0.8, then a compressed highlight that desaturates towards white.
fn neutral(c: [f64; 3]) -> [f64; 3] {
    const START: f64 = 0.8 - 0.04;
    const DESATURATION: f64 = 0.15;
    let x = c[0].min(c[1]).min(c[2]);
    let offset = if x < 0.08 { x - 6.25 * x * x } else { 0.04 };
    let c = c.map(|v| v - offset);
    let peak = c[0].max(c[1]).max(c[2]);
    if peak < START {
        return c;
    }
    let d = 1.0 - START;
    let new_peak = 1.0 - d * d / (peak + d - START);
    let c = c.map(|v| v * new_peak / peak);
    let g = 1.0 - 1.0 / (DESATURATION * (peak - new_peak) + 1.0);
    c.map(|v| v * (1.0 - g) + new_peak * g)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mid_tones_pass_and_highlights_roll_off() {
        let mid = neutral([0.5, 0.3, 0.2]);
        assert!((mid[0] - (0.5 - 0.04)).abs() < 1e-12);
        let hot = neutral([50.0, 10.0, 1.0]);
        assert!(hot.iter().all(|&v| v <= 1.0 && v > 0.0), "{hot:?}");
    }
}
