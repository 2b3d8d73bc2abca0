//! The overlapping Allan deviation at power-of-two cluster sizes, from a cascade of window
//! sums.
//!
//! The term of cluster `m` at start `i` is `x_{i+2m} - 2 x_{i+m} + x_i = S_m[i+m] - S_m[i]`,
//! the difference of two window sums `S_m[i] = Σ_{j<m} (y_{i+j} - r)` (`r` a reference
//! reading of the axis, which every term cancels exactly). Windows of `2m` samples are sums of
//! two windows of `m`: `S_2m[i] = S_m[i] + S_m[i+m]`. So each level `m = 2^k` reads its window
//! sums once, in order, and for each new `S_m[t]` takes the one `m` back, `S_m[t-m]`:
//!
//! ```text
//!     term  = S_m[t] - S_m[t-m]          (cluster m, start t - m)
//!     S_2m[t-m] = S_m[t-m] + S_m[t]      (the next level's next window sum)
//! ```
//!
//! One subtraction, one addition and one square per term, independent of each other, so they
//! vectorise; a level keeps only its last `m` window sums (a ring of `m` doubles, slot
//! `t mod m`). The general path (`allan.rs`) instead reads three double-double phases per term
//! (48 bytes); here a term reads two doubles and writes one.
//!
//! Digits: the window sums are plain doubles, but they are small: the reference removes the
//! axis's level (its value is the mean of the first batch of readings, so `S_m` is about
//! `σ √m`, not `m × bias`), and a window sum's rounding errors are relative to the window
//! sums it is made of (about 2 to 3.4 roundings of `S_m` over all levels, where a phase
//! difference of the general path rounds once, relative to `S_m` with `r` the first reading).
//! The tests hold the two paths within 1e-12 of each other on data with a large bias.
//!
//! Threads: the levels of each axis are cut in two stages, the lower half (with the readings)
//! and the upper half, which takes the window sums the lower half hands it a group of batches
//! at a time. While the lower stage of an axis makes group `g + 1`, its upper stage reads
//! group `g`: twice as many chains of tasks as axes, of about equal work, so that three axes
//! keep two cores busy (or one axis, two). The calling thread and the pool's threads take the
//! tasks of a push as they become ready, in one job for the whole push (see
//! `pool::in_chains`): an upper task once the lower task it reads has ended, a lower task
//! once the handoff buffer it fills has been read. Each stage runs its groups in order with
//! one thread or many, and each level's sums are made in a fixed order, so the result does
//! not depend on the number of threads.

use super::{kahan_add, AllanResult, Cluster, BATCH, LANES};
use crate::pool::lock;
use std::sync::Mutex;

/// Window sums a level reads per call (its input and output buffers, 64 KiB each, stay in
/// the core's second-level cache; 2,048 to 16,384 measured the same).
const STEP: usize = 8192;

/// Rows of a push from which the axes run on several threads.
const PARALLEL_ROWS: usize = 4096;

/// Batches an axis processes per task: fewer wake-ups of the thread pool, while the group's
/// rows still fit in the shared cache for the other axes.
const GROUP: usize = 4;

/// Largest cluster size (as a power of two) the cascade takes: its rings hold `2^(top+1)`
/// doubles per axis (2 GiB at 2²⁷); longer exact clusters go to the general path, which
/// explains how to stride them.
const MAX_TOP: u32 = 27;

/// Bytes of buffers that dropped accumulators leave for the next ones (see [`SPARE`]).
const SPARE_BYTES: usize = 64 << 20;

/// Buffers of dropped accumulators, kept for the next: a one-shot deviation makes and drops
/// an accumulator per call, and fresh memory costs a page fault per 4 KiB on its first write
/// (7.5 ms for the 16 MB of three axes at clusters up to 2^18, against 13 ms for their
/// terms). Every slot of a ring is written before it is read, so a buffer needs no clearing.
static SPARE: std::sync::Mutex<Vec<Vec<f64>>> = std::sync::Mutex::new(Vec::new());

