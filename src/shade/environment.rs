//! The world as an equirectangular image: radiance by direction, and directions drawn in
//! proportion to the image's brightness, so a path tracer can use the world as a light.
//!
//! The mapping is Blender's Environment Texture (Cycles' `direction_to_equirectangular`,
//! which EEVEE's `node_tex_environment_equirectangular` matches), so an HDRI lights and looks
//! as it does in Blender:
//! - dofray's world is +Y up (glTF's axes); Blender's is +Z up, and its glTF exporter writes
//!   Blender's (x, y, z) as (x, z, -y). A direction `d` is first turned into Blender's axes,
//!   `b = (d.x, -d.z, d.y)`.
//! - `rotation` is the Z rotation of a Mapping node (type Point) in front of the texture: the
//!   lookup vector is `m = Rz(rotation) b` (Cycles' `euler_to_transform`), counter-clockwise
//!   seen from above. The picture therefore turns the other way: a feature the unrotated map
//!   shows at Blender direction `f` is seen at `Rz(-rotation) f`, clockwise seen from above.
//! - `u = 0.5 - atan2(m.y, m.x) / 2pi`, `v = 0.5 + asin(m.z) / pi`; `v = 1` is the image's
//!   top row. The centre column faces Blender +X (dofray +X), the left quarter column Blender
//!   +Y (dofray -Z, where an unrotated glTF camera looks), the right quarter Blender -Y
//!   (dofray +Z); the left and right edges meet at Blender -X.
//! - Lookups are bilinear between texel centres (Blender's default "Linear" interpolation),
//!   wrapping across the left/right seam and clamped at the poles.
//!
//! Sampling draws a texel cell from a piecewise-constant 2D distribution (a marginal over
//! rows, a conditional per row, as pbrt-v4's `PiecewiseConstant2D`), then a point uniform in
//! solid angle within the cell (uniform in `u` and in `cos theta`). A cell's weight is the
//! channel average of the bilinear radiance integrated over the cell (texels filtered by
//! (1/8, 3/4, 1/8) across and down), times the cell's solid angle; so the density is
//! positive wherever the radiance is, a uniform image is sampled uniformly (pdf 1 / 4pi
//! exactly) and the density stays finite at the poles. Sampling and the pdf are two binary
//! searches each; nothing is allocated after construction.

use std::f32::consts::PI;
use std::f64::consts::PI as PI64;

use glam::{Vec2, Vec3};

use super::texture::floor;

/// Why an environment map could not be built. Texels are counted from the top-left corner.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvironmentError {
    /// A map without texels.
    #[error("the environment image is {width}x{height}: expected at least one texel")]
    Empty {
        /// Width in texels.
        width: usize,
        /// Height in texels.
        height: usize,
    },
    /// The texel array does not match the size.
    #[error("the environment image is {width}x{height} ({expected} texels) but has {got} texels")]
    SizeMismatch {
        /// Width in texels.
        width: usize,
        /// Height in texels.
        height: usize,
        /// `width * height`.
        expected: usize,
        /// The texels given.
        got: usize,
    },
    /// A texel that is not a finite, non-negative radiance.
    #[error(
        "texel ({x}, {y}) (column, row from the top) is ({}, {}, {}): expected finite, \
         non-negative linear RGB radiance",
        value[0], value[1], value[2]
    )]
    BadTexel {
        /// Column, from the left.
        x: usize,
        /// Row, from the top.
        y: usize,
        /// The texel's red, green and blue.
        value: [f32; 3],
    },
    /// A strength that is negative or not finite.
    #[error("environment strength {0}: expected a finite number >= 0")]
    BadStrength(f32),
    /// A rotation that is not finite.
    #[error("environment rotation {0}: expected a finite angle in radians")]
    BadRotation(f32),
    /// The sampling tables could not be allocated.
    #[error(
        "a {width}x{height} environment image needs {bytes} bytes for its sampling tables, \
         more than could be allocated"
    )]
    OutOfMemory {
        /// Width in texels.
        width: usize,
        /// Height in texels.
        height: usize,
        /// Bytes the tables need.
        bytes: u64,
    },
}

/// A direction drawn from an [`EnvironmentMap`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvSample {
    /// Unit direction towards the world (away from the point being lit), dofray's axes.
    pub dir: Vec3,
    /// Radiance arriving from `dir` (strength included); may be 0 at the edge of a lit cell.
    pub radiance: Vec3,
    /// Density of `dir` per unit solid angle, > 0; equal to [`EnvironmentMap::pdf`] of `dir`.
    pub pdf: f32,
}

