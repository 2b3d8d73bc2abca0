//! Sphere of known radius: the error sum and the seed's three centre searches, plus the linear
//! least-squares sphere fit (centre and radius unknown).
//!
//! Error model: a reading is `p = offset + field`, where the field (gravity, the Earth's
//! magnetic field) has a known or unknown constant magnitude `R` in any orientation. The offset
//! (bias, hard iron) is the centre of the sphere the readings lie on. Gains and cross-axis
//! terms are ignored here: see `ellipsoid` for those.
//!
//! The error sum is the one of `../shared/seeds/sphere-center-descent.txt`:
//! `E(c) = sum_i |(x_i - c_x)^2 + (y_i - c_y)^2 + (z_i - c_z)^2 - R^2|`.

use crate::error::{check_positive, CalError, Result};
use crate::geometry;
use crate::simd::{arr3, dispatch, Simd};
use nalgebra::{Matrix4, Vector3, Vector4};
use rayon::prelude::*;

/// Points per rayon task.
const CHUNK: usize = 4096;

/// Below this many points the sums run on the calling thread: a sum over fewer takes a few
/// tens of microseconds, less than waking rayon's workers and waiting for them (the descent
/// sums once per neighbourhood, so a wake-up per neighbourhood would cost more than it saves).
const PARALLEL_FROM: usize = 1 << 16;

/// The result of a centre search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Descent {
    /// The centre found (same units as the points).
    pub center: [f64; 3],
    /// The error sum at `center`.
    pub error: f64,
    /// Neighbourhoods examined (descent) or grid nodes visited (cube search).
    pub iterations: usize,
    /// Evaluations of the error sum.
    pub evaluations: usize,
    /// The step in force at the end.
    pub step: f64,
    /// False when the iteration limit stopped the search before the step fell below `min_step`.
    pub converged: bool,
}

/// Options of [`descend_center`]; see [`DescentOptions::default`].
#[derive(Debug, Clone, Copy)]
pub struct DescentOptions {
    /// Where the search starts.
    pub start: [f64; 3],
    /// The first step along each axis.
    pub step: f64,
    /// The search stops once the step has fallen below this. `min_step == step` gives the
    /// fixed-step 26-neighbour descent.
    pub min_step: f64,
    /// The step is divided by this when no neighbour improves (must be > 1).
    pub shrink: f64,
    /// At most this many neighbourhoods are examined (a guard against a hang).
    pub max_iter: usize,
}

impl Default for DescentOptions {
    /// The seed's values: start at the origin, step 1000, divide by 10 down to 0.01.
    fn default() -> Self {
        DescentOptions {
            start: [0.0; 3],
            step: 1000.0,
            min_step: 0.01,
            shrink: 10.0,
            max_iter: 1_000_000,
        }
    }
}

/// The error sum `sum |‖p - center‖² - radius²|`.
///
/// ```
/// let pts = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
/// let e = triaxcal::sphere::sphere_error(&pts, [0.0; 3], 1.0).unwrap();
/// assert_eq!(e, 3.0);
/// ```
pub fn sphere_error(points: &[[f64; 3]], center: [f64; 3], radius: f64) -> Result<f64> {
    let scan = geometry::scan(points, true)?;
    if !radius.is_finite() || radius < 0.0 {
        return Err(CalError::InvalidArgument(format!(
            "radius must be a finite number >= 0, got {radius}"
        )));
    }
    if !center.iter().all(|c| c.is_finite()) {
        return Err(CalError::InvalidArgument("center must be finite".into()));
    }
    let m = magnitude(scan.max_abs, &[radius]);
    if geometry::needs_rescale(m) {
        let e = geometry::exponent(m);
        let pts = rescaled(points, e);
        let c = center.map(|v| geometry::times_pow2(v, -e));
        let err = error_sum(&pts, c, geometry::times_pow2(radius, -e).powi(2));
        return unscale_error(err, e, None);
    }
    Ok(error_sum(points, center, radius * radius))
}

/// The largest of `max_abs` and the magnitudes of `more`.
fn magnitude(max_abs: f64, more: &[f64]) -> f64 {
    more.iter().fold(max_abs, |m, v| m.max(v.abs()))
}

