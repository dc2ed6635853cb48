//! The real lens's blur bound ([`crate::camera::Lens::coc_px`] and
//! [`crate::camera::Lens::coc_px_at`]): the spot a point makes, tabulated over inverse depth
//! and film radius and interpolated linearly in inverse depth. Spots grow about linearly in
//! inverse depth on either side of focus (a V), so the chords of the table stay above them
//! where a knot sits at the V's tip: the table's knots are even in inverse depth on each
//! side of the focus distance's, which is one of them (evenly spaced knots put a chord across
//! the tip: a telephoto focused at 4 m was bounded at 4.1 px in focus, where its spots are 0.1
//! to 1.2 px). Nearer than the table it grows with inverse depth from the last knot.
//!
//! The table is built radius by radius: each film radius's evaluator is made once, holding
//! what its spots at every depth share (the rays of `spot.rs`'s `SpotRays`), and each knot's
//! spot is evaluated from it with only the work its depth needs.

use rayon::prelude::*;

/// Inverse-depth knots of the table.
const ENTRIES: usize = 48;
/// Film radii of the table, evenly spaced from the centre to [`EDGE`] of the half diagonal.
const RADII: usize = 9;
/// The table's outermost radius, a fraction of the film's half diagonal (its corners'
/// pixel centres lie a little inside the corner).
const EDGE: f64 = 0.98;

/// Blur diameters (px) per inverse-depth knot and film radius.
#[derive(Debug, Clone, PartialEq, Default)]
pub(super) struct BlurTable {
    /// The nearest knot's inverse depth (1/m).
    max_inv: f64,
    /// The focus distance's inverse depth, a knot (0: focused at infinity).
    inv_focus: f64,
    /// The focus distance's knot: knots `0..=focus_knot` are even over `[0, inv_focus]`,
    /// the rest over `[inv_focus, max_inv]`.
    focus_knot: usize,
    /// Per knot, the spot at each radius `j / (RADII - 1) * EDGE` of the half diagonal.
    rows: Vec<[f32; RADII]>,
    /// Per knot, the largest over the radii: the bound over the whole film.
    row_max: Vec<f32>,
}

impl BlurTable {
    /// The table from the nearest inverse depth it covers, `max_inv` (1/m), the focus
    /// distance's, and `spot`: `spot(r)` is film radius `r`'s evaluator (`r` a fraction of
    /// the half diagonal), made once per radius, which gives the spot (px) of a point at
    /// inverse depth `inv`.
    pub(super) fn new<E>(max_inv: f64, inv_focus: f64, spot: impl Fn(f64) -> E + Sync) -> Self
    where
        E: Fn(f64) -> f32 + Send + Sync,
    {
        // A focus beyond the nearest knot cannot happen (the lens focuses no nearer than its
        // front); keep the tip inside the table anyway.
        let max_inv = max_inv.max(1.5 * inv_focus);
        let inv_focus = inv_focus.max(0.0);
        let share = inv_focus / max_inv;
        let least = if inv_focus > 0.0 { 1 } else { 0 };
        let focus_knot =
            ((share * (ENTRIES - 1) as f64).round() as usize).clamp(least, ENTRIES - 2);
        let mut table = Self {
            max_inv,
            inv_focus,
            focus_knot,
            rows: Vec::new(),
            row_max: Vec::new(),
        };
        // Each radius's evaluator first (what its spots share, traced once), then thousands
        // of traced rays a spot: the knots in parallel.
        let at: Vec<E> = (0..RADII)
            .into_par_iter()
            .map(|j| spot(j as f64 / (RADII - 1) as f64 * EDGE))
            .collect();
        table.rows = (0..ENTRIES)
            .into_par_iter()
            .map(|k| {
                let inv = table.knot(k);
                std::array::from_fn(|j| at[j](inv))
            })
            .collect();
        table.row_max = table
            .rows
            .iter()
            .map(|row| row.iter().copied().fold(0.0f32, f32::max))
            .collect();
        table
    }

    /// Knot `k`'s inverse depth.
    fn knot(&self, k: usize) -> f64 {
        let n = self.focus_knot;
        if k <= n {
            if n == 0 {
                0.0
            } else {
                k as f64 / n as f64 * self.inv_focus
            }
        } else {
            let t = (k - n) as f64 / (ENTRIES - 1 - n) as f64;
            self.inv_focus + t * (self.max_inv - self.inv_focus)
        }
    }

