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
    #[error(
        "the environment image is {width}x{height} ({expected} texels) but has {got} texels"
    )]
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
        let at = |x: i64, y: i64| {
            self.texels[(y.clamp(0, h - 1) * w + x.rem_euclid(w)) as usize]
        };
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
        for row in 0..h {
            let total = self.cell_weights(row, &mut filtered);
            push_cdf(&mut self.columns, &filtered, total);
            row_weights.push(total * solid_angles[row]);
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
    let expected = width.checked_mul(height).unwrap_or(usize::MAX);
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
    (
        Vec3::new(r * phi.cos(), y, r * phi.sin()),
        1.0 / (4.0 * PI),
    )
}