/// The points times `2^-e` (exact).
fn rescaled(points: &[[f64; 3]], e: i32) -> Vec<[f64; 3]> {
    points
        .iter()
        .map(|p| p.map(|v| geometry::times_pow2(v, -e)))
        .collect()
}

/// An error sum of points scaled by `2^-e`, in the caller's units (`x 4^e`); `center` (in the
/// caller's units) is named in the error when the sum overflows.
fn unscale_error(err: f64, e: i32, center: Option<[f64; 3]>) -> Result<f64> {
    let out = geometry::times_pow2(err, 2 * e);
    if out.is_finite() {
        Ok(out)
    } else {
        let found = center.map_or(String::new(), |c| {
            format!(
                " (the centre found is [{:e}, {:e}, {:e}])",
                c[0], c[1], c[2]
            )
        });
        Err(CalError::InvalidArgument(format!(
            "the error sum (squared distances summed over the points) is {err:.3e} x 2^{}, beyond \
             the largest double (1.8e308){found}: divide the points, the radius and the steps by \
             a power of ten",
            2 * e
        )))
    }
}

fn error_sum(points: &[[f64; 3]], c: [f64; 3], r2: f64) -> f64 {
    if points.len() < PARALLEL_FROM {
        error_sum_serial(points, c, r2)
    } else {
        points
            .par_chunks(CHUNK)
            .map(|ch| error_sum_serial(ch, c, r2))
            .sum()
    }
}

/// `Σ |‖p - c‖² - r2|` on the calling thread (AVX2 + FMA when the CPU has them).
fn error_sum_serial(points: &[[f64; 3]], c: [f64; 3], r2: f64) -> f64 {
    dispatch!(|simd| error_sum_lanes(simd, points, c, r2))
}

/// `|‖p - c‖² - r2|` of a group of four points.
#[inline(always)]
fn error_term<S: Simd>(s: S, g: &[[f64; 3]; 4], c: &[S::V; 3], r2: S::V) -> S::V {
    let x = s.load_xyz(g);
    let d = arr3!(|k| s.sub(x[k], c[k]));
    s.abs(s.sub(s.fma(d[2], d[2], s.fma(d[1], d[1], s.mul(d[0], d[0]))), r2))
}

/// Two groups of four points at a time, each with its own partial sums.
#[inline(always)]
fn error_sum_lanes<S: Simd>(s: S, points: &[[f64; 3]], c: [f64; 3], r2: f64) -> f64 {
    let cv = arr3!(|k| s.splat(c[k]));
    let r2v = s.splat(r2);
    let term = |g: &[[f64; 3]; 4]| error_term(s, g, &cv, r2v);
    let (groups, rest) = points.as_chunks::<4>();
    let (pairs, odd) = groups.as_chunks::<2>();
    let (mut a0, mut a1) = (s.zero(), s.zero());
    for p in pairs {
        a0 = s.add(a0, term(&p[0]));
        a1 = s.add(a1, term(&p[1]));
    }
    for g in odd {
        a0 = s.add(a0, term(g));
    }
    let mut tail = 0.0;
    for p in rest {
        let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        tail += (x * x + y * y + z * z - r2).abs();
    }
    s.sum(s.add(a0, a1)) + tail
}

/// The 26 neighbour offsets in units of the step, in a fixed order: x-major, then y, then z,
/// from -1 to +1, skipping the centre. Ties between neighbours go to the first in this order.
pub const NEIGHBOURS: [[i8; 3]; 26] = {
    let mut out = [[0i8; 3]; 26];
    let mut n = 0;
    let mut i = -1i8;
    while i <= 1 {
        let mut j = -1i8;
        while j <= 1 {
            let mut k = -1i8;
            while k <= 1 {
                if !(i == 0 && j == 0 && k == 0) {
                    out[n] = [i, j, k];
                    n += 1;
                }
                k += 1;
            }
            j += 1;
        }
        i += 1;
    }
    out
};

