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

mod neighbours;
#[cfg(test)]
mod tests;

use neighbours::neighbour_sums;
pub use neighbours::NEIGHBOURS;

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
        let parts = points
            .par_chunks(CHUNK)
            .map(|ch| error_sum_serial(ch, c, r2))
            .collect();
        crate::kernel::in_order(parts, || 0.0, |a, b| a + b)
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