/// An equirectangular environment: linear RGB radiance by direction, importance-sampled.
/// See the module documentation for the conventions.
#[derive(Debug, Clone)]
pub struct EnvironmentMap {
    width: usize,
    height: usize,
    /// Row-major, top row first.
    texels: Vec<Vec3>,
    strength: f32,
    rotation: f32,
    /// Cosine and sine of `rotation`.
    cos_sin: (f32, f32),
    /// Marginal CDF over rows (`height + 1` values from 0 to 1); empty when nothing emits.
    rows: Vec<f32>,
    /// The conditional CDF of each row, `width + 1` values a row.
    columns: Vec<f32>,
    /// Solid angle of one texel of each row, steradians.
    cell_solid_angle: Vec<f32>,
    /// Mean radiance over the sphere, strength included.
    average: Vec3,
}

/// The largest f32 below 1: where sample coordinates are clamped, so `u < 1` always.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

impl EnvironmentMap {
    /// A map of `width` x `height` texels (row-major, top row first, linear RGB radiance),
    /// scaled by `strength` and turned by `rotation` radians about the up axis. Refuses
    /// non-finite or negative texels (naming the first), a size that does not match the
    /// texels, and a negative or non-finite strength or rotation. Equirectangular images are
    /// normally 2:1; other shapes are accepted and stretched over the sphere as Blender does.
    pub fn new(
        width: usize,
        height: usize,
        texels: Vec<Vec3>,
        strength: f32,
        rotation: f32,
    ) -> Result<Self, EnvironmentError> {
        check(width, height, &texels, strength, rotation)?;
        let oom = EnvironmentError::OutOfMemory {
            width,
            height,
            bytes: (height as u64 * (width as u64 + 4) + 1) * 4 + width as u64 * 8,
        };
        let mut map = Self {
            width,
            height,
            texels,
            strength,
            rotation,
            cos_sin: (rotation.cos(), rotation.sin()),
            rows: Vec::new(),
            columns: Vec::new(),
            cell_solid_angle: Vec::new(),
            average: Vec3::ZERO,
        };
        let solid_angles = row_solid_angles(width, height);
        map.cell_solid_angle = solid_angles.iter().map(|&o| o as f32).collect();
        map.average = map.mean_texel(&solid_angles) * strength;
        if strength > 0.0 && map.average != Vec3::ZERO {
            map.build_distribution(&solid_angles)
                .map_err(|_| oom.clone())?;
        }
        Ok(map)
    }

    /// Width in texels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The texels, row-major, top row first (strength not applied).
    pub fn texels(&self) -> &[Vec3] {
        &self.texels
    }

    /// The factor every texel is multiplied by.
    pub fn strength(&self) -> f32 {
        self.strength
    }

    /// The rotation about the up axis, radians (Blender's Mapping node Z rotation).
    pub fn rotation(&self) -> f32 {
        self.rotation
    }

    /// Whether [`Self::sample`] can draw directions (some texel emits and the strength is
    /// not 0). A map that cannot is black: light sampling should skip it.
    pub fn can_sample(&self) -> bool {
        !self.rows.is_empty()
    }

    /// Mean radiance over the sphere, `(1 / 4pi) * integral of L over directions`, strength
    /// included: texels weighted by their solid angle. The irradiance it gives a surface
    /// open to the whole upper hemisphere is `pi` times this for a uniform world.
    pub fn average_radiance(&self) -> Vec3 {
        self.average
    }

    /// Power the world sends into a scene bounded by a sphere of `radius`: `4 pi * pi r^2`
    /// times [`Self::average_radiance`] (pbrt-v4's infinite lights' `Phi`), for weighing the
    /// world against the scene's other lights.
    pub fn power(&self, radius: f32) -> Vec3 {
        self.average * (4.0 * PI * PI * radius * radius)
    }

