//! In-focus sites share their samples through the pixel filter.
//!
//! A site draws its samples' film positions from the pixel filter around its own pixel
//! (filter importance sampling), and each counts towards that pixel alone, though the filter
//! of every pixel within its reach covers it too. Where blur reaches no pixel, the sites lend
//! nothing ([`super::reuse`]), so each keeps to its own samples, as noisy as dense's. Here
//! every such site q is a *technique* that draws film positions x with density `f(x - q)`
//! (the filter's), and pixel p's filtered radiance `∫ f(x - p) L(x) dx` is estimated from the
//! samples of all of them by multiple importance sampling, each technique's samples averaged
//! as one:
//!
//! `value(p) = Σ_q (1 / W_q) Σ_i w_i f(x_i - p) L_i / P(x_i)`, with `P(x) = Σ_r f(x - r)`
//!
//! over the techniques r, where `w_i` is a sample's lens-filter weight and `W_q` their sum
//! over q's samples. Its expectation is p's filtered radiance whatever the sites' sample
//! counts (`P` does not depend on them), so a quiet site that stops early ([`super::allocation`])
//! weighs its neighbours as much as a noisy one. The value is then divided by the same
//! weights' sum (`Σ_q (1 / W_q) Σ_i w_i f(x_i - p) / P(x_i)`, whose expectation is 1): exact
//! on a flat region, as a site's own mean is, for a ratio's bias of order 1 / samples. The
//! weights use the sampler's own tabulated density ([`FilterSampler::density`]), so they
//! cancel the density each sample was drawn with exactly.
//!
//! A 3 px Blackman-Harris filter covers about 2.2 pixels' samples (`1 / ∫ f²`): light noise
//! there falls by up to that factor (a site's own samples are stratified, the gathered ones
//! are not: 1.6 times on the in-focus pixels of `scenes/gallery.toml`), for a few filter
//! evaluations per sample. The noise of neighbouring pixels becomes correlated (finer
//! grain), as with any splatting film. Filters wider than 3 px take no part.
//!
//! The techniques are the frame's pixels that no blur reaches ([`super::maps::Blur::blurred`]):
//! a property of the depth pass, so a sample's `P` is known as it is traced, and a region
//! renders as the whole frame does.

use glam::{Vec2, Vec3, Vec4};

use crate::filter::FilterSampler;

/// A sample reaches pixels up to this far from its site's, per axis: the filter's reach
/// (half its width, at most 1.5 px) from an offset of at most as much.
pub const REACH: usize = 2;
const SIDE: usize = 2 * REACH + 1;
/// The pixels a site's samples may reach.
pub const SLOTS: usize = SIDE * SIDE;

/// What samples add to one pixel, each weighed by `w f(x - p) / P(x)`: their light and that
/// weight (the normaliser), their hits and the weight of those the lens let through.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Slot {
    light: Vec4,
    cover: Vec2,
}

impl std::ops::AddAssign for Slot {
    fn add_assign(&mut self, o: Self) {
        self.light += o.light;
        self.cover += o.cover;
    }
}

impl std::ops::Mul<f32> for Slot {
    type Output = Self;
    fn mul(self, k: f32) -> Self {
        Self {
            light: self.light * k,
            cover: self.cover * k,
        }
    }
}

impl Slot {
    /// The colour and coverage its weights give, None without weight. Self-normalised (its
    /// light over its normaliser, both estimating what they would over the filter's unit
    /// mass): exact for a flat region, as a site's own mean is, at a bias of order 1 /
    /// samples.
    pub fn value(&self) -> Option<Vec4> {
        let l = self.light;
        if l.w.is_nan() || l.w <= 0.0 {
            return None;
        }
        let coverage = if self.cover.y > 0.0 {
            (self.cover.x / self.cover.y).min(1.0)
        } else {
            0.0
        };
        Some((l.truncate() / l.w).extend(coverage))
    }
}

/// What one site's samples add to the pixels around it (offsets -REACH..=REACH per axis, row
/// by row); divided by the site's weight once its samples are all taken.
pub type Slots = [Slot; SLOTS];

/// The techniques of a frame and the filter they draw from.
#[derive(Debug, Clone, Copy)]
pub struct Gather<'a> {
    /// By pixel of the frame: whether its site is a technique (no blur reaches it).
    techniques: &'a [bool],
    width: usize,
    height: usize,
    sampler: &'a FilterSampler,
}

