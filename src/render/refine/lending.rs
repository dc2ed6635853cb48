//! [`super::refine`] with sample reuse ([`reuse`]): buckets lend across their borders.
//!
//! Lending within each bucket alone left seams at its borders: receivers either side of one
//! drew on disjoint sets of samples, so their (smooth, low-frequency) error jumped there.
//! Here a site borrows from its own bucket's sites and its neighbours', so one near a
//! border draws on both sides of it, as one inside draws on all around it.
//!
//! **Sites, once.** Once the 3 x 3 block of buckets around a bucket is refined, its sites are
//! worked out ([`prepare`]): each one's cluster of shifts from its own samples, and whether a
//! nearer sample of any site of that block crosses it (it then neither lends nor borrows).
//! Every window that holds the bucket reads them.
//!
//! **Windows.** A block of up to [`CHUNK`] buckets (4 across, 2 down) lends as one
//! *window*: its sites receive, and every site of the block one bucket larger each way lends
//! (a sample reaches receivers within its blur plus the filter's reach of it, and its
//! density counts the sites within that of it again: a bucket's width covers both but for
//! the largest blurs, which lose the lenders beyond it). The windows are fixed by the frame,
//! so a region renders as in the full frame: the buckets its windows read are prepared, and
//! those around them refined, too.
//!
//! **One value a site.** A site on a bucket's last column or row (a cell's corner there) may
//! be traced by two to four buckets; their samples are the same up to the fewer's count, so
//! it counts once, as traced by the one that took the most, and its value is the one its
//! own bucket's window gives it. Every bucket that interpolates from it uses that value.
//!
//! **Order and memory.** Buckets are refined a band of rows at a time (enough for the
//! threads); each step also prepares the rows whose neighbours are refined, lends the
//! windows whose blocks are prepared and colours the rows whose next row is lent, and a
//! row's samples are dropped once nothing still to come reads them: a few rows of samples
//! are held, not the frame's, and each bucket asks the memory budget for room before it is
//! refined ([`Pipeline::room_to_refine`]).
//!
//! **What it costs.** A sample near a window's border is weighed once per window it reaches,
//! so larger windows lend for less: on paper at 1920 px, 64 spp, 4 x 2 took the render from
//! 8.98 to 7.37 s against 4 x 1, 4 x 3 to 7.06 s. Working each window's sites out afresh (a
//! site about three times) took, on paper at 640 px, 32 spp, one thread, windows of 4 x 1:
//! clusters 0.09 s, occlusion 0.22 s, gathering the windows 0.09 s, the lending itself 0.38 s,
//! against 0.02, 0.05, 0.03 and 0.34 s when each bucket lent alone; preparing them once took
//! lending from 0.40 to 0.34 s on two threads (the render 1.13 to 1.02 s), 1920 px from 7.23
//! to 6.76 s, for a row more held and a ring more of buckets refined around a region.

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use super::{Bucket, Finished, Layout, Maps, Refined, Rounds, SAMPLING_SHARE};
use crate::limits::{MemoryError, check_budget, try_collect, try_vec};
use crate::render::estimate::Estimate;
use crate::render::reuse::{self, Site, SiteRecords};
use crate::render::site::SiteShader;
use crate::render::{Progress, RenderError, Tally};

/// How many buckets across and down receive in one lending window: more share the work of
/// the window's sites (and of samples that reach several of them) among more receivers,
/// fewer give more windows to run in parallel and regions fewer buckets to refine.
const CHUNK: (usize, usize) = (4, 2);

/// The receivers of one lending window: bucket columns `cols` of bucket rows `rows`.
#[derive(Debug, Clone)]
struct Chunk {
    cols: Range<usize>,
    rows: Range<usize>,
}

impl Chunk {
    /// How many buckets receive.
    fn count(&self) -> usize {
        self.cols.len() * self.rows.len()
    }

    /// The window's buckets (columns, rows): the chunk's and one more each way.
    fn block(&self, layout: &Layout) -> (Range<usize>, Range<usize>) {
        (
            self.cols.start.saturating_sub(1)..(self.cols.end + 1).min(layout.nx),
            self.rows.start.saturating_sub(1)..(self.rows.end + 1).min(layout.ny),
        )
    }
}