/// A buffer of `len` doubles: a spare one of that length, else a fresh one.
fn take(len: usize) -> Vec<f64> {
    if let Ok(mut spare) = SPARE.lock() {
        if let Some(i) = spare.iter().position(|v| v.len() == len) {
            return spare.swap_remove(i);
        }
    }
    vec![0.0; len]
}

/// Keeps `bufs` for the next accumulators, up to [`SPARE_BYTES`] in all.
fn give(bufs: impl Iterator<Item = Vec<f64>>) {
    if let Ok(mut spare) = SPARE.lock() {
        let mut held: usize = spare.iter().map(|v| 8 * v.len()).sum();
        for b in bufs {
            if held + 8 * b.len() <= SPARE_BYTES {
                held += 8 * b.len();
                spare.push(b);
            }
        }
    }
}

/// One level (cluster size `m = 2^k`) of one axis.
#[derive(Debug, Clone)]
struct Level {
    /// The last `m` window sums `S_m[t]`, in slot `t mod m`.
    ring: Vec<f64>,
    /// Window sums received so far (`S_m[0] .. S_m[seen - 1]`).
    seen: u64,
    /// Σ terms², a Kahan sum and its compensation.
    sum: f64,
    comp: f64,
}

/// Everything about one axis.
#[derive(Debug, Clone)]
struct Axis {
    reference: f64,
    levels: Vec<Level>,
    /// A batch of readings less the reference (level 0's window sums).
    readings: Vec<f64>,
    /// Ping-pong buffers of the lower stage and of the upper: the window sums a level reads,
    /// and those it makes.
    bufs: [Vec<f64>; 4],
    /// The window sums the lower stage hands the upper, one group per buffer (ping-pong), and
    /// how many each holds.
    handoff: [(Vec<f64>, usize); 2],
}

/// The cascade accumulator of every axis.
#[derive(Debug, Clone)]
pub(super) struct Cascade {
    /// Per level (cluster size `2^level`): whether a cluster of that size was asked for.
    want: Vec<bool>,
    /// Levels in the lower stage (all of them when there are too few to share).
    lower: usize,
    axes: Vec<Axis>,
}

impl Cascade {
    /// An accumulator for `nax` axes and the `clusters` (sorted); `None` unless every size is
    /// a power of two computed at every start (stride 1), up to 2^[`MAX_TOP`].
    pub(super) fn new(nax: usize, clusters: &[Cluster]) -> Option<Cascade> {
        if clusters
            .iter()
            .any(|c| !c.m.is_power_of_two() || c.stride != 1)
        {
            return None;
        }
        let top = clusters.iter().map(|c| c.m.trailing_zeros()).max()?;
        if top > MAX_TOP {
            return None;
        }
        let mut want = vec![false; top as usize + 1];
        for c in clusters {
            want[c.m.trailing_zeros() as usize] = true;
        }
        let levels = want.len();
        // the upper stage takes half the levels, when there are enough to share
        let lower = if levels >= 4 {
            levels.div_ceil(2)
        } else {
            levels
        };
        let handoff = if lower < levels { GROUP * BATCH } else { 0 };
        let axis = || Axis {
            reference: f64::NAN,
            levels: (0..=top)
                .map(|k| Level {
                    ring: take(1usize << k),
                    seen: 0,
                    sum: 0.0,
                    comp: 0.0,
                })
                .collect(),
            readings: vec![0.0; STEP],
            bufs: std::array::from_fn(|_| vec![0.0; STEP]),
            handoff: std::array::from_fn(|_| (take(handoff), 0)),
        };
        Some(Cascade {
            want,
            lower,
            axes: (0..nax).map(|_| axis()).collect(),
        })
    }

