//! AgX as Blender 4 forms it for an sRGB display, and its looks.
//!
//! Blender's configuration (`datafiles/colormanagement/config.ocio`, view "AgX", colour space
//! "AgX Base sRGB") encodes scene-linear colour as FilmLight E-Gamut in log2 (-10 to +15
//! stops around 0.18), looks it up in a 57^3 LUT with tetrahedral interpolation, and decodes
//! the LUT's power-2.4 output to the sRGB curve. That LUT was baked by Eary Chow's generator
//! (github.com/EaryChow/AgX_LUT_Gen, `AgXBasesRGB.py`) from Troy Sobotka's AgX formation,
//! which [`form`] implements: a lower guard rail in Rec.2020, the inset matrix, a log2
//! encoding from -10 to +6.5 stops, Troy's sigmoid, a hue mix of 40% towards the formed
//! hue, the outset matrix, Rec.709 with its lower guard rail, and power 1/2.4. Baking it on
//! the same grid and sampling it the same way gives Blender's code values (tested against
//! Blender's own LUT file where Blender is installed: scripts/view-transform-check.py).

use super::lut::Lut3;
use super::matrix::{self, Mat3, Primaries};

/// Mid grey, the pivot of every log encoding here.
const GREY: f64 = 0.18;
/// The formation's log2 range in stops around [`GREY`].
const FORM_STOPS: (f64, f64) = (-10.0, 6.5);
/// The LUT's input encoding: E-Gamut in log2 from -10 to +15 stops around [`GREY`].
const SHAPER_STOPS: (f64, f64) = (-10.0, 15.0);
/// Blender's `AgX Log` allocation, `lg2` over `[2^-12.47393, 2^12.5260688117]`: the same
/// range as [`SHAPER_STOPS`] in absolute log2 units; the looks work in it.
const LOG_ALLOCATION: (f32, f32) = (-12.47393, 12.526_069);
/// The grid Blender's `AgX_Base_sRGB.cube` uses.
const LUT_SIZE: usize = 57;
/// Rec.2020 luminance as AgX's generator computes it (CIE 2015 observer, D65 as a 6504 K
/// black body); the guard rails and the greyscale look use it.
const LUMA_2020: [f64; 3] = [
    0.265_818_037_025_044_9,
    0.598_469_860_453_65,
    0.135_712_102_521_305_2,
];
/// The inset matrix (Troy Sobotka's SB2383 script, rotate [3, -1, -2], inset
/// [0.4, 0.22, 0.13] in Rec.2020), as Blender's `AgX Log` colour space gives it.
const INSET: Mat3 = [
    [
        0.856_627_153_315_983,
        0.095_121_240_538_158_8,
        0.048_251_606_145_858_3,
    ],
    [
        0.137_318_972_929_847,
        0.761_241_990_602_591,
        0.101_439_036_467_562,
    ],
    [
        0.111_898_212_999_95,
        0.076_799_418_603_190_3,
        0.811_302_368_396_859,
    ],
];
/// The outset matrix's inverse (rotate [0, 0, 0], inset [0.4, 0.22, 0.04]).
const OUTSET_INVERSE: Mat3 = [
    [
        0.899_796_955_911_611,
        0.087_199_619_202_835_1,
        0.013_003_424_885_555,
    ],
    [
        0.111_420_988_957_48,
        0.875_575_586_156_966,
        0.013_003_424_885_554_8,
    ],
    [
        0.111_420_988_957_48,
        0.087_199_619_202_834_9,
        0.801_379_391_839_686,
    ],
];

/// The baked view: linear Rec.709 in, display-linear Rec.709 (before the sRGB curve) out.
pub(super) struct AgX {
    lut: Lut3,
    rec709_to_egamut: [[f32; 3]; 3],
}