    /// Radiance arriving from unit direction `dir` (dofray's axes), bilinear, strength
    /// included. Non-finite directions give black.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let Some((u, t)) = self.lookup(dir) else {
            return Vec3::ZERO;
        };
        let x = u * self.width as f32 - 0.5;
        let y = t * self.height as f32 - 0.5;
        let (x0, y0) = (floor(x), floor(y));
        let (fx, fy) = (x - x0, y - y0);
        let (w, h) = (self.width as i64, self.height as i64);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |x: i64, y: i64| self.texels[(y.clamp(0, h - 1) * w + x.rem_euclid(w)) as usize];
        let top = at(x0, y0).lerp(at(x0 + 1, y0), fx);
        let bottom = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy) * self.strength
    }

    /// A direction drawn in proportion to the radiance from a uniform point `u` in [0, 1)^2
    /// (`u.y` chooses the row, `u.x` the column), with its radiance and solid-angle density;
    /// `None` for a black map.
    pub fn sample(&self, u: Vec2) -> Option<EnvSample> {
        if self.rows.is_empty() {
            return None;
        }
        let (row, p_row, t_row) = pick(&self.rows, u.y);
        let (column, p_column, t_column) = pick(self.row_cdf(row), u.x);
        let pdf = p_row * p_column / self.cell_solid_angle[row];
        let dir = self.cell_direction(column, row, t_column, t_row);
        Some(EnvSample {
            dir,
            radiance: self.radiance(dir),
            pdf,
        })
    }

    /// The solid-angle density with which [`Self::sample`] draws unit direction `dir`; 0 for
    /// a black map and for directions whose cell (and neighbours) emit nothing.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.rows.is_empty() {
            return 0.0;
        }
        let Some((u, t)) = self.lookup(dir) else {
            return 0.0;
        };
        let row = ((t * self.height as f32) as usize).min(self.height - 1);
        let column = ((u * self.width as f32) as usize) % self.width;
        let cdf = self.row_cdf(row);
        let p_row = self.rows[row + 1] - self.rows[row];
        let p_column = cdf[column + 1] - cdf[column];
        p_row * p_column / self.cell_solid_angle[row]
    }

    /// The image coordinates `u` (0 to 1 across) and `t` (0 at the top row to 1 at the
    /// bottom, `1 - v`) that unit direction `dir` looks up; `None` if not finite.
    fn lookup(&self, dir: Vec3) -> Option<(f32, f32)> {
        let b = Vec3::new(dir.x, -dir.z, dir.y);
        let (c, s) = self.cos_sin;
        let m = Vec3::new(c * b.x - s * b.y, s * b.x + c * b.y, b.z);
        let u = 0.5 - m.y.atan2(m.x) / (2.0 * PI);
        let t = m.x.hypot(m.y).atan2(m.z) / PI;
        (u.is_finite() && t.is_finite()).then_some((u, t))
    }

    /// The direction (dofray's axes) at fractions `fu` across and `fz` down (in `cos theta`)
    /// of cell (`column`, `row`). Computed in f64: cells near the poles are thin in `cos
    /// theta`.
    fn cell_direction(&self, column: usize, row: usize, fu: f32, fz: f32) -> Vec3 {
        let u = (column as f64 + fu as f64) / self.width as f64;
        let theta = |r: usize| r as f64 * PI64 / self.height as f64;
        let (z_top, z_bottom) = (theta(row).cos(), theta(row + 1).cos());
        let z = z_top + (z_bottom - z_top) * fz as f64;
        let sin_theta = (1.0 - z * z).max(0.0).sqrt();
        let phi = PI64 * (1.0 - 2.0 * u);
        let m = Vec3::new(
            (sin_theta * phi.cos()) as f32,
            (sin_theta * phi.sin()) as f32,
            z as f32,
        );
        let (c, s) = self.cos_sin;
        let b = Vec3::new(c * m.x + s * m.y, c * m.y - s * m.x, m.z);
        Vec3::new(b.x, b.z, -b.y).normalize()
    }

    /// Row `row`'s conditional CDF.
    fn row_cdf(&self, row: usize) -> &[f32] {
        let n = self.width + 1;
        &self.columns[row * n..(row + 1) * n]
    }

    /// The texels' mean over the sphere, each weighted by its solid angle.
    fn mean_texel(&self, solid_angles: &[f64]) -> Vec3 {
        let mut sum = [0.0f64; 3];
        for (row, &omega) in self.texels.chunks_exact(self.width).zip(solid_angles) {
            let mut r = [0.0f64; 3];
            for t in row {
                for c in 0..3 {
                    r[c] += t[c] as f64;
                }
            }
            for c in 0..3 {
                sum[c] += r[c] * omega;
            }
        }
        let mean = sum.map(|s| (s / (4.0 * PI64)) as f32);
        Vec3::from_array(mean)
    }

    /// Fills the marginal and conditional CDFs (see the module documentation).
    fn build_distribution(
        &mut self,
        solid_angles: &[f64],
    ) -> Result<(), std::collections::TryReserveError> {
        let (w, h) = (self.width, self.height);
        self.columns.try_reserve_exact(h * (w + 1))?;
        self.rows.try_reserve_exact(h + 1)?;
        let mut filtered = Vec::new();
        filtered.try_reserve_exact(w)?;
        filtered.resize(w, 0.0f64);
        let mut row_weights = Vec::new();
        row_weights.try_reserve_exact(h)?;
        for (row, &omega) in solid_angles.iter().enumerate() {
            let total = self.cell_weights(row, &mut filtered);
            push_cdf(&mut self.columns, &filtered, total);
            row_weights.push(total * omega);
        }
        let total: f64 = row_weights.iter().sum();
        push_cdf(&mut self.rows, &row_weights, total);
        Ok(())
    }

    /// The cell weights of row `row` into `out` (the channel average of the bilinear
    /// radiance integrated over each cell, per unit of the cell's area in the image); their
    /// sum is returned.
    fn cell_weights(&self, row: usize, out: &mut [f64]) -> f64 {
        let (w, h) = (self.width, self.height);
        let average = |x: usize, y: usize| {
            let t = self.texels[y * w + x];
            (t.x as f64 + t.y as f64 + t.z as f64) / 3.0
        };
        let (above, below) = (row.saturating_sub(1), (row + 1).min(h - 1));
        let down = |x: usize| {
            0.125 * average(x, above) + 0.75 * average(x, row) + 0.125 * average(x, below)
        };
        let mut sum = 0.0;
        for (x, o) in out.iter_mut().enumerate() {
            let (left, right) = ((x + w - 1) % w, (x + 1) % w);
            *o = 0.125 * down(left) + 0.75 * down(x) + 0.125 * down(right);
            sum += *o;
        }
        sum
    }
}

