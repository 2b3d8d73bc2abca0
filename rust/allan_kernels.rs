//! The inner loops of the general Allan deviation path (`allan.rs`): the double-double
//! phases, the strided copies between levels, and the sums of the terms; and the check for
//! NaN and infinities that every path makes.

use super::{Ring, LANES};

/// The double-double running phase (`hi` the plain sum, `lo` the exact sum of its rounding
/// errors: TwoSum) over the readings `col[0], col[nax], col[2 nax]...` less `reference`,
/// written to `dh` and `dl` (one per reading).
#[inline(always)]
pub(super) fn phases(
    hi: &mut f64,
    lo: &mut f64,
    reference: f64,
    col: &[f64],
    nax: usize,
    dh: &mut [f64],
    dl: &mut [f64],
) {
    let n = dh.len().min(dl.len());
    if n == 0 {
        return;
    }
    let col = &col[..(n - 1) * nax + 1];
    let (dh, dl) = (&mut dh[..n], &mut dl[..n]);
    let (mut h, mut l) = (*hi, *lo);
    let mut step = |y: f64, oh: &mut f64, ol: &mut f64| {
        let y = y - reference;
        let s = h + y;
        let bp = s - h;
        l += (h - (s - bp)) + (y - bp);
        h = s;
        *oh = h;
        *ol = l;
    };
    // the readings of one axis, every nax-th value: a fixed stride for the usual axis counts
    // (no index arithmetic or bounds checks in the loop)
    match nax {
        1 => {
            for ((y, oh), ol) in col.iter().zip(dh.iter_mut()).zip(dl.iter_mut()) {
                step(*y, oh, ol);
            }
        }
        3 => {
            let (lh, bh) = dh.split_last_mut().expect("n > 0");
            let (ll, bl) = dl.split_last_mut().expect("n > 0");
            for ((y, oh), ol) in col[..(n - 1) * 3]
                .chunks_exact(3)
                .zip(bh.iter_mut())
                .zip(bl.iter_mut())
            {
                step(y[0], oh, ol);
            }
            step(col[(n - 1) * 3], lh, ll);
        }
        _ => {
            for ((y, oh), ol) in col
                .iter()
                .step_by(nax)
                .zip(dh.iter_mut())
                .zip(dl.iter_mut())
            {
                step(*y, oh, ol);
            }
        }
    }
    *hi = h;
    *lo = l;
}

/// Copies `count` entries, every `d`-th from position `q` of a source ring of `src_cap`
/// entries, to consecutive positions from `p` of `dst` (a ring of `cap` entries), in runs
/// that wrap around neither ring.
#[allow(clippy::too_many_arguments)]
pub(super) fn gather(
    src_hi: &[f64],
    src_lo: &[f64],
    src_cap: usize,
    mut q: usize,
    d: usize,
    mut count: usize,
    dst: &mut Ring,
    cap: usize,
    mut p: usize,
) {
    while count > 0 {
        let run = count
            .min(cap - p)
            .min((src_cap.min(src_hi.len()) - q).div_ceil(d));
        let (dh, dl) = (&mut dst.hi[p..p + run], &mut dst.lo[p..p + run]);
        let last = q + (run - 1) * d;
        let (sh, sl) = (&src_hi[q..=last], &src_lo[q..=last]);
        for i in 0..run {
            dh[i] = sh[i * d];
            dl[i] = sl[i * d];
        }
        count -= run;
        p = (p + run) % cap;
        q += run * d;
        if q >= src_cap {
            q -= src_cap;
        }
    }
}

/// Σ (x_e - 2 x_{e-mp} + x_{e-2mp})² for entries `e0 ..= e1` of a ring, in contiguous runs.
pub(super) fn sum_terms(ring: &Ring, cap: usize, mp: usize, e0: u64, e1: u64) -> f64 {
    let mut total = 0.0;
    let mut e = e0;
    while e <= e1 {
        let p2 = (e % cap as u64) as usize;
        let p1 = ((e - mp as u64) % cap as u64) as usize;
        let p0 = ((e - 2 * mp as u64) % cap as u64) as usize;
        let len = ((e1 - e + 1) as usize)
            .min(cap - p2)
            .min(cap - p1)
            .min(cap - p0);
        total += run(
            &ring.hi[p2..p2 + len],
            &ring.hi[p1..p1 + len],
            &ring.hi[p0..p0 + len],
            &ring.lo[p2..p2 + len],
            &ring.lo[p1..p1 + len],
            &ring.lo[p0..p0 + len],
        );
        e += len as u64;
    }
    total
}