impl AgX {
    /// Bakes the formation (about 185 000 evaluations; tens of milliseconds).
    pub(super) fn new() -> Self {
        let egamut_to_2020 = matrix::convert(Primaries::E_GAMUT, Primaries::REC2020);
        let spaces = Spaces::new();
        let lut = Lut3::bake(LUT_SIZE, |enc| {
            let egamut = enc.map(|e| log2_decode(e, SHAPER_STOPS));
            form(&spaces, matrix::apply(&egamut_to_2020, egamut))
        });
        let m = matrix::convert(Primaries::REC709, Primaries::E_GAMUT);
        Self {
            lut,
            rec709_to_egamut: m.map(|row| row.map(|v| v as f32)),
        }
    }

    /// Linear Rec.709 to display-linear Rec.709 in `[0, 1]`.
    pub(super) fn apply(&self, rgb: [f32; 3]) -> [f32; 3] {
        let m = &self.rec709_to_egamut;
        let eg: [f32; 3] =
            std::array::from_fn(|i| m[i][0] * rgb[0] + m[i][1] * rgb[1] + m[i][2] * rgb[2]);
        let (lo, hi) = LOG_ALLOCATION;
        let enc = eg.map(|v| (v.max(f32::MIN_POSITIVE).log2() - lo) / (hi - lo));
        self.lut.sample(enc).map(|v| v.max(0.0).powf(2.4))
    }
}

/// `enc` in a normalised log2 range of `stops` around [`GREY`], to linear.
fn log2_decode(enc: f64, stops: (f64, f64)) -> f64 {
    GREY * (enc * (stops.1 - stops.0) + stops.0).exp2()
}

/// The matrices the formation needs, computed once per bake.
struct Spaces {
    outset: Mat3,
    rec2020_to_709: Mat3,
    rec709_to_2020: Mat3,
}

impl Spaces {
    fn new() -> Self {
        Self {
            outset: matrix::inverse(&OUTSET_INVERSE),
            rec2020_to_709: matrix::convert(Primaries::REC2020, Primaries::REC709),
            rec709_to_2020: matrix::convert(Primaries::REC709, Primaries::REC2020),
        }
    }
}

/// AgX's formation of one linear Rec.2020 colour: Rec.709 display values encoded with power
/// 1/2.4, in `[0, 1]` (the content of Blender's `AgX_Base_sRGB.cube`).
fn form(spaces: &Spaces, rec2020: [f64; 3]) -> [f64; 3] {
    let c = matrix::apply(&INSET, lower_guard_rail_2020(rec2020));
    let pre_hue = hsv(c)[0];
    let formed = c.map(|v| {
        if v <= 0.0 {
            return 0.0;
        }
        let x = ((v / GREY).log2() - FORM_STOPS.0) / (FORM_STOPS.1 - FORM_STOPS.0);
        sigmoid(x).max(0.0).powf(2.4)
    });
    let [h, s, v] = hsv(formed);
    // 60% of the hue before formation, 40% of the formed one (a plain lerp, as the generator).
    let mixed = from_hsv([pre_hue + 0.4 * (h - pre_hue), s, v]);
    let rec2020 = matrix::apply(&spaces.outset, mixed);
    let rec709 = matrix::apply(&spaces.rec2020_to_709, rec2020);
    lower_guard_rail_709(&spaces.rec709_to_2020, rec709)
        .map(|v| v.max(0.0).powf(1.0 / 2.4).min(1.0))
}

