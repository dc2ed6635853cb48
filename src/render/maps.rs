//! The per-pixel maps the seed's method works from: how far blur reaches, the sample
//! interval per pixel (figure 3 of the seed), and which pixels are sample sites.

use rayon::prelude::*;

use super::unseen::UnseenBlur;
use crate::limits::{MemoryError, try_collect, try_vec};

/// The blur the site rules decide from, per pixel: the depth pass's CoC map, widened by what it
/// cannot see ([`UnseenBlur`]).
#[derive(Debug, Clone)]
pub struct Blur {
    /// The sharpest blur (CoC, pixels) that may reach the pixel: the depth pass's CoC, lowered
    /// where an unseen primitive's sharper light reaches. Sample intervals start from it.
    pub sharpest: Vec<f32>,
    /// The widest blur that may reach the pixel: how far one highlight's light spreads.
    pub widest: Vec<f32>,
    /// Whether blur of more than a pixel reaches the pixel ([`blurred`], or an unseen
    /// primitive's): such sites take `spp` samples, the others `aa`.
    pub blurred: Vec<bool>,
    /// Whether the light of a primitive the depth pass did not see may reach the pixel: an
    /// adaptive site there takes all its samples at once, since a few that miss a sub-pixel
    /// highlight would look converged and stop (keeping a fraction of its energy on average).
    pub unseen: Vec<bool>,
}

impl Blur {
    /// The maps of a `width` x `height` frame whose depth pass gave `coc`, with `unseen`.
    pub fn with_unseen(
        coc: &[f32],
        width: usize,
        height: usize,
        unseen: &UnseenBlur,
    ) -> Result<Self, MemoryError> {
        let mut blurred = blurred(coc, width, height)?;
        let mut sharpest = try_vec(coc.len(), 0.0, "the blur map")?;
        let mut widest = try_vec(coc.len(), 0.0, "the blur map")?;
        let mut reached = try_vec(coc.len(), false, "the blur map")?;
        for (p, &c) in coc.iter().enumerate() {
            let (x, y) = (p % width, p / width);
            let (lo, hi) = (unseen.sharpest(x, y), unseen.widest(x, y));
            sharpest[p] = c.min(lo);
            widest[p] = c.max(hi);
            blurred[p] |= hi > 1.0;
            reached[p] = lo.is_finite();
        }
        Ok(Self {
            sharpest,
            widest,
            blurred,
            unseen: reached,
        })
    }
}

/// Minima over growing squares by doubling (the sparse-table idea), for every level
/// `l` in `1..=top`: `out[l - 1][p]` is the minimum of `src` over the (2r + 1)^2 square around
/// pixel p with r = 2^l, clipped at the borders (missing pixels count as `u8::MAX`).
///
/// `M_1` is the image; `M_2s` at q is the min of `M_s` at q, q + s right, q + s down and
/// q + s both, i.e. the minimum over the 2s x 2s square whose top-left corner is q. The
/// (2r + 1)^2 square around p is covered by the four 2r x 2r squares whose corners are at
/// p - r and p - (r - 1) on each axis. Every step is a min of whole shifted slices, which
/// vectorises: a few passes over the bytes instead of a filter per pixel.
fn square_minima(
    src: &[u8],
    width: usize,
    height: usize,
    top: u32,
) -> Result<Vec<Vec<u8>>, MemoryError> {
    if top == 0 {
        return Ok(Vec::new());
    }
    // Pad every side by the largest radius so shifted reads stay inside the buffer.
    let pad = 1usize << top;
    let (pw, ph) = (width + 2 * pad, height + 2 * pad);
    let mut m = try_vec(pw * ph, u8::MAX, "the padded blur map")?;
    m.par_chunks_mut(pw)
        .skip(pad)
        .zip(src.par_chunks(width))
        .for_each(|(row, line)| row[pad..pad + width].copy_from_slice(line));
    let shifted_min = |m: &[u8], offsets: [usize; 4], out: &mut [u8]| {
        let n = out.len();
        let [a, b, c, d] = offsets.map(|o| &m[o..o + n]);
        for ((((o, &a), &b), &c), &d) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
            *o = a.min(b).min(c).min(d);
        }
    };
    let mut out = Vec::with_capacity(top as usize);
    let mut side = 1;
    for level in 1..=top {
        let r = 1usize << level;
        while side < 2 * r {
            let mut next = try_vec(m.len(), u8::MAX, "the padded blur map")?;
            let n = m.len() - side * pw - side;
            shifted_min(&m, [0, side, side * pw, side * pw + side], &mut next[..n]);
            m = next;
            side *= 2;
        }
        // m is now M_2r: the four covering squares around each pixel.
        let mut level_min = try_vec(width * height, 0u8, "a minimum map")?;
        level_min
            .par_chunks_mut(width)
            .enumerate()
            .for_each(|(y, row)| {
                let at = (y + pad - r) * pw + pad - r;
                let row_at = |dy: usize, dx: usize| at + dy * pw + dx;
                shifted_min(
                    &m,
                    [row_at(0, 0), row_at(0, 1), row_at(1, 0), row_at(1, 1)],
                    row,
                );
            });
        out.push(level_min);
    }
    Ok(out)
}