    /// Bytes held (fixed at construction).
    pub(super) fn memory_bytes(&self) -> usize {
        let per_axis = self.axes.first().map_or(0, |ax| {
            let rings: usize = ax.levels.iter().map(|l| l.ring.len()).sum();
            let handoff: usize = ax.handoff.iter().map(|h| h.0.len()).sum();
            8 * (rings + handoff + ax.readings.len() + ax.bufs.iter().map(Vec::len).sum::<usize>())
        }) + self.want.len() * std::mem::size_of::<Level>();
        per_axis * self.axes.len()
    }

    /// Adds `rows` rows of `samples` (row-major, all finite: the caller checked), a group of
    /// batches at a time through each axis's stages, on several threads when there are many
    /// rows.
    pub(super) fn push(&mut self, samples: &[f64], rows: usize, parallel: bool) {
        let nax = self.axes.len();
        let parallel = parallel && rows >= PARALLEL_ROWS;
        let (want, lower) = (&self.want[..], self.lower);
        let split = lower < want.len();
        let groups = rows.div_ceil(GROUP * BATCH);
        // per axis: the lower stage's state, the upper stage's and the two handoff buffers
        let parts: Vec<Parts> = self
            .axes
            .iter_mut()
            .map(|ax| {
                let Axis {
                    reference,
                    levels,
                    readings,
                    bufs: [b0, b1, b2, b3],
                    handoff: [h0, h1],
                } = ax;
                let (low, high) = levels.split_at_mut(lower);
                Parts {
                    low: Mutex::new(Low {
                        next: 0,
                        reference,
                        levels: low,
                        readings,
                        bufs: (b0, b1),
                    }),
                    high: Mutex::new(High {
                        next: 0,
                        levels: high,
                        bufs: (b2, b3),
                    }),
                    handoff: [Mutex::new(h0), Mutex::new(h1)],
                }
            })
            .collect();
        // chain `c < nax`: the lower stage of axis `c`, one task per group; chain `nax + a`:
        // the upper stage of axis `a`, whose task `g` reads what the lower stage's task `g`
        // made
        let run = |c: usize, g: usize| {
            let start = g * GROUP * BATCH;
            if c < nax {
                let end = (start + GROUP * BATCH).min(rows);
                let p = &parts[c];
                let mut low = lock(&p.low);
                let mut made = lock(&p.handoff[g % 2]);
                let low = &mut *low;
                // the chains keep each stage's groups in order (a task out of order would
                // corrupt the sums: stop rather than return them)
                assert_eq!(low.next, g, "lower stage out of order");
                low.next += 1;
                Task::Lower {
                    reference: &mut *low.reference,
                    levels: &mut *low.levels,
                    readings: &mut low.readings[..],
                    bufs: (&mut *low.bufs.0, &mut *low.bufs.1),
                    handoff: split.then_some(&mut **made),
                    rows: &samples[start * nax + c..],
                    count: end - start,
                    nax,
                }
                .run(want);
            } else {
                let p = &parts[c - nax];
                let mut high = lock(&p.high);
                let mut read = lock(&p.handoff[g % 2]);
                let high = &mut *high;
                assert_eq!(high.next, g, "upper stage out of order");
                high.next += 1;
                Task::Upper {
                    levels: &mut *high.levels,
                    bufs: (&mut *high.bufs.0, &mut *high.bufs.1),
                    handoff: &mut read,
                    k0: lower,
                }
                .run(want);
            }
        };
        // a lower task may start once the upper task two groups back has read the handoff
        // buffer it fills; an upper task once the lower task it reads has ended
        let ready = |c: usize, g: usize, ended: &[usize]| {
            if c < nax {
                !split || ended[nax + c] + 1 >= g
            } else {
                ended[c - nax] > g
            }
        };
        let rank = |c: usize, g: usize| if c < nax { 2 * g + 1 } else { 2 * g + 2 };
        let lens = vec![groups; if split { 2 * nax } else { nax }];
        crate::pool::in_chains(parallel, &lens, &ready, &rank, &run);
    }

