//! Allan deviation (overlapping, and non-overlapping) of rate samples, streamed chunk by chunk.
//!
//! Noise model (IEEE Std 952 / 1554): a gyroscope (or accelerometer) at rest reports its rate
//! `y_k` (deg/s, rad/s, m/s², counts...) every `τ0 = 1 / rate` seconds. With the phase
//! (integrated rate, in samples × unit) `x_0 = 0`, `x_k = Σ_{j<k} y_j`, the overlapping Allan
//! variance at cluster size `m` (averaging time `τ = m τ0`) is
//!
//! ```text
//!     σ²(τ) = Σ_i (x_{i+2m} - 2 x_{i+m} + x_i)² / (2 m² n)
//! ```
//!
//! over the `n` start indices `i = 0, d, 2d, ...` with `i + 2m ≤ N` (NIST SP 1065 eq. 11;
//! allantools' `oadev` for `d = 1`, its `calc_adev_phase(.., stride=d)` in general). The
//! deviation `σ` is in the unit of the samples.
//!
//! Streaming: samples arrive in chunks of any size and are not kept. The phase is accumulated
//! in double-double arithmetic (a running sum and the exact sum of its rounding errors), so a
//! constant bias or a 10⁸-sample log loses no digits. Each stride `d` (a "level") keeps a ring
//! of the last phases at multiples of `d`, just long enough for its longest cluster:
//!
//! * clusters of up to `exact_up_to` samples use every start (`d = 1`): exactly the classic
//!   fully overlapping estimator;
//! * a longer cluster `m` uses the power-of-two stride `d` that leaves between
//!   [`DECIMATED_STARTS`] and twice that many starts per cluster (`m` is rounded to a multiple
//!   of `d`). The estimator is then unbiased and statistically as good as the fully
//!   overlapping one (starts closer than `m / 2048` give nearly identical terms), while the
//!   memory no longer grows with the cluster.
//!
//! The non-overlapping deviation (allantools' `adev`; [`Allan::non_overlapping`]) is the same
//! sum with the starts `m` apart (`d = m`): a cluster then costs one term per `m` samples.
//! When every size is a power of two (octave taus) it skips the phases: the terms are the
//! differences of consecutive block sums, and a pyramid of block sums (pairs of blocks of `m`
//! make the blocks of `2m`; plain doubles about the mean of the first readings, up to four axes
//! of a row side by side) gives them all for about one addition per sample
//! (`allan_octave.rs`).
//!
//! The overlapping deviation at power-of-two sizes, every start, skips the phases too: each
//! term is the difference of two window sums `m` apart, and the windows of `2m` are sums of
//! pairs of windows of `m` (`allan_cascade.rs`), two reads and a write per term instead of
//! three double-double phases.
//!
//! Memory is fixed when the accumulator is made (a few MB per axis for clusters up to 2⁴⁰
//! samples) and independent of the number of samples; the work per sample is one
//! double-double addition plus a few operations per exact cluster size. Rows are processed in
//! batches: the phases of a batch are written straight into the ring of stride 1 (the other
//! strides take every `d`-th of them), then each axis's new terms are summed in `PARTS`
//! parts, each part through all the clusters in increasing size (the phases `2m` back that the
//! cluster of `m` reads are the ones the cluster of `2m` reads `2m` back: still in cache);
//! the parts run in parallel when there are many terms, and their sums are added in a fixed
//! order, so that the result does not depend on the number of threads.

use crate::error::{CalError, Result};

#[path = "allan_cascade.rs"]
mod cascade;
#[path = "allan_kernels.rs"]
mod kernels;
#[path = "allan_octave.rs"]
mod octave;

use kernels::{first_batch_mean, first_non_finite, gather, phases, sum_terms};

/// Rows of a chunk processed together (phases are computed for a batch, then every cluster
/// reads them as contiguous slices, which vectorises).
const BATCH: usize = 16_384;

/// The terms of a batch are summed on several threads from this many on (fewer: the cost of
/// waking the pool exceeds the gain).
const PARALLEL_TERMS: u64 = 1 << 16;

/// Values per piece of a push's check for non-finite values, which runs on several threads
/// from four pieces on (512 KiB each).
const CHECK_CHUNK: usize = 1 << 16;