/// The chunks of the frame, a row of chunks after another.
fn chunks(layout: &Layout) -> Vec<Chunk> {
    let (across, down) = CHUNK;
    (0..layout.ny)
        .step_by(down)
        .flat_map(|r| {
            (0..layout.nx).step_by(across).map(move |c| Chunk {
                cols: c..(c + across).min(layout.nx),
                rows: r..(r + down).min(layout.ny),
            })
        })
        .collect()
}

/// A row of buckets' sites once lent (the owned pixels of the row, the frame's width).
struct RowValues {
    est: Vec<Estimate>,
    borrowed: Vec<bool>,
}

impl RowValues {
    fn new(layout: &Layout) -> Result<Self, MemoryError> {
        let n = layout.width * layout.size;
        Ok(Self {
            est: try_vec(n, Estimate::default(), "the lent values")?,
            borrowed: try_vec(n, false, "the sites that borrowed")?,
        })
    }
}

/// A bucket's owned pixels' sites, pixel by pixel ([`prepare`]).
type BucketSites = Vec<Option<Site>>;

/// A step's work.
enum Task {
    Refine(usize),
    Prepare(usize),
    Lend(usize),
}

/// What a [`Task`] gave.
enum Done {
    Rounds(usize, Option<Rounds>, Box<Tally>, f64),
    Prepared(usize, BucketSites, f64),
    Lent(usize, (Vec<Estimate>, Vec<bool>), f64),
}

/// How far each stage has come: the rows of buckets before these are done.
#[derive(Debug, Default)]
struct Stages {
    refined: usize,
    prepared: usize,
    lent: usize,
    coloured: usize,
}

/// Which chunks lend, and which buckets are prepared and refined, for the buckets `wanted`.
struct Plan {
    chunks: Vec<Chunk>,
    /// By chunk: whether it lends.
    lent: Vec<bool>,
    /// By bucket: whether its sites are worked out ([`prepare`]): those of the lending
    /// windows.
    prepared: Vec<bool>,
    /// By bucket: whether it is refined: those around the prepared ones.
    traced: Vec<bool>,
}

/// Units of progress a bucket's refinement counts, against one per bucket a window lends to:
/// tracing is most of a render's work, lending about a third of it (paper at 640 px).
const REFINE_UNITS: u64 = 2;

impl Plan {
    /// The units of progress of the whole plan: its refinements and its windows' buckets.
    fn units(&self) -> u64 {
        let refined = self.traced.iter().filter(|&&t| t).count() as u64;
        let lent = (self.chunks.iter().zip(&self.lent))
            .filter_map(|(c, &l)| l.then_some(c.count() as u64))
            .sum::<u64>();
        REFINE_UNITS * refined + lent
    }

    fn new(layout: &Layout, wanted: &[bool]) -> Self {
        let chunks = chunks(layout);
        // A wanted bucket reads its own row's values and the next row's (its closure's last
        // row), in its own columns and the next one (its closure's last column).
        let lent: Vec<bool> = (chunks.iter())
            .map(|c| {
                let rows = c.rows.start.saturating_sub(1)..c.rows.end;
                let cols = c.cols.start.saturating_sub(1)..c.cols.end;
                rows.flat_map(|y| cols.clone().map(move |x| y * layout.nx + x))
                    .any(|i| wanted[i])
            })
            .collect();
        let mut prepared = vec![false; layout.count()];
        for c in (chunks.iter().zip(&lent)).filter_map(|(c, &l)| l.then_some(c)) {
            let (xs, ys) = c.block(layout);
            for y in ys {
                for x in xs.clone() {
                    prepared[y * layout.nx + x] = true;
                }
            }
        }
        let traced = (0..layout.count())
            .map(|i| layout.around(i).any(|j| prepared[j]))
            .collect();
        Self {
            chunks,
            lent,
            prepared,
            traced,
        }
    }
}

/// The work of [`refine`] as it goes: what is held and how far each stage has come.
struct Pipeline<'a> {
    shader: &'a SiteShader<'a>,
    maps: &'a Maps<'a>,
    layout: &'a Layout,
    plan: Plan,
    /// By bucket: its rounds, from its refinement until nothing still to come reads them.
    store: Vec<Option<Rounds>>,
    /// By bucket: its owned pixels' sites ([`prepare`]), until its windows are lent.
    sites: Vec<Option<BucketSites>>,
    /// By row of buckets: its sites' lent values, until the row is coloured.
    values: Vec<Option<RowValues>>,
    /// The most bytes of records a bucket has held ([`Rounds::record_bytes`]).
    /// Updated as each bucket is refined, so the buckets of the same step see it too.
    bucket_bytes: AtomicUsize,
    out: Finished,
}