/// Maxima over growing squares, for every level `l` in `1..=top`: `out[l - 1][p]` is the
/// maximum of `src` over the (2r + 1)^2 square around pixel p with r = 2^l, clipped at the
/// borders (missing pixels count as 0).
pub fn square_maxima(
    src: &[u8],
    width: usize,
    height: usize,
    top: u32,
) -> Result<Vec<Vec<u8>>, MemoryError> {
    let inverted = try_collect(src.iter().map(|&v| u8::MAX - v), "the peak map")?;
    let mut levels = square_minima(&inverted, width, height, top)?;
    for level in &mut levels {
        for v in level.iter_mut() {
            *v = u8::MAX - *v;
        }
    }
    Ok(levels)
}

/// Which pixels the blur of a defocused surface reaches. A surface seen at pixel q with
/// CoC c > 1 spreads over the disc of diameter c around q, so a pixel whose own surface is in
/// focus can still be covered by a defocused neighbour (a foreground object's halo); such
/// pixels need lens samples too. The disc of radius r is covered by the diamond
/// |dx| + |dy| <= r sqrt(2), whose reach is a separable max-minus-distance propagation
/// (two linear scans per axis), so this never underestimates and costs O(pixels).
pub fn blurred(coc: &[f32], width: usize, height: usize) -> Result<Vec<bool>, MemoryError> {
    let none = f32::NEG_INFINITY;
    let reach = coc.iter().map(|&c| {
        if c > 1.0 {
            c * 0.5 * std::f32::consts::SQRT_2
        } else {
            none
        }
    });
    let mut reach = try_collect(reach, "the blur reach map")?;
    reach.par_chunks_mut(width).for_each(|row| {
        for x in 1..row.len() {
            row[x] = row[x].max(row[x - 1] - 1.0);
        }
        for x in (0..row.len().saturating_sub(1)).rev() {
            row[x] = row[x].max(row[x + 1] - 1.0);
        }
    });
    for y in 1..height {
        let (done, rest) = reach.split_at_mut(y * width);
        let above = &done[(y - 1) * width..];
        for (r, &a) in rest[..width].iter_mut().zip(above) {
            *r = r.max(a - 1.0);
        }
    }
    for y in (0..height.saturating_sub(1)).rev() {
        let (head, below) = reach.split_at_mut((y + 1) * width);
        for (r, &b) in head[y * width..].iter_mut().zip(&below[..width]) {
            *r = r.max(b - 1.0);
        }
    }
    try_collect(reach.iter().map(|&r| r >= 0.0), "the blur map")
}

/// Largest power of two <= v, for v >= 1 (an integer's highest bit: no log2 per pixel).
fn floor_pow2(v: f32) -> u32 {
    // `as` saturates, so huge values give the top bit; v < 2^31 is exact.
    let n = (v.max(1.0) as u32).max(1);
    1 << (31 - n.leading_zeros())
}

/// The seed's per-pixel interval: 1 where the pixel is in focus (CoC <= 1 px), else
/// `max(2, k * CoC)`, quantised down to a power-of-two layer and capped at `max_interval`.
pub fn paper_interval(coc: f32, k: f32, max_interval: u32) -> u32 {
    layer_interval(coc, k, 2.0, max_interval)
}

/// `max(floor, k * CoC)` quantised down to a power-of-two layer and capped, 1 in focus.
fn layer_interval(coc: f32, k: f32, floor: f32, max_interval: u32) -> u32 {
    if coc <= 1.0 {
        1
    } else {
        floor_pow2((k * coc).max(floor)).min(max_interval)
    }
}