/// The phases of a batch of this many rows are made on several threads (one axis each).
const PARALLEL_PHASES: usize = 4096;

/// The new terms of a cluster in a batch: (level, cluster size in entries of the level,
/// first and last entry).
type Task = (usize, usize, u64, u64);

/// The new terms of each axis are summed in this many parts (the units of parallel work).
const PARTS: usize = 4;

/// Terms summed side by side in the inner loop (two AVX2 registers).
const LANES: usize = 8;

/// Fewest starts per cluster for clusters longer than the exact range (see module docs).
pub const DECIMATED_STARTS: u64 = 2048;

/// Largest ring (phase entries per axis and level) an exact computation may ask for: 2²⁸
/// entries are 4 GiB per axis. Longer exact clusters must use `exact_up_to`.
const MAX_RING: u64 = 1 << 28;

/// One cluster size as computed: `m` samples, starts every `stride` samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cluster {
    /// Cluster size in samples (`τ = m / rate`).
    pub m: u64,
    /// Distance in samples between the starts of consecutive terms (1: fully overlapping).
    pub stride: u64,
}

/// The cluster sizes actually computed for the requested `ms`: sorted, deduplicated, with
/// sizes above `exact_up_to` rounded to a multiple of their power-of-two stride (see the
/// module documentation). `None` computes every size exactly.
///
/// ```
/// use triaxcal::allan::{plan, Cluster};
/// let p = plan(&[1, 4, 4, 100_000], Some(65_536)).unwrap();
/// assert_eq!(p[0], Cluster { m: 1, stride: 1 });
/// assert_eq!(p[2], Cluster { m: 100_000, stride: 32 });
/// ```
pub fn plan(ms: &[u64], exact_up_to: Option<u64>) -> Result<Vec<Cluster>> {
    let mut out = Vec::with_capacity(ms.len());
    for &m in ms {
        if m == 0 {
            return Err(CalError::InvalidArgument(
                "cluster sizes must be at least 1 sample (tau >= 1 / rate_hz)".into(),
            ));
        }
        let exact = match exact_up_to {
            None => true,
            Some(e) => m <= e || m < 2 * DECIMATED_STARTS,
        };
        if exact {
            out.push(Cluster { m, stride: 1 });
            continue;
        }
        let mut shift = 63 - (m / DECIMATED_STARTS).leading_zeros();
        loop {
            let d = 1u64 << shift;
            let mp = (m + d / 2) / d;
            if mp >= 2 * DECIMATED_STARTS {
                shift += 1;
                continue;
            }
            out.push(Cluster {
                m: mp * d,
                stride: d,
            });
            break;
        }
    }
    out.sort_by_key(|c| (c.m, c.stride));
    out.dedup_by_key(|c| c.m);
    Ok(out)
}

/// Rings of one stride for one axis.
#[derive(Debug, Clone)]
struct Ring {
    hi: Vec<f64>,
    lo: Vec<f64>,
}

/// A stride and the clusters computed with it.
#[derive(Debug, Clone)]
struct Level {
    stride: u64,
    cap: usize,
    /// Entries appended so far (the phase at index `k` is entry `k / stride`).
    count: u64,
    /// (cluster index, cluster size in entries of this level).
    clusters: Vec<(usize, usize)>,
}

/// Everything about one axis.
#[derive(Debug, Clone)]
struct Axis {
    reference: f64,
    hi: f64,
    lo: f64,
    rings: Vec<Ring>,
    /// Per cluster: Σ terms² (Kahan sum and its compensation).
    sum: Vec<f64>,
    comp: Vec<f64>,
    /// Phases of the current batch.
    bhi: Vec<f64>,
    blo: Vec<f64>,
}

