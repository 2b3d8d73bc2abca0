//! The non-overlapping Allan deviation at power-of-two cluster sizes, from a pyramid of block
//! sums.
//!
//! With the starts `m` apart, the term of cluster `k` is `x_{(k+2)m} - 2 x_{(k+1)m} + x_{km} =
//! B_{k+1} - B_k`, the difference of consecutive block sums `B_k = Σ_{j<m} (y_{km+j} - r)`
//! (`r` the axis's first reading). When every cluster size is a power of two, the blocks of
//! `2m` samples are the sums of pairs of blocks of `m`: level 0 holds the readings, level
//! `j + 1` the sums of pairs of level `j`. The whole pyramid costs one addition per sample
//! (`b/2 + b/4 + ...`), and the additions are independent, so they vectorise; the phase of
//! the general path is a chain of dependent additions, one per sample.
//!
//! The blocks are double-double numbers (the rounded sum and the exact sum of its rounding
//! errors), like the phases of the general path, so that long clusters keep their digits:
//! `y - r` is split exactly (TwoSum), and each pair is added as double-double.
//!
//! Each axis keeps, per level, the last block (for the next difference) and a block waiting
//! for its pair; the rest lives in two batch buffers. Axes are independent and run in
//! parallel; the sums of each axis are made in a fixed order, so that the result does not
//! depend on the number of threads.

use super::{AllanResult, Cluster, BATCH, LANES};

/// Rows of a push from which the axes run on several threads.
const PARALLEL_ROWS: usize = 4096;

/// Batches an axis processes per task (see [`Octave::push_rows`]).
const GROUP: usize = 4;

/// The fewest rows in a piece (see [`Octave::push`]).
const MIN_PIECE: usize = 1 << 16;

/// One level of one axis.
#[derive(Debug, Clone, Default)]
struct Level {
    /// The first block seen (hi, lo): where a piece joins the blocks before it.
    first: Option<(f64, f64)>,
    /// The last block seen (hi, lo): the next block's difference starts from it.
    prev: Option<(f64, f64)>,
    /// A block waiting for its pair (the next level's block is their sum).
    pend: Option<(f64, f64)>,
    /// Σ (B_{k+1} - B_k)², a Kahan sum and its compensation.
    sum: f64,
    comp: f64,
}

/// Ping-pong buffers of one batch's blocks: (hi, lo) of the level read, of the level made.
#[derive(Debug, Clone)]
struct Scratch {
    a: (Vec<f64>, Vec<f64>),
    b: (Vec<f64>, Vec<f64>),
}

impl Scratch {
    fn new() -> Scratch {
        Scratch {
            a: (vec![0.0; BATCH], vec![0.0; BATCH]),
            b: (vec![0.0; BATCH], vec![0.0; BATCH]),
        }
    }
}

thread_local! {
    /// The scratch of the pieces a thread runs (one batch, 512 KiB, kept for the thread's life).
    static PIECE_SCRATCH: std::cell::RefCell<Option<Scratch>> = const { std::cell::RefCell::new(None) };
}

/// Everything about one axis.
#[derive(Debug, Clone)]
struct Axis {
    reference: f64,
    levels: Vec<Level>,
    scratch: Scratch,
}