/// Partial sums for the 26 neighbours of one centre.
///
/// For a point with `q = p - c`, `s = |q|² - R²` and `(a, b, c) = 2h q`, the error at the
/// neighbour `c + h (i, j, k)` is `s - (i a + j b + k c) + h² (i² + j² + k²)`. A point whose
/// error keeps one sign over the whole neighbourhood (`|s|` larger than the most the
/// neighbourhood can change it) adds a term that is linear in `(i, j, k)`: such points are
/// summed as moments, and only points near the sphere's surface are evaluated 26 times.
#[derive(Clone, Copy)]
struct NeighbourSums {
    direct: [f64; 26],
    // moments of the points of stable sign, each already multiplied by that sign:
    // sum of s, of a, of b, of c, and the count (signed)
    m: [f64; 5],
}

impl NeighbourSums {
    fn zero() -> Self {
        NeighbourSums {
            direct: [0.0; 26],
            m: [0.0; 5],
        }
    }
    fn add(mut self, o: Self) -> Self {
        for t in 0..26 {
            self.direct[t] += o.direct[t];
        }
        for t in 0..5 {
            self.m[t] += o.m[t];
        }
        self
    }
    fn totals(&self, h2: f64) -> [f64; 26] {
        let mut out = [0.0; 26];
        for (t, d) in NEIGHBOURS.iter().enumerate() {
            let (i, j, k) = (d[0] as f64, d[1] as f64, d[2] as f64);
            let n = i * i + j * j + k * k;
            out[t] = self.direct[t] + self.m[0] - i * self.m[1] - j * self.m[2] - k * self.m[3]
                + h2 * n * self.m[4];
        }
        out
    }
}

fn neighbour_sums(points: &[[f64; 3]], c: [f64; 3], r2: f64, h: f64) -> [f64; 26] {
    let h2 = h * h;
    let part = |chunk: &[[f64; 3]]| dispatch!(|simd| neighbour_part(simd, chunk, c, r2, h));
    let sums = if points.len() < PARALLEL_FROM {
        part(points)
    } else {
        points
            .par_chunks(CHUNK)
            .map(part)
            .reduce(NeighbourSums::zero, NeighbourSums::add)
    };
    sums.totals(h2)
}

/// Points of [`neighbour_part`] examined between two passes over the points near the sphere.
const BLOCK: usize = 128;

/// The points near the sphere found in a block, one `[e0, a, b, c]` each: `e0 = |q|² - R²`
/// and `(a, b, c) = 2h q` (see [`NeighbourSums`]). Room for a block and the up to three points
/// a block leaves over for the next.
struct Near {
    v: [[f64; 4]; BLOCK + 8],
    n: usize,
}