    /// The deviation after `n` samples per axis, for `clusters` (those given to [`Cascade::new`]).
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
            |m| (n + 1).saturating_sub(2 * m),
            levels,
        )
    }
}

impl Drop for Cascade {
    fn drop(&mut self) {
        give(self.axes.iter_mut().flat_map(|ax| {
            let rings = ax.levels.iter_mut().map(|l| std::mem::take(&mut l.ring));
            let handoff = ax.handoff.iter_mut().map(|h| std::mem::take(&mut h.0));
            rings.chain(handoff).collect::<Vec<_>>()
        }));
    }
}

/// One axis's state, cut between the stages: each task locks the parts it works on (the
/// locks are never contended: the chains keep the tasks that share a part apart).
struct Parts<'a> {
    low: Mutex<Low<'a>>,
    high: Mutex<High<'a>>,
    /// The lower stage's task `g` fills `handoff[g % 2]`, which the upper stage's task `g` reads.
    handoff: [Mutex<&'a mut (Vec<f64>, usize)>; 2],
}

/// The lower stage's state of one axis.
struct Low<'a> {
    /// The group of its next task.
    next: usize,
    reference: &'a mut f64,
    levels: &'a mut [Level],
    readings: &'a mut Vec<f64>,
    bufs: (&'a mut Vec<f64>, &'a mut Vec<f64>),
}

/// The upper stage's state of one axis.
struct High<'a> {
    /// The group of its next task.
    next: usize,
    levels: &'a mut [Level],
    bufs: (&'a mut Vec<f64>, &'a mut Vec<f64>),
}

/// The work of one stage of one axis on one group of rows.
enum Task<'a> {
    /// Levels `0..` on `count` readings `rows[0], rows[nax], ...`; their last level's window
    /// sums appended to `handoff` (if the upper stage has levels).
    Lower {
        reference: &'a mut f64,
        levels: &'a mut [Level],
        readings: &'a mut [f64],
        bufs: (&'a mut Vec<f64>, &'a mut Vec<f64>),
        handoff: Option<&'a mut (Vec<f64>, usize)>,
        rows: &'a [f64],
        count: usize,
        nax: usize,
    },
    /// Levels `k0..` on the window sums in `handoff` (emptied).
    Upper {
        levels: &'a mut [Level],
        bufs: (&'a mut Vec<f64>, &'a mut Vec<f64>),
        handoff: &'a mut (Vec<f64>, usize),
        k0: usize,
    },
}

impl Task<'_> {
    fn run(self, want: &[bool]) {
        match self {
            Task::Lower {
                reference,
                levels,
                readings,
                bufs: (x, y),
                mut handoff,
                rows,
                count,
                nax,
            } => {
                let mut s = 0;
                while s < count {
                    let b = STEP.min(count - s);
                    let col = &rows[s * nax..];
                    let input = &mut readings[..b];
                    less_reference(reference, col, nax, input);
                    cascade(levels, want, 0, input, x, y, handoff.as_deref_mut());
                    s += b;
                }
            }
            Task::Upper {
                levels,
                bufs: (x, y),
                handoff,
                k0,
            } => {
                let (sums, filled) = handoff;
                for chunk in sums[..*filled].chunks(STEP) {
                    cascade(levels, want, k0, chunk, x, y, None);
                }
                *filled = 0;
            }
        }
    }
}

/// The readings `col[0], col[nax], ...` less the axis's reference, into `out` (the reference
/// is set by the first batch: its mean, so that window sums hold the noise, not the level).
fn less_reference(reference: &mut f64, col: &[f64], nax: usize, out: &mut [f64]) {
    let b = out.len();
    if reference.is_nan() {
        *reference = super::first_batch_mean(col, nax, b);
    }
    let r = *reference;
    let col = &col[..(b - 1) * nax + 1];
    match nax {
        1 => {
            for (dst, y) in out.iter_mut().zip(col) {
                *dst = y - r;
            }
        }
        3 => {
            for (dst, y) in out[..b - 1].iter_mut().zip(col.chunks_exact(3)) {
                *dst = y[0] - r;
            }
            out[b - 1] = col[(b - 1) * 3] - r;
        }
        _ => {
            for (dst, y) in out.iter_mut().zip(col.iter().step_by(nax)) {
                *dst = y - r;
            }
        }
    }
}

