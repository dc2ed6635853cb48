//! Filling the pixels between sample sites from the surrounding sites.

use glam::Vec4;
use rayon::prelude::*;

use super::maps::cell;
use crate::limits::{MemoryError, try_copy};

/// Replaces every non-site pixel's colour and coverage (RGBA) by the bilinear blend of the
/// sites at the corners of its lattice cell (see [`super::maps::site_mask`], which guarantees
/// they are sites). A [`MemoryError`] (nothing changed) when its copy of the sites' colours
/// cannot be allocated.
pub fn interpolate(
    color: &mut [Vec4],
    interval: &[u32],
    sites: &[bool],
    width: usize,
    height: usize,
) -> Result<(), MemoryError> {
    if sites.iter().all(|&s| s) {
        return Ok(()); // nothing to fill (dense)
    }
    let snapshot = try_copy(color, "the colours to interpolate from")?;
    color
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let p = y * width + x;
                if sites[p] {
                    continue;
                }
                let i = interval[p];
                let (x0, x1) = cell(x, i, width);
                let (y0, y1) = cell(y, i, height);
                let tx = if x1 > x0 {
                    (x - x0) as f32 / (x1 - x0) as f32
                } else {
                    0.0
                };
                let ty = if y1 > y0 {
                    (y - y0) as f32 / (y1 - y0) as f32
                } else {
                    0.0
                };
                let top = snapshot[y0 * width + x0].lerp(snapshot[y0 * width + x1], tx);
                let bottom = snapshot[y1 * width + x0].lerp(snapshot[y1 * width + x1], tx);
                *out = top.lerp(bottom, ty);
            }
        });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::maps::site_mask;

    #[test]
    fn linear_gradients_are_reproduced_exactly() {
        let (w, h) = (17, 9);
        let interval = vec![4u32; w * h];
        let sites = site_mask(&interval, w, h).unwrap();
        let truth: Vec<Vec4> = (0..w * h)
            .map(|p| Vec4::new((p % w) as f32 * 0.1, (p / w) as f32 * 0.2, 1.0, 0.5))
            .collect();
        let mut color: Vec<Vec4> = truth
            .iter()
            .zip(&sites)
            .map(|(c, &s)| if s { *c } else { Vec4::splat(-1.0) })
            .collect();
        interpolate(&mut color, &interval, &sites, w, h).unwrap();
        for (got, want) in color.iter().zip(&truth) {
            assert!((*got - *want).length() < 1e-5, "{got} vs {want}");
        }
    }
}