/// [`NeighbourSums`] of `points` about the centre `c`, four points per vector: points far from
/// the sphere (their error keeps its sign over the whole neighbourhood) add to the moments; the
/// others are set aside and evaluated at all 26 neighbours after each block.
#[inline(always)]
fn neighbour_part<S: Simd>(
    s: S,
    points: &[[f64; 3]],
    c: [f64; 3],
    r2: f64,
    h: f64,
) -> NeighbourSums {
    let h2 = h * h;
    let cv = arr3!(|k| s.splat(c[k]));
    let (r2v, h2x2, low, one) = (
        s.splat(r2),
        s.splat(2.0 * h),
        s.splat(-3.0 * h2),
        s.splat(1.0),
    );
    // moments of the points of stable sign, signed: e0, a, b, c, count
    let mut m = [s.zero(); 5];
    let mut direct = [s.zero(); 26];
    let mut near = Near {
        v: [[0.0; 4]; BLOCK + 8],
        n: 0,
    };
    let (groups, rest) = points.as_chunks::<4>();
    for block in groups.chunks(BLOCK / 4) {
        for g in block {
            let x = s.load_xyz(g);
            let q = arr3!(|k| s.sub(x[k], cv[k]));
            let e0 = s.sub(s.fma(q[2], q[2], s.fma(q[1], q[1], s.mul(q[0], q[0]))), r2v);
            let v = [e0, s.mul(h2x2, q[0]), s.mul(h2x2, q[1]), s.mul(h2x2, q[2])];
            let reach = s.add(s.add(s.abs(v[1]), s.abs(v[2])), s.abs(v[3]));
            // positive everywhere in the neighbourhood (h² n >= 0 only adds), or negative
            let pos = s.gt(e0, reach);
            let neg = s.gt(s.sub(low, reach), e0);
            for t in 0..4 {
                m[t] = s.add(m[t], s.sub(s.and(pos, v[t]), s.and(neg, v[t])));
            }
            m[4] = s.add(m[4], s.sub(s.and(pos, one), s.and(neg, one)));
            let unstable = !(s.sign_bits(pos) | s.sign_bits(neg)) & 0xF;
            if unstable != 0 {
                // one point per vector; each written, kept only if near the sphere
                let rows = s.transpose(v);
                for (l, r) in rows.iter().enumerate() {
                    near.v[near.n] = s.to_array(*r);
                    near.n += ((unstable >> l) & 1) as usize;
                }
            }
        }
        near_sums(s, &mut near, h2, &mut direct);
    }
    let mut acc = NeighbourSums::zero();
    for t in 0..5 {
        acc.m[t] = s.sum(m[t]);
    }
    for t in 0..26 {
        acc.direct[t] = s.sum(direct[t]);
    }
    // the points after the last group of four, and what the blocks left over: one at a time
    let mut left: Vec<[f64; 4]> = near.v[..near.n].to_vec();
    for p in rest {
        let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        let e0 = x * x + y * y + z * z - r2;
        let v = [e0, 2.0 * h * x, 2.0 * h * y, 2.0 * h * z];
        let reach = v[1].abs() + v[2].abs() + v[3].abs();
        if e0 > reach {
            for t in 0..4 {
                acc.m[t] += v[t];
            }
            acc.m[4] += 1.0;
        } else if e0 < -reach - 3.0 * h2 {
            for t in 0..4 {
                acc.m[t] -= v[t];
            }
            acc.m[4] -= 1.0;
        } else {
            left.push(v);
        }
    }
    for v in left {
        for (t, d) in NEIGHBOURS.iter().enumerate() {
            let (i, j, k) = (d[0] as f64, d[1] as f64, d[2] as f64);
            let e = v[0] - i * v[1] - j * v[2] - k * v[3] + h2 * (i * i + j * j + k * k);
            acc.direct[t] += e.abs();
        }
    }
    acc
}

/// Adds the errors of the points set aside in `near`, at the 26 neighbours, to `direct`, four
/// points at a time; the up to three left over move to the front of `near`.
#[inline(always)]
fn near_sums<S: Simd>(s: S, near: &mut Near, h2: f64, direct: &mut [S::V; 26]) {
    let full = near.n / 4 * 4;
    // one plane of neighbours (i = -1, 0, 1) at a time: its nine sums stay in registers
    near_plane::<S, 0>(s, near, full, h2, direct);
    near_plane::<S, 1>(s, near, full, h2, direct);
    near_plane::<S, 2>(s, near, full, h2, direct);
    near.v.copy_within(full..near.n, 0);
    near.n -= full;
}

/// The sums of [`near_sums`] for the neighbours with `i = I - 1`.
#[inline(always)]
fn near_plane<S: Simd, const I: usize>(
    s: S,
    near: &Near,
    full: usize,
    h2: f64,
    direct: &mut [S::V; 26],
) {
    let h2v = s.splat(h2);
    // the plane's sums: index 3 (j + 1) + (k + 1), the centre's slot (4) unused
    let mut acc = [s.zero(); 9];
    let (groups, _) = near.v[..full].as_chunks::<4>();
    for g in groups {
        let [e0, a, b, cc] = s.transpose(g.map(|r| s.vector(r)));
        // e(i, j, k) = e0 - i a - j b - k c + h² (i² + j² + k²), built one axis at a time
        let xi = match I {
            0 => s.add(s.add(e0, h2v), a),
            1 => e0,
            _ => s.sub(s.add(e0, h2v), a),
        };
        let xh = s.add(xi, h2v);
        let ey = [s.add(xh, b), xi, s.sub(xh, b)];
        for (jj, &yj) in ey.iter().enumerate() {
            let yh = s.add(yj, h2v);
            let ez = [s.add(yh, cc), yj, s.sub(yh, cc)];
            for (kk, &e) in ez.iter().enumerate() {
                if I == 1 && jj == 1 && kk == 1 {
                    continue; // the centre
                }
                acc[3 * jj + kk] = s.add(acc[3 * jj + kk], s.abs(e));
            }
        }
    }
    for (m, a) in acc.iter().enumerate() {
        if I == 1 && m == 4 {
            continue;
        }
        let t = 9 * I + m;
        let t = if t > 13 { t - 1 } else { t };
        direct[t] = s.add(direct[t], *a);
    }
}