/// Window sums `input` through `levels` (the axis's levels `k0..`), each level passing the
/// window sums it makes to the next in the buffers `x` and `y`; the last level writes its own
/// after those `sink` holds, if any.
fn cascade(
    levels: &mut [Level],
    want: &[bool],
    k0: usize,
    input: &[f64],
    x: &mut [f64],
    y: &mut [f64],
    mut sink: Option<&mut (Vec<f64>, usize)>,
) {
    let top = want.len() - 1;
    let (mut made, mut spare) = (x, y);
    let mut len = input.len();
    let last = levels.len() - 1;
    for (i, lv) in levels.iter_mut().enumerate() {
        if len == 0 {
            return;
        }
        let k = k0 + i;
        std::mem::swap(&mut made, &mut spare);
        // `spare` holds the previous level's window sums, `made` takes this level's
        let src = if i == 0 { input } else { &spare[..len] };
        len = match sink.as_deref_mut() {
            Some((sums, filled)) if i == last => {
                let n = step(lv, src, &mut sums[*filled..], k < top, want[k]);
                *filled += n;
                n
            }
            _ => step(lv, src, made, k < top, want[k]),
        };
    }
}

/// One level (`m = ring.len()`) reads the window sums `input` (the next ones after the
/// `seen` it had): adds their terms to its sum (if `keep`), writes the next level's window
/// sums to `out` (if `pass`), and returns how many it wrote (every input but those less than
/// `m` after the first).
fn step(lv: &mut Level, input: &[f64], out: &mut [f64], pass: bool, keep: bool) -> usize {
    let m = lv.ring.len();
    let mask = m as u64 - 1;
    let t0 = lv.seen;
    let len = input.len();
    // inputs before index `skip` are the first m window sums of the level: no term yet
    let skip = (m as u64).saturating_sub(t0).min(len as u64) as usize;
    let mut total = 0.0;
    let mut o = 0;
    // runs of the ring from input index `from` to `to`, contiguous in both
    let runs = |from: usize, to: usize, f: &mut dyn FnMut(usize, usize, usize)| {
        let mut j = from;
        while j < to {
            let s = ((t0 + j as u64) & mask) as usize;
            let run = (to - j).min(m - s);
            f(j, s, run);
            j += run;
        }
    };
    if m >= len {
        // every window sum m back is in the ring, in the slot the new one takes: swapped in
        // place, so the ring is read and written once
        runs(0, skip, &mut |j, s, run| {
            lv.ring[s..s + run].copy_from_slice(&input[j..j + run]);
        });
        runs(skip, len, &mut |j, s, run| {
            total += swap(
                &input[j..j + run],
                &mut lv.ring[s..s + run],
                &mut out[o..],
                pass,
            );
            o += run;
        });
    } else {
        // the first m from the ring, the rest from this input; then the ring keeps the last m
        let ring = &lv.ring;
        runs(skip, m, &mut |j, s, run| {
            total += pair(&input[j..j + run], &ring[s..s + run], &mut out[o..], pass);
            o += run;
        });
        let from = m.max(skip);
        total += pair(
            &input[from..],
            &input[from - m..len - m],
            &mut out[o..],
            pass,
        );
        o += len - from;
        runs(len - m, len, &mut |j, s, run| {
            lv.ring[s..s + run].copy_from_slice(&input[j..j + run]);
        });
    }
    lv.seen += len as u64;
    if keep {
        kahan_add(&mut lv.sum, &mut lv.comp, total);
    }
    if pass {
        o
    } else {
        0
    }
}