/// Refines the buckets `wanted` (and those around them that their windows read), lends
/// each window's sites, and colours the wanted buckets (see the module documentation).
pub(super) fn refine(
    shader: &SiteShader,
    maps: &Maps,
    layout: &Layout,
    wanted: &[bool],
    progress: &dyn Progress,
    tally: &mut Tally,
) -> Result<Finished, RenderError> {
    let mut run = Pipeline {
        shader,
        maps,
        layout,
        plan: Plan::new(layout, wanted),
        store: (0..layout.count()).map(|_| None).collect(),
        sites: (0..layout.count()).map(|_| None).collect(),
        values: (0..layout.ny).map(|_| None).collect(),
        bucket_bytes: AtomicUsize::new(0),
        out: Finished::new(maps, layout)?,
    };
    progress.start("adaptive", run.plan.units());
    let band = (8 * rayon::current_num_threads().max(1))
        .div_ceil(layout.nx)
        .max(1);
    let down = CHUNK.1;
    let mut at = Stages::default();
    while at.coloured < layout.ny {
        let refine = at.refined..(at.refined + band).min(layout.ny);
        // A row is prepared once the row below it is refined, a row of chunks lent once the
        // row of buckets below it is prepared, a row of buckets coloured once the row below
        // it is lent.
        let prepare = at.prepared..after(at.refined, at.prepared, layout.ny);
        let mut lend_end = at.lent;
        while lend_end < layout.ny && at.prepared >= (lend_end + down + 1).min(layout.ny) {
            lend_end = (lend_end + down).min(layout.ny);
        }
        let lend = at.lent..lend_end;
        run.step(
            [refine.clone(), prepare.clone(), lend.clone()],
            progress,
            tally,
        )?;
        (at.refined, at.prepared, at.lent) = (refine.end, prepare.end, lend.end);
        let colour = at.coloured..after(at.lent, at.coloured, layout.ny);
        run.colour(colour.clone(), wanted);
        at.coloured = colour.end;
        run.drop_done(&at);
    }
    Ok(run.out)
}