/// Variable-step 26-neighbour descent for the centre of a sphere of known `radius`.
///
/// From `opts.start`, evaluate the error sum at the 26 neighbours one step away along each
/// axis; move to the best one if it is better than the current centre, otherwise divide the
/// step by `opts.shrink`; stop when the step falls below `opts.min_step`. With
/// `min_step == step` this is the fixed-step descent.
///
/// ```
/// use triaxcal::sphere::{descend_center, DescentOptions};
/// let pts = [[11.0, 0.0, 0.0], [9.0, 0.0, 0.0], [10.0, 1.0, 0.0],
///            [10.0, -1.0, 0.0], [10.0, 0.0, 1.0], [10.0, 0.0, -1.0]];
/// let opts = DescentOptions { step: 1.0, min_step: 0.01, ..Default::default() };
/// let d = descend_center(&pts, 1.0, opts).unwrap();
/// assert_eq!(d.center, [10.0, 0.0, 0.0]);
/// ```
pub fn descend_center(points: &[[f64; 3]], radius: f64, opts: DescentOptions) -> Result<Descent> {
    let scan = geometry::scan(points, true)?;
    check_positive("radius", radius)?;
    check_positive("step", opts.step)?;
    check_positive("min_step", opts.min_step)?;
    if !(opts.shrink.is_finite() && opts.shrink > 1.0) {
        return Err(CalError::InvalidArgument(format!(
            "shrink must be a finite number greater than 1, got {}",
            opts.shrink
        )));
    }
    if opts.min_step > opts.step {
        return Err(CalError::InvalidArgument(format!(
            "min_step ({}) must not exceed step ({}): the descent stops once the step falls below \
             min_step (min_step == step gives the fixed-step descent)",
            opts.min_step, opts.step
        )));
    }
    if !opts.start.iter().all(|v| v.is_finite()) {
        return Err(CalError::InvalidArgument("start must be finite".into()));
    }
    let n = points.len();
    if n < 4 {
        return Err(CalError::TooFewPoints {
            got: n,
            need: 4,
            what: "the centre search",
        });
    }
    // the step shrinks `levels` times at least: bound the work before starting
    let levels = ((opts.step / opts.min_step).ln() / opts.shrink.ln()).floor() + 1.0;
    let work = levels * n as f64;
    if !(work <= DESCENT_WORK_LIMIT) {
        return Err(CalError::InvalidArgument(format!(
            "the descent would examine at least {levels:.3e} neighbourhoods (the step falls from \
             {:e} to {:e} by a factor {} at a time) of {n} points each, {work:.2e} point \
             evaluations, over the limit of {DESCENT_WORK_LIMIT:.0e}: use a larger shrink (the \
             seed's is 10) or a larger min_step",
            opts.step, opts.min_step, opts.shrink
        )));
    }
    // squares of the points and the radius must stay inside double precision (a far start
    // or a huge step only makes the first neighbourhoods infinite, which the descent leaves)
    let m = magnitude(scan.max_abs, &[radius]);
    if geometry::needs_rescale(m) {
        let e = geometry::exponent(m);
        let down = |v: f64| geometry::times_pow2(v, -e);
        let pts = rescaled(points, e);
        let o = DescentOptions {
            start: opts.start.map(down),
            step: down(opts.step),
            min_step: down(opts.min_step).max(f64::from_bits(1)),
            ..opts
        };
        let d = descend_center(&pts, down(radius), o)?;
        let center = d.center.map(|v| geometry::times_pow2(v, e));
        return Ok(Descent {
            center,
            error: unscale_error(d.error, e, Some(center))?,
            step: geometry::times_pow2(d.step, e),
            ..d
        });
    }
    geometry::classify(&scan, n, "centre")?;
    let r2 = radius * radius;
    let mut c = opts.start;
    let mut err = error_sum(points, c, r2);
    let mut evaluations = 1;
    let mut step = opts.step;
    let mut iterations = 0;
    let mut converged = false;
    // the work limit holds at run time too (moves are not bounded in advance)
    let cap = opts.max_iter.min((DESCENT_WORK_LIMIT / n as f64) as usize);
    while !converged && iterations < cap {
        iterations += 1;
        let sums = neighbour_sums(points, c, r2, step);
        evaluations += 26;
        let (best, best_err) =
            sums.iter()
                .enumerate()
                .fold((usize::MAX, f64::INFINITY), |(bi, be), (i, &e)| {
                    if e < be {
                        (i, e)
                    } else {
                        (bi, be)
                    }
                });
        if best_err < err {
            let d = NEIGHBOURS[best];
            for k in 0..3 {
                c[k] += step * d[k] as f64;
            }
            err = best_err;
        } else {
            step /= opts.shrink;
            converged = step < opts.min_step;
        }
    }
    // report the exact sum at the final centre (the neighbour sums add in another order)
    let error = error_sum(points, c, r2);
    if !error.is_finite() {
        return Err(CalError::InvalidArgument(format!(
            "the error sum overflows double precision at every centre the descent reached              (start {:?}, step {}): start nearer the points (their mean, say)",
            opts.start, opts.step
        )));
    }
    Ok(Descent {
        center: c,
        error,
        iterations,
        evaluations: evaluations + 1,
        step,
        converged,
    })
}

