//! The inner loop of lending, eight members at a time. A lender's sample visits every member
//! within its reach (about fifty, a few to a row) and works out for each its kernel at the
//! sample and its role. The compiler does not vectorise that loop member by member; here the
//! members are columns (one array per field, padded by [`LANES`]) and each row of them is
//! worked out in blocks of eight `f32x8` lanes with the same arithmetic in the same order.
//! The table lookups in between are plain loads. Only summing the lenders' density stays one member at a time, in pixel order,
//! so every value is the same to the last bit as member by member.

use glam::Vec2;
use wide::{CmpEq, CmpGt, CmpLe, CmpLt, f32x8, i32x8};

use super::{DiscKernel, Member, RADIAL, ShiftKernel};

/// Members worked out together.
pub(super) const LANES: usize = 8;

/// A window's members ([`Member`]) as columns, each padded by [`LANES`] so that a block
/// starting at any member can be read whole.
#[derive(Debug, Default)]
pub(super) struct Columns {
    x: Vec<f32>,
    y: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    lo: Vec<f32>,
    hi: Vec<f32>,
    n: Vec<f32>,
    lattice: Vec<i32>,
    /// 1 where the member is needy, covered; else 0.
    needy: Vec<f32>,
    covered: Vec<f32>,
}

impl Columns {
    /// The columns of `members`.
    pub(super) fn new(members: &[Member]) -> Self {
        let len = members.len() + LANES;
        let column = |f: &dyn Fn(&Member) -> f32| {
            let mut c = Vec::with_capacity(len);
            c.extend(members.iter().map(f));
            c.resize(len, 0.0);
            c
        };
        let mut lattice: Vec<i32> = members.iter().map(|m| m.lattice as i32).collect();
        // Padding lanes are never used (masked by the block's length); any value does.
        lattice.resize(len, 0);
        Self {
            x: column(&|m| m.at.x),
            y: column(&|m| m.at.y),
            gx: column(&|m| m.gradient.x),
            gy: column(&|m| m.gradient.y),
            lo: column(&|m| m.lo),
            hi: column(&|m| m.hi),
            n: column(&|m| m.n),
            lattice,
            needy: column(&|m| f32::from(u8::from(m.needy))),
            covered: column(&|m| f32::from(u8::from(m.covered))),
        }
    }

    /// For the block from `start` and a sample at `centre` of shift `shift`: the offsets
    /// `centre - at`, their squared lengths, and the sample's shift carried along each
    /// member's surface to it (comparable with its cluster; [`super::Member::carried`]).
    #[inline]
    fn offsets(&self, centre: Vec2, shift: f32, start: usize) -> ((f32x8, f32x8), f32x8, f32x8) {
        let dx = f32x8::splat(centre.x) - load(&self.x, start);
        let dy = f32x8::splat(centre.y) - load(&self.y, start);
        let d2 = dx * dx + dy * dy;
        let carried =
            f32x8::splat(shift) - (load(&self.gx, start) * dx + load(&self.gy, start) * dy);
        ((dx, dy), d2, carried)
    }
}

/// Of members `start..start + valid` (`valid` at most [`LANES`]), those within `extent` of
/// a sample at `centre` whose shift `shift`, carried along the member's surface, lies nearer
/// than its cluster ([`super::Member::lo`]): bit j for member `start + j`.
#[inline]
pub(super) fn covers(
    cols: &Columns,
    (centre, shift, extent): (Vec2, f32, f32),
    start: usize,
    valid: usize,
) -> u32 {
    let (_, d2, c) = cols.offsets(centre, shift, start);
    let hit = d2.cmp_lt(f32x8::splat(extent * extent)) & c.cmp_lt(load(&cols.lo, start));
    (hit.move_mask() as u32) & ((1u32 << valid) - 1)
}

/// One lender's sample as the block loop reads it.
pub(super) struct Sample<'a> {
    /// Its centre and shift ([`super::Record`]).
    pub centre: Vec2,
    pub shift: f32,
    /// The square of its reach: members this far or farther are out of it.
    pub reach2: f32,
    /// The lattice of its lenders: member q lends when `q.lattice & mask == 0`.
    pub mask: u32,
    /// Its kernel.
    pub kernel: &'a ShiftKernel<'a>,
}

/// What a block of members makes of one sample, lane by lane.
#[derive(Debug, Default)]
pub(super) struct Block {
    /// The sample's kernel at the member (set only in blocks where some member counts or
    /// takes the sample).
    pub k: [f32; LANES],
    /// What the member adds to the lenders' density there (0 when it is not a technique).
    pub technique: [f32; LANES],
    /// What the member's own technique adds to the density for it as a receiver (0 for a
    /// lender: it is counted among them).
    pub own: [f32; LANES],
    /// Bit j: member `start + j` is a technique (the others' `technique` is 0).
    pub techniques: u32,
    /// Bit j: member `start + j` takes the sample.
    pub receives: u32,
}