/// Sample intervals for every pixel. With `paper_exact` each pixel follows the seed's rule on
/// its own CoC. Otherwise the rule is conservative: a pixel's interval may not exceed the
/// interval any pixel within that interval's reach would get, so interpolation never spans an
/// in-focus edge beside a blurred region.
pub fn interval_map(
    coc: &[f32],
    width: usize,
    height: usize,
    k: f32,
    paper_exact: bool,
    max_interval: u32,
) -> Result<Vec<u32>, MemoryError> {
    let raw = coc.iter().map(|&c| paper_interval(c, k, max_interval));
    let raw = try_collect(raw, "the interval map")?;
    if paper_exact {
        return Ok(raw);
    }
    conservative(raw, width, height)
}

/// The error-controlled rule's starting intervals: `k * CoC` in power-of-two layers with no
/// every-other-pixel floor (a CoC below 2 / k starts at 1), made conservative like
/// [`interval_map`]'s. These are upper bounds; [`super::refine`] only ever halves them.
pub fn start_intervals(
    coc: &[f32],
    width: usize,
    height: usize,
    k: f32,
    max: u32,
) -> Result<Vec<u32>, MemoryError> {
    let raw = coc.iter().map(|&c| layer_interval(c, k, 1.0, max));
    conservative(try_collect(raw, "the interval map")?, width, height)
}

/// Lowers each interval until no pixel within its reach has a smaller one.
fn conservative(raw: Vec<u32>, width: usize, height: usize) -> Result<Vec<u32>, MemoryError> {
    // Work on log2 of the layers as bytes: a quarter of the memory traffic of u32.
    let layer = try_collect(
        raw.iter().map(|&i| i.trailing_zeros() as u8),
        "the interval layers",
    )?;
    let top = u32::from(layer.iter().copied().max().unwrap_or(0));
    // The raw map is the result's buffer.
    let mut out = raw;
    out.fill(1);
    // Level l is allowed where every pixel within 2^l (the pixel itself included) allows it.
    for (level, min_in_reach) in (1..=top).zip(square_minima(&layer, width, height, top)?) {
        for (o, &m) in out.iter_mut().zip(&min_in_reach) {
            if u32::from(m) >= level {
                *o = 1 << level;
            }
        }
    }
    Ok(out)
}

/// The lattice cell of pixel coordinate `x` at interval `i` in an axis of length `n`:
/// (lower site, upper site); equal when `x` is itself on the lattice.
pub fn cell(x: usize, interval: u32, n: usize) -> (usize, usize) {
    debug_assert!(interval.is_power_of_two());
    let i = interval as usize;
    let x0 = x & !(i - 1);
    if x0 == x {
        (x, x)
    } else {
        (x0, (x0 + i).min(n - 1))
    }
}