/// Largest number of neighbourhoods times points that [`descend_center`] examines (about 10 s
/// on one core in the worst case, where every point is near the sphere).
pub const DESCENT_WORK_LIMIT: f64 = 5e8;

/// Largest number of grid nodes times points that [`grid_center`] accepts (about 10 s on one
/// core).
pub const GRID_WORK_LIMIT: f64 = 2e10;

/// Brute-force search of the cube `[lo, hi]` at `step` for the centre of a sphere of known
/// `radius`: every node `lo + step * (i, j, k)` inside the cube is evaluated and the best
/// kept (the first in x-major order on ties).
pub fn grid_center(
    points: &[[f64; 3]],
    radius: f64,
    lo: [f64; 3],
    hi: [f64; 3],
    step: f64,
) -> Result<Descent> {
    let scan = geometry::scan(points, true)?;
    check_positive("radius", radius)?;
    check_positive("step", step)?;
    if points.is_empty() {
        return Err(CalError::TooFewPoints {
            got: 0,
            need: 1,
            what: "the cube search",
        });
    }
    let mut counts = [0usize; 3];
    for k in 0..3 {
        if !(lo[k].is_finite() && hi[k].is_finite() && hi[k] >= lo[k]) {
            return Err(CalError::InvalidArgument(format!(
                "the cube must have finite bounds with lo <= hi on every axis, got lo={lo:?} hi={hi:?}"
            )));
        }
        let n = ((hi[k] - lo[k]) / step * (1.0 + 1e-12)).floor() + 1.0;
        if !(n * points.len() as f64 <= GRID_WORK_LIMIT) {
            return Err(CalError::InvalidArgument(format!(
                "the cube search would take too long ({n:.3e} nodes along one axis, {} points): \
                 use a larger step, a smaller cube, or descend_center",
                points.len()
            )));
        }
        counts[k] = n as usize;
    }
    let nodes = counts[0] as f64 * counts[1] as f64 * counts[2] as f64;
    if nodes * points.len() as f64 > GRID_WORK_LIMIT {
        return Err(CalError::InvalidArgument(format!(
            "the cube search would evaluate {nodes:.3e} nodes x {} points, over the limit of \
             {GRID_WORK_LIMIT:.0e}: use a larger step, a smaller cube, or descend_center",
            points.len()
        )));
    }
    let m = magnitude(scan.max_abs, &[radius]);
    if geometry::needs_rescale(m) {
        let e = geometry::exponent(m);
        let down = |v: f64| geometry::times_pow2(v, -e);
        let pts = rescaled(points, e);
        let d = grid_nodes(&pts, down(radius), lo.map(down), down(step), counts)?;
        let center = d.center.map(|v| geometry::times_pow2(v, e));
        return Ok(Descent {
            center,
            error: unscale_error(d.error, e, Some(center))?,
            step,
            ..d
        });
    }
    grid_nodes(points, radius, lo, step, counts)
}