/// Troy Sobotka's sigmoid with AgX's parameters: through mid grey's encoding
/// `(10 / 16.5, 0.18^(1/2.4))` with slope 2.4, power-1.5 toe and shoulder, meeting `(0, 0)`
/// and `(1, 1)`. Each side is `s * e(slope * (x - px) / s) + py` with
/// `e(z) = z / (1 + z^p)^(1/p)`; its scale `s` makes it pass through its limit.
fn sigmoid(x: f64) -> f64 {
    const SLOPE: f64 = 2.4;
    const POWER: f64 = 1.5;
    let px = -FORM_STOPS.0 / (FORM_STOPS.1 - FORM_STOPS.0);
    let py = GREY.powf(1.0 / 2.4);
    let scale = |lx: f64, ly: f64, tx: f64, ty: f64| {
        let run = SLOPE * (lx - tx);
        (run.powf(-POWER) * ((run / (ly - ty)).powf(POWER) - 1.0)).powf(-1.0 / POWER)
    };
    let s = if x < px {
        // The toe mirrors the shoulder: measured from (1, 1) towards its limit (0, 0).
        -scale(1.0, 1.0, 1.0 - px, 1.0 - py)
    } else {
        scale(1.0, 1.0, px, py)
    };
    let z = SLOPE * (x - px) / s;
    s * z / (1.0 + z.powf(POWER)).powf(1.0 / POWER) + py
}

/// The lower guard rail in Rec.2020: lifts negative components while keeping luminance
/// (identity for colours without negatives).
fn lower_guard_rail_2020(rgb: [f64; 3]) -> [f64; 3] {
    lower_guard_rail(rgb, |c| opponent_luma(c, |c| dot(c, LUMA_2020)))
}

/// The lower guard rail of the Rec.709 display, luminance measured in Rec.2020 and the
/// opponent compensation faded out (`Y^0.08`) as luminance grows.
fn lower_guard_rail_709(to_2020: &Mat3, rgb: [f64; 3]) -> [f64; 3] {
    let luma = |c: [f64; 3]| dot(matrix::apply(to_2020, c), LUMA_2020);
    lower_guard_rail(rgb, |c| {
        let y = luma(c);
        // A negative luminance has no power 0.08: the generator's NaN leaves it as is below.
        let t = y.powf(0.08).clamp(0.0, 1.0);
        (1.0 - t) * opponent_luma(c, luma) + t * y
    })
}

/// The luminance of `c` compensated by its opponent colour's (`max - c`), so a colour with
/// negative components is measured as the light it stands for.
fn opponent_luma(c: [f64; 3], luma: impl Fn([f64; 3]) -> f64) -> f64 {
    let m = max3(c);
    let inv = c.map(|v| m - v);
    max3(inv) - luma(inv) + luma(c)
}

/// Offsets `rgb` so no component is negative, then scales it back down to the `measure` the
/// original had when the offset raised it (Eary Chow's guard rail, after Sakari Kapanen).
fn lower_guard_rail(rgb: [f64; 3], measure: impl Fn([f64; 3]) -> f64) -> [f64; 3] {
    let target = measure(rgb);
    let offset = (-min3(rgb)).max(0.0);
    let lifted = rgb.map(|v| v + offset);
    let now = measure(lifted);
    let ratio = if now > target {
        target / now.max(1e-100)
    } else {
        1.0
    };
    lifted.map(|v| v * ratio)
}

/// The look's grading, applied in Blender's `AgX Log` space (Rec.2020, inset, log2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Grade {
    /// OpenColorIO's `GradingPrimaryTransform` in log style: contrast around the encoding of
    /// mid grey, then saturation with Rec.709 luma weights (as OpenColorIO computes it).
    Primary { contrast: f32, saturation: f32 },
    /// Every channel set to the Rec.2020 luminance of the inset colour.
    Greyscale,
}

