//! Geometry piled up in one place, which no acceleration structure can separate: every ray
//! through the pile tests every primitive in it. A glTF node tree can place one triangle a
//! hundred thousand times within a millionth of a unit (exact repeats are skipped when loading;
//! near ones are not), and a render of it then takes minutes for a few pixels. Real geometry
//! is never like that: a tessellated surface has a few primitives around any point of their
//! own size, fur and grass some hundreds.
//!
//! **The measure.** Each primitive (triangle or sphere) falls in a size class (its bounding
//! box's largest extent, by power of two) and, within the class, in the cell of a grid as
//! fine as the class that holds its box's centre. Primitives that all overlap one point have
//! centres within their size of it, so at least one in 16 of them share a cell (8 neighbouring
//! cells, 2 neighbouring classes). A cell holding more than [`MAX_STACKED`] primitives is
//! refused ([`Stack`]).
//!
//! **Cost.** Two passes over the primitives and fixed memory: counts per hashed cell in a
//! table of 2^20 counters (an overestimate where cells collide), then exact counts only for
//! the cells whose slot crossed the limit.

use std::collections::HashMap;

use glam::Vec3;

use super::{Object, SceneDesc};
use crate::limits::{MemoryError, try_vec};

/// The most primitives of one size class whose centres may share one cell of that size.
pub const MAX_STACKED: u32 = 4096;

/// Counters of the first pass (a power of two).
const SLOTS: usize = 1 << 20;

/// A pile of more than [`MAX_STACKED`] primitives of about one size in one place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stack {
    /// Primitives in the cell.
    pub count: u32,
    /// The cell's centre (world space).
    pub at: Vec3,
    /// The cell's side (the primitives are at most this large).
    pub size: f32,
}

/// A primitive's size class and cell.
type Cell = (i32, [i64; 3]);

/// The cell of the box `lo`..`hi`: its class is the exponent of the power of two just above
/// its largest extent, or above a millionth of its distance from the origin if that is more
/// (f32 positions hold no finer detail there: degenerate triangles are as large as that).
fn cell(lo: Vec3, hi: Vec3) -> Option<Cell> {
    let centre = 0.5 * (lo + hi);
    let extent = (hi - lo).max_element();
    if !(extent.is_finite() && centre.is_finite()) {
        return None;
    }
    let extent = extent
        .max(1e-6 * centre.abs().max_element())
        .max(f32::MIN_POSITIVE);
    let class = extent.log2().floor() as i32 + 1;
    let side = 2f32.powi(class);
    let k = (centre / side).floor();
    Some((class, [k.x as i64, k.y as i64, k.z as i64]))
}

/// The slot of the first pass's table a cell counts in.
fn slot((class, k): &Cell) -> usize {
    let mut h = crate::sampler::hash64(*class as u64);
    for v in k {
        h = crate::sampler::hash64(h ^ *v as u64);
    }
    (h as usize) & (SLOTS - 1)
}

/// Calls `f` with the bounding box of every primitive of `desc`.
fn each_box(desc: &SceneDesc, mut f: impl FnMut(Vec3, Vec3)) {
    for object in &desc.objects {
        match object {
            Object::Sphere { center, radius, .. } => {
                f(
                    *center - Vec3::splat(*radius),
                    *center + Vec3::splat(*radius),
                );
            }
            Object::Mesh { mesh, .. } => {
                let p = mesh.positions();
                for t in mesh.indices() {
                    let [a, b, c] = t.map(|i| Vec3::from(p[i as usize]));
                    f(a.min(b).min(c), a.max(b).max(c));
                }
            }
        }
    }
}

/// The fullest cell of `desc` if it holds more than [`MAX_STACKED`] primitives; an error when
/// the counters cannot be allocated.
pub fn find_stack(desc: &SceneDesc) -> Result<Option<Stack>, MemoryError> {
    // Fallible: the first 4 MiB a scene asks for, where a tight `ulimit -v` is met first.
    let mut counts = try_vec(SLOTS, 0u32, "the pile check's counters")?;
    each_box(desc, |lo, hi| {
        if let Some(c) = cell(lo, hi) {
            let s = &mut counts[slot(&c)];
            *s = s.saturating_add(1);
        }
    });
    if counts.iter().all(|&n| n <= MAX_STACKED) {
        return Ok(None);
    }
    // Exact counts of the cells in hot slots only.
    let mut exact: HashMap<Cell, u32> = HashMap::new();
    each_box(desc, |lo, hi| {
        if let Some(c) = cell(lo, hi)
            && counts[slot(&c)] > MAX_STACKED
        {
            *exact.entry(c).or_insert(0) += 1;
        }
    });
    let fullest = exact
        .into_iter()
        .filter(|&(_, n)| n > MAX_STACKED)
        .max_by_key(|&((class, k), n)| (n, class, k));
    Ok(fullest.map(|((class, k), count)| {
        let size = 2f32.powi(class);
        let at = (Vec3::new(k[0] as f32, k[1] as f32, k[2] as f32) + 0.5) * size;
        Stack { count, at, size }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_of_one_size_in_one_place_share_a_cell() {
        let a = cell(Vec3::ZERO, Vec3::splat(0.9)).unwrap();
        let b = cell(Vec3::splat(1e-6), Vec3::splat(0.9 + 1e-6)).unwrap();
        assert_eq!(a, b);
        // Twice the size: the next class; far away: another cell.
        assert_ne!(cell(Vec3::ZERO, Vec3::splat(2.0)).unwrap().0, a.0);
        assert_ne!(cell(Vec3::splat(5.0), Vec3::splat(6.0)).unwrap().1, a.1);
        assert!(cell(Vec3::ZERO, Vec3::splat(f32::NAN)).is_none());
        // Degenerate triangles far apart do not pile up in one cell.
        let p = Vec3::new(1e4, 0.0, 0.0);
        assert_ne!(cell(p, p), cell(-p, -p));
        assert_ne!(cell(p, p), cell(p * 1.01, p * 1.01));
    }
}