fn grid_nodes(
    points: &[[f64; 3]],
    radius: f64,
    lo: [f64; 3],
    step: f64,
    counts: [usize; 3],
) -> Result<Descent> {
    let total = counts[0] * counts[1] * counts[2];
    let r2 = radius * radius;
    let node = |idx: usize| -> [f64; 3] {
        let i = idx / (counts[1] * counts[2]);
        let j = (idx / counts[2]) % counts[1];
        let k = idx % counts[2];
        [
            lo[0] + step * i as f64,
            lo[1] + step * j as f64,
            lo[2] + step * k as f64,
        ]
    };
    let eval = |idx: usize| -> (f64, usize) { (error_sum_serial(points, node(idx), r2), idx) };
    let better = |a: (f64, usize), b: (f64, usize)| {
        if b.0 < a.0 || (b.0 == a.0 && b.1 < a.1) {
            b
        } else {
            a
        }
    };
    let (error, best) = (0..total)
        .into_par_iter()
        .map(eval)
        .reduce(|| (f64::INFINITY, usize::MAX), better);
    if best == usize::MAX {
        return Err(CalError::InvalidArgument(
            "the error sum overflows double precision at every node: divide the points, the \
             radius and the cube by a power of ten"
                .into(),
        ));
    }
    Ok(Descent {
        center: node(best),
        error,
        iterations: total,
        evaluations: total,
        step,
        converged: true,
    })
}

/// The result of a linear least-squares sphere fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearSphere {
    /// Centre of the sphere.
    pub center: [f64; 3],
    /// Radius of the sphere.
    pub radius: f64,
    /// RMS of `‖p - center‖ - radius` over the points.
    pub rms: f64,
}

