//! The non-overlapping Allan deviation at power-of-two cluster sizes, from a pyramid of block
//! sums.
//!
//! With the starts `m` apart, the term of cluster `k` is `x_{(k+2)m} - 2 x_{(k+1)m} + x_{km} =
//! B_{k+1} - B_k`, the difference of consecutive block sums `B_k = Σ_{j<m} (y_{km+j} - r)`
//! (`r` a reference reading of the axis, which every term cancels exactly). When every cluster
//! size is a power of two, the blocks of `2m` samples are the sums of pairs of blocks of `m`:
//! level 0 holds the readings, level `j + 1` the sums of pairs of level `j`. The whole pyramid
//! costs one addition per sample (`b/2 + b/4 + ...`), and each level is read once, in order:
//! for each pair of blocks, two differences squared and one sum.
//!
//! Rows, not axes: a record holds up to four axes of one row (or of one block) side by side,
//! so that one 256-bit operation serves every axis of a row. The readings are loaded four
//! values at a time straight from the interleaved rows (for three axes, the fourth lane is
//! the next row's first value, and is cleared); the levels above are runs of such records.
//! Each group of up to four axes reads its rows once.
//!
//! Digits: the block sums are plain doubles, but they are small: the reference removes the
//! axis's level (its value is the mean of the first batch of readings, so a block holds the
//! noise and drift of `m` samples, not `m × bias`), and pairwise sums round once per level,
//! relative to the block made (`log2 m` roundings of `B_m` at most). The tests hold the
//! pyramid within 1e-13 of the general path on data with a large bias and drift, and exact on
//! integer readings on a bias of 2⁴⁰ (their differences from a reference near them are exact,
//! and so are their sums while below 2⁵³ units of the last place).
//!
//! Each group keeps, per level, the last block (for the next difference) and a block waiting
//! for its pair; the rest lives in two batch buffers. A long push is cut into pieces that run
//! in parallel, each a pyramid of its own, joined in order; the sums are made in a fixed order,
//! so that the result does not depend on the number of threads.

use super::{kahan_add, AllanResult, Cluster, BATCH};

/// Axes per record (one 256-bit register of doubles).
const W: usize = 4;

/// Up to [`W`] axes of one row or one block, side by side (unused lanes hold 0).
type Rec = [f64; W];

/// Rows of a push from which groups of axes run on several threads.
const PARALLEL_ROWS: usize = 4096;

/// Batches checked for NaN at a time (their rows stay in cache while every group reads them).
const GROUP: usize = 4;

/// The fewest rows in a piece (see [`Octave::push`]).
const MIN_PIECE: usize = 1 << 16;

/// Records of a batch buffer: level 1 of a batch of `BATCH` rows, and one carried over.
const SCRATCH: usize = BATCH / 2 + 1;

/// One level of one group of axes.
#[derive(Debug, Clone, Default)]
struct Level {
    /// The first block seen: where a piece joins the blocks before it.
    first: Option<Rec>,
    /// The last block seen: the next block's difference starts from it.
    prev: Option<Rec>,
    /// A block waiting for its pair (the next level's block is their sum).
    pend: Option<Rec>,
    /// Σ (B_{k+1} - B_k)² per lane, a Kahan sum and its compensation.
    sum: Rec,
    comp: Rec,
}

/// Ping-pong buffers of one batch's blocks: the level read, the level made.
#[derive(Debug, Clone)]
struct Scratch {
    a: Vec<Rec>,
    b: Vec<Rec>,
}

impl Scratch {
    fn new() -> Scratch {
        Scratch {
            a: vec![[0.0; W]; SCRATCH],
            b: vec![[0.0; W]; SCRATCH],
        }
    }
}

thread_local! {
    /// The scratch of the pieces a thread runs (one batch, 512 KiB, kept for the thread's life).
    static PIECE_SCRATCH: std::cell::RefCell<Option<Scratch>> = const { std::cell::RefCell::new(None) };
}