/// Validates [`EnvironmentMap::new`]'s arguments.
fn check(
    width: usize,
    height: usize,
    texels: &[Vec3],
    strength: f32,
    rotation: f32,
) -> Result<(), EnvironmentError> {
    if width == 0 || height == 0 {
        return Err(EnvironmentError::Empty { width, height });
    }
    let expected = width.saturating_mul(height);
    if texels.len() != expected {
        return Err(EnvironmentError::SizeMismatch {
            width,
            height,
            expected,
            got: texels.len(),
        });
    }
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(EnvironmentError::BadStrength(strength));
    }
    if !rotation.is_finite() {
        return Err(EnvironmentError::BadRotation(rotation));
    }
    let bad = |t: &Vec3| !(t.is_finite() && t.min_element() >= 0.0);
    if let Some(i) = texels.iter().position(bad) {
        return Err(EnvironmentError::BadTexel {
            x: i % width,
            y: i / width,
            value: texels[i].to_array(),
        });
    }
    Ok(())
}

/// The solid angle of one texel of each row: rows are equal steps of `theta` from the top
/// (`theta = 0`, up) down, so a texel of row `r` spans `2pi / width` in azimuth and
/// `cos(r pi / h) - cos((r + 1) pi / h)` in `cos theta`, written as a product of sines to
/// keep its precision near the poles.
fn row_solid_angles(width: usize, height: usize) -> Vec<f64> {
    let step = PI64 / height as f64;
    (0..height)
        .map(|r| {
            let dz = 2.0 * ((r as f64 + 0.5) * step).sin() * (0.5 * step).sin();
            2.0 * PI64 / width as f64 * dz
        })
        .collect()
}

/// Appends the normalised CDF of `weights` (summing to `total`): `weights.len() + 1` values
/// from 0 to exactly 1, or all 0 when `total` is 0.
fn push_cdf(out: &mut Vec<f32>, weights: &[f64], total: f64) {
    out.push(0.0);
    if total <= 0.0 {
        out.extend(weights.iter().map(|_| 0.0));
        return;
    }
    let mut sum = 0.0;
    for &w in &weights[..weights.len() - 1] {
        sum += w;
        out.push((sum / total).min(1.0) as f32);
    }
    out.push(1.0);
}

/// The interval of `cdf` (from 0 to 1) that `u` falls in: its index, its probability (> 0)
/// and where in it `u` is (0 to 1).
fn pick(cdf: &[f32], u: f32) -> (usize, f32, f32) {
    let u = u.clamp(0.0, ONE_MINUS_EPSILON);
    let i = (cdf.partition_point(|&c| c <= u) - 1).min(cdf.len() - 2);
    let p = cdf[i + 1] - cdf[i];
    let t = ((u - cdf[i]) / p).clamp(0.0, ONE_MINUS_EPSILON);
    (i, p, t)
}