impl Pipeline<'_> {
    /// Refines, prepares and lends the rows of buckets `rows` (each stage's whose inputs
    /// the earlier steps made), in parallel.
    fn step(
        &mut self,
        [refine, to_prepare, lend]: [Range<usize>; 3],
        progress: &dyn Progress,
        tally: &mut Tally,
    ) -> Result<(), RenderError> {
        let (layout, plan) = (self.layout, &self.plan);
        let (across, down) = CHUNK;
        let per_row = layout.nx.div_ceil(across);
        let buckets = |rows: Range<usize>| rows.start * layout.nx..rows.end * layout.nx;
        // The windows first: they are the longest tasks, and started last they would keep
        // the other threads waiting at the step's end.
        let tasks: Vec<Task> = (lend.start / down * per_row..lend.end.div_ceil(down) * per_row)
            .filter(|&c| plan.lent[c])
            .map(Task::Lend)
            .chain(
                buckets(to_prepare)
                    .filter(|&i| plan.prepared[i])
                    .map(Task::Prepare),
            )
            .chain(
                buckets(refine)
                    .filter(|&i| plan.traced[i])
                    .map(Task::Refine),
            )
            .collect();
        let s = self.shader.settings;
        let done: Vec<Done> = tasks
            .par_iter()
            .with_max_len(1)
            .map(|task| {
                let started = Instant::now();
                let seconds = || started.elapsed().as_secs_f64();
                match *task {
                    Task::Refine(i) => {
                        let room = self.room_to_refine();
                        if room > 0 {
                            check_budget(reuse::RECORDS_HELD, room)?;
                        }
                        let mut local = Tally::new(s.record_rays);
                        let b = layout.bucket(i);
                        let rounds =
                            super::refine_bucket(self.shader, self.maps, &b, progress, &mut local);
                        progress.advance(REFINE_UNITS);
                        if let Ok(Some(r)) = &rounds {
                            self.bucket_bytes
                                .fetch_max(r.record_bytes(), Ordering::Relaxed);
                        }
                        rounds.map(|r| Done::Rounds(i, r, Box::new(local), seconds()))
                    }
                    Task::Prepare(i) => {
                        let sites = prepare(self.maps, layout, &self.store, i)?;
                        Ok(Done::Prepared(i, sites, seconds()))
                    }
                    Task::Lend(c) => {
                        let chunk = &plan.chunks[c];
                        let window = (&self.store[..], &self.sites[..]);
                        let lent = lend_chunk(self.maps, layout, window, chunk, s.transparent)?;
                        progress.advance(chunk.count() as u64);
                        Ok(Done::Lent(c, lent, seconds()))
                    }
                }
            })
            .collect::<Result<_, MemoryError>>()?;
        for d in done {
            match d {
                Done::Rounds(i, rounds, local, seconds) => {
                    tally.merge(*local);
                    let Some(mut rounds) = rounds else {
                        return Err(RenderError::Cancelled);
                    };
                    self.out.gather(&mut rounds, layout.width);
                    self.store[i] = Some(rounds);
                    self.out.work_seconds += seconds;
                }
                Done::Prepared(i, sites, seconds) => {
                    self.sites[i] = Some(sites);
                    self.out.work_seconds += seconds;
                    self.out.lend_seconds += seconds;
                }
                Done::Lent(c, lent, seconds) => {
                    let chunk = &self.plan.chunks[c];
                    place(layout, chunk, &mut self.values, lent)?;
                    self.out.work_seconds += seconds;
                    self.out.lend_seconds += seconds;
                }
            }
        }
        Ok(())
    }

    /// The memory a bucket checks is left before it is refined: under a cgroup no allocation
    /// fails (the kernel grants it, then its OOM killer ends the process), so each bucket
    /// first asks the budget for room for twice the records the largest so far held, for
    /// every thread (buckets grow down a frame, and windows take their share). Nothing
    /// (0) while that is under a megabyte: reading the budget costs about 0.1 ms, a bucket
    /// that records a megabyte takes far longer to trace.
    fn room_to_refine(&self) -> u128 {
        let most = self.bucket_bytes.load(Ordering::Relaxed) as u128;
        let room = 2 * most * rayon::current_num_threads() as u128;
        if room < 1 << 20 { 0 } else { room }
    }

    /// Drops what no later step reads, given how far the stages have come.
    fn drop_done(&mut self, at: &Stages) {
        let nx = self.layout.nx;
        // A row's samples are read by the preparing of the rows beside it, by the windows
        // whose blocks hold it or the row below it (a site on a block's first row may be
        // the row above's), and by its colouring; its sites by the windows whose blocks hold
        // it; its values by its own and the row above's colouring.
        let samples = (at.prepared.saturating_sub(1))
            .min(at.lent.saturating_sub(2))
            .min(at.coloured);
        for y in 0..samples {
            self.store[y * nx..(y + 1) * nx].fill_with(|| None);
        }
        for y in 0..at.lent.saturating_sub(1) {
            self.sites[y * nx..(y + 1) * nx].fill_with(|| None);
        }
        self.values[..at.coloured].fill_with(|| None);
    }

    /// Colours the buckets `wanted` in the rows `rows` (whose own and next rows are lent).
    fn colour(&mut self, rows: Range<usize>, wanted: &[bool]) {
        let layout = self.layout;
        let started = Instant::now();
        let (store, values) = (&self.store, &self.values);
        let coloured: Vec<(Bucket, Refined)> = (rows.start * layout.nx..rows.end * layout.nx)
            .filter(|&i| wanted[i])
            .collect::<Vec<_>>()
            .par_iter()
            .map(|&i| {
                let b = layout.bucket(i);
                let row = b.y0 / layout.size;
                let rounds = store[i].as_ref().expect("a coloured bucket is refined");
                let own = values[row]
                    .as_ref()
                    .expect("a coloured bucket's row is lent");
                let next = values.get(row + 1).and_then(Option::as_ref);
                let refined = colour(layout, rounds, &b, (own, next));
                (b, refined)
            })
            .collect();
        self.out.work_seconds += started.elapsed().as_secs_f64();
        self.out.buckets.extend(coloured);
    }
}

/// The end of the rows whose next row is done, given rows up to `done_to` are done and up
/// to `from` were already taken, of `n`.
fn after(done_to: usize, from: usize, n: usize) -> usize {
    if done_to == n {
        n
    } else {
        done_to.saturating_sub(1).max(from)
    }
}

