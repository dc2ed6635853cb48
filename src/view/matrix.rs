//! 3x3 colour matrices between RGB spaces given by their chromaticities (all with a D65
//! white: the spaces here share it, so no chromatic adaptation is needed).

/// A row-major 3x3 matrix applied to column vectors.
pub(super) type Mat3 = [[f64; 3]; 3];

/// An RGB space's red, green and blue chromaticities (CIE 1931 xy), white D65.
#[derive(Clone, Copy)]
pub(super) struct Primaries([[f64; 2]; 3]);

impl Primaries {
    /// ITU-R BT.709 / sRGB.
    pub(super) const REC709: Self = Self([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]]);
    /// ITU-R BT.2020.
    pub(super) const REC2020: Self = Self([[0.708, 0.292], [0.170, 0.797], [0.131, 0.046]]);
    /// FilmLight E-Gamut (AgX's LUT input).
    pub(super) const E_GAMUT: Self = Self([[0.8, 0.3177], [0.18, 0.9], [0.065, -0.0805]]);
}

const D65: [f64; 2] = [0.3127, 0.3290];

fn xyz([x, y]: [f64; 2]) -> [f64; 3] {
    [x / y, 1.0, (1.0 - x - y) / y]
}

/// RGB in `p` to CIE XYZ (white maps to Y = 1).
fn to_xyz(p: Primaries) -> Mat3 {
    let cols = p.0.map(xyz);
    let m: Mat3 = std::array::from_fn(|r| std::array::from_fn(|c| cols[c][r]));
    let s = apply(&inverse(&m), xyz(D65));
    std::array::from_fn(|r| std::array::from_fn(|c| m[r][c] * s[c]))
}

/// The matrix taking linear RGB in `from` to linear RGB in `to`.
pub(super) fn convert(from: Primaries, to: Primaries) -> Mat3 {
    product(&inverse(&to_xyz(to)), &to_xyz(from))
}

pub(super) fn apply(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

pub(super) fn product(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

pub(super) fn inverse(m: &Mat3) -> Mat3 {
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj: Mat3 = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    adj.map(|row| row.map(|v| v / det))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rec709_to_rec2020_is_the_published_matrix() {
        // ITU-R BT.2087's matrix.
        let m = convert(Primaries::REC709, Primaries::REC2020);
        let want = [
            [0.6274, 0.3293, 0.0433],
            [0.0691, 0.9195, 0.0114],
            [0.0164, 0.0880, 0.8956],
        ];
        let close = |a: &Mat3, b: &Mat3, tol: f64| {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .all(|(x, y)| (x - y).abs() < tol)
        };
        assert!(close(&m, &want, 1e-4), "{m:?}");
        // White stays white.
        let w = apply(&m, [1.0; 3]);
        assert!(w.iter().all(|v| (v - 1.0).abs() < 1e-12));
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(close(&product(&m, &inverse(&m)), &identity, 1e-12));
    }
}