/// A look applied to linear Rec.709 (before the view), as Blender's `AgX - ...` looks do.
pub(super) fn apply_look(grade: Grade, rgb: [f32; 3]) -> [f32; 3] {
    static MATRICES: std::sync::LazyLock<(Mat3, Mat3)> = std::sync::LazyLock::new(|| {
        let to_log = matrix::product(
            &INSET,
            &matrix::convert(Primaries::REC709, Primaries::REC2020),
        );
        (to_log, matrix::inverse(&to_log))
    });
    let (to_log, from_log) = &*MATRICES;
    let c = matrix::apply(to_log, rgb.map(f64::from));
    let (lo, hi) = LOG_ALLOCATION;
    let (lo, hi) = (f64::from(lo), f64::from(hi));
    let encode = |v: f64| (v.max(f64::MIN_POSITIVE).log2() - lo) / (hi - lo);
    let decode = |e: f64| (e * (hi - lo) + lo).exp2();
    let graded = match grade {
        Grade::Primary {
            contrast,
            saturation,
        } => {
            // OpenColorIO's log-style pivot: 0.5 + 0.5 * pivot, with Blender's pivot -0.2.
            let pivot = 0.4;
            let e = c.map(|v| (encode(v) - pivot) * f64::from(contrast) + pivot);
            let luma = 0.2126 * e[0] + 0.7152 * e[1] + 0.0722 * e[2];
            e.map(|v| decode(luma + f64::from(saturation) * (v - luma)))
        }
        Grade::Greyscale => {
            let y = dot(c.map(|v| decode(encode(v))), LUMA_2020);
            [y; 3]
        }
    };
    matrix::apply(from_log, graded).map(|v| v as f32)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn max3(c: [f64; 3]) -> f64 {
    c[0].max(c[1]).max(c[2])
}

fn min3(c: [f64; 3]) -> f64 {
    c[0].min(c[1]).min(c[2])
}

/// Hue (in turns), saturation, value.
fn hsv(c: [f64; 3]) -> [f64; 3] {
    let (max, min) = (max3(c), min3(c));
    let delta = max - min;
    let s = if max > 0.0 { delta / max } else { 0.0 };
    if delta <= 0.0 {
        return [0.0, s, max];
    }
    let h = if c[0] == max {
        (c[1] - c[2]) / delta
    } else if c[1] == max {
        2.0 + (c[2] - c[0]) / delta
    } else {
        4.0 + (c[0] - c[1]) / delta
    } / 6.0;
    [h.rem_euclid(1.0), s, max]
}

fn from_hsv([h, s, v]: [f64; 3]) -> [f64; 3] {
    let h6 = h.rem_euclid(1.0) * 6.0;
    let sector = h6.floor();
    let f = h6 - sector;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match sector as u8 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sigmoid_meets_its_pivot_and_limits() {
        let py = GREY.powf(1.0 / 2.4);
        assert!((sigmoid(10.0 / 16.5) - py).abs() < 1e-12);
        assert!(sigmoid(0.0).abs() < 1e-9);
        assert!((sigmoid(1.0) - 1.0).abs() < 1e-9);
        // Monotonic through the whole range.
        let mut last = f64::NEG_INFINITY;
        for i in 0..=100 {
            let y = sigmoid(f64::from(i) / 100.0);
            assert!(y > last);
            last = y;
        }
    }

    #[test]
    fn mid_grey_forms_to_mid_grey() {
        // Grey stays grey through inset, sigmoid and outset (their rows sum to one), and
        // 0.18 sits on the pivot: the display shows 0.18 linear, sRGB code 118.
        let agx = AgX::new();
        let out = agx.apply([0.18; 3]);
        for v in out {
            assert!((v - 0.18).abs() < 2e-3, "{out:?}");
        }
    }

    #[test]
    fn guard_rails_leave_positive_colours_alone() {
        let c = [0.3, 0.02, 0.7];
        assert_eq!(lower_guard_rail_2020(c), c);
        let lifted = lower_guard_rail_2020([0.3, -0.05, 0.7]);
        assert!(lifted.iter().all(|&v| v >= 0.0));
    }

    #[test]
    fn hsv_round_trips() {
        for c in [
            [0.2, 0.5, 0.9],
            [0.9, 0.1, 0.1],
            [0.3, 0.3, 0.3],
            [0.0, 0.7, 0.2],
        ] {
            let back = from_hsv(hsv(c));
            for i in 0..3 {
                assert!((back[i] - c[i]).abs() < 1e-12, "{c:?} -> {back:?}");
            }
        }
    }
}