/// The streaming accumulator: feed rows with [`Allan::push`], read with [`Allan::result`].
///
/// ```
/// use triaxcal::allan::Allan;
/// // one axis, white noise-like alternation +1, -1 at 100 Hz: the 1-sample deviation is 2/sqrt(2)
/// let mut acc = Allan::new(100.0, 1, &[1, 2], Some(65_536)).unwrap();
/// acc.push(&[1.0, -1.0, 1.0, -1.0, 1.0]).unwrap();
/// acc.push(&[-1.0, 1.0]).unwrap();
/// let r = acc.result();
/// assert!((r.adev[0][0] - 2f64.sqrt()).abs() < 1e-15);
/// assert_eq!(r.terms[0], 6);
/// ```
#[derive(Debug, Clone)]
pub struct Allan {
    rate_hz: f64,
    nax: usize,
    clusters: Vec<Cluster>,
    levels: Vec<Level>,
    axes: Vec<Axis>,
    n: u64,
    parallel: bool,
    /// The pyramid of block sums that replaces the levels and axes above (non-overlapping
    /// deviation at power-of-two sizes only).
    octave: Option<octave::Octave>,
    /// The cascade of window sums that replaces the levels and axes above (overlapping
    /// deviation at power-of-two sizes, every start).
    cascade: Option<cascade::Cascade>,
}

/// The Allan deviation of everything pushed so far.
#[derive(Debug, Clone, PartialEq)]
pub struct AllanResult {
    /// The clusters, in increasing size.
    pub clusters: Vec<Cluster>,
    /// Averaging times `m / rate` in seconds.
    pub taus: Vec<f64>,
    /// `adev[c][a]`: deviation at cluster `c` for axis `a`, in the unit of the samples (NaN
    /// where there is no term yet).
    pub adev: Vec<Vec<f64>>,
    /// Number of terms (starts) averaged per cluster.
    pub terms: Vec<u64>,
    /// Samples pushed.
    pub n: u64,
}

impl Allan {
    /// An accumulator for `axes` interleaved channels sampled at `rate_hz`, computing the
    /// cluster sizes `ms` (in samples; see [`plan`] for `exact_up_to`).
    ///
    /// When every size is a power of two computed at every start (octave taus within
    /// `exact_up_to`), the deviation is computed from a cascade of window sums (see
    /// `allan_cascade.rs`): the same terms for a third of the memory traffic.
    pub fn new(rate_hz: f64, axes: usize, ms: &[u64], exact_up_to: Option<u64>) -> Result<Allan> {
        Allan::new_with(rate_hz, axes, ms, exact_up_to, true)
    }

    /// [`Allan::new`], with the cascade of window sums allowed or not (`false`: the general
    /// path, whatever the sizes).
    pub(crate) fn new_with(
        rate_hz: f64,
        axes: usize,
        ms: &[u64],
        exact_up_to: Option<u64>,
        cascade: bool,
    ) -> Result<Allan> {
        crate::error::check_positive("rate_hz", rate_hz)?;
        if axes == 0 || axes > 64 {
            return Err(CalError::InvalidArgument(format!(
                "axes must be between 1 and 64 channels, got {axes}"
            )));
        }
        if ms.is_empty() {
            return Err(CalError::InvalidArgument(
                "no cluster sizes asked for: give at least one tau".into(),
            ));
        }
        let clusters = plan(ms, exact_up_to)?;
        if cascade {
            if let Some(c) = cascade::Cascade::new(axes, &clusters) {
                return Ok(Allan::of_sums(rate_hz, axes, clusters, None, Some(c)));
            }
        }
        Allan::with_clusters(rate_hz, axes, clusters)
    }

    /// An accumulator of the non-overlapping Allan deviation (allantools' `adev`): each
    /// cluster size `m` of `ms` starts its terms every `m` samples, so that consecutive
    /// clusters do not overlap.
    ///
    /// When every size is a power of two (octave taus), the deviation is computed from a
    /// pyramid of block sums (see `allan_octave.rs`): the same terms, about the mean of the
    /// first readings, at a fraction of the work.
    pub fn non_overlapping(rate_hz: f64, axes: usize, ms: &[u64]) -> Result<Allan> {
        Allan::non_overlapping_with(rate_hz, axes, ms, true)
    }