/// Up to [`W`] consecutive axes, `a0..a0 + w`.
#[derive(Debug, Clone)]
struct Group {
    a0: usize,
    w: usize,
    /// Per lane: the mean of the axis's first batch of readings (set by the first push).
    reference: Option<Rec>,
    levels: Vec<Level>,
    scratch: Scratch,
}

/// Where a group's lanes are in a row, and what they subtract.
#[derive(Debug, Clone, Copy)]
struct Lanes {
    a0: usize,
    w: usize,
    reference: Rec,
}

impl Group {
    fn lanes(&self) -> Lanes {
        Lanes {
            a0: self.a0,
            w: self.w,
            reference: self.reference.unwrap_or([0.0; W]),
        }
    }
}

/// A batch of rows for one group: `b` rows of `samples` (row-major, `nax` axes) from `row0`.
#[derive(Debug, Clone, Copy)]
struct Rows<'a> {
    samples: &'a [f64],
    nax: usize,
    lanes: Lanes,
    row0: usize,
    b: usize,
}

/// The pyramid accumulator of every axis.
#[derive(Debug, Clone)]
pub(super) struct Octave {
    /// Per level (cluster size `2^level`): the index of the cluster it computes, if asked for.
    want: Vec<Option<usize>>,
    nax: usize,
    groups: Vec<Group>,
}

impl Octave {
    /// An accumulator for `nax` axes and the `clusters` (sorted, each `m` a power of two and
    /// its own stride); `None` when a size is not a power of two.
    pub(super) fn new(nax: usize, clusters: &[Cluster]) -> Option<Octave> {
        if clusters
            .iter()
            .any(|c| !c.m.is_power_of_two() || c.stride != c.m)
        {
            return None;
        }
        let top = clusters.iter().map(|c| c.m.trailing_zeros()).max()? as usize;
        let mut want = vec![None; top + 1];
        for (ci, c) in clusters.iter().enumerate() {
            want[c.m.trailing_zeros() as usize] = Some(ci);
        }
        let groups = (0..nax)
            .step_by(W)
            .map(|a0| Group {
                a0,
                w: W.min(nax - a0),
                reference: None,
                levels: vec![Level::default(); top + 1],
                scratch: Scratch::new(),
            })
            .collect();
        Some(Octave { want, nax, groups })
    }

    /// Bytes held (fixed at construction; a thread that runs pieces keeps one more batch of
    /// scratch, 512 KiB).
    pub(super) fn memory_bytes(&self) -> usize {
        let per_group = 2 * SCRATCH * std::mem::size_of::<Rec>()
            + self.want.len() * std::mem::size_of::<Level>();
        per_group * self.groups.len()
    }

    /// Rows per piece: a multiple of the largest cluster size, so that no block of any level
    /// straddles two pieces.
    fn piece_rows(&self) -> u64 {
        (1u64 << (self.want.len() - 1)).max(MIN_PIECE as u64)
    }

    /// Adds `rows` rows of `samples` (row-major) to axes that have seen `n` rows. Returns the
    /// index of the first NaN or infinite value, if any, having then added nothing.
    ///
    /// The first push sets each axis's reference, from its first batch of readings. The rows
    /// up to the next multiple of [`Octave::piece_rows`] extend the pyramid in place
    /// ([`Octave::push_rows`]). The rest is cut at the multiples into pieces, and each piece
    /// starts a pyramid of its own, so that the pieces run on every core whatever the number
    /// of axes. A piece starts and, but for the last, ends on a boundary of every level's
    /// blocks, so it joins the pyramid before it by one difference per level (its first
    /// block less the last block before it) and its sums; the pieces are joined in order,
    /// whatever the number of threads, so the result does not depend on it.
    pub(super) fn push(
        &mut self,
        samples: &[f64],
        rows: usize,
        parallel: bool,
        n: u64,
    ) -> Option<usize> {
        if rows == 0 {
            return None;
        }
        let saved: Vec<(Option<Rec>, Vec<Level>)> = self
            .groups
            .iter()
            .map(|g| (g.reference, g.levels.clone()))
            .collect();
        let bad = self.set_references(samples, rows).or_else(|| {
            let piece = self.piece_rows();
            let head = ((piece - n % piece) % piece).min(rows as u64) as usize;
            self.push_rows(samples, head, parallel).or_else(|| {
                if head == rows {
                    return None;
                }
                self.push_pieces(samples, head, rows, piece as usize, parallel)
            })
        });
        if bad.is_some() {
            for (g, (r, levels)) in self.groups.iter_mut().zip(saved) {
                g.reference = r;
                g.levels = levels;
            }
        }
        bad
    }