impl<'a> Gather<'a> {
    /// The gathering of a `width` x `height` frame whose pixels `techniques` take part, for
    /// the pixel filter whose offsets `sampler` draws, reaching `reach` pixels from the
    /// centre; None beyond 1.5 px (a filter wider than 3), whose samples would reach farther
    /// than [`REACH`].
    pub fn new(
        techniques: &'a [bool],
        (width, height): (usize, usize),
        (sampler, reach): (&'a FilterSampler, f32),
    ) -> Option<Self> {
        (reach <= 1.5).then_some(Self {
            techniques,
            width,
            height,
            sampler,
        })
    }

    /// Whether pixel (x, y) takes part.
    pub fn takes_part(&self, (x, y): (usize, usize)) -> bool {
        self.techniques[y * self.width + x]
    }

    /// Adds to `slots` a sample of the site at pixel (x, y) (a technique) at film position
    /// `film`, of value `value` (lens weight applied) and lens-filter weight `w`; `hit`:
    /// whether it hit geometry, None when the lens blocked it (no light, no coverage).
    pub fn add(
        &self,
        slots: &mut Slots,
        (x, y): (usize, usize),
        film: Vec2,
        (value, w, hit): (Vec3, f32, Option<bool>),
    ) {
        let along = |c: usize, n: usize, at: f32| -> [f32; SIDE] {
            std::array::from_fn(|i| {
                let r = (c + i).wrapping_sub(REACH);
                if r < n {
                    self.sampler.density(at - (r as f32 + 0.5))
                } else {
                    0.0
                }
            })
        };
        let (fx, fy) = (along(x, self.width, film.x), along(y, self.height, film.y));
        // The receivers' weights, row by row: none where it is no technique (or outside).
        // Only the few taps inside the filter's support are visited (3 x 3 of the 5 x 5 for
        // the 3 px filters), in the same order, so the sums are the same to the bit.
        let mut weights = [(0usize, 0.0f32); SLOTS];
        let mut len = 0;
        let mut total = 0.0f32;
        for (j, &wy) in fy.iter().enumerate().filter(|(_, w)| **w > 0.0) {
            for (i, &wx) in fx.iter().enumerate().filter(|(_, w)| **w > 0.0) {
                let f = wx * wy;
                if f > 0.0 && self.takes_part((x + i - REACH, y + j - REACH)) {
                    weights[len] = (j * SIDE + i, f);
                    len += 1;
                    total += f;
                }
            }
        }
        // The site's own pixel always weighs the sample (it drew it from its filter).
        if total.is_nan() || total <= 0.0 {
            return;
        }
        let seen = if hit.is_some() { w } else { 0.0 };
        let hits = if hit == Some(true) { w } else { 0.0 };
        let sample = Slot {
            light: (value * w).extend(w),
            cover: Vec2::new(hits, seen),
        } * (1.0 / total);
        for &(k, f) in &weights[..len] {
            slots[k] += sample * f;
        }
    }

    /// Adds to `out` (a window `out_width` wide whose top left pixel is `origin` in the
    /// frame) what the site at pixel (x, y) gives the pixels around it: its `slots` over its
    /// samples' summed lens-filter weight `weight`. Nothing without samples.
    pub fn spread(
        &self,
        slots: &Slots,
        weight: f32,
        (x, y): (usize, usize),
        (origin, out_width): ((usize, usize), usize),
        out: &mut [Slot],
    ) {
        if weight.is_nan() || weight <= 0.0 {
            return;
        }
        for j in 0..SIDE {
            for i in 0..SIDE {
                let s = slots[j * SIDE + i];
                if s == Slot::default() {
                    continue;
                }
                let (rx, ry) = (x + i - REACH, y + j - REACH);
                let (ox, oy) = (rx - origin.0, ry - origin.1);
                out[oy * out_width + ox] += s * (1.0 / weight);
            }
        }
    }
}

/// What one bucket's sites give the pixels within [`REACH`] of its own: a window of the
/// frame. Summed over the buckets in a fixed order ([`Layer::add_to`]), every pixel gets its
/// value from the same sums in the same order, whichever buckets a region renders.
#[derive(Debug, Clone)]
pub struct Layer {
    origin: (usize, usize),
    width: usize,
    height: usize,
    values: Vec<Slot>,
}

impl Layer {
    /// The empty layer of the bucket whose own pixels are `width` x `height` from `(x0, y0)`,
    /// in a frame `frame` in size.
    pub fn new(
        (x0, y0): (usize, usize),
        (width, height): (usize, usize),
        frame: (usize, usize),
    ) -> Result<Self, crate::limits::MemoryError> {
        let origin = (x0.saturating_sub(REACH), y0.saturating_sub(REACH));
        let end = (
            (x0 + width + REACH).min(frame.0),
            (y0 + height + REACH).min(frame.1),
        );
        let (w, h) = (end.0 - origin.0, end.1 - origin.1);
        Ok(Self {
            origin,
            width: w,
            height: h,
            values: crate::limits::try_vec(w * h, Slot::default(), "the gathered samples")?,
        })
    }

    /// Adds the site at frame pixel (x, y) (of this layer's bucket): see [`Gather::spread`].
    pub fn spread(&mut self, gather: &Gather, slots: &Slots, weight: f32, at: (usize, usize)) {
        let window = (self.origin, self.width);
        gather.spread(slots, weight, at, window, &mut self.values);
    }