    /// The knot whose chord holds inverse depth `inv` and how far along it `inv` lies (past 1
    /// beyond the last knot).
    fn chord(&self, inv: f64) -> (usize, f64) {
        let n = self.focus_knot;
        let x = if n > 0 && inv <= self.inv_focus {
            inv / self.inv_focus * n as f64
        } else {
            n as f64
                + (inv - self.inv_focus) / (self.max_inv - self.inv_focus)
                    * (ENTRIES - 1 - n) as f64
        };
        let k = (x.max(0.0).floor() as usize).min(ENTRIES - 2);
        (k, x - k as f64)
    }

    /// The bound over the whole film at `depth` (m along the view axis; infinite: points at
    /// infinity).
    pub(super) fn whole(&self, depth: f32) -> f32 {
        self.along_depth(depth, |k| self.row_max[k])
    }

    /// The bound at `depth` near film radius `r` (a fraction of the half diagonal): the
    /// larger of the two table radii that bracket it (the last two past the table's edge).
    pub(super) fn near(&self, depth: f32, r: f64) -> f32 {
        if !r.is_finite() {
            return self.whole(depth);
        }
        let j = ((r.max(0.0) / EDGE * (RADII - 1) as f64) as usize).min(RADII - 2);
        self.along_depth(depth, |k| self.rows[k][j].max(self.rows[k][j + 1]))
    }

    /// The table at `depth` for the value `at(k)` of each knot `k`: linear in inverse depth
    /// between knots; nearer than the table (within 5 cm of the front element) growing at
    /// least as the inverse depth from the last knot, or along the last chord where it rises.
    fn along_depth(&self, depth: f32, at: impl Fn(usize) -> f32) -> f32 {
        let inv = if depth > 0.0 {
            1.0 / f64::from(depth)
        } else {
            self.max_inv
        };
        let (k, f) = self.chord(inv);
        let f = f as f32;
        let (here, next) = (at(k), at(k + 1));
        let rise = next - here;
        if f <= 1.0 {
            return (here + rise * f).max(0.0);
        }
        // k is the table's last chord here, so `next` is its last knot.
        let along = next + rise.max(0.0) * (f - 1.0);
        along.max(next * (inv / self.max_inv) as f32).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A V in inverse depth with its tip at the focus distance's, and wider at the rim.
    fn v(inv_focus: f64) -> impl Fn(f64, f64) -> f32 {
        move |inv, r| (40.0 * (inv - inv_focus).abs() + 0.1 + r) as f32
    }

    #[test]
    fn the_focus_distance_is_a_knot_and_the_chords_hold_the_v() {
        for (max_inv, inv_focus) in [(14.0, 0.25), (14.0, 0.0), (5.0, 2.0), (20.0, 13.9)] {
            let spot = v(inv_focus);
            let made = AtomicUsize::new(0);
            let t = BlurTable::new(max_inv, inv_focus, |r| {
                made.fetch_add(1, Ordering::Relaxed);
                let spot = &spot;
                move |inv| spot(inv, r)
            });
            // What a radius's spots share is made once for all its knots.
            assert_eq!(made.into_inner(), RADII);
            assert_eq!(t.knot(t.focus_knot), inv_focus);
            assert_eq!(t.knot(ENTRIES - 1), t.max_inv);
            assert!(t.max_inv >= max_inv);
            for i in 0..=4000 {
                let inv = i as f64 / 4000.0 * t.max_inv;
                let depth = (1.0 / inv) as f32;
                let exact = spot(inv, EDGE);
                let got = t.whole(depth);
                // Linear pieces of a V with a knot at its tip: exact up to f32 rounding.
                assert!(
                    (got - exact).abs() <= 1e-3 * exact.max(1.0),
                    "{inv_focus}: {got} at {inv} for {exact}"
                );
                assert!(t.near(depth, 0.0) <= got && t.near(depth, 0.0) >= spot(inv, 0.0));
            }
            // Nearer than the table it keeps growing.
            assert!(t.whole((0.5 / max_inv) as f32) >= t.whole((1.0 / max_inv) as f32));
        }
    }
}