    /// Sets the references not yet set: per axis, the mean of the first batch of rows (each
    /// reading divided first, so that no sum overflows). Returns the index of the first NaN or
    /// infinite value among those rows, if any.
    fn set_references(&mut self, samples: &[f64], rows: usize) -> Option<usize> {
        if self.groups.iter().all(|g| g.reference.is_some()) {
            return None;
        }
        let b = rows.min(BATCH);
        let nax = self.nax;
        if let Some(i) = super::first_non_finite(&samples[..b * nax]) {
            return Some(i);
        }
        for g in &mut self.groups {
            let mut r = [0.0; W];
            for (j, rj) in r[..g.w].iter_mut().enumerate() {
                *rj = super::first_batch_mean(&samples[g.a0 + j..], nax, b);
            }
            g.reference = Some(r);
        }
        None
    }

    /// Extends each group's pyramid by the first `rows` rows, a batch at a time, the groups
    /// of a batch in parallel when there are several. Returns the index of the first NaN or
    /// infinite value, if any (the caller undoes the push).
    fn push_rows(&mut self, samples: &[f64], rows: usize, parallel: bool) -> Option<usize> {
        let nax = self.nax;
        let parallel = parallel && self.groups.len() > 1 && rows >= PARALLEL_ROWS;
        let want = &self.want;
        let mut start = 0;
        while start < rows {
            let g = (GROUP * BATCH).min(rows - start);
            if let Some(i) = super::first_non_finite(&samples[start * nax..(start + g) * nax]) {
                return Some(start * nax + i);
            }
            let run = |gr: &mut Group| {
                let lanes = gr.lanes();
                let mut s = start;
                while s < start + g {
                    let b = BATCH.min(start + g - s);
                    let rows = Rows {
                        samples,
                        nax,
                        lanes,
                        row0: s,
                        b,
                    };
                    push_batch(&mut gr.levels, &mut gr.scratch, want, rows);
                    s += b;
                }
            };
            if parallel {
                use rayon::prelude::*;
                self.groups.par_iter_mut().for_each(run);
            } else {
                self.groups.iter_mut().for_each(run);
            }
            start += g;
        }
        None
    }

    /// Rows `from..rows` (`from` on a piece boundary): a fresh pyramid per piece and group,
    /// then each joined to its group's, in order. Returns the index of the first NaN or
    /// infinite value, if any, having then joined nothing.
    fn push_pieces(
        &mut self,
        samples: &[f64],
        from: usize,
        rows: usize,
        piece: usize,
        parallel: bool,
    ) -> Option<usize> {
        let nax = self.nax;
        let starts: Vec<usize> = (from..rows).step_by(piece).collect();
        let want = &self.want;
        let lanes: Vec<Lanes> = self.groups.iter().map(Group::lanes).collect();
        // a piece's groups take turns on each group of its batches, while the rows are in
        // this core's cache
        let run = |&s: &usize| -> Result<Vec<Vec<Level>>, usize> {
            PIECE_SCRATCH.with(|cell| {
                let mut cell = cell.borrow_mut();
                let scratch = cell.get_or_insert_with(Scratch::new);
                let mut levels = vec![vec![Level::default(); want.len()]; lanes.len()];
                let end = (s + piece).min(rows);
                let mut at = s;
                while at < end {
                    let g = (GROUP * BATCH).min(end - at);
                    if let Some(i) = super::first_non_finite(&samples[at * nax..(at + g) * nax]) {
                        return Err(at * nax + i);
                    }
                    for (ln, lv) in lanes.iter().zip(levels.iter_mut()) {
                        let mut q = at;
                        while q < at + g {
                            let b = BATCH.min(at + g - q);
                            let batch = Rows {
                                samples,
                                nax,
                                lanes: *ln,
                                row0: q,
                                b,
                            };
                            push_batch(lv, scratch, want, batch);
                            q += b;
                        }
                    }
                    at += g;
                }
                Ok(levels)
            })
        };
        let done: Vec<Result<Vec<Vec<Level>>, usize>> =
            if parallel && starts.len() > 1 && rows - from >= PARALLEL_ROWS {
                use rayon::prelude::*;
                starts.par_iter().map(run).collect()
            } else {
                starts.iter().map(run).collect()
            };
        if let Some(&i) = done.iter().filter_map(|d| d.as_ref().err()).min() {
            return Some(i);
        }
        for d in done.into_iter().flatten() {
            for (g, levels) in self.groups.iter_mut().zip(d) {
                join(&mut g.levels, levels, want);
            }
        }
        None
    }