impl Sample<'_> {
    /// Members `start..start + valid` (`valid` at most [`LANES`]) into `out`: exactly what
    /// lending one member at a time works out (see [`super::lend_one`]); lanes from `valid` on
    /// neither count nor receive.
    #[inline]
    pub(super) fn block(&self, cols: &Columns, start: usize, valid: usize, out: &mut Block) {
        let column = |c: &[f32]| load(c, start);
        let flag = |c: &[f32]| column(c).cmp_eq(f32x8::ONE);
        let kernel = self.kernel;
        let ((dx, dy), d2, c) = cols.offsets(self.centre, self.shift, start);
        let lane: [f32; LANES] = std::array::from_fn(|j| j as f32);
        let in_reach = d2.cmp_lt(f32x8::splat(self.reach2))
            & f32x8::from(lane).cmp_lt(f32x8::splat(valid as f32));
        let (lo, hi) = (column(&cols.lo), column(&cols.hi));
        let covered = flag(&cols.covered);
        let takes = !covered & lo.cmp_le(c) & c.cmp_le(hi);
        let counts = takes | (covered & c.cmp_lt(lo));
        let lattice = i32x8::from(lanes(&cols.lattice, start)) & i32x8::splat(self.mask as i32);
        let lender = lattice.round_float().cmp_eq(f32x8::ZERO);
        let technique = in_reach & lender & counts;
        let receiver = in_reach & flag(&cols.needy) & takes;
        // Where sites are dense and few borrow, whole blocks neither count nor take it.
        let wanted = (technique | receiver).move_mask();
        if wanted == 0 {
            out.technique = [0.0; LANES];
            out.techniques = 0;
            out.receives = 0;
            return;
        }
        let k = match kernel {
            ShiftKernel::Disc(disc) => disc_block(disc, (dx, dy), d2),
            // Any other aperture's table is read only where it is used (the others' value
            // is masked).
            ShiftKernel::Shaped(table) => table.at_lanes((dx, dy), wanted as u32),
        };
        let nk = column(&cols.n) * k;
        out.k = k.to_array();
        out.technique = technique.blend(nk, f32x8::ZERO).to_array();
        out.own = lender.blend(f32x8::ZERO, nk).to_array();
        out.techniques = technique.move_mask() as u32;
        out.receives = (receiver & k.cmp_gt(f32x8::ZERO)).move_mask() as u32;
    }
}

/// The unit disc's kernel ([`DiscKernel::within`]) at offsets `(dx, dy)`, of squared lengths
/// `d2`, lane by lane.
#[inline]
fn disc_block(kernel: &DiscKernel, (dx, dy): (f32x8, f32x8), d2: f32x8) -> f32x8 {
    // As `DiscKernel::within`: the bin is at most RADIAL - 1 (also for offsets out of
    // reach, whose value is masked).
    let kt = d2 * f32x8::splat(kernel.bins_per_d2);
    let t0 = kt.min(f32x8::splat((RADIAL - 1) as f32)).fast_trunc_int();
    let ft = kt - t0.round_float();
    let bins = t0.to_array();
    let (mut b0x, mut b0y, mut b1x, mut b1y) = (
        [0.0f32; LANES],
        [0.0f32; LANES],
        [0.0f32; LANES],
        [0.0f32; LANES],
    );
    for j in 0..LANES {
        let t = (bins[j] as usize).min(RADIAL - 1);
        (b0x[j], b0y[j]) = kernel.bins[t].into();
        (b1x[j], b1y[j]) = kernel.bins[t + 1].into();
    }
    let one_minus = f32x8::ONE - ft;
    let v0 = f32x8::from(b0x) * one_minus + f32x8::from(b1x) * ft;
    let v1 = f32x8::from(b0y) * one_minus + f32x8::from(b1y) * ft;
    let tilt = f32x8::splat(kernel.tilt.x) * dx + f32x8::splat(kernel.tilt.y) * dy;
    (v0 - tilt * v1).max(f32x8::ZERO)
}

/// The block of `column` from `start`, as a vector.
#[inline]
fn load(column: &[f32], start: usize) -> f32x8 {
    f32x8::from(lanes(column, start))
}

/// The block of `column` from `start`: one bounds check for all its lanes.
#[inline]
fn lanes<T: Copy>(column: &[T], start: usize) -> [T; LANES] {
    let block: &[T; LANES] = column[start..start + LANES]
        .try_into()
        .expect("a slice of LANES elements");
    *block
}

#[cfg(test)]
mod tests {
    use super::super::{Kernel, Member};
    use super::*;
    use crate::camera::aperture::{ApertureShape, test_shapes};
    use crate::filter::{PixelFilter, PixelFilterKind};
    use crate::sampler::hash64;

