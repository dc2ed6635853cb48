//! Samples of pixel x lens: Owen-scrambled 4D Sobol points, deterministic from
//! (seed, pixel, sample index). This module only makes numbers in [0, 1); the lens maps its
//! pair onto the aperture (`camera::aperture`).
//!
//! Dimensions 0 and 1 (the lens position) form a (0,2)-sequence: any power-of-two prefix of 16
//! points is stratified in every 2^a x 2^b elementary interval of area 1/16, so one 16-sample
//! packet covers the aperture evenly. Dimensions 2 and 3 (the position within the pixel, which
//! the pixel filter warps) are Sobol dimensions 3 and 4 of Joe and Kuo's direction numbers, so
//! the four together are jointly stratified: every coordinate of 16 points in 16 strata, the
//! pixel pair a (0,2)-sequence like the lens pair, and the pixel's x stratified against both
//! lens coordinates (4 x 4). Each pixel scrambles every
//! dimension with its own hash-derived seed (Burley 2020, "Practical Hash-based Owen
//! Scrambling"), so neighbouring pixels' patterns are uncorrelated and no image depends on
//! thread count or tile order.

use glam::Vec2;

/// A 64-bit mix (SplitMix64's finaliser): a good hash for small structured inputs.
pub fn hash64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// First Sobol dimension: the van der Corput sequence in base 2.
fn sobol0(i: u32) -> u32 {
    i.reverse_bits()
}

/// Second Sobol dimension (its generator matrix is Pascal's triangle mod 2).
const fn sobol1(mut i: u32) -> u32 {
    let mut v = 1u32 << 31;
    let mut r = 0;
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// `sobol1` of each byte of an index in each of its four places: as Sobol dimensions are
/// linear over GF(2) in the index's bits, `sobol1(i)` is the XOR of four lookups
/// ([`sobol1_bytes`]), for the full 32-bit indices the path dimensions' shuffles make.
const SOBOL1_BYTES: [[u32; 256]; 4] = {
    let mut t = [[0u32; 256]; 4];
    let mut place = 0;
    while place < 4 {
        let mut b = 0;
        while b < 256 {
            t[place][b] = sobol1((b as u32) << (8 * place));
            b += 1;
        }
        place += 1;
    }
    t
};

/// [`sobol1`] by table.
#[inline]
fn sobol1_bytes(i: u32) -> u32 {
    SOBOL1_BYTES[0][(i & 0xff) as usize]
        ^ SOBOL1_BYTES[1][((i >> 8) & 0xff) as usize]
        ^ SOBOL1_BYTES[2][((i >> 16) & 0xff) as usize]
        ^ SOBOL1_BYTES[3][(i >> 24) as usize]
}

/// Direction numbers of a Sobol dimension from its primitive polynomial (degree `s`, inner
/// coefficients `a`) and initial values `m` (Bratley and Fox's recurrence, as in Joe and Kuo's
/// tables): point `i` is the XOR of `v[k]` over the set bits `k` of `i`.
const fn directions(s: usize, a: u32, m: [u32; 3]) -> [u32; 32] {
    let mut v = [0u32; 32];
    let mut k = 0;
    while k < 32 {
        if k < s {
            v[k] = m[k] << (31 - k);
        } else {
            let mut x = v[k - s] ^ (v[k - s] >> s);
            let mut j = 1;
            while j < s {
                if (a >> (s - 1 - j)) & 1 != 0 {
                    x ^= v[k - j];
                }
                j += 1;
            }
            v[k] = x;
        }
        k += 1;
    }
    v
}

/// Joe and Kuo's dimensions 3 (x^2 + x + 1; m = 1, 3) and 4 (x^3 + x + 1; m = 1, 3, 1).
const SOBOL2_DIRECTIONS: [u32; 32] = directions(2, 1, [1, 3, 0]);
const SOBOL3_DIRECTIONS: [u32; 32] = directions(3, 1, [1, 3, 1]);

const fn sobol_with(directions: &[u32; 32], mut i: u32) -> u32 {
    let mut r = 0;
    let mut k = 0;
    while i != 0 {
        if i & 1 != 0 {
            r ^= directions[k];
        }
        i >>= 1;
        k += 1;
    }
    r
}

/// `sobol_with(directions, i)` bit-reversed for i in 0..16 (see [`SOBOL1_LOW_REVERSED`]).
const fn low_reversed(directions: &[u32; 32]) -> [u32; 16] {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        t[i] = sobol_with(directions, i as u32).reverse_bits();
        i += 1;
    }
    t
}