    /// The deviation after `n` samples per axis, for `clusters` (those given to [`Octave::new`]).
    pub(super) fn result(&self, clusters: &[Cluster], rate_hz: f64, n: u64) -> AllanResult {
        let levels = |a: usize, k: usize| {
            let l = &self.groups[a / W].levels[k];
            (l.sum[a % W], l.comp[a % W])
        };
        super::octave_result(
            clusters,
            rate_hz,
            n,
            self.nax,
            |m| (n / m).saturating_sub(1),
            levels,
        )
    }
}

/// Joins the pyramid of a piece (`piece`, started fresh on a boundary of every level's
/// blocks) to the pyramid of the rows before it (`run`, which ends on that boundary).
fn join(run: &mut [Level], piece: Vec<Level>, want: &[Option<usize>]) {
    for (j, (r, p)) in run.iter_mut().zip(piece).enumerate() {
        let Some(first) = p.first else {
            // the piece is too short to make a block of this level, or of any above it
            break;
        };
        debug_assert!(r.pend.is_none());
        if want[j].is_some() {
            for l in 0..W {
                let joint = r.prev.map_or(0.0, |prev| {
                    let d = first[l] - prev[l];
                    d * d
                });
                kahan_add(
                    &mut r.sum[l],
                    &mut r.comp[l],
                    (p.sum[l] - p.comp[l]) + joint,
                );
            }
        }
        r.first = r.first.or(p.first);
        r.prev = p.prev;
        r.pend = p.pend;
    }
}

/// One batch of rows of one group of axes: its readings become level 0, then each level adds
/// its differences and pairs its blocks into the next (dispatches to the AVX2 build where the
/// CPU has it).
fn push_batch(levels: &mut [Level], scratch: &mut Scratch, want: &[Option<usize>], rows: Rows) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return crate::simd::avx2_call!(push_batch_avx2(levels, scratch, want, rows));
    }
    push_batch_impl(levels, scratch, want, rows)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn push_batch_avx2(
    levels: &mut [Level],
    scratch: &mut Scratch,
    want: &[Option<usize>],
    rows: Rows,
) {
    push_batch_impl(levels, scratch, want, rows)
}

#[inline(always)]
fn push_batch_impl(
    levels: &mut [Level],
    scratch: &mut Scratch,
    want: &[Option<usize>],
    rows: Rows,
) {
    let Scratch { a, b: other } = scratch;
    let (mut src, mut dst) = (a, other);
    let (lv, summed) = (&mut levels[0], want[0].is_some());
    let mut n = match rows.lanes.w {
        1 => readings::<1>(lv, summed, rows, src),
        2 => readings::<2>(lv, summed, rows, src),
        3 => readings::<3>(lv, summed, rows, src),
        _ => readings::<W>(lv, summed, rows, src),
    };
    for j in 1..want.len() {
        if n == 0 {
            break;
        }
        let read = &src[..n];
        let i0 = usize::from(levels[j].pend.is_some()).min(n);
        let pairs = read[i0..].chunks_exact(2).map(|c| (c[0], c[1]));
        n = level_pass(
            &mut levels[j],
            want[j].is_some(),
            n,
            |i| read[i],
            pairs,
            dst,
        );
        std::mem::swap(&mut src, &mut dst);
    }
}