/// Linear least-squares sphere fit: solves `|p|² = 2 c·p + d` for `c` and `d` on normalised
/// coordinates (one streaming pass for the moments), then `radius² = d + |c|²`.
///
/// This minimises an algebraic error, not the geometric distance: fast, one pass, and the
/// starting point of the geometric fits.
pub fn fit_sphere_linear(points: &[[f64; 3]]) -> Result<LinearSphere> {
    let scan = geometry::scan(points, true)?;
    if points.len() < 4 {
        return Err(CalError::TooFewPoints {
            got: points.len(),
            need: 4,
            what: "a sphere fit",
        });
    }
    if geometry::needs_rescale(scan.max_abs) {
        let e = geometry::exponent(scan.max_abs);
        let f = fit_sphere_linear(&rescaled(points, e))?;
        let up = |v: f64| geometry::times_pow2(v, e);
        return Ok(LinearSphere {
            center: f.center.map(up),
            radius: up(f.radius),
            rms: up(f.rms),
        });
    }
    let sp = geometry::classify(&scan, points.len(), "sphere")?;
    let (m, s) = (sp.mean, sp.scale);
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for p in points {
        let q = (Vector3::new(p[0], p[1], p[2]) - m) / s;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        let rhs = q.norm_squared();
        ata += row * row.transpose();
        atb += row * rhs;
    }
    let sol = ata
        .cholesky()
        .map(|ch| ch.solve(&atb))
        .ok_or_else(|| CalError::Degenerate {
            why: "the points do not determine a sphere".into(),
            fix: "turn the sensor through more orientations".into(),
        })?;
    let c = Vector3::new(sol[0], sol[1], sol[2]);
    let r2 = sol[3] + c.norm_squared();
    if !(r2 > 0.0) || !r2.is_finite() {
        return Err(CalError::Degenerate {
            why: "the linear sphere fit found no real radius".into(),
            fix: "the points do not lie near a sphere: check units and sensor selection".into(),
        });
    }
    let center = m + c * s;
    let radius = r2.sqrt() * s;
    let ss: f64 = points
        .iter()
        .map(|p| {
            let d = (Vector3::new(p[0], p[1], p[2]) - center).norm() - radius;
            d * d
        })
        .sum();
    Ok(LinearSphere {
        center: [center.x, center.y, center.z],
        radius,
        rms: (ss / points.len() as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_points(c: [f64; 3], r: f64, n: usize) -> Vec<[f64; 3]> {
        // a Fibonacci sphere: deterministic and even coverage
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let rr = (1.0 - z * z).sqrt();
                let t = golden * i as f64;
                [
                    c[0] + r * rr * t.cos(),
                    c[1] + r * rr * t.sin(),
                    c[2] + r * z,
                ]
            })
            .collect()
    }

    fn brute_neighbours(points: &[[f64; 3]], c: [f64; 3], r2: f64, h: f64) -> [f64; 26] {
        let mut out = [0.0; 26];
        for (t, d) in NEIGHBOURS.iter().enumerate() {
            let cc = [
                c[0] + h * d[0] as f64,
                c[1] + h * d[1] as f64,
                c[2] + h * d[2] as f64,
            ];
            out[t] = error_sum(points, cc, r2);
        }
        out
    }

    #[test]
    fn neighbour_sums_match_direct_evaluation() {
        // several blocks and rayon chunks; one block and a point after the groups of four;
        // fewer points than a group
        for n in [70_000, 1001, 7] {
            let pts = sphere_points([100.0, -50.0, 20.0], 1000.0, n);
            for (c, h) in [
                ([0.0, 0.0, 0.0], 1000.0),
                ([90.0, -45.0, 25.0], 10.0),
                ([100.0, -50.0, 20.0], 0.01),
                ([100.0, -50.0, 20.0], 3.0),
            ] {
                let fast = neighbour_sums(&pts, c, 1e6, h);
                let slow = brute_neighbours(&pts, c, 1e6, h);
                for t in 0..26 {
                    assert!(
                        (fast[t] - slow[t]).abs() <= 1e-9 * slow[t].max(1.0),
                        "{n} points, {t}: {} vs {}",
                        fast[t],
                        slow[t]
                    );
                }
            }
        }
    }

    #[test]
    fn descent_finds_centre_of_exact_sphere() {
        let pts = sphere_points([123.4, -56.7, 8.9], 16384.0, 500);
        let d = descend_center(&pts, 16384.0, DescentOptions::default()).unwrap();
        for k in 0..3 {
            assert!(
                (d.center[k] - [123.4, -56.7, 8.9][k]).abs() < 0.02,
                "{:?}",
                d.center
            );
        }
        assert!(d.converged && d.step < 0.01);
    }

    #[test]
    fn grid_matches_descent_at_the_grid_step() {
        let pts = sphere_points([3.0, -2.0, 1.0], 10.0, 300);
        let g = grid_center(&pts, 10.0, [-5.0; 3], [5.0; 3], 1.0).unwrap();
        assert_eq!(g.center, [3.0, -2.0, 1.0]);
        assert_eq!(g.iterations, 11 * 11 * 11);
    }

    #[test]
    fn grid_refuses_huge_work() {
        let pts = sphere_points([0.0; 3], 1.0, 1000);
        assert!(matches!(
            grid_center(&pts, 1.0, [-1e4; 3], [1e4; 3], 0.01),
            Err(CalError::InvalidArgument(_))
        ));
    }

    #[test]
    fn linear_fit_exact() {
        let pts = sphere_points([1e4, -2e4, 500.0], 16384.0, 100);
        let f = fit_sphere_linear(&pts).unwrap();
        assert!((f.center[0] - 1e4).abs() < 1e-6 && (f.radius - 16384.0).abs() < 1e-6);
        assert!(f.rms < 1e-6);
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let mut pts = sphere_points([0.0; 3], 1.0, 10);
        pts[3][1] = f64::NAN;
        assert_eq!(
            fit_sphere_linear(&pts),
            Err(CalError::NonFinite { index: 3 })
        );
        assert!(matches!(
            fit_sphere_linear(&pts[..2]),
            Err(CalError::NonFinite { .. }) | Err(CalError::TooFewPoints { .. })
        ));
        let ok = sphere_points([0.0; 3], 1.0, 10);
        assert!(matches!(
            descend_center(&ok, -1.0, DescentOptions::default()),
            Err(CalError::InvalidArgument(_))
        ));
        let o = DescentOptions {
            shrink: 1.0,
            ..Default::default()
        };
        assert!(matches!(
            descend_center(&ok, 1.0, o),
            Err(CalError::InvalidArgument(_))
        ));
    }
}