/// Copies a chunk's lent values (its owned pixels, row by row) into its rows of buckets'.
fn place(
    layout: &Layout,
    chunk: &Chunk,
    values: &mut [Option<RowValues>],
    (est, borrowed): (Vec<Estimate>, Vec<bool>),
) -> Result<(), MemoryError> {
    let (x0, y0) = (
        chunk.cols.start * layout.size,
        chunk.rows.start * layout.size,
    );
    let w = (chunk.cols.end * layout.size).min(layout.width) - x0;
    for (y, (e, b)) in est.chunks(w).zip(borrowed.chunks(w)).enumerate() {
        let (row, local) = ((y0 + y) / layout.size, (y0 + y) % layout.size);
        let row = match &mut values[row] {
            Some(row) => row,
            empty => empty.insert(RowValues::new(layout)?),
        };
        let at = local * layout.width + x0;
        row.est[at..at + w].copy_from_slice(e);
        row.borrowed[at..at + w].copy_from_slice(b);
    }
    Ok(())
}

/// Bucket `i`'s owned pixels' sites as they take part in lending ([`reuse::sites`]), their
/// coverage tested against every sample of the 3 x 3 block of buckets around it
/// ([`reuse::mark_covered`]): worked out once, read by every window that holds the bucket.
fn prepare(
    maps: &Maps,
    layout: &Layout,
    store: &[Option<Rounds>],
    i: usize,
) -> Result<BucketSites, MemoryError> {
    let kernel = maps.kernel.as_ref().expect("lending has its kernel");
    let b = layout.bucket(i);
    let (w, h) = (b.owned_w, b.owned_h);
    let at = |p: usize| canonical(layout, store, (b.x0 + p % w, b.y0 + p / w));
    let own = try_collect((0..w * h).map(at), "a bucket's sites")?;
    let records = try_collect(own.iter().map(Canonical::records), "a bucket's sites")?;
    let mut sites = reuse::sites((b.x0, b.y0), w, &records);
    // Every sample of the buckets around (a site two buckets traced twice: its samples
    // count once for coverage as twice).
    let around: Vec<&SiteRecords> = layout
        .around(i)
        .flat_map(|j| {
            let rounds = store[j]
                .as_ref()
                .expect("a prepared bucket's neighbours are refined");
            rounds.records()
        })
        .collect();
    reuse::mark_covered(kernel, (b.x0, b.y0), (w, h), &mut sites, &around);
    Ok(sites)
}

/// Lends the sites of `chunk` the samples of every site of its window
/// ([`reuse::lend_sites`]), given each bucket's `rounds` and `sites` ([`prepare`]): the
/// values of the chunk's owned pixels (lent where they borrowed, their own samples' mean
/// elsewhere, nothing where untraced) and which borrowed, row by row. Only blurred sites
/// still noisier than the rule wanted borrow (the others' error is already within what the
/// tolerance allows); where and how many samples were taken was decided on the sites' own
/// samples alone.
fn lend_chunk(
    maps: &Maps,
    layout: &Layout,
    (store, prepared): (&[Option<Rounds>], &[Option<BucketSites>]),
    chunk: &Chunk,
    transparent: bool,
) -> Result<(Vec<Estimate>, Vec<bool>), MemoryError> {
    let kernel = maps.kernel.as_ref().expect("lending has its kernel");
    let size = layout.size;
    let (xs, ys) = chunk.block(layout);
    let (x0, y0) = (xs.start * size, ys.start * size);
    let (w, h) = (
        (xs.end * size).min(layout.width) - x0,
        (ys.end * size).min(layout.height) - y0,
    );
    let pixel = |p: usize| (x0 + p % w, y0 + p / w);
    let at = |p: usize| canonical(layout, store, pixel(p));
    let traced = try_collect((0..w * h).map(at), "a lending window's sites")?;
    let records = try_collect(
        traced.iter().map(Canonical::records),
        "a lending window's sites",
    )?;
    let own = try_collect(traced.iter().map(|s| *s.est()), "a lending window's sites")?;
    let site = |p: usize| {
        let (x, y) = pixel(p);
        let i = (y / size) * layout.nx + x / size;
        let b = layout.bucket(i);
        let sites = prepared[i]
            .as_ref()
            .expect("a window's buckets are prepared");
        sites[(y - b.y0) * b.owned_w + (x - b.x0)]
    };
    let sites = try_collect((0..w * h).map(site), "a lending window's sites")?;
    // The receivers: the chunk's owned pixels.
    let (cx0, cy0) = (chunk.cols.start * size, chunk.rows.start * size);
    let cw = (chunk.cols.end * size).min(layout.width) - cx0;
    let ch = (chunk.rows.end * size).min(layout.height) - cy0;
    let index = |x: usize, y: usize| (cy0 + y - y0) * w + (cx0 + x - x0);
    let limit = SAMPLING_SHARE * maps.tolerance;
    let mut needy = try_vec(w * h, false, "the sites that borrow")?;
    for y in 0..ch {
        for x in 0..cw {
            let p = index(x, y);
            needy[p] = reuse::borrows(sites[p], traced[p].noisier_than(limit, transparent));
        }
    }
    let window = (&records[..], &sites[..]);
    let lending = (kernel, maps.nearest.as_ref());
    let lent = reuse::lend_sites(lending, (x0, y0), (w, h), window, &own, &needy)?;
    let mut est = try_vec(cw * ch, Estimate::default(), "the lent values")?;
    let mut borrowed = try_vec(cw * ch, false, "the sites that borrowed")?;
    for y in 0..ch {
        for x in 0..cw {
            est[y * cw + x] = lent.estimates[index(x, y)];
            borrowed[y * cw + x] = lent.borrowed[index(x, y)];
        }
    }
    Ok((est, borrowed))
}