    /// A number in [lo, hi) from a counter.
    fn uniform(i: u64, lo: f32, hi: f32) -> f32 {
        lo + (hash64(i) >> 40) as f32 / (1u64 << 24) as f32 * (hi - lo)
    }

    /// Members scattered around a sample, some covered, some not needy, on lattices of
    /// every spacing, with clusters around and away from the sample's shift.
    fn members(seed: u64, count: usize) -> Vec<Member> {
        (0..count)
            .map(|i| {
                let key = seed ^ ((i as u64) << 8);
                let u = |k: u64, lo: f32, hi: f32| uniform(key + k, lo, hi);
                let lo = u(0, -3.0, 9.0);
                Member {
                    p: i,
                    lattice: (hash64(key + 1) % 64) as usize,
                    at: Vec2::new(u(2, 0.0, 40.0), u(3, 0.0, 40.0)),
                    n: u(4, 1.0, 64.0).floor(),
                    lo,
                    hi: lo + u(5, 0.0, 3.0),
                    gradient: Vec2::new(u(6, -0.3, 0.3), u(7, -0.3, 0.3)),
                    needy: hash64(key + 8) % 4 != 0,
                    covered: hash64(key + 9) % 5 == 0,
                    hidden: false,
                }
            })
            .collect()
    }

    /// The block loop gives exactly (to the bit) what the member-by-member arithmetic gives,
    /// and nothing for the lanes past `valid`: for the disc, polygons and an oval.
    #[test]
    fn a_block_is_the_members_one_by_one() {
        for aperture in test_shapes() {
            block_is_members_one_by_one(&aperture);
        }
    }

    fn block_is_members_one_by_one(aperture: &ApertureShape) {
        let kernel = Kernel::new(
            &PixelFilter::new(PixelFilterKind::BlackmanHarris).density(),
            aperture,
        );
        for seed in 0..40u64 {
            let ms = members(seed << 32, 37);
            let cols = Columns::new(&ms);
            let shift = uniform(seed, -12.0, 12.0);
            let gradient = Vec2::new(uniform(seed + 1, -0.2, 0.2), uniform(seed + 2, -0.2, 0.2));
            let k_at = kernel.for_sample(shift, gradient);
            let centre = Vec2::new(uniform(seed + 3, 5.0, 35.0), uniform(seed + 4, 5.0, 35.0));
            let extent = kernel.reach().of(shift.abs().max(0.5));
            let mask = (1u32 << (seed % 6)) - 1;
            let sample = Sample {
                centre,
                shift,
                reach2: extent * extent,
                mask,
                kernel: &k_at,
            };
            let mut block = Block::default();
            for start in (0..ms.len()).step_by(LANES) {
                let valid = (ms.len() - start).min(LANES);
                sample.block(&cols, start, valid, &mut block);
                let covers = covers(&cols, (centre, shift, extent), start, valid);
                for j in 0..LANES {
                    let receives_j = block.receives & (1 << j) != 0;
                    if j >= valid {
                        assert!(!receives_j && block.technique[j] == 0.0);
                        assert_eq!(block.techniques & (1 << j), 0);
                        assert_eq!(covers & (1 << j), 0);
                        continue;
                    }
                    let m = &ms[start + j];
                    let d = centre - m.at;
                    let in_reach = d.length_squared() < extent * extent;
                    let c = shift - m.gradient.dot(d);
                    let takes = !m.covered && (m.lo..=m.hi).contains(&c);
                    let counts = takes || (m.covered && c < m.lo);
                    let lender = m.lattice as u32 & mask == 0;
                    let k = k_at.at(d);
                    let what = format!("seed {seed}, member {}", start + j);
                    // The kernel is read only where the site counts or takes the sample (a
                    // block where none does stops before it).
                    if in_reach && ((lender && counts) || (m.needy && takes)) {
                        assert_eq!(block.k[j].to_bits(), k.to_bits(), "{what}");
                    }
                    let technique = if in_reach && lender && counts {
                        m.n * k
                    } else {
                        0.0
                    };
                    assert_eq!(block.technique[j].to_bits(), technique.to_bits(), "{what}");
                    if block.techniques & (1 << j) == 0 {
                        assert_eq!(technique, 0.0, "{what}");
                    }
                    let receives = in_reach && m.needy && takes && k > 0.0;
                    assert_eq!(receives_j, receives, "{what}");
                    if receives {
                        let own = if lender { 0.0 } else { m.n * k };
                        assert_eq!(block.own[j].to_bits(), own.to_bits(), "{what}");
                    }
                    assert_eq!(covers & (1 << j) != 0, in_reach && c < m.lo, "{what}");
                }
            }
        }
    }
}
