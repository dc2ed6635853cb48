//! The per-pixel maps the seed's method works from: how far blur reaches, the sample
//! interval per pixel (figure 3 of the seed), and which pixels are sample sites.

use rayon::prelude::*;

/// The van Herk / Gil-Werman square-window filter, O(n) for any radius, applied to `lanes`
/// interleaved signals at once: element `i * lanes + l` is sample `i` of signal `l`. `pad` holds
/// the signals with `radius` samples of the identity before and after; `dst` receives the
/// `n = pad.len() / lanes - 2 radius` filtered samples.
fn van_herk<T: Copy>(pad: &[T], lanes: usize, radius: usize, dst: &mut [T], f: impl Fn(T, T) -> T) {
    let m = pad.len() / lanes;
    let k = 2 * radius + 1;
    let mut prefix = pad.to_vec();
    let mut suffix = pad.to_vec();
    for block in (0..m).step_by(k) {
        let end = (block + k).min(m);
        for i in block + 1..end {
            let (before, row) = prefix.split_at_mut(i * lanes);
            for (p, &q) in row[..lanes].iter_mut().zip(&before[(i - 1) * lanes..]) {
                *p = f(q, *p);
            }
        }
        for i in (block..end - 1).rev() {
            let (row, after) = suffix.split_at_mut((i + 1) * lanes);
            for (s, &q) in row[i * lanes..].iter_mut().zip(&after[..lanes]) {
                *s = f(*s, q);
            }
        }
    }
    for (j, out) in dst.chunks_mut(lanes).enumerate() {
        let s = &suffix[j * lanes..(j + 1) * lanes];
        let p = &prefix[(j + 2 * radius) * lanes..(j + 2 * radius + 1) * lanes];
        for ((o, &a), &b) in out.iter_mut().zip(s).zip(p) {
            *o = f(a, b);
        }
    }
}

/// Columns per strip in the vertical pass: strips are independent, so they run in parallel.
const STRIP: usize = 64;

/// Applies `f` over the (2 radius + 1)^2 square around every pixel (clipped at the borders,
/// where missing pixels count as `identity`): rows in parallel, then strips of columns in
/// parallel, each filtered a whole strip-row at a time so memory is read in order.
fn filter_2d<T: Copy + Send + Sync>(
    src: &[T],
    width: usize,
    height: usize,
    radius: usize,
    identity: T,
    f: impl Fn(T, T) -> T + Copy + Send + Sync,
) -> Vec<T> {
    let mut rows = src.to_vec();
    rows.par_chunks_mut(width).for_each(|row| {
        let mut pad = vec![identity; width + 2 * radius];
        pad[radius..radius + width].copy_from_slice(row);
        van_herk(&pad, 1, radius, row, f);
    });
    let strips: Vec<(usize, Vec<T>)> = (0..width.div_ceil(STRIP))
        .into_par_iter()
        .map(|s| {
            let x0 = s * STRIP;
            let sw = STRIP.min(width - x0);
            let mut pad = vec![identity; (height + 2 * radius) * sw];
            for y in 0..height {
                let at = (y + radius) * sw;
                pad[at..at + sw].copy_from_slice(&rows[y * width + x0..y * width + x0 + sw]);
            }
            let mut strip = vec![identity; height * sw];
            van_herk(&pad, sw, radius, &mut strip, f);
            (x0, strip)
        })
        .collect();
    let mut out = rows;
    for (x0, strip) in strips {
        let sw = strip.len() / height;
        for (y, line) in strip.chunks(sw).enumerate() {
            out[y * width + x0..y * width + x0 + sw].copy_from_slice(line);
        }
    }
    out
}