/// Σ (cur - old)² over a run, and (if `pass`) `out = old + cur` (dispatches to the AVX2
/// build where the CPU has it).
#[inline]
fn pair(cur: &[f64], old: &[f64], out: &mut [f64], pass: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return if pass {
            crate::simd::avx2_call!(pair_avx2::<true>(cur, old, out))
        } else {
            crate::simd::avx2_call!(pair_avx2::<false>(cur, old, out))
        };
    }
    if pass {
        pair_impl::<true>(cur, old, out)
    } else {
        pair_impl::<false>(cur, old, out)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn pair_avx2<const PASS: bool>(cur: &[f64], old: &[f64], out: &mut [f64]) -> f64 {
    pair_impl::<PASS>(cur, old, out)
}

/// Lanes of [`LANES`] terms side by side, which vectorise.
#[inline(always)]
fn pair_impl<const PASS: bool>(cur: &[f64], old: &[f64], out: &mut [f64]) -> f64 {
    let n = cur.len();
    let old = &old[..n];
    let mut acc = [0.0f64; LANES];
    let full = n / LANES * LANES;
    if PASS {
        let out = &mut out[..n];
        let lanes = cur[..full]
            .chunks_exact(LANES)
            .zip(old[..full].chunks_exact(LANES))
            .zip(out[..full].chunks_exact_mut(LANES));
        for ((c, p), w) in lanes {
            for j in 0..LANES {
                let d = c[j] - p[j];
                acc[j] += d * d;
                w[j] = p[j] + c[j];
            }
        }
        for i in full..n {
            out[i] = old[i] + cur[i];
        }
    } else {
        for (c, p) in cur[..full]
            .chunks_exact(LANES)
            .zip(old[..full].chunks_exact(LANES))
        {
            for j in 0..LANES {
                let d = c[j] - p[j];
                acc[j] += d * d;
            }
        }
    }
    let mut tail = 0.0;
    for i in full..n {
        let d = cur[i] - old[i];
        tail += d * d;
    }
    acc.iter().sum::<f64>() + tail
}

/// [`pair`] with the old window sums in `ring`, each replaced by its new one (dispatches to
/// the AVX2 build where the CPU has it).
#[inline]
fn swap(cur: &[f64], ring: &mut [f64], out: &mut [f64], pass: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return if pass {
            crate::simd::avx2_call!(swap_avx2::<true>(cur, ring, out))
        } else {
            crate::simd::avx2_call!(swap_avx2::<false>(cur, ring, out))
        };
    }
    if pass {
        swap_impl::<true>(cur, ring, out)
    } else {
        swap_impl::<false>(cur, ring, out)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn swap_avx2<const PASS: bool>(cur: &[f64], ring: &mut [f64], out: &mut [f64]) -> f64 {
    swap_impl::<PASS>(cur, ring, out)
}

#[inline(always)]
fn swap_impl<const PASS: bool>(cur: &[f64], ring: &mut [f64], out: &mut [f64]) -> f64 {
    let n = cur.len();
    let ring = &mut ring[..n];
    let out = if PASS { &mut out[..n] } else { &mut out[..0] };
    let mut acc = [0.0f64; LANES];
    let full = n / LANES * LANES;
    for (k, (c, p)) in cur[..full]
        .chunks_exact(LANES)
        .zip(ring[..full].chunks_exact_mut(LANES))
        .enumerate()
    {
        let mut w = [0.0f64; LANES];
        for j in 0..LANES {
            let old = p[j];
            let d = c[j] - old;
            acc[j] += d * d;
            w[j] = old + c[j];
            p[j] = c[j];
        }
        if PASS {
            out[k * LANES..(k + 1) * LANES].copy_from_slice(&w);
        }
    }
    let mut tail = 0.0;
    for i in full..n {
        let old = ring[i];
        let d = cur[i] - old;
        tail += d * d;
        if PASS {
            out[i] = old + cur[i];
        }
        ring[i] = cur[i];
    }
    acc.iter().sum::<f64>() + tail
}