const SOBOL2_LOW_REVERSED: [u32; 16] = low_reversed(&SOBOL2_DIRECTIONS);
const SOBOL3_LOW_REVERSED: [u32; 16] = low_reversed(&SOBOL3_DIRECTIONS);

/// `sobol1(i)` bit-reversed for i in 0..16. Sobol dimensions are linear over GF(2) in the
/// bits of the index, so `sobol1(base | i) == sobol1(base) ^ sobol1(i)` when base's low four
/// bits are zero: one packet of 16 samples needs one full `sobol1` and 16 table lookups.
const SOBOL1_LOW_REVERSED: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        t[i] = sobol1(i as u32).reverse_bits();
        i += 1;
    }
    t
};

/// Samples per [`PixelSampler::get16`] call.
pub const BATCH: usize = 16;

#[inline]
fn laine_karras(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// Nested uniform (Owen) scrambling of a 32-bit fixed-point coordinate.
fn owen_scramble(x: u32, seed: u32) -> u32 {
    laine_karras(x.reverse_bits(), seed).reverse_bits()
}

#[inline]
fn to_unit(x: u32) -> f32 {
    // 24 bits keep the result strictly below 1.0 in f32 (and fit an i32, whose conversion
    // vectorises; the value is the same as converting the u32).
    ((x >> 8) as i32) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Samples `first .. first + 16` of `sample` one at a time, as structure of arrays: the
/// batched paths' fallback for a `first` that is not a multiple of 16.
fn one_by_one(first: u32, sample: impl Fn(u32) -> Vec2) -> ([f32; BATCH], [f32; BATCH]) {
    let mut u = [0.0f32; BATCH];
    let mut v = [0.0f32; BATCH];
    for lane in 0..BATCH {
        let p = sample(first.wrapping_add(lane as u32));
        (u[lane], v[lane]) = (p.x, p.y);
    }
    (u, v)
}

/// The sample stream of one pixel: point `i` of an Owen-scrambled 4D Sobol sequence, whose
/// dimensions 0 and 1 place the sample on the lens and 2 and 3 within the pixel.
#[derive(Debug, Clone, Copy)]
pub struct PixelSampler {
    seed_x: u32,
    seed_y: u32,
    seed_px: u32,
    seed_py: u32,
}

impl PixelSampler {
    /// The stream for pixel `pixel` (any unique index, e.g. `y * width + x`) of image seed `seed`.
    pub fn new(seed: u64, pixel: u64) -> Self {
        let h = hash64(hash64(seed) ^ pixel);
        let h2 = hash64(h);
        Self {
            seed_x: h as u32,
            seed_y: (h >> 32) as u32,
            seed_px: h2 as u32,
            seed_py: (h2 >> 32) as u32,
        }
    }

    /// The lens coordinates of sample `i`, in [0, 1)^2.
    pub fn get(&self, i: u32) -> Vec2 {
        Vec2::new(
            to_unit(owen_scramble(sobol0(i), self.seed_x)),
            to_unit(owen_scramble(sobol1(i), self.seed_y)),
        )
    }

    /// The pixel coordinates of sample `i`, in [0, 1)^2 (Sobol dimensions 2 and 3).
    pub fn get_pixel(&self, i: u32) -> Vec2 {
        Vec2::new(
            to_unit(owen_scramble(
                sobol_with(&SOBOL2_DIRECTIONS, i),
                self.seed_px,
            )),
            to_unit(owen_scramble(
                sobol_with(&SOBOL3_DIRECTIONS, i),
                self.seed_py,
            )),
        )
    }

    /// [`PixelSampler::get_pixel`] of samples `first .. first + 16` as structure of arrays,
    /// bit for bit; `first` must be a multiple of 16 (other values fall back to `get_pixel`).
    pub fn get_pixel16(&self, first: u32) -> ([f32; BATCH], [f32; BATCH]) {
        if first % BATCH as u32 != 0 {
            return one_by_one(first, |i| self.get_pixel(i));
        }
        let mut u = [0.0f32; BATCH];
        let mut v = [0.0f32; BATCH];
        // Sobol points are linear in the index bits: the high part once, the low 4 bits from
        // tables, all bit-reversed as the scramble wants them.
        let high_x = sobol_with(&SOBOL2_DIRECTIONS, first).reverse_bits();
        let high_y = sobol_with(&SOBOL3_DIRECTIONS, first).reverse_bits();
        for lane in 0..BATCH {
            let x = laine_karras(high_x ^ SOBOL2_LOW_REVERSED[lane], self.seed_px);
            let y = laine_karras(high_y ^ SOBOL3_LOW_REVERSED[lane], self.seed_py);
            u[lane] = to_unit(x.reverse_bits());
            v[lane] = to_unit(y.reverse_bits());
        }
        (u, v)
    }

    /// Samples `first .. first + 16` as structure of arrays (x coordinates, y coordinates),
    /// bit for bit equal to [`PixelSampler::get`] of each index. `first` must be a multiple of
    /// 16 (other values fall back to `get`).
    pub fn get16(&self, first: u32) -> ([f32; BATCH], [f32; BATCH]) {
        if first % BATCH as u32 != 0 {
            return one_by_one(first, |i| self.get(i));
        }
        let mut u = [0.0f32; BATCH];
        let mut v = [0.0f32; BATCH];
        // owen_scramble(sobol0(i)) = reverse(laine_karras(i)): sobol0 is a bit reversal.
        let high_y = sobol1(first).reverse_bits();
        for lane in 0..BATCH {
            let x = laine_karras(first | lane as u32, self.seed_x);
            let y = laine_karras(high_y ^ SOBOL1_LOW_REVERSED[lane], self.seed_y);
            u[lane] = to_unit(x.reverse_bits());
            v[lane] = to_unit(y.reverse_bits());
        }
        (u, v)
    }
}

/// Which sample a path belongs to: what [`path_numbers`] draws its decisions from, so a
/// sample's path is the same whatever packet, thread or tile traces it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SampleKey {
    /// A hash of (seed, pixel): scrambles and shuffles the pixel's sequences.
    pixel: u64,
    /// The sample's index within its pixel.
    sample: u32,
}

/// The key of sample `sample` of pixel `pixel` under `seed`.
pub fn sample_key(seed: u64, pixel: u64, sample: u32) -> SampleKey {
    SampleKey {
        pixel: hash64(hash64(seed ^ 0x5bd1_e995) ^ hash64(pixel)),
        sample,
    }
}

/// How many numbers [`path_numbers`] gives per bounce.
pub const PATH_DIMENSIONS: usize = 10;

/// Uniform numbers in [0, 1) for the decisions a path makes at bounce `bounce`: 0 the light
/// choice, 1-2 the point on the light, 3 the BSDF lobe, 4-5 its direction, 6 Russian roulette,
/// 8-9 a direction towards the world.
///
/// The pairs (1, 2), (4, 5), (8, 9) are each an Owen-scrambled 2D Sobol (0,2)-sequence over
/// the pixel's samples, and the other dimensions a scrambled van der Corput sequence: any
/// power-of-two prefix of a pixel's samples spreads its light points and BSDF directions
/// evenly at every bounce, as Cycles' Sobol-Burley does. Each group's sample order is shuffled
/// by its own nested uniform scramble of the index (Burley 2020, "Practical Hash-based Owen
/// Scrambling"), which keeps each prefix a block of the sequence (so still stratified) while
/// decorrelating the groups from each other, from other bounces and from the lens and film
/// dimensions.
pub fn path_numbers(key: SampleKey, bounce: u32) -> [f32; PATH_DIMENSIONS] {
    let base = hash64(key.pixel ^ u64::from(bounce).wrapping_mul(0xd6e8_feb8_6659_fd93));
    let mut out = [0.0f32; PATH_DIMENSIONS];
    // One shuffled, scrambled stream per group of dimensions: a pair or a single.
    let stream = |group: u64| {
        let h = hash64(base.wrapping_add(group));
        let index = owen_scramble(key.sample, h as u32);
        let sx = (h >> 32) as u32;
        (
            index,
            sx,
            sx.wrapping_mul(0x9e37_79b9) ^ (h as u32).rotate_left(16),
        )
    };
    for (group, d) in [(0u64, 1usize), (1, 4), (2, 8)] {
        let (i, sx, sy) = stream(group);
        out[d] = to_unit(owen_scramble(sobol0(i), sx));
        out[d + 1] = to_unit(owen_scramble(sobol1_bytes(i), sy));
    }
    for (group, d) in [(3u64, 0usize), (4, 3), (5, 6), (6, 7)] {
        let (i, sx, _) = stream(group);
        out[d] = to_unit(owen_scramble(sobol0(i), sx));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table-driven second dimension equals the bit-by-bit one.
    #[test]
    fn sobol1_by_bytes_equals_sobol1() {
        let mut i = 1u32;
        for _ in 0..100_000 {
            assert_eq!(sobol1_bytes(i), sobol1(i), "index {i}");
            i = i.wrapping_mul(0x9e37_79b9).wrapping_add(12345);
        }
    }

    /// At every bounce, 16 samples of a pixel put their light points, BSDF directions and world
    /// directions in every elementary interval of area 1/16 once, and every single dimension in
    /// each sixteenth once; the 32 after them too; and different dimension pairs are not
    /// correlated (what the shuffles are for).
    #[test]
    fn path_dimensions_are_stratified_per_pixel_and_decorrelated() {
        let strata = |pts: &[(f32, f32)], shapes: &[(u32, u32)]| {
            for &(cols, rows) in shapes {
                let mut seen = vec![0; 16];
                for &(x, y) in pts {
                    seen[((y * rows as f32) as u32 * cols + (x * cols as f32) as u32) as usize] +=
                        1;
                }
                let per = pts.len() / 16;
                assert!(seen.iter().all(|&c| c == per), "{cols}x{rows}: {seen:?}");
            }
        };
        let mut cross = 0.0f64;
        let mut n = 0;
        for pixel in 0..40u64 {
            for bounce in [0u32, 1, 5] {
                for range in [0..16u32, 16..48] {
                    let numbers: Vec<_> = range
                        .map(|s| path_numbers(sample_key(3, pixel, s), bounce))
                        .collect();
                    for d in [1, 4, 8] {
                        let pts: Vec<_> = numbers.iter().map(|u| (u[d], u[d + 1])).collect();
                        strata(&pts, &[(16, 1), (8, 2), (4, 4), (2, 8), (1, 16)]);
                    }
                    for d in [0, 3, 6, 7] {
                        let pts: Vec<_> = numbers.iter().map(|u| (u[d], 0.0)).collect();
                        strata(&pts, &[(16, 1)]);
                    }
                    for u in &numbers {
                        cross += f64::from((u[1] - 0.5) * (u[4] - 0.5));
                        n += 1;
                    }
                }
            }
        }
        // Independent uniforms: mean 0, standard deviation 1/12 / sqrt(n) = 0.0007 here.
        assert!((cross / n as f64).abs() < 0.003, "{}", cross / n as f64);
    }

    #[test]
    fn sixteen_samples_are_stratified_in_every_elementary_interval() {
        for pixel in 0..50u64 {
            let s = PixelSampler::new(7, pixel);
            let pts: Vec<Vec2> = (0..16).map(|i| s.get(i)).collect();
            for (cols, rows) in [(16u32, 1u32), (8, 2), (4, 4), (2, 8), (1, 16)] {
                let mut seen = vec![0; 16];
                for p in &pts {
                    let cx = (p.x * cols as f32) as u32;
                    let cy = (p.y * rows as f32) as u32;
                    seen[(cy * cols + cx) as usize] += 1;
                }
                assert!(
                    seen.iter().all(|&c| c == 1),
                    "pixel {pixel}, {cols}x{rows}: {seen:?}"
                );
            }
        }
    }

    /// The direction-number recurrence reproduces the hand-written second dimension, and the
    /// generated dimensions have Joe and Kuo's first points.
    #[test]
    fn generated_directions_match_known_sobol_points() {
        let pascal = directions(1, 0, [1, 0, 0]);
        for i in 0..4096 {
            assert_eq!(sobol_with(&pascal, i), sobol1(i), "index {i}");
        }
        // Points 1..4 worked out by hand from the direction numbers: dimension 3 has
        // v = .1, .11, .011 (binary), dimension 4 has v = .1, .11, .001.
        let unit = |x: u32| x as f64 / 2f64.powi(32);
        let d3: Vec<f64> = (1..5)
            .map(|i| unit(sobol_with(&SOBOL2_DIRECTIONS, i)))
            .collect();
        let d4: Vec<f64> = (1..5)
            .map(|i| unit(sobol_with(&SOBOL3_DIRECTIONS, i)))
            .collect();
        assert_eq!(d3, [0.5, 0.75, 0.25, 0.375]);
        assert_eq!(d4, [0.5, 0.75, 0.25, 0.125]);
    }

    /// 16 samples of pixel x lens: every coordinate alone in 16 strata, the pixel pair (like
    /// the lens pair) in every elementary interval of 16, and both lens coordinates against
    /// the pixel's x in a 4 x 4 grid. (No choice among Joe and Kuo's first eight dimensions
    /// also stratifies the pixel's y against both lens coordinates while keeping the pixel
    /// pair a (0,2)-sequence.)
    #[test]
    fn sixteen_samples_are_jointly_stratified_over_pixel_and_lens() {
        for pixel in 0..50u64 {
            let s = PixelSampler::new(3, pixel);
            let pts: Vec<[f32; 4]> = (0..16)
                .map(|i| {
                    let (l, p) = (s.get(i), s.get_pixel(i));
                    [l.x, l.y, p.x, p.y]
                })
                .collect();
            let strata = |a: usize, na: u32, b: usize, nb: u32| {
                let mut seen = vec![0; (na * nb) as usize];
                for p in &pts {
                    let ca = (p[a] * na as f32) as u32;
                    let cb = (p[b] * nb as f32) as u32;
                    seen[(cb * na + ca) as usize] += 1;
                }
                seen.iter().all(|&c| c == 1)
            };
            for d in 0..4 {
                assert!(strata(d, 16, d, 1), "pixel {pixel}, dimension {d}");
            }
            for (cols, rows) in [(16u32, 1u32), (8, 2), (4, 4), (2, 8), (1, 16)] {
                assert!(strata(2, cols, 3, rows), "pixel {pixel}: {cols}x{rows}");
            }
            for (a, b) in [(0, 2), (1, 2)] {
                assert!(strata(a, 4, b, 4), "pixel {pixel}: dimensions {a}, {b}");
            }
        }
    }

    #[test]
    fn samples_are_deterministic_and_differ_between_pixels() {
        let a = PixelSampler::new(1, 42);
        let b = PixelSampler::new(1, 42);
        let c = PixelSampler::new(1, 43);
        let d = PixelSampler::new(2, 42);
        assert_eq!(a.get(5), b.get(5));
        assert_ne!(a.get(5), c.get(5));
        assert_ne!(a.get(5), d.get(5));
    }

    #[test]
    fn batches_equal_single_samples_bit_for_bit() {
        for pixel in 0..200u64 {
            let s = PixelSampler::new(3, pixel * 7919);
            for first in [0u32, 16, 32, 48, 1024, 4096 + 32, 7, u32::MAX - 15] {
                let (u, v) = s.get16(first);
                let (pu, pv) = s.get_pixel16(first);
                for lane in 0..BATCH {
                    let p = s.get(first.wrapping_add(lane as u32));
                    assert_eq!(
                        (u[lane].to_bits(), v[lane].to_bits()),
                        (p.x.to_bits(), p.y.to_bits())
                    );
                    let p = s.get_pixel(first.wrapping_add(lane as u32));
                    assert_eq!(
                        (pu[lane].to_bits(), pv[lane].to_bits()),
                        (p.x.to_bits(), p.y.to_bits())
                    );
                }
            }
        }
    }
}