/// The pyramid accumulator of every axis.
#[derive(Debug, Clone)]
pub(super) struct Octave {
    /// Per level (cluster size `2^level`): the index of the cluster it computes, if asked for.
    want: Vec<Option<usize>>,
    axes: Vec<Axis>,
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
        let axis = Axis {
            reference: f64::NAN,
            levels: vec![Level::default(); top + 1],
            scratch: Scratch::new(),
        };
        Some(Octave {
            want,
            axes: vec![axis; nax],
        })
    }

    /// Bytes held (fixed at construction; a thread that runs pieces keeps one more batch of
    /// scratch, 512 KiB).
    pub(super) fn memory_bytes(&self) -> usize {
        let per_axis = 4 * 8 * BATCH + self.want.len() * std::mem::size_of::<Level>();
        per_axis * self.axes.len()
    }

    /// Rows per piece: a multiple of the largest cluster size, so that no block of any level
    /// straddles two pieces.
    fn piece_rows(&self) -> u64 {
        (1u64 << (self.want.len() - 1)).max(MIN_PIECE as u64)
    }

    /// Adds `rows` rows of `samples` (row-major) to axes that have seen `n` rows. Returns the
    /// index of the first NaN or infinite value, if any, having then added nothing.
    ///
    /// The rows up to the next multiple of [`Octave::piece_rows`] extend the pyramid in place
    /// ([`Octave::push_rows`]). The rest is cut at the multiples into pieces, and each piece
    /// of each axis starts a pyramid of its own, so that the pieces run on every core even
    /// when there are fewer axes than cores. A piece starts and, but for the last, ends on a
    /// boundary of every level's blocks, so it joins the pyramid before it by one difference
    /// per level (its first block less the last block before it) and its sums; the pieces
    /// are joined in order, whatever the number of threads, so the result does not depend
    /// on it.
    pub(super) fn push(
        &mut self,
        samples: &[f64],
        rows: usize,
        parallel: bool,
        n: u64,
    ) -> Option<usize> {
        let piece = self.piece_rows();
        let head = ((piece - n % piece) % piece).min(rows as u64) as usize;
        let saved: Vec<(f64, Vec<Level>)> = self
            .axes
            .iter()
            .map(|a| (a.reference, a.levels.clone()))
            .collect();
        let bad = self.push_rows(samples, head, parallel).or_else(|| {
            if head == rows {
                return None;
            }
            self.push_pieces(samples, head, rows, piece as usize, parallel)
        });
        if bad.is_some() {
            for (ax, (r, levels)) in self.axes.iter_mut().zip(saved) {
                ax.reference = r;
                ax.levels = levels;
            }
        }
        bad
    }

    /// Extends each axis's pyramid by the first `rows` rows, a batch at a time (its rows stay
    /// in cache while every axis reads them), the axes of a batch in parallel. Returns the
    /// index of the first NaN or infinite value, if any (the caller undoes the push).
    fn push_rows(&mut self, samples: &[f64], rows: usize, parallel: bool) -> Option<usize> {
        let nax = self.axes.len();
        let parallel = parallel && nax > 1 && rows >= PARALLEL_ROWS;
        let want = &self.want;
        let mut start = 0;
        while start < rows {
            // a group of batches per task: fewer wake-ups of the thread pool, while the
            // group's rows still fit in the shared cache for the other axes
            let g = (GROUP * BATCH).min(rows - start);
            if let Some(i) = super::first_non_finite(&samples[start * nax..(start + g) * nax]) {
                return Some(start * nax + i);
            }
            let run = |(a, ax): (usize, &mut Axis)| {
                let mut s = start;
                while s < start + g {
                    let b = BATCH.min(start + g - s);
                    let col = &samples[s * nax + a..];
                    let (r, levels) = (&mut ax.reference, &mut ax.levels);
                    push_batch(r, levels, &mut ax.scratch, want, col, nax, b);
                    s += b;
                }
            };
            if parallel {
                use rayon::prelude::*;
                self.axes.par_iter_mut().enumerate().for_each(run);
            } else {
                self.axes.iter_mut().enumerate().for_each(run);
            }
            start += g;
        }
        None
    }

    /// Rows `from..rows` (`from` on a piece boundary): a fresh pyramid per piece and axis,
    /// then each joined to its axis's, in order. Returns the index of the first NaN or
    /// infinite value, if any, having then joined nothing.
    fn push_pieces(
        &mut self,
        samples: &[f64],
        from: usize,
        rows: usize,
        piece: usize,
        parallel: bool,
    ) -> Option<usize> {
        let nax = self.axes.len();
        for (a, ax) in self.axes.iter_mut().enumerate() {
            if ax.reference.is_nan() {
                ax.reference = samples[from * nax + a];
            }
        }
        let starts: Vec<usize> = (from..rows).step_by(piece).collect();
        let (want, axes) = (&self.want, &self.axes);
        // a piece's axes take turns on each group of its batches, while the group's rows are
        // in this core's cache
        let run = |&s: &usize| -> Result<Vec<Vec<Level>>, usize> {
            PIECE_SCRATCH.with(|cell| {
                let mut cell = cell.borrow_mut();
                let scratch = cell.get_or_insert_with(Scratch::new);
                let mut refs: Vec<f64> = axes.iter().map(|a| a.reference).collect();
                let mut levels = vec![vec![Level::default(); want.len()]; nax];
                let end = (s + piece).min(rows);
                let mut at = s;
                while at < end {
                    let g = (GROUP * BATCH).min(end - at);
                    if let Some(i) = super::first_non_finite(&samples[at * nax..(at + g) * nax]) {
                        return Err(at * nax + i);
                    }
                    for (a, (r, lv)) in refs.iter_mut().zip(levels.iter_mut()).enumerate() {
                        let mut q = at;
                        while q < at + g {
                            let b = BATCH.min(at + g - q);
                            push_batch(r, lv, scratch, want, &samples[q * nax + a..], nax, b);
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
            for (ax, levels) in self.axes.iter_mut().zip(d) {
                join(&mut ax.levels, levels, &self.want);
            }
        }
        None
    }

    /// The deviation after `n` samples per axis, for `clusters` (those given to [`Octave::new`]).
    pub(super) fn result(&self, clusters: &[Cluster], rate_hz: f64, n: u64) -> AllanResult {
        let levels = |a: usize, k: usize| {
            let l = &self.axes[a].levels[k];
            (l.sum, l.comp)
        };
        super::octave_result(
            clusters,
            rate_hz,
            n,
            self.axes.len(),
            |m| (n / m).saturating_sub(1),
            levels,
        )
    }
}

/// Joins the pyramid of a piece (`piece`, started fresh on a boundary of every level's
/// blocks) to the pyramid of the rows before it (`run`, which ends on that boundary).
fn join(run: &mut [Level], piece: Vec<Level>, want: &[Option<usize>]) {
    for (j, (r, p)) in run.iter_mut().zip(piece).enumerate() {
        let Some((fh, fl)) = p.first else {
            // the piece is too short to make a block of this level, or of any above it
            break;
        };
        debug_assert!(r.pend.is_none());
        if want[j].is_some() {
            let joint = r.prev.map_or(0.0, |(ph, pl)| {
                let d = (fh - ph) + (fl - pl);
                d * d
            });
            kahan(r, (p.sum - p.comp) + joint);
        }
        r.first = r.first.or(p.first);
        r.prev = p.prev;
        r.pend = p.pend;
    }
}

/// One batch of `b` rows of one axis: its readings `col[0], col[nax], ...` become level 0,
/// then each level adds its differences and pairs its blocks into the next (dispatches to
/// the AVX2 build where the CPU has it).
fn push_batch(
    reference: &mut f64,
    levels: &mut [Level],
    scratch: &mut Scratch,
    want: &[Option<usize>],
    col: &[f64],
    nax: usize,
    b: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return crate::simd::avx2_call!(push_batch_avx2(
            reference, levels, scratch, want, col, nax, b
        ));
    }
    push_batch_impl(reference, levels, scratch, want, col, nax, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn push_batch_avx2(
    reference: &mut f64,
    levels: &mut [Level],
    scratch: &mut Scratch,
    want: &[Option<usize>],
    col: &[f64],
    nax: usize,
    b: usize,
) {
    push_batch_impl(reference, levels, scratch, want, col, nax, b)
}

#[inline(always)]
fn push_batch_impl(
    reference: &mut f64,
    levels: &mut [Level],
    scratch: &mut Scratch,
    want: &[Option<usize>],
    col: &[f64],
    nax: usize,
    b: usize,
) {
    if reference.is_nan() {
        *reference = col[0];
    }
    let Scratch { a, b: other } = scratch;
    let (mut src, mut dst) = (a, other);
    // level 0: the readings less the reference (rounded once, as the phases of the general
    // path are); its blocks have no error part, so it is differenced and paired on its own.
    // The readings are split into the even and odd members of this batch's pairs (after the
    // one that completes a pair left by the last batch), so that the pairs and differences
    // are read from two contiguous runs
    let level = &mut levels[0];
    let carried = level.pend.take();
    let i = usize::from(carried.is_some());
    let p = (b - i) / 2;
    let (even, odd) = dst.0.split_at_mut(BATCH / 2);
    let (even, odd) = (&mut even[..p], &mut odd[..p]);
    readings_split(&col[i * nax..], nax, *reference, even, odd);
    let first = col[0] - *reference;
    let last = col[(b - 1) * nax] - *reference;
    if want[0].is_some() {
        let mut s = level
            .prev
            .map_or(0.0, |(ph, _)| (first - ph) * (first - ph));
        if p == 0 {
            if b == 2 {
                s += (last - first) * (last - first);
            }
        } else {
            if i == 1 {
                s += (even[0] - first) * (even[0] - first);
            }
            if i + 2 * p < b {
                s += (last - odd[p - 1]) * (last - odd[p - 1]);
            }
        }
        kahan(level, s + diffs_split(even, odd));
    }
    level.first = level.first.or(Some((first, 0.0)));
    level.prev = Some((last, 0.0));
    if want.len() == 1 {
        return;
    }
    let mut n = 0;
    if let Some((ph, _)) = carried {
        (src.0[0], src.1[0]) = two_sum(ph, first);
        n = 1;
    }
    for (q, (e, o)) in even.iter().zip(odd.iter()).enumerate() {
        (src.0[n + q], src.1[n + q]) = two_sum(*e, *o);
    }
    n += p;
    if i + 2 * p < b {
        level.pend = Some((last, 0.0));
    }
    for (j, level) in levels.iter_mut().enumerate().skip(1) {
        if n == 0 {
            break;
        }
        let (h, l) = (&src.0[..n], &src.1[..n]);
        if want[j].is_some() {
            kahan(level, squares(level.prev, h, l));
        }
        level.first = level.first.or(Some((h[0], l[0])));
        level.prev = Some((h[n - 1], l[n - 1]));
        if j + 1 == want.len() {
            break;
        }
        n = pairs(&mut level.pend, h, l, &mut dst.0, &mut dst.1);
        std::mem::swap(&mut src, &mut dst);
    }
}

/// Adds a batch's sum of squares to a level's total.
#[inline(always)]
fn kahan(level: &mut Level, s: f64) {
    super::kahan_add(&mut level.sum, &mut level.comp, s);
}

/// `y - r` of the readings `col[2 q nax]` (into `even`) and `col[(2 q + 1) nax]` (into
/// `odd`).
#[inline(always)]
fn readings_split(col: &[f64], nax: usize, r: f64, even: &mut [f64], odd: &mut [f64]) {
    match nax {
        1 => split_of::<1>(col, r, even, odd),
        2 => split_of::<2>(col, r, even, odd),
        3 => split_of::<3>(col, r, even, odd),
        _ => {
            for (q, (e, o)) in even.iter_mut().zip(odd.iter_mut()).enumerate() {
                *e = col[2 * q * nax] - r;
                *o = col[(2 * q + 1) * nax] - r;
            }
        }
    }
}

#[inline(always)]
fn split_of<const K: usize>(col: &[f64], r: f64, even: &mut [f64], odd: &mut [f64]) {
    let p = even.len();
    if p == 0 {
        return;
    }
    // the last pair's second reading may end the slice: it is read on its own
    for ((e, o), y) in even[..p - 1]
        .iter_mut()
        .zip(odd[..p - 1].iter_mut())
        .zip(col[..2 * (p - 1) * K].chunks_exact(2 * K))
    {
        *e = y[0] - r;
        *o = y[K] - r;
    }
    even[p - 1] = col[2 * (p - 1) * K] - r;
    odd[p - 1] = col[(2 * p - 1) * K] - r;
}

/// Σ (o_q - e_q)² + Σ (e_{q+1} - o_q)²: the differences of consecutive readings, split into
/// the even and odd members of their pairs (level 0, no error parts).
#[inline(always)]
fn diffs_split(even: &[f64], odd: &[f64]) -> f64 {
    let p = even.len().min(odd.len());
    if p == 0 {
        return 0.0;
    }
    let m = p - 1;
    let full = m / LANES * LANES;
    let mut acc = [0.0f64; LANES];
    for ((e, e1), o) in even[..full]
        .chunks_exact(LANES)
        .zip(even[1..=full].chunks_exact(LANES))
        .zip(odd[..full].chunks_exact(LANES))
    {
        for j in 0..LANES {
            let d = o[j] - e[j];
            let d1 = e1[j] - o[j];
            acc[j] += d * d;
            acc[j] += d1 * d1;
        }
    }
    let mut tail = 0.0;
    for q in full..m {
        let d = odd[q] - even[q];
        let d1 = even[q + 1] - odd[q];
        tail += d * d;
        tail += d1 * d1;
    }
    let d = odd[m] - even[m];
    acc.iter().sum::<f64>() + tail + d * d
}

/// `a + b` as the rounded sum and its exact error (Knuth's TwoSum).
#[inline(always)]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bp = s - a;
    (s, (a - (s - bp)) + (b - bp))
}

/// The double-double sum of two double-double numbers, normalised.
#[inline(always)]
fn dd_add(ah: f64, al: f64, bh: f64, bl: f64) -> (f64, f64) {
    let (s, e) = two_sum(ah, bh);
    let e = e + (al + bl);
    let hi = s + e;
    (hi, e - (hi - s))
}

/// Pairs the blocks `(h, l)` (after the one waiting in `pend`, if any) into `oh`, `ol`;
/// returns how many were made, and leaves an unpaired last block in `pend`.
#[inline(always)]
fn pairs(
    pend: &mut Option<(f64, f64)>,
    h: &[f64],
    l: &[f64],
    oh: &mut [f64],
    ol: &mut [f64],
) -> usize {
    let n = h.len();
    let (mut i, mut k) = (0, 0);
    if let Some((ph, pl)) = pend.take() {
        (oh[0], ol[0]) = dd_add(ph, pl, h[0], l[0]);
        (i, k) = (1, 1);
    }
    let p = (n - i) / 2;
    let (hs, ls) = (&h[i..i + 2 * p], &l[i..i + 2 * p]);
    let (oh, ol) = (&mut oh[k..k + p], &mut ol[k..k + p]);
    for q in 0..p {
        (oh[q], ol[q]) = dd_add(hs[2 * q], ls[2 * q], hs[2 * q + 1], ls[2 * q + 1]);
    }
    if i + 2 * p < n {
        *pend = Some((h[n - 1], l[n - 1]));
    }
    k + p
}

/// Σ (B_{i} - B_{i-1})² over the blocks `(h, l)`, the first against `prev` (if any).
#[inline(always)]
fn squares(prev: Option<(f64, f64)>, h: &[f64], l: &[f64]) -> f64 {
    let first = prev.map_or(0.0, |(ph, pl)| {
        let d = (h[0] - ph) + (l[0] - pl);
        d * d
    });
    first + diffs_impl(h, l)
}

/// Σ ((h_i - h_{i-1}) + (l_i - l_{i-1}))² for i ≥ 1.
#[inline(always)]
fn diffs_impl(h: &[f64], l: &[f64]) -> f64 {
    let n = h.len().min(l.len());
    if n < 2 {
        return 0.0;
    }
    let (h1, h0, l1, l0) = (&h[1..n], &h[..n - 1], &l[1..n], &l[..n - 1]);
    let m = n - 1;
    let full = m / LANES * LANES;
    let mut acc = [0.0f64; LANES];
    for (((a1, a0), b1), b0) in h1[..full]
        .chunks_exact(LANES)
        .zip(h0[..full].chunks_exact(LANES))
        .zip(l1[..full].chunks_exact(LANES))
        .zip(l0[..full].chunks_exact(LANES))
    {
        for j in 0..LANES {
            let d = (a1[j] - a0[j]) + (b1[j] - b0[j]);
            acc[j] += d * d;
        }
    }
    let mut tail = 0.0;
    for i in full..m {
        let d = (h1[i] - h0[i]) + (l1[i] - l0[i]);
        tail += d * d;
    }
    acc.iter().sum::<f64>() + tail
}
