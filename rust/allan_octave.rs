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

/// Batches an axis processes per task (see [`Octave::push`]).
const GROUP: usize = 4;

/// One level of one axis.
#[derive(Debug, Clone, Default)]
struct Level {
    /// The last block seen (hi, lo): the next block's difference starts from it.
    prev: Option<(f64, f64)>,
    /// A block waiting for its pair (the next level's block is their sum).
    pend: Option<(f64, f64)>,
    /// Σ (B_{k+1} - B_k)², a Kahan sum and its compensation.
    sum: f64,
    comp: f64,
}

/// Everything about one axis.
#[derive(Debug, Clone)]
struct Axis {
    reference: f64,
    levels: Vec<Level>,
    /// Ping-pong buffers of one batch's blocks: (hi, lo) of the level read, of the level made.
    a: (Vec<f64>, Vec<f64>),
    b: (Vec<f64>, Vec<f64>),
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
            a: (vec![0.0; BATCH], vec![0.0; BATCH]),
            b: (vec![0.0; BATCH], vec![0.0; BATCH]),
        };
        Some(Octave {
            want,
            axes: vec![axis; nax],
        })
    }

    /// Bytes held (fixed at construction).
    pub(super) fn memory_bytes(&self) -> usize {
        let per_axis = 4 * 8 * BATCH + self.want.len() * std::mem::size_of::<Level>();
        per_axis * self.axes.len()
    }

    /// Adds `rows` rows of `samples` (row-major), a batch at a time (its rows stay in cache
    /// while every axis reads them), the axes of a batch in parallel. Returns the index of
    /// the first NaN or infinite value, if any, having then added nothing.
    pub(super) fn push(&mut self, samples: &[f64], rows: usize, parallel: bool) -> Option<usize> {
        let nax = self.axes.len();
        let parallel = parallel && nax > 1 && rows >= PARALLEL_ROWS;
        let saved: Vec<(f64, Vec<Level>)> = self
            .axes
            .iter()
            .map(|a| (a.reference, a.levels.clone()))
            .collect();
        let want = &self.want;
        let mut start = 0;
        while start < rows {
            // a group of batches per task: fewer wake-ups of the thread pool, while the
            // group's rows still fit in the shared cache for the other axes
            let g = (GROUP * BATCH).min(rows - start);
            if let Some(i) = super::first_non_finite(&samples[start * nax..(start + g) * nax]) {
                for (ax, (r, levels)) in self.axes.iter_mut().zip(saved) {
                    ax.reference = r;
                    ax.levels = levels;
                }
                return Some(start * nax + i);
            }
            let run = |(a, ax): (usize, &mut Axis)| {
                let mut s = start;
                while s < start + g {
                    let b = BATCH.min(start + g - s);
                    push_batch(ax, want, &samples[s * nax + a..], nax, b);
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

    /// The deviation after `n` samples per axis, for `clusters` (those given to [`new`]).
    pub(super) fn result(&self, clusters: &[Cluster], rate_hz: f64, n: u64) -> AllanResult {
        let terms: Vec<u64> = clusters
            .iter()
            .map(|c| (n / c.m).saturating_sub(1))
            .collect();
        let adev = clusters
            .iter()
            .enumerate()
            .map(|(ci, c)| {
                let level = c.m.trailing_zeros() as usize;
                self.axes
                    .iter()
                    .map(|ax| {
                        let l = &ax.levels[level];
                        super::deviation(l.sum, l.comp, terms[ci], c.m)
                    })
                    .collect()
            })
            .collect();
        AllanResult {
            clusters: clusters.to_vec(),
            taus: clusters.iter().map(|c| c.m as f64 / rate_hz).collect(),
            adev,
            terms,
            n,
        }
    }
}

/// One batch of `b` rows of one axis: its readings `col[0], col[nax], ...` become level 0,
/// then each level adds its differences and pairs its blocks into the next (dispatches to
/// the AVX2 build where the CPU has it).
fn push_batch(ax: &mut Axis, want: &[Option<usize>], col: &[f64], nax: usize, b: usize) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return crate::simd::avx2_call!(push_batch_avx2(ax, want, col, nax, b));
    }
    push_batch_impl(ax, want, col, nax, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn push_batch_avx2(ax: &mut Axis, want: &[Option<usize>], col: &[f64], nax: usize, b: usize) {
    push_batch_impl(ax, want, col, nax, b)
}

#[inline(always)]
fn push_batch_impl(ax: &mut Axis, want: &[Option<usize>], col: &[f64], nax: usize, b: usize) {
    if ax.reference.is_nan() {
        ax.reference = col[0];
    }
    let Axis {
        reference,
        levels,
        a,
        b: other,
    } = ax;
    let (mut src, mut dst) = (a, other);
    // level 0: the readings less the reference (rounded once, as the phases of the general
    // path are); its blocks have no error part, so it is differenced and paired on its own
    let h0 = &mut dst.0[..b];
    readings(col, nax, *reference, h0);
    let level = &mut levels[0];
    if want[0].is_some() {
        let first = level
            .prev
            .map_or(0.0, |(ph, _)| (h0[0] - ph) * (h0[0] - ph));
        kahan(level, first + diffs0(h0));
    }
    level.prev = Some((h0[b - 1], 0.0));
    if want.len() == 1 {
        return;
    }
    let mut n = pairs0(&mut level.pend, h0, &mut src.0, &mut src.1);
    for (j, level) in levels.iter_mut().enumerate().skip(1) {
        if n == 0 {
            break;
        }
        let (h, l) = (&src.0[..n], &src.1[..n]);
        if want[j].is_some() {
            kahan(level, squares(level.prev, h, l));
        }
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

/// `y - r` of each reading `col[i nax]`.
#[inline(always)]
fn readings(col: &[f64], nax: usize, r: f64, h: &mut [f64]) {
    let n = h.len();
    match nax {
        1 => readings_of::<1>(col, r, h),
        2 => readings_of::<2>(col, r, h),
        3 => readings_of::<3>(col, r, h),
        _ => {
            for (i, y) in h
                .iter_mut()
                .zip(col[..(n - 1) * nax + 1].iter().step_by(nax))
            {
                *i = *y - r;
            }
        }
    }
}

#[inline(always)]
fn readings_of<const K: usize>(col: &[f64], r: f64, h: &mut [f64]) {
    let n = h.len();
    let (last, body) = h.split_last_mut().expect("a batch has rows");
    for (i, y) in body.iter_mut().zip(col[..(n - 1) * K].chunks_exact(K)) {
        *i = y[0] - r;
    }
    *last = col[(n - 1) * K] - r;
}

/// Σ (h_i - h_{i-1})² for i ≥ 1 (level 0, no error parts).
#[inline(always)]
fn diffs0(h: &[f64]) -> f64 {
    let n = h.len();
    if n < 2 {
        return 0.0;
    }
    let (h1, h0) = (&h[1..n], &h[..n - 1]);
    let m = n - 1;
    let full = m / LANES * LANES;
    let mut acc = [0.0f64; LANES];
    for (a1, a0) in h1[..full]
        .chunks_exact(LANES)
        .zip(h0[..full].chunks_exact(LANES))
    {
        for j in 0..LANES {
            let d = a1[j] - a0[j];
            acc[j] += d * d;
        }
    }
    let mut tail = 0.0;
    for i in full..m {
        let d = h1[i] - h0[i];
        tail += d * d;
    }
    acc.iter().sum::<f64>() + tail
}

/// [`pairs`] for level 0 (blocks without error parts): each pair's exact sum.
#[inline(always)]
fn pairs0(pend: &mut Option<(f64, f64)>, h: &[f64], oh: &mut [f64], ol: &mut [f64]) -> usize {
    let n = h.len();
    let (mut i, mut k) = (0, 0);
    if let Some((ph, _)) = pend.take() {
        (oh[0], ol[0]) = two_sum(ph, h[0]);
        (i, k) = (1, 1);
    }
    let p = (n - i) / 2;
    let hs = &h[i..i + 2 * p];
    let (oh, ol) = (&mut oh[k..k + p], &mut ol[k..k + p]);
    for q in 0..p {
        (oh[q], ol[q]) = two_sum(hs[2 * q], hs[2 * q + 1]);
    }
    if i + 2 * p < n {
        *pend = Some((h[n - 1], 0.0));
    }
    k + p
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