    /// Adds the layer into `frame` (the frame's pixels, `frame_width` wide).
    pub fn add_to(&self, frame: &mut [Slot], frame_width: usize) {
        for y in 0..self.height {
            let row = &self.values[y * self.width..(y + 1) * self.width];
            let at = (self.origin.1 + y) * frame_width + self.origin.0;
            for (o, v) in frame[at..at + self.width].iter_mut().zip(row) {
                *o += *v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::{PixelFilter, PixelFilterKind};
    use crate::sampler::hash64;

    /// A number in [0, 1) from a counter.
    fn uniform(i: u64) -> f32 {
        (hash64(i) >> 40) as f32 / (1u64 << 24) as f32
    }

    const N: usize = 9;

    /// The gathered values of an N x N frame whose sites `techniques` take part, each site q
    /// taking `count(q)` samples drawn from its filter, of light `light(x, y, i)` (film
    /// position and sample index); `trial` seeds the draws.
    fn gathered(
        techniques: &[bool],
        count: impl Fn(usize) -> usize,
        light: impl Fn(f32, f32, u64) -> f32,
        trial: u64,
    ) -> Vec<Option<Vec4>> {
        let filter = PixelFilter::new(PixelFilterKind::BlackmanHarris);
        let sampler = filter.sampler();
        let g = Gather::new(techniques, (N, N), (&sampler, filter.width / 2.0)).unwrap();
        let mut frame = vec![Slot::default(); N * N];
        for q in (0..N * N).filter(|&q| techniques[q]) {
            let (x, y) = (q % N, q / N);
            let mut slots = [Slot::default(); SIDE * SIDE];
            let n = count(q);
            for i in 0..n {
                let k = ((trial * 131 + q as u64) * 64 + i as u64) * 4;
                let film = Vec2::new(
                    x as f32 + 0.5 + sampler.offset(uniform(k)),
                    y as f32 + 0.5 + sampler.offset(uniform(k + 1)),
                );
                let l = light(film.x, film.y, k + 2);
                g.add(&mut slots, (x, y), film, (Vec3::splat(l), 1.0, Some(true)));
            }
            g.spread(&slots, n as f32, (x, y), ((0, 0), N), &mut frame);
        }
        frame.iter().map(Slot::value).collect()
    }

    /// A flat image comes out exactly flat and opaque, however many samples each site took
    /// and whichever sites take part: the weights are normalised pixel by pixel.
    #[test]
    fn a_flat_image_stays_exactly_flat() {
        let techniques: Vec<bool> = (0..N * N).map(|q| hash64(q as u64) % 5 != 0).collect();
        let values = gathered(&techniques, |q| 1 + q % 7, |_, _, _| 0.7, 1);
        for (q, v) in values.iter().enumerate() {
            if techniques[q] {
                let v = v.expect("a site that took samples has a value");
                assert!(
                    (v.x - 0.7).abs() < 1e-5 && (v.w - 1.0).abs() < 1e-5,
                    "{q}: {v}"
                );
            }
        }
    }

    /// Over many trials the gathered value of a pixel is its filtered light, as its own
    /// samples' mean is, on an image with an edge and a ramp through the filter, sites of
    /// uneven sample counts and, around it, pixels that take no part; and on light with noise
    /// of its own it is less noisy than that mean.
    #[test]
    fn the_gathered_value_is_the_filtered_light_with_less_noise() {
        let p = 4 * N + 4;
        let edge = |x: f32, y: f32| {
            if x + 0.3 * y > 5.2 {
                1.0
            } else {
                0.2 + 0.05 * y
            }
        };
        let noisy = |x: f32, y: f32, k: u64| edge(x, y) + 2.0 * (uniform(k) - 0.5);
        let count = |q: usize| 4 + 12 * (q % 3);
        let alone: Vec<bool> = (0..N * N).map(|q| q == p).collect();
        // (gathered - own, its square; gathered's squared error, own's) over the trials.
        let trial = |techniques: &[bool], t: u64| {
            let value = |techniques: &[bool]| gathered(techniques, count, noisy, t)[p].unwrap().x;
            (f64::from(value(techniques)), f64::from(value(&alone)))
        };
        let trials = 2000u64;
        let n = trials as f64;
        // Two of its neighbours take no part (a blurred region's edge): the weights must
        // still add up where they are missing. The own mean is unbiased, so the two must
        // agree but for noise (they share the pixel's own samples, so their difference is
        // the quieter statistic).
        let holes: Vec<bool> = (0..N * N).map(|q| q != p + 1 && q != p - N).collect();
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for t in 0..trials {
            let (g, o) = trial(&holes, t);
            sum += g - o;
            sum2 += (g - o).powi(2);
        }
        let mean = sum / n;
        let se = ((sum2 / n - mean * mean) / n).sqrt();
        assert!(
            mean.abs() < 4.0 * se,
            "gathered - own: {mean} (standard error {se})"
        );
        // Every pixel around it takes part: its noise falls by about the filter's footprint
        // (1.85 times here).
        let all = vec![true; N * N];
        let (mut g1, mut g2, mut o1, mut o2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for t in 0..trials {
            let (g, o) = trial(&all, t);
            (g1, g2, o1, o2) = (g1 + g, g2 + g * g, o1 + o, o2 + o * o);
        }
        let variance = |s1: f64, s2: f64| s2 / n - (s1 / n).powi(2);
        let (gathered, own) = (variance(g1, g2), variance(o1, o2));
        assert!(
            gathered < 0.65 * own,
            "variance gathered {gathered}, own {own}"
        );
    }
}