/// One contiguous run of terms (dispatches to the AVX2 build where the CPU has it).
#[inline]
fn run(h2: &[f64], h1: &[f64], h0: &[f64], l2: &[f64], l1: &[f64], l0: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return crate::simd::avx2_call!(run_avx2(h2, h1, h0, l2, l1, l0));
    }
    run_impl(h2, h1, h0, l2, l1, l0)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2(h2: &[f64], h1: &[f64], h0: &[f64], l2: &[f64], l1: &[f64], l0: &[f64]) -> f64 {
    run_impl(h2, h1, h0, l2, l1, l0)
}

/// The second difference is formed as a difference of window sums, hi and lo parts apart, so
/// that no digit is lost to the size of the phase; lanes of [`LANES`] terms vectorise.
#[inline(always)]
fn run_impl(h2: &[f64], h1: &[f64], h0: &[f64], l2: &[f64], l1: &[f64], l0: &[f64]) -> f64 {
    let n = h2.len();
    let (h1, h0, l2, l1, l0) = (&h1[..n], &h0[..n], &l2[..n], &l1[..n], &l0[..n]);
    let mut acc = [0.0f64; LANES];
    let full = n / LANES * LANES;
    let lanes = h2[..full]
        .chunks_exact(LANES)
        .zip(h1[..full].chunks_exact(LANES))
        .zip(h0[..full].chunks_exact(LANES))
        .zip(l2[..full].chunks_exact(LANES))
        .zip(l1[..full].chunks_exact(LANES))
        .zip(l0[..full].chunks_exact(LANES));
    for (((((a2, a1), a0), b2), b1), b0) in lanes {
        for j in 0..LANES {
            let t = ((a2[j] - a1[j]) - (a1[j] - a0[j])) + ((b2[j] - b1[j]) - (b1[j] - b0[j]));
            acc[j] += t * t;
        }
    }
    let mut tail = 0.0;
    for i in full..n {
        let t = ((h2[i] - h1[i]) - (h1[i] - h0[i])) + ((l2[i] - l1[i]) - (l1[i] - l0[i]));
        tail += t * t;
    }
    acc.iter().sum::<f64>() + tail
}

/// The mean of `col[0], col[nax], ..., col[(b - 1) nax]`: the reference of an axis taken from
/// its first batch of readings, so that window and block sums hold the noise, not the level
/// (each reading divided first: no overflow whatever the readings' size).
pub(super) fn first_batch_mean(col: &[f64], nax: usize, b: usize) -> f64 {
    (0..b).map(|j| col[j * nax] / b as f64).sum()
}

/// The index of the first NaN or infinite value, if any. The common case, all finite, is one
/// vectorised pass: `v * 0` is 0 for a finite `v` and NaN otherwise (AVX2 where the CPU has
/// it: the samples are read once per push, and this pass is a tenth of a non-overlapping
/// deviation's work).
pub(super) fn first_non_finite(samples: &[f64]) -> Option<usize> {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::has_avx2_fma() {
        return crate::simd::avx2_call!(first_non_finite_avx2(samples));
    }
    first_non_finite_impl(samples)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn first_non_finite_avx2(samples: &[f64]) -> Option<usize> {
    first_non_finite_impl(samples)
}

#[inline(always)]
fn first_non_finite_impl(samples: &[f64]) -> Option<usize> {
    let mut acc = [0.0f64; 2 * LANES];
    let chunks = samples.chunks_exact(2 * LANES);
    let tail = chunks.remainder();
    for c in chunks {
        for j in 0..2 * LANES {
            acc[j] += c[j] * 0.0;
        }
    }
    let clean = acc.iter().chain(tail).all(|v| v.is_finite());
    if clean {
        None
    } else {
        samples.iter().position(|v| !v.is_finite())
    }
}