    /// [`Allan::non_overlapping`], with the pyramid of block sums allowed or not (`false`:
    /// the general path, whatever the sizes).
    pub(crate) fn non_overlapping_with(
        rate_hz: f64,
        axes: usize,
        ms: &[u64],
        pyramid: bool,
    ) -> Result<Allan> {
        crate::error::check_positive("rate_hz", rate_hz)?;
        if axes == 0 || axes > 64 {
            return Err(CalError::InvalidArgument(format!(
                "axes must be between 1 and 64 channels, got {axes}"
            )));
        }
        let mut clusters = Vec::with_capacity(ms.len());
        for &m in ms {
            if m == 0 {
                return Err(CalError::InvalidArgument(
                    "cluster sizes must be at least 1 sample (tau >= 1 / rate_hz)".into(),
                ));
            }
            clusters.push(Cluster { m, stride: m });
        }
        clusters.sort_by_key(|c| c.m);
        clusters.dedup_by_key(|c| c.m);
        if pyramid {
            if let Some(octave) = octave::Octave::new(axes, &clusters) {
                return Ok(Allan::of_sums(rate_hz, axes, clusters, Some(octave), None));
            }
        }
        Allan::with_clusters(rate_hz, axes, clusters)
    }

    /// An accumulator of block or window sums (the general path's levels and axes unused).
    fn of_sums(
        rate_hz: f64,
        nax: usize,
        clusters: Vec<Cluster>,
        octave: Option<octave::Octave>,
        cascade: Option<cascade::Cascade>,
    ) -> Allan {
        Allan {
            rate_hz,
            nax,
            clusters,
            levels: Vec::new(),
            axes: Vec::new(),
            n: 0,
            parallel: true,
            octave,
            cascade,
        }
    }

    fn with_clusters(rate_hz: f64, axes: usize, clusters: Vec<Cluster>) -> Result<Allan> {
        crate::error::check_positive("rate_hz", rate_hz)?;
        if axes == 0 || axes > 64 {
            return Err(CalError::InvalidArgument(format!(
                "axes must be between 1 and 64 channels, got {axes}"
            )));
        }
        if clusters.is_empty() {
            return Err(CalError::InvalidArgument(
                "no cluster sizes asked for: give at least one tau".into(),
            ));
        }
        let mut levels: Vec<Level> = Vec::new();
        for (ci, c) in clusters.iter().enumerate() {
            let mp = c.m / c.stride;
            let li = match levels.iter().position(|l| l.stride == c.stride) {
                Some(i) => i,
                None => {
                    levels.push(Level {
                        stride: c.stride,
                        cap: 0,
                        count: 0,
                        clusters: Vec::new(),
                    });
                    levels.len() - 1
                }
            };
            levels[li].clusters.push((ci, mp as usize));
        }
        for l in levels.iter_mut() {
            let mp_max = l.clusters.iter().map(|c| c.1 as u64).max().unwrap_or(0);
            let cap = (BATCH as u64) / l.stride + 2 + 2 * mp_max + 1;
            if cap > MAX_RING {
                return Err(CalError::InvalidArgument(format!(
                    "computing clusters of {} samples exactly needs {:.1} GB per axis: pass a \
                     finite exact_up_to (e.g. 65536) so that long clusters are strided",
                    mp_max,
                    cap as f64 * 16.0 / 1e9
                )));
            }
            l.cap = cap as usize;
        }
        let axis = Axis {
            reference: f64::NAN,
            hi: 0.0,
            lo: 0.0,
            // NaN-filled so that every page is touched now: the footprint stays flat later
            rings: levels
                .iter()
                .map(|l| Ring {
                    hi: vec![f64::NAN; l.cap],
                    lo: vec![f64::NAN; l.cap],
                })
                .collect(),
            sum: vec![0.0; clusters.len()],
            comp: vec![0.0; clusters.len()],
            bhi: vec![0.0; BATCH],
            blo: vec![0.0; BATCH],
        };
        let mut acc = Allan {
            rate_hz,
            nax: axes,
            clusters,
            levels,
            axes: vec![axis; axes],
            n: 0,
            parallel: true,
            octave: None,
            cascade: None,
        };
        // phase index 0 (x_0 = 0) belongs to every level
        for a in acc.axes.iter_mut() {
            for r in a.rings.iter_mut() {
                r.hi[0] = 0.0;
                r.lo[0] = 0.0;
            }
        }
        for l in acc.levels.iter_mut() {
            l.count = 1;
        }
        Ok(acc)
    }