/// A direction uniform over the sphere from a uniform point `u` in [0, 1)^2, and its density
/// `1 / 4pi`: for a world of one colour.
pub fn uniform_sphere(u: Vec2) -> (Vec3, f32) {
    let y = 1.0 - 2.0 * u.x;
    let r = (1.0 - y * y).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    (Vec3::new(r * phi.cos(), y, r * phi.sin()), 1.0 / (4.0 * PI))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic uniform generator for the tests (SplitMix64).
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 += 1;
            (crate::sampler::hash64(self.0) >> 40) as f32 / (1u64 << 24) as f32
        }

        fn point(&mut self) -> Vec2 {
            Vec2::new(self.next(), self.next())
        }
    }

    fn map(width: usize, height: usize, texel: impl Fn(usize, usize) -> Vec3) -> Vec<Vec3> {
        (0..width * height)
            .map(|i| texel(i % width, i / width))
            .collect()
    }

    /// A sky brightening towards the top, one very bright texel (the sun) and a black
    /// lower half, turned by `rotation`.
    fn sky_with_sun(rotation: f32) -> EnvironmentMap {
        let (w, h) = (64, 32);
        let texels = map(w, h, |x, y| match (x, y) {
            (40, 9) => Vec3::new(20000.0, 18000.0, 15000.0),
            (_, y) if y < h / 2 => Vec3::new(0.2, 0.4, 1.0) * (1.0 - y as f32 / h as f32),
            _ => Vec3::ZERO,
        });
        EnvironmentMap::new(w, h, texels, 1.5, rotation).unwrap()
    }

    /// A sky brightening towards the top with a dimmer lower half, turned by `rotation`.
    fn sky(rotation: f32) -> EnvironmentMap {
        let (w, h) = (32, 16);
        let texels = map(w, h, |x, y| match (x, y) {
            (20..=22, 4..=6) => Vec3::new(40.0, 30.0, 20.0),
            (_, y) if y < h / 2 => Vec3::new(0.2, 0.4, 1.0) * (1.0 - y as f32 / h as f32),
            _ => Vec3::splat(0.05),
        });
        EnvironmentMap::new(w, h, texels, 1.0, rotation).unwrap()
    }

    /// The sum of the pdf times the solid angle over the cells of `m`, the pdf taken at each
    /// cell's centre: exact for a density constant over each cell. The centres are placed by
    /// Blender's formula and rotation (inverted here, independently of the map's code).
    fn sum_over_cells(m: &EnvironmentMap) -> f64 {
        let (w, h) = (m.width(), m.height());
        let mut sum = 0.0;
        for j in 0..h {
            let (t0, t1) = (j as f64 * PI64 / h as f64, (j + 1) as f64 * PI64 / h as f64);
            let omega = 2.0 * PI64 / w as f64 * (t0.cos() - t1.cos());
            let theta = 0.5 * (t0 + t1);
            for i in 0..w {
                // u = 0.5 - atan2(b.y, b.x) / 2pi, theta from Blender's +Z.
                let phi = PI64 * (1.0 - 2.0 * (i as f64 + 0.5) / w as f64);
                let lookup = [
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ];
                let (c, s) = ((m.rotation() as f64).cos(), (m.rotation() as f64).sin());
                // The lookup vector is Rz(rotation) b.
                let b = [
                    c * lookup[0] + s * lookup[1],
                    c * lookup[1] - s * lookup[0],
                    lookup[2],
                ];
                let d = Vec3::new(b[0] as f32, b[2] as f32, -b[1] as f32);
                sum += m.pdf(d) as f64 * omega;
            }
        }
        sum
    }

    /// Integral of `f` over the sphere by the midpoint rule on an `n` x `2n` grid in
    /// (`y` = cos of the angle from up, azimuth), where the solid angle is uniform.
    fn integrate(n: usize, f: impl Fn(Vec3) -> f64) -> f64 {
        let mut sum = 0.0;
        for i in 0..n {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            for j in 0..2 * n {
                let phi = PI64 * (j as f64 + 0.5) / n as f64;
                sum += f(Vec3::new(
                    (r * phi.cos()) as f32,
                    y as f32,
                    (r * phi.sin()) as f32,
                ));
            }
        }
        sum * 4.0 * PI64 / (2 * n * n) as f64
    }

    #[test]
    fn the_pdf_integrates_to_one_and_matches_the_samples() {
        let maps = [
            sky(1.0),
            sky_with_sun(1.0),
            EnvironmentMap::new(1, 4, map(1, 4, |_, y| Vec3::splat(y as f32)), 1.0, 0.0).unwrap(),
            EnvironmentMap::new(5, 1, map(5, 1, |x, _| Vec3::splat(x as f32)), 1.0, 0.3).unwrap(),
            EnvironmentMap::new(1, 1, vec![Vec3::ONE], 2.0, 0.0).unwrap(),
        ];
        for (k, m) in maps.iter().enumerate() {
            // Exact for a density constant over each cell; a grid that ignores the cells
            // converges slowly where a bright cell's edges cut it, hence its tolerance.
            let cells = sum_over_cells(m);
            assert!((cells - 1.0).abs() < 1e-4, "map {k}: {cells}");
            let grid = integrate(600, |d| m.pdf(d) as f64);
            assert!((grid - 1.0).abs() < 1e-2, "map {k}: {grid}");
            let mut rng = Rng(k as u64);
            let mut agree = 0;
            for _ in 0..20_000 {
                let s = m.sample(rng.point()).unwrap();
                assert!((s.dir.length() - 1.0).abs() < 1e-5, "{s:?}");
                assert!(s.pdf > 0.0 && s.pdf.is_finite(), "{s:?}");
                assert_eq!(s.radiance, m.radiance(s.dir));
                if (m.pdf(s.dir) - s.pdf).abs() <= 1e-4 * s.pdf {
                    agree += 1;
                }
            }
            // Directions that round onto a cell border may be looked up in the neighbour.
            assert!(agree >= 19_980, "map {k}: {agree} of 20000 agree");
        }
    }

    #[test]
    fn sample_counts_follow_the_pdf() {
        let m = sky(0.4);
        // Bins: 6 in azimuth x 4 in y, unrelated to the texel grid.
        let bin = |d: Vec3| {
            let a = ((d.z.atan2(d.x) / (2.0 * PI) + 0.5) * 6.0) as usize;
            let b = ((1.0 - d.y) * 2.0) as usize;
            a.min(5) + 6 * b.min(3)
        };
        let mut expected = [0.0f64; 24];
        let n = 800;
        for i in 0..n {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            for j in 0..2 * n {
                let phi = PI64 * (j as f64 + 0.5) / n as f64;
                let d = Vec3::new((r * phi.cos()) as f32, y as f32, (r * phi.sin()) as f32);
                expected[bin(d)] += m.pdf(d) as f64 * 4.0 * PI64 / (2 * n * n) as f64;
            }
        }
        let samples = 200_000;
        let mut counts = [0u32; 24];
        let mut rng = Rng(7);
        for _ in 0..samples {
            counts[bin(m.sample(rng.point()).unwrap().dir)] += 1;
        }
        for (b, (&c, &p)) in counts.iter().zip(&expected).enumerate() {
            let mean = p * samples as f64;
            let sigma = mean.max(1.0).sqrt();
            assert!(
                (c as f64 - mean).abs() < 5.0 * sigma + 0.002 * mean,
                "bin {b}: {c} samples, expected {mean:.1}"
            );
        }
        assert!(expected.iter().filter(|&&p| p > 0.0).count() >= 12);
    }

    /// Mean and standard error of `n` values of `f`.
    fn estimate(n: usize, mut f: impl FnMut() -> f64) -> (f64, f64) {
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let v = f();
            s += v;
            s2 += v * v;
        }
        let mean = s / n as f64;
        (mean, ((s2 / n as f64 - mean * mean) / n as f64).sqrt())
    }

    #[test]
    fn irradiance_by_importance_and_by_uniform_sampling_agree() {
        let m = sky_with_sun(0.0);
        let lum = |c: Vec3| c.dot(Vec3::ONE) as f64 / 3.0;
        // E on an upward-facing plane: the integral of L cos over the upper hemisphere.
        let quadrature = integrate(1500, |d| lum(m.radiance(d)) * d.y.max(0.0) as f64);
        let mut rng = Rng(11);
        let (importance, se_i) = estimate(50_000, || {
            let s = m.sample(rng.point()).unwrap();
            lum(s.radiance) * s.dir.y.max(0.0) as f64 / s.pdf as f64
        });
        let (uniform, se_u) = estimate(400_000, || {
            let (d, pdf) = uniform_sphere(rng.point());
            lum(m.radiance(d)) * d.y.max(0.0) as f64 / pdf as f64
        });
        let noise = (se_i * se_i + se_u * se_u).sqrt();
        assert!(
            (importance - uniform).abs() < 4.0 * noise,
            "importance {importance} +- {se_i}, uniform {uniform} +- {se_u}"
        );
        assert!(
            (importance - quadrature).abs() < 4.0 * se_i + 2e-3 * quadrature,
            "importance {importance} +- {se_i}, quadrature {quadrature}"
        );
        // The sun is most of the light; importance sampling finds it (per sample, far less
        // noise than uniform sampling).
        let per_sample = |se: f64, n: f64| se * n.sqrt();
        assert!(per_sample(se_i, 5e4) * 10.0 < per_sample(se_u, 4e5));
    }

    #[test]
    fn a_uniform_map_is_sampled_uniformly() {
        let c = Vec3::new(0.5, 1.0, 2.0);
        let m = EnvironmentMap::new(7, 3, vec![c; 21], 3.0, 0.7).unwrap();
        let mut rng = Rng(3);
        let quarter_pi = 1.0 / (4.0 * PI);
        for _ in 0..5000 {
            let (d, _) = uniform_sphere(rng.point());
            assert!((m.pdf(d) - quarter_pi).abs() < 1e-5 * quarter_pi, "{d}");
            assert!((m.radiance(d) - 3.0 * c).abs().max_element() < 1e-5);
            let s = m.sample(rng.point()).unwrap();
            assert!((s.pdf - quarter_pi).abs() < 1e-5 * quarter_pi);
        }
        assert!((m.average_radiance() - 3.0 * c).abs().max_element() < 1e-5);
        let r = 2.0;
        let power = m.power(r);
        assert!(
            (power - 3.0 * c * 4.0 * PI * PI * r * r)
                .abs()
                .max_element()
                < 1e-3
        );
    }

    /// An 8 x 5 map whose equator (row 2) is red around its centre column (u = 0.5), green
    /// around u = 0.25, blue around u = 0.75 and white across the seam; the top row is
    /// yellow and the bottom row cyan.
    fn compass(rotation: f32) -> EnvironmentMap {
        let red = Vec3::X;
        let green = Vec3::Y;
        let blue = Vec3::Z;
        let texels = map(8, 5, |x, y| match (y, x) {
            (0, _) => Vec3::new(1.0, 1.0, 0.0),
            (4, _) => Vec3::new(0.0, 1.0, 1.0),
            (2, 3 | 4) => red,
            (2, 1 | 2) => green,
            (2, 5 | 6) => blue,
            (2, 7 | 0) => Vec3::ONE,
            _ => Vec3::ZERO,
        });
        EnvironmentMap::new(8, 5, texels, 1.0, rotation).unwrap()
    }

    fn assert_close(a: Vec3, b: Vec3, what: &str) {
        assert!((a - b).abs().max_element() < 1e-5, "{what}: {a} != {b}");
    }

    #[test]
    fn the_mapping_is_blenders() {
        let m = compass(0.0);
        // Blender +X (dofray +X) sees the centre column, Blender +Y (dofray -Z) the left
        // quarter, Blender -Y (dofray +Z) the right quarter, Blender -X the seam.
        assert_close(m.radiance(Vec3::X), Vec3::X, "+X");
        assert_close(m.radiance(-Vec3::Z), Vec3::Y, "-Z");
        assert_close(m.radiance(Vec3::Z), Vec3::Z, "+Z");
        assert_close(m.radiance(-Vec3::X), Vec3::ONE, "-X");
        assert_close(m.radiance(Vec3::Y), Vec3::new(1.0, 1.0, 0.0), "up");
        assert_close(m.radiance(-Vec3::Y), Vec3::new(0.0, 1.0, 1.0), "down");
        // Halfway between two texel centres the lookup blends them.
        let between = Vec3::new(1.0, 0.0, -1.0).normalize(); // u = 3/8: texels 2 and 3.
        assert_close(m.radiance(between), Vec3::new(0.5, 0.5, 0.0), "between");
    }

    #[test]
    fn a_quarter_turn_moves_the_picture_clockwise_seen_from_above() {
        // Blender's Mapping node rotates the lookup vector by +90 degrees about up: what was
        // at Blender +X (red) is now seen at Blender -Y (dofray +Z), what was at Blender +Y
        // (green, dofray -Z) at Blender +X.
        let m = compass(std::f32::consts::FRAC_PI_2);
        assert_close(m.radiance(Vec3::Z), Vec3::X, "+Z");
        assert_close(m.radiance(Vec3::X), Vec3::Y, "+X");
        assert_close(m.radiance(-Vec3::Z), Vec3::ONE, "-Z");
        assert_close(m.radiance(-Vec3::X), Vec3::Z, "-X");
        assert_close(m.radiance(Vec3::Y), Vec3::new(1.0, 1.0, 0.0), "up");
        // Sampling turns with the picture: samples of a light around the centre column, just
        // below the equator, arrive from around +Z.
        let light = map(32, 16, |x, y| {
            if y == 8 && (15..=16).contains(&x) {
                Vec3::X
            } else {
                Vec3::ZERO
            }
        });
        let m = EnvironmentMap::new(32, 16, light, 1.0, std::f32::consts::FRAC_PI_2).unwrap();
        let mut rng = Rng(5);
        for _ in 0..1000 {
            let s = m.sample(rng.point()).unwrap();
            assert!(s.dir.z > 0.85, "{s:?}");
        }
    }

    #[test]
    fn black_maps_cannot_be_sampled() {
        let black = EnvironmentMap::new(4, 2, vec![Vec3::ZERO; 8], 1.0, 0.0).unwrap();
        let dark = EnvironmentMap::new(4, 2, vec![Vec3::ONE; 8], 0.0, 0.0).unwrap();
        for m in [black, dark] {
            assert!(!m.can_sample());
            assert!(m.sample(Vec2::new(0.3, 0.6)).is_none());
            assert_eq!(m.pdf(Vec3::Y), 0.0);
            assert_eq!(m.radiance(Vec3::X), Vec3::ZERO);
            assert_eq!(m.average_radiance(), Vec3::ZERO);
        }
        // A texel of zero radiance far from any light has density 0; one next to a light
        // does not (the bilinear lookup reaches into it).
        let texels = map(8, 4, |x, y| {
            if (x, y) == (2, 1) {
                Vec3::ONE
            } else {
                Vec3::ZERO
            }
        });
        let m = EnvironmentMap::new(8, 4, texels, 1.0, 0.0).unwrap();
        assert!(m.can_sample());
        assert_eq!(m.pdf(Vec3::X), 0.0);
        assert_eq!(m.radiance(Vec3::X), Vec3::ZERO);
        let mut rng = Rng(9);
        for _ in 0..20_000 {
            let (d, _) = uniform_sphere(rng.point());
            assert!(m.radiance(d) == Vec3::ZERO || m.pdf(d) > 0.0, "{d}");
        }
    }

    #[test]
    fn bad_maps_are_refused_naming_the_texel() {
        let mut texels = vec![Vec3::ONE; 12];
        texels[6] = Vec3::new(1.0, f32::NAN, 0.0);
        let e = EnvironmentMap::new(4, 3, texels.clone(), 1.0, 0.0).unwrap_err();
        assert!(
            matches!(e, EnvironmentError::BadTexel { x: 2, y: 1, .. }),
            "{e:?}"
        );
        assert!(e.to_string().contains("texel (2, 1)"), "{e}");
        assert!(e.to_string().contains("finite, non-negative"), "{e}");
        texels[6] = Vec3::new(f32::INFINITY, 0.0, 0.0);
        assert!(EnvironmentMap::new(4, 3, texels.clone(), 1.0, 0.0).is_err());
        texels[6] = Vec3::new(0.0, 0.0, -1e-3);
        let e = EnvironmentMap::new(4, 3, texels.clone(), 1.0, 0.0).unwrap_err();
        assert!(e.to_string().contains("-0.001"), "{e}");
        texels[6] = Vec3::ONE;
        let ok = |w, h, s, r| EnvironmentMap::new(w, h, texels.clone(), s, r).map(|_| ());
        assert_eq!(ok(4, 3, 1.0, 0.0), Ok(()));
        assert!(matches!(
            ok(5, 3, 1.0, 0.0),
            Err(EnvironmentError::SizeMismatch { .. })
        ));
        assert!(matches!(
            ok(0, 3, 1.0, 0.0),
            Err(EnvironmentError::Empty { .. })
        ));
        assert!(matches!(
            ok(4, 3, -1.0, 0.0),
            Err(EnvironmentError::BadStrength(_))
        ));
        assert!(matches!(
            ok(4, 3, f32::NAN, 0.0),
            Err(EnvironmentError::BadStrength(_))
        ));
        assert!(matches!(
            ok(4, 3, 1.0, f32::INFINITY),
            Err(EnvironmentError::BadRotation(_))
        ));
    }
}