/// Level 0 of a batch: its rows' `U` axes of the group (`U` = `lanes.w`) less their
/// references (see [`level_pass`]).
#[inline(always)]
fn readings<const U: usize>(lv: &mut Level, summed: bool, rows: Rows, out: &mut [Rec]) -> usize {
    let Rows {
        samples,
        nax,
        lanes,
        row0,
        b,
    } = rows;
    let (a0, r) = (lanes.a0, lanes.reference);
    let at = |v: &[f64]| -> Rec {
        let mut x = [0.0; W];
        for j in 0..U {
            x[j] = v[j] - r[j];
        }
        x
    };
    let row = |t: usize| at(&samples[(row0 + t) * nax + a0..][..U]);
    // the pairs of rows from the first one not taken by a waiting block
    let i0 = usize::from(lv.pend.is_some()).min(b);
    let p = (b - i0) / 2;
    let from = (row0 + i0) * nax;
    let pairs = samples[from..from + 2 * p * nax]
        .chunks_exact(2 * nax)
        .map(|c| (at(&c[a0..a0 + U]), at(&c[nax + a0..nax + a0 + U])));
    level_pass(lv, summed, b, row, pairs, out)
}

/// One level's `n` new blocks, `block(i)`: adds the squares of their differences (the first
/// against the level's last block) to the level's sums when `summed`, and writes the sums of
/// their pairs (the first with the block waiting for its pair, if any) to `out`. `pairs` gives
/// the blocks `(i, i + 1)` for `i` from 1 if a block was waiting, else 0, in steps of 2. Returns
/// how many it wrote; an unpaired last block waits in `pend`.
#[inline(always)]
fn level_pass(
    lv: &mut Level,
    summed: bool,
    n: usize,
    block: impl Fn(usize) -> Rec,
    pairs: impl Iterator<Item = (Rec, Rec)>,
    out: &mut [Rec],
) -> usize {
    if n == 0 {
        return 0;
    }
    let mut acc0 = [0.0; W];
    let mut acc1 = [0.0; W];
    let first = block(0);
    if let Some(p) = lv.prev {
        square_add(&mut acc0, first, p);
    }
    lv.first = lv.first.or(Some(first));
    // the pairs start at block 0 with `last` = block 0 (a difference of 0) unless block 0
    // completes the waiting pair
    let mut last = first;
    let mut i = 0;
    if let Some(p) = lv.pend.take() {
        out[0] = add(p, first);
        i = 1;
    }
    let made = (n - i) / 2;
    for ((e, o), slot) in pairs.zip(out[i..i + made].iter_mut()) {
        square_add(&mut acc0, e, last);
        square_add(&mut acc1, o, e);
        *slot = add(e, o);
        last = o;
    }
    if (n - i) % 2 == 1 {
        let e = block(n - 1);
        square_add(&mut acc0, e, last);
        lv.pend = Some(e);
        last = e;
    }
    lv.prev = Some(last);
    if summed {
        for j in 0..W {
            kahan_add(&mut lv.sum[j], &mut lv.comp[j], acc0[j] + acc1[j]);
        }
    }
    i + made
}

#[inline(always)]
fn add(a: Rec, b: Rec) -> Rec {
    let mut s = [0.0; W];
    for j in 0..W {
        s[j] = a[j] + b[j];
    }
    s
}

/// `acc += (a - b)²`, lane by lane.
#[inline(always)]
fn square_add(acc: &mut Rec, a: Rec, b: Rec) {
    for j in 0..W {
        let d = a[j] - b[j];
        acc[j] += d * d;
    }
}