    /// Whether large pushes sum their terms on several threads (rayon; the default). Off, the
    /// work runs on the calling thread: for instruction counts.
    pub fn set_parallel(&mut self, parallel: bool) {
        self.parallel = parallel;
    }

    /// The clusters this accumulator computes.
    pub fn clusters(&self) -> &[Cluster] {
        &self.clusters
    }

    /// Number of interleaved channels.
    pub fn result_axes(&self) -> usize {
        self.nax
    }

    /// Samples pushed so far.
    pub fn len(&self) -> u64 {
        self.n
    }

    /// Whether nothing was pushed yet.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Bytes held by the rings and buffers (fixed at construction).
    pub fn memory_bytes(&self) -> usize {
        if let Some(o) = &self.octave {
            return o.memory_bytes();
        }
        if let Some(c) = &self.cascade {
            return c.memory_bytes();
        }
        let per_axis: usize = self.levels.iter().map(|l| 16 * l.cap).sum::<usize>()
            + 16 * BATCH
            + 16 * self.clusters.len();
        per_axis * self.nax
    }

    /// Adds rows of samples, row-major (`rows × axes` values, axes interleaved). Nothing is
    /// added when a value is NaN or infinite (the error names the row, counted from the first
    /// sample ever pushed).
    pub fn push(&mut self, samples: &[f64]) -> Result<()> {
        if !samples.len().is_multiple_of(self.nax) {
            return Err(CalError::InvalidArgument(format!(
                "got {} values, not a whole number of rows of {} axes",
                samples.len(),
                self.nax
            )));
        }
        let rows = samples.len() / self.nax;
        let bad = if let Some(o) = &mut self.octave {
            // checks each batch as it goes (while it is in cache) and undoes the push on a
            // non-finite value
            o.push(samples, rows, self.parallel, self.n)
        } else if self.parallel && samples.len() >= 4 * CHECK_CHUNK {
            // a pass over the whole push before any of its work: on the calling thread alone
            // it was a tenth of a 3 x 1e6 overlapping deviation's time on two threads
            crate::pool::map_chunks(samples, CHECK_CHUNK, first_non_finite)
                .into_iter()
                .enumerate()
                .find_map(|(c, bad)| bad.map(|i| c * CHECK_CHUNK + i))
        } else {
            first_non_finite(samples)
        };
        if let Some(i) = bad {
            return Err(CalError::NonFiniteSample {
                row: self.n + (i / self.nax) as u64,
                axis: i % self.nax,
            });
        }
        if self.octave.is_some() {
            self.n += rows as u64;
            return Ok(());
        }
        if let Some(c) = &mut self.cascade {
            c.push(samples, rows, self.parallel);
            self.n += rows as u64;
            return Ok(());
        }
        let mut start = 0usize;
        while start < rows {
            let b = BATCH.min(rows - start);
            self.push_batch(samples, start, b);
            start += b;
            self.n += b as u64;
        }
        Ok(())
    }