/// Which pixels the blur of a defocused surface reaches. A surface seen at pixel q with
/// CoC c > 1 spreads over the disc of diameter c around q, so a pixel whose own surface is in
/// focus can still be covered by a defocused neighbour (a foreground object's halo); such
/// pixels need lens samples too. The disc of radius r is covered by the diamond
/// |dx| + |dy| <= r sqrt(2), whose reach is a separable max-minus-distance propagation
/// (two linear scans per axis), so this never underestimates and costs O(pixels).
pub fn blurred(coc: &[f32], width: usize, height: usize) -> Vec<bool> {
    let none = f32::NEG_INFINITY;
    let mut reach: Vec<f32> = coc
        .iter()
        .map(|&c| {
            if c > 1.0 {
                c * 0.5 * std::f32::consts::SQRT_2
            } else {
                none
            }
        })
        .collect();
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
    reach.into_iter().map(|r| r >= 0.0).collect()
}

/// Largest power of two <= v (v >= 1).
fn floor_pow2(v: f32) -> u32 {
    1u32 << (v.max(1.0).log2().floor() as u32).min(31)
}

/// The seed's per-pixel interval: 1 where the pixel is in focus (CoC <= 1 px), else
/// `max(2, k * CoC)`, quantised down to a power-of-two layer and capped at `max_interval`.
pub fn paper_interval(coc: f32, k: f32, max_interval: u32) -> u32 {
    if coc <= 1.0 {
        1
    } else {
        floor_pow2((k * coc).max(2.0)).min(max_interval)
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
) -> Vec<u32> {
    let raw: Vec<u32> = coc
        .iter()
        .map(|&c| paper_interval(c, k, max_interval))
        .collect();
    if paper_exact {
        return raw;
    }
    // Filter log2 of the layers as bytes: a quarter of the memory traffic of u32.
    let layer: Vec<u8> = raw.iter().map(|&i| i.trailing_zeros() as u8).collect();
    let top = layer.iter().copied().max().unwrap_or(0);
    let mut out = vec![1u32; raw.len()];
    for level in 1..=top {
        let min_in_reach = filter_2d(&layer, width, height, 1 << level, u8::MAX, u8::min);
        for ((o, &l), &m) in out.iter_mut().zip(&layer).zip(&min_in_reach) {
            if l >= level && m >= level {
                *o = 1 << level;
            }
        }
    }
    out
}

/// The lattice cell of pixel coordinate `x` at interval `i` in an axis of length `n`:
/// (lower site, upper site); equal when `x` is itself on the lattice.
pub fn cell(x: usize, interval: u32, n: usize) -> (usize, usize) {
    let i = interval as usize;
    let x0 = x / i * i;
    if x0 == x {
        (x, x)
    } else {
        (x0, (x0 + i).min(n - 1))
    }
}

/// Marks the sample sites: every lattice corner that some pixel interpolates from (a pixel
/// with interval 1 is its own site). Interpolated pixels therefore only read traced sites, at
/// every boundary between layers.
pub fn site_mask(interval: &[u32], width: usize, height: usize) -> Vec<bool> {
    let mut sites = vec![false; interval.len()];
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
    sites
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
    fn window_filter_matches_brute_force() {
        let (w, h) = (23, 17);
        let src: Vec<u32> = (0..w * h)
            .map(|i| (crate::sampler::hash64(i as u64) % 1000) as u32)
            .collect();
        for r in [0, 1, 2, 3, 7, 30] {
            assert_eq!(
                filter_2d(&src, w, h, r, u32::MAX, u32::min),
                brute(&src, w, h, r),
                "radius {r}"
            );
        }
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
    }

    #[test]
    fn conservative_intervals_never_reach_an_in_focus_pixel() {
        // Left half in focus (CoC 0), right half heavily blurred (CoC 40 -> interval 16).
        let (w, h) = (96, 8);
        let coc: Vec<f32> = (0..w * h)
            .map(|i| if i % w < 40 { 0.0 } else { 40.0 })
            .collect();
        let exact = interval_map(&coc, w, h, 0.4, true, 64);
        let safe = interval_map(&coc, w, h, 0.4, false, 64);
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
        let blurred = blurred(&coc, w, h);
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
            let interval = interval_map(&coc, w, h, 0.4, exact, 64);
            let sites = site_mask(&interval, w, h);
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
