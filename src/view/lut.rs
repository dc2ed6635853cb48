//! A 3D lookup table over `[0, 1]^3`, baked from a function and sampled with tetrahedral
//! interpolation: how Blender's OpenColorIO configuration applies its view transforms
//! (`FileTransform {interpolation: tetrahedral}`), so a view baked on the same grid from the
//! same formula gives the same code values as Blender, interpolation error included.

/// An `n x n x n` table of RGB values; index `(b * n + g) * n + r`, red fastest (as in a
/// `.cube` file).
pub(super) struct Lut3 {
    n: usize,
    table: Vec<[f32; 3]>,
}

impl Lut3 {
    /// Evaluates `f` at every grid point (`i / (n - 1)` along each axis).
    pub(super) fn bake(n: usize, f: impl Fn([f64; 3]) -> [f64; 3]) -> Self {
        let step = 1.0 / (n - 1) as f64;
        let mut table = Vec::with_capacity(n * n * n);
        for b in 0..n {
            for g in 0..n {
                for r in 0..n {
                    let v = f([r as f64 * step, g as f64 * step, b as f64 * step]);
                    table.push(v.map(|c| if c.is_finite() { c as f32 } else { 0.0 }));
                }
            }
        }
        Self { n, table }
    }

    fn at(&self, r: usize, g: usize, b: usize) -> [f32; 3] {
        self.table[(b * self.n + g) * self.n + r]
    }

    /// The table at `p` (each coordinate clamped to `[0, 1]`; NaN counts as 0), interpolated
    /// within the grid cell's tetrahedron that contains `p`, as OpenColorIO does.
    pub(super) fn sample(&self, p: [f32; 3]) -> [f32; 3] {
        let last = (self.n - 1) as f32;
        let mut base = [0usize; 3];
        let mut frac = [0f32; 3];
        for i in 0..3 {
            let x = if p[i].is_nan() {
                0.0
            } else {
                p[i].clamp(0.0, 1.0)
            } * last;
            let lo = (x.floor() as usize).min(self.n - 2);
            base[i] = lo;
            frac[i] = x - lo as f32;
        }
        let [r, g, b] = base;
        let [fr, fg, fb] = frac;
        let c000 = self.at(r, g, b);
        let c111 = self.at(r + 1, g + 1, b + 1);
        // The tetrahedron is picked by the order of the fractions; each walks from c000 to
        // c111 along one edge per axis, in that order.
        let (w, c1, c2) = if fr > fg {
            if fg > fb {
                ([fr, fg, fb], self.at(r + 1, g, b), self.at(r + 1, g + 1, b))
            } else if fr > fb {
                ([fr, fb, fg], self.at(r + 1, g, b), self.at(r + 1, g, b + 1))
            } else {
                ([fb, fr, fg], self.at(r, g, b + 1), self.at(r + 1, g, b + 1))
            }
        } else if fb > fg {
            ([fb, fg, fr], self.at(r, g, b + 1), self.at(r, g + 1, b + 1))
        } else if fb > fr {
            ([fg, fb, fr], self.at(r, g + 1, b), self.at(r, g + 1, b + 1))
        } else {
            ([fg, fr, fb], self.at(r, g + 1, b), self.at(r + 1, g + 1, b))
        };
        let [f1, f2, f3] = w;
        std::array::from_fn(|i| {
            (1.0 - f1) * c000[i] + (f1 - f2) * c1[i] + (f2 - f3) * c2[i] + f3 * c111[i]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tetrahedral_interpolation_is_exact_for_linear_functions() {
        // Any affine function is reproduced exactly by tetrahedral interpolation, whichever
        // tetrahedron a point falls in.
        let f = |p: [f64; 3]| {
            [
                0.3 * p[0] - 0.2 * p[1] + 0.7 * p[2] + 0.1,
                p[1],
                2.0 * p[2] - p[0],
            ]
        };
        let lut = Lut3::bake(5, f);
        for p in [
            [0.1, 0.5, 0.9],
            [0.9, 0.5, 0.1],
            [0.5, 0.9, 0.1],
            [0.5, 0.1, 0.9],
            [0.1, 0.9, 0.5],
            [0.9, 0.1, 0.5],
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
        ] {
            let got = lut.sample(p.map(|c: f64| c as f32));
            let want = f(p);
            for i in 0..3 {
                assert!(
                    (got[i] as f64 - want[i]).abs() < 1e-5,
                    "{p:?}: {got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn out_of_domain_and_nan_are_clamped() {
        let lut = Lut3::bake(3, |p| p);
        assert_eq!(lut.sample([-1.0, 2.0, f32::NAN]), [0.0, 1.0, 0.0]);
    }
}