    /// Rows `start..start + b` (all finite): their phases, appended to every level's ring,
    /// then the new terms of every cluster and axis, in parallel when there are many.
    fn push_batch(&mut self, samples: &[f64], start: usize, b: usize) {
        let nax = self.nax;
        let n_before = self.n;
        let parallel = self.parallel;
        let Allan { levels, axes, .. } = self;
        // phases, a double-double running sum per axis (hi the plain sum, lo the exact sum of
        // its rounding errors), written straight into the ring of stride 1 (or, without one,
        // into the batch buffer); this batch holds phase indices k = n_before + 1 ..=
        // n_before + b
        let l1 = levels.iter().position(|l| l.stride == 1);
        let levels_ro: &[Level] = levels;
        let run_phases = |(a, ax): (usize, &mut Axis)| {
            if ax.reference.is_nan() {
                ax.reference = samples[start * nax + a];
            }
            let (r, mut hi, mut lo) = (ax.reference, ax.hi, ax.lo);
            let col = &samples[start * nax + a..];
            match l1 {
                Some(li) => {
                    let cap = levels_ro[li].cap;
                    let p0 = (levels_ro[li].count % cap as u64) as usize;
                    let first = b.min(cap - p0);
                    let ring = &mut ax.rings[li];
                    let (h, l) = (&mut ring.hi[p0..p0 + first], &mut ring.lo[p0..p0 + first]);
                    phases(&mut hi, &mut lo, r, col, nax, h, l);
                    let (h, l) = (&mut ring.hi[..b - first], &mut ring.lo[..b - first]);
                    phases(
                        &mut hi,
                        &mut lo,
                        r,
                        col.get(first * nax..).unwrap_or(&[]),
                        nax,
                        h,
                        l,
                    );
                }
                None => phases(
                    &mut hi,
                    &mut lo,
                    r,
                    col,
                    nax,
                    &mut ax.bhi[..b],
                    &mut ax.blo[..b],
                ),
            }
            ax.hi = hi;
            ax.lo = lo;
        };
        if parallel && nax > 1 && b >= PARALLEL_PHASES {
            use rayon::prelude::*;
            axes.par_iter_mut().enumerate().for_each(run_phases);
        } else {
            axes.iter_mut().enumerate().for_each(run_phases);
        }
        // every level keeps the phases at multiples of its stride
        let mut tasks: Vec<Task> = Vec::new();
        let mut task_cluster: Vec<usize> = Vec::new();
        let mut terms = 0u64;
        for li in 0..levels.len() {
            let d = levels[li].stride;
            let k_first = (n_before + 1).div_ceil(d) * d;
            let k_last = n_before + b as u64;
            if k_first > k_last {
                continue;
            }
            let e_first = levels[li].count;
            let count = ((k_last - k_first) / d + 1) as usize;
            if d > 1 {
                let cap = levels[li].cap;
                let p0 = (e_first % cap as u64) as usize;
                for ax in axes.iter_mut() {
                    match l1 {
                        // the source: the ring of stride 1, whose entry k holds phase k
                        Some(l) => {
                            let c = levels[l].cap;
                            let (src, dst) = if l < li {
                                let (x, y) = ax.rings.split_at_mut(li);
                                (&x[l], &mut y[0])
                            } else {
                                let (x, y) = ax.rings.split_at_mut(l);
                                (&y[0], &mut x[li])
                            };
                            let q0 = (k_first % c as u64) as usize;
                            gather(&src.hi, &src.lo, c, q0, d as usize, count, dst, cap, p0);
                        }
                        None => {
                            let q0 = (k_first - n_before - 1) as usize;
                            let ring = &mut ax.rings[li];
                            gather(
                                &ax.bhi,
                                &ax.blo,
                                usize::MAX,
                                q0,
                                d as usize,
                                count,
                                ring,
                                cap,
                                p0,
                            );
                        }
                    }
                }
            }
            let l = &mut levels[li];
            let e_last = e_first + count as u64 - 1;
            l.count = e_first + count as u64;
            for &(ci, mp) in &l.clusters {
                let lo_e = e_first.max(2 * mp as u64);
                if lo_e > e_last {
                    continue;
                }
                terms += e_last - lo_e + 1;
                tasks.push((li, mp, lo_e, e_last));
                task_cluster.push(ci);
            }
        }
        // the terms: each axis's new entries in PARTS parts, each part through every cluster
        // in order (a cluster of 2m reads the phases 2m back that the cluster of m has just
        // read: they are still in cache), the parts in parallel when there are many terms;
        // the partial sums are the same whichever thread makes them, and are added in order
        let part_sums = |(a, part): (usize, usize)| -> Vec<f64> {
            tasks
                .iter()
                .map(|&(li, mp, e0, e1)| {
                    let n = e1 - e0 + 1;
                    let lo = e0 + n * part as u64 / PARTS as u64;
                    let hi = e0 + n * (part as u64 + 1) / PARTS as u64;
                    if lo < hi {
                        sum_terms(&axes[a].rings[li], levels[li].cap, mp, lo, hi - 1)
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let jobs: Vec<(usize, usize)> = (0..nax)
            .flat_map(|a| (0..PARTS).map(move |p| (a, p)))
            .collect();
        let sums: Vec<Vec<f64>> = if parallel && terms * nax as u64 >= PARALLEL_TERMS {
            use rayon::prelude::*;
            jobs.par_iter().map(|&j| part_sums(j)).collect()
        } else {
            jobs.iter().map(|&j| part_sums(j)).collect()
        };
        for (k, &ci) in task_cluster.iter().enumerate() {
            for (a, ax) in axes.iter_mut().enumerate() {
                let s: f64 = (0..PARTS).map(|p| sums[a * PARTS + p][k]).sum();
                kahan_add(&mut ax.sum[ci], &mut ax.comp[ci], s);
            }
        }
    }

    /// The Allan deviation of everything pushed so far.
    pub fn result(&self) -> AllanResult {
        if let Some(o) = &self.octave {
            return o.result(&self.clusters, self.rate_hz, self.n);
        }
        if let Some(c) = &self.cascade {
            return c.result(&self.clusters, self.rate_hz, self.n);
        }
        let nc = self.clusters.len();
        let mut terms = vec![0u64; nc];
        for l in &self.levels {
            for &(ci, mp) in &l.clusters {
                terms[ci] = l.count.saturating_sub(2 * mp as u64);
            }
        }
        let adev = (0..nc)
            .map(|ci| {
                let m = self.clusters[ci].m;
                self.axes
                    .iter()
                    .map(|ax| deviation(ax.sum[ci], ax.comp[ci], terms[ci], m))
                    .collect()
            })
            .collect();
        AllanResult {
            clusters: self.clusters.clone(),
            taus: self
                .clusters
                .iter()
                .map(|c| c.m as f64 / self.rate_hz)
                .collect(),
            adev,
            terms,
            n: self.n,
        }
    }
}

/// The result at power-of-two cluster sizes from each axis's per-level Kahan sums:
/// `sums(axis, level)` gives (sum, compensation) of the level `log2 m`, and `terms(m)` the
/// number of terms after `n` samples.
fn octave_result(
    clusters: &[Cluster],
    rate_hz: f64,
    n: u64,
    nax: usize,
    terms: impl Fn(u64) -> u64,
    sums: impl Fn(usize, usize) -> (f64, f64),
) -> AllanResult {
    let terms: Vec<u64> = clusters.iter().map(|c| terms(c.m)).collect();
    let adev = clusters
        .iter()
        .zip(&terms)
        .map(|(c, &t)| {
            let level = c.m.trailing_zeros() as usize;
            (0..nax)
                .map(|a| {
                    let (sum, comp) = sums(a, level);
                    deviation(sum, comp, t, c.m)
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

/// Adds `s` to a Kahan sum (`sum`, and `comp` its compensation), so that the total over a
/// whole log keeps full precision (true sum = sum - comp).
#[inline(always)]
fn kahan_add(sum: &mut f64, comp: &mut f64, s: f64) {
    let yv = s - *comp;
    let t = *sum + yv;
    *comp = (t - *sum) - yv;
    *sum = t;
}

/// The deviation of a cluster of `m` samples from its Kahan sum of squared terms (NaN without
/// a term).
fn deviation(sum: f64, comp: f64, terms: u64, m: u64) -> f64 {
    if terms == 0 {
        f64::NAN
    } else {
        ((sum - comp) / (2.0 * terms as f64)).sqrt() / m as f64
    }
}

/// Non-overlapping Allan deviation of samples held in memory (`rows × axes`, row-major), at
/// the cluster sizes `ms` (allantools' `adev`).
pub fn adev(samples: &[f64], axes: usize, rate_hz: f64, ms: &[u64]) -> Result<AllanResult> {
    let mut acc = Allan::non_overlapping(rate_hz, axes, ms)?;
    acc.push(samples)?;
    Ok(acc.result())
}

/// Overlapping Allan deviation of samples held in memory (`rows × axes`, row-major): one
/// accumulator, one push.
pub fn oadev(
    samples: &[f64],
    axes: usize,
    rate_hz: f64,
    ms: &[u64],
    exact_up_to: Option<u64>,
) -> Result<AllanResult> {
    let mut acc = Allan::new(rate_hz, axes, ms, exact_up_to)?;
    acc.push(samples)?;
    Ok(acc.result())
}

#[cfg(test)]
#[path = "allan_tests.rs"]
mod tests;