/// Marks the sample sites: every lattice corner that some pixel interpolates from (a pixel
/// with interval 1 is its own site). Interpolated pixels therefore only read traced sites, at
/// every boundary between layers.
pub fn site_mask(interval: &[u32], width: usize, height: usize) -> Result<Vec<bool>, MemoryError> {
    if interval.iter().all(|&i| i == 1) {
        // Dense, or nothing defocused: every pixel is its own site.
        return try_vec(interval.len(), true, "the site mask");
    }
    let mut sites = try_vec(interval.len(), false, "the site mask")?;
    for y in 0..height {
        for x in 0..width {
            let i = interval[y * width + x];
            let (x0, x1) = cell(x, i, width);
            let (y0, y1) = cell(y, i, height);
            for yy in [y0, y1] {
                sites[yy * width + x0] = true;
                sites[yy * width + x1] = true;
            }
        }
    }
    Ok(sites)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(src: &[u32], w: usize, h: usize, r: usize) -> Vec<u32> {
        let mut out = vec![0; src.len()];
        for y in 0..h {
            for x in 0..w {
                let mut m = u32::MAX;
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        m = m.min(src[yy * w + xx]);
                    }
                }
                out[y * w + x] = m;
            }
        }
        out
    }

    #[test]
    fn square_minima_match_brute_force() {
        for (w, h) in [(23, 17), (5, 40), (70, 3), (1, 1)] {
            let src: Vec<u8> = (0..w * h)
                .map(|i| (crate::sampler::hash64(i as u64) % 200) as u8)
                .collect();
            let wide: Vec<u32> = src.iter().map(|&v| u32::from(v)).collect();
            let got = square_minima(&src, w, h, 5).unwrap();
            assert_eq!(got.len(), 5);
            for (level, mins) in (1..=5).zip(&got) {
                let want = brute(&wide, w, h, 1 << level);
                let mins: Vec<u32> = mins.iter().map(|&v| u32::from(v)).collect();
                assert_eq!(mins, want, "{w}x{h} level {level}");
            }
        }
        assert!(square_minima(&[3], 1, 1, 0).unwrap().is_empty());
    }

    #[test]
    fn paper_rule_quantises_to_power_of_two_layers() {
        assert_eq!(paper_interval(0.5, 0.4, 64), 1);
        assert_eq!(paper_interval(1.0, 0.4, 64), 1);
        assert_eq!(paper_interval(1.5, 0.4, 64), 2); // at least every other pixel
        assert_eq!(paper_interval(10.0, 0.4, 64), 4); // 0.4 * 10 = 4
        assert_eq!(paper_interval(30.0, 0.4, 64), 8); // 12 -> 8
        assert_eq!(paper_interval(30.0, 0.2, 64), 4); // 6 -> 4
        assert_eq!(paper_interval(1000.0, 0.4, 16), 16);
        assert_eq!(paper_interval(19.999, 0.4, 64), 4); // 7.9996 -> 4
        assert_eq!(paper_interval(20.0, 0.4, 64), 8);
        assert_eq!(paper_interval(f32::INFINITY, 0.4, 64), 64);
        for v in [1.0f32, 1.5, 2.0, 3.99, 4.0, 1023.0, 1024.0, 1e9] {
            assert_eq!(floor_pow2(v), 1 << (v.log2().floor() as u32), "{v}");
        }
    }

    #[test]
    fn conservative_intervals_never_reach_an_in_focus_pixel() {
        // Left half in focus (CoC 0), right half heavily blurred (CoC 40 -> interval 16).
        let (w, h) = (96, 8);
        let coc: Vec<f32> = (0..w * h)
            .map(|i| if i % w < 40 { 0.0 } else { 40.0 })
            .collect();
        let exact = interval_map(&coc, w, h, 0.4, true, 64).unwrap();
        let safe = interval_map(&coc, w, h, 0.4, false, 64).unwrap();
        assert_eq!(exact[h / 2 * w + 40], 16);
        for y in 0..h {
            for x in 0..w {
                let i = safe[y * w + x];
                if x < 40 {
                    assert_eq!(i, 1);
                    continue;
                }
                // No in-focus pixel within the interval's reach: it starts at x = 39.
                assert!(i == 1 || x - i as usize > 39, "x {x} got interval {i}");
                assert!(i <= exact[y * w + x]);
            }
        }
        // Far from the edge the full interval is kept.
        assert_eq!(safe[h / 2 * w + 80], 16);
    }

    #[test]
    fn blur_covers_the_disc_of_each_defocused_pixel() {
        let (w, h) = (64, 64);
        let mut coc = vec![0.0f32; w * h];
        coc[32 * w + 32] = 20.0; // reaches 10 px around
        coc[5 * w + 5] = 0.8; // in focus: reaches nothing
        let blurred = blurred(&coc, w, h).unwrap();
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 - 32.0, y as f32 - 32.0);
                if (dx * dx + dy * dy).sqrt() <= 10.0 {
                    assert!(blurred[y * w + x], "({x},{y}) is inside the blur disc");
                }
                if dx.abs() + dy.abs() > 10.0 * std::f32::consts::SQRT_2 + 1e-3 {
                    assert!(!blurred[y * w + x], "({x},{y}) is far outside");
                }
            }
        }
        assert!(!blurred[5 * w + 5]);
    }

    #[test]
    fn every_interpolated_pixel_reads_only_sites() {
        let (w, h) = (50, 37);
        let coc: Vec<f32> = (0..w * h)
            .map(|i| ((i % w) as f32 - 20.0).abs() * 1.5)
            .collect();
        for exact in [true, false] {
            let interval = interval_map(&coc, w, h, 0.4, exact, 64).unwrap();
            let sites = site_mask(&interval, w, h).unwrap();
            for y in 0..h {
                for x in 0..w {
                    let i = interval[y * w + x];
                    let (x0, x1) = cell(x, i, w);
                    let (y0, y1) = cell(y, i, h);
                    for (cx, cy) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
                        assert!(
                            sites[cy * w + cx],
                            "pixel ({x},{y}) interval {i} reads ({cx},{cy})"
                        );
                    }
                }
            }
            let count = sites.iter().filter(|&&s| s).count();
            assert!(count < w * h * 2 / 3, "sparser than dense: {count}");
        }
    }
}