/// A site as one bucket traced it: that bucket's rounds and the site's index in its closure.
#[derive(Clone, Copy)]
struct Canonical<'a> {
    rounds: &'a Rounds,
    q: usize,
}

impl<'a> Canonical<'a> {
    fn est(&self) -> &'a Estimate {
        &self.rounds.traced.est[self.q]
    }

    fn records(&self) -> &'a SiteRecords {
        &self.rounds.records()[self.q]
    }

    /// Noisier than `limit` in colour or, with `transparent`, coverage (code values).
    fn noisier_than(&self, limit: f32, transparent: bool) -> bool {
        let t = &self.rounds.traced;
        t.se[self.q] > limit || (transparent && t.se_alpha[self.q] > limit)
    }
}

/// The site at pixel `(x, y)` as the bucket that took the most samples of it has it: its
/// owner, or one whose closure's last column or row it lies on (the owner on a tie).
fn canonical<'a>(
    layout: &Layout,
    store: &'a [Option<Rounds>],
    (x, y): (usize, usize),
) -> Canonical<'a> {
    let size = layout.size;
    let (bx, by) = (x / size, y / size);
    let (left, up) = (x % size == 0 && bx > 0, y % size == 0 && by > 0);
    let candidates = [
        (bx, by, true),
        (bx.wrapping_sub(1), by, left),
        (bx, by.wrapping_sub(1), up),
        (bx.wrapping_sub(1), by.wrapping_sub(1), left && up),
    ];
    let mut best: Option<Canonical> = None;
    for (cx, cy, _) in candidates.into_iter().filter(|&(.., on)| on) {
        let i = cy * layout.nx + cx;
        let b = layout.bucket(i);
        let rounds = store[i]
            .as_ref()
            .expect("the buckets that may have traced a site are refined");
        let found = Canonical {
            rounds,
            q: (y - b.y0) * b.w + (x - b.x0),
        };
        if best.is_none_or(|best| found.est().n > best.est().n) {
            best = Some(found);
        }
    }
    best.expect("a pixel's own bucket is a candidate")
}

/// Bucket `b`'s colours from its sites' lent values: those of its own row, `rows.0`, and of
/// the next, `rows.1` (its closure's last row lies there).
fn colour(
    layout: &Layout,
    rounds: &Rounds,
    b: &Bucket,
    (own, next): (&RowValues, Option<&RowValues>),
) -> Refined {
    let row_y0 = b.y0 / layout.size * layout.size;
    let mut est = rounds.traced.est.clone();
    let mut borrowed = vec![false; b.w * b.h];
    for y in 0..b.h {
        let gy = b.y0 + y;
        let (values, vy) = if gy < row_y0 + layout.size {
            (own, gy - row_y0)
        } else {
            (
                next.expect("a bucket's last closure row is lent"),
                gy - row_y0 - layout.size,
            )
        };
        for x in 0..b.w {
            let (q, v) = (y * b.w + x, vy * layout.width + b.x0 + x);
            // Pixels this bucket did not trace are interpolated from those it did.
            if est[q].n > 0 {
                est[q] = values.est[v];
                borrowed[q] = values.borrowed[v];
            }
        }
    }
    rounds.result(b, &est, borrowed)
}
