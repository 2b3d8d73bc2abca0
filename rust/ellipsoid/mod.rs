//! Geometric ellipsoid fits by Gauss-Newton / Levenberg-Marquardt.
//!
//! Error model (the autopilots' compass and accelerometer calibrators use the same one): a raw
//! reading `p` and the true field `f` of constant magnitude `R` are related by
//!
//! ```text
//!     f = W (p - offset)
//! ```
//!
//! where `offset` is the bias / hard iron and the symmetric positive-definite `W` holds the
//! scale factors on its diagonal (`diag`) and the cross-axis / soft-iron terms off it
//! (`offdiag`). Calibrated readings are `(raw - offset) @ W.T` in numpy terms: the gain
//! *multiplies*. Three models:
//!
//! | model    | unknowns                    | W                       |
//! |----------|-----------------------------|-------------------------|
//! | `Sphere` | offset, 1 scale             | `k I`                   |
//! | `Axis`   | offset, 3 gains             | `diag(g)`               |
//! | `Full`   | offset, symmetric 3x3 `W`   | `[[d,e,f],[e,d',g],..]` |
//!
//! Any parameter can be held at a given value instead (`FitOptions::fixed`): the seed's
//! spreadsheet fits the offsets and two gains with the third gain fixed at 1, and a sphere of
//! known radius needs only its centre. The fewest readings a model takes is its number of free
//! unknowns: with exactly that many the solve is exactly determined (no residual is left to
//! estimate the noise or the standard errors from, and the fit says so).
//!
//! The residual of a point is `‖W (p - offset)‖ - R`, the geometric error along the field
//! direction. Internally the fit works on normalised coordinates `q = (p - mean) / scale` with
//! `R = 1`; results are mapped back at the end (readings beyond 2^±400 in magnitude are first
//! rescaled by a power of two, which is exact, so that no square overflows or underflows). It
//! starts from an algebraic fit (the least-squares quadric, i.e. the smallest eigenvector of
//! the design scatter matrix, itself started from the linear sphere fit where the quadric is no
//! ellipsoid), then refines with Levenberg-Marquardt. Each iteration is one streaming pass that
//! accumulates `JᵀJ`, `Jᵀr` and the cost (`kernel`): extra memory does not grow with the
//! number of points. A step predicted to lower the cost by less than 1e-4 of it moves `JᵀJ` by
//! less than 1 % of the relative noise: its pass sums only `Jᵀr` and the cost, about half the
//! work, and the last `JᵀJ` serves the next step and the standard errors.
//!
//! Large inputs are solved first on a subsample of [`SUBSAMPLE_SIZE`] points, taken by a hash
//! of each point's coordinates (so that neither the order nor a period of the data can make it
//! unrepresentative; data with few distinct values fall back to one point at a fixed
//! pseudo-random place in each of that many equal blocks), picked in the same pass that checks
//! the points and takes their moments. From the subsample's solution, inputs of 400,000 points
//! and more take one pass over all points (`JᵀJ`, `Jᵀr`) and a Newton step whose curvature
//! term comes from a larger sample taken by the same hash (`refine::polish_once`): when that
//! step can be shown to leave less than `tol` of the cost, the fit has read the points twice
//! in all. Otherwise, and for smaller inputs, Gauss-Newton passes polish on all points, reusing
//! the `JᵀJ` at hand and summing only `Jᵀr` until the last pass, which accumulates the full
//! `JᵀJ` for the standard errors and the residual statistics (the coverage of the sphere comes
//! from the subsample). The answer is the minimum over all points, so it does not depend on
//! their order beyond round-off (passes that stop contracting fall back to Levenberg-Marquardt
//! on all points).
//!
//! Noise biases every length-based fit by O(σ²) (σ² the variance of raw noise per axis): a
//! noisy vector is longer on average, `E‖W(p - offset)‖ ≈ R + σ²(tr W² - ûᵀW²û)/(2R)`, and
//! the Jacobian, computed from the same noisy points, correlates with the residual (errors in
//! variables: `Cov(J, r)` along the scale direction is the radial variance `σ²ûᵀW²û`). The
//! plain geometric fit therefore shrinks `W` by about `2σ²/R²`. With `debias` (the default)
//! the residual is `‖W(p - offset)‖ - R - σ²(tr W² + ûᵀW²û)/(2R)`, which zeroes both terms to
//! first order; `σ²` comes from the residuals (`Var r ≈ σ² ûᵀW²û`) of the same pass, as the
//! fixed point `σ² = Σ r² / Σ ûᵀW²û`. The correction is skipped when the bias is below a tenth
//! of the statistical error (σ < 0.1/√N relative to the radius: 0.7 % for 200 points, 0.03 %
//! for 10⁵), where it cannot matter. At 5 % noise this cuts the matrix error at large N by
//! 5-8x and makes the fit clearly more accurate than the algebraic one; `debias = false` gives
//! the plain geometric least-squares fit (the seed's objective).

use crate::algebraic::{self, Norm};
use crate::bounds;
use crate::error::{check_positive, CalError, Result};
use crate::geometry::{self, Spread};
use crate::kernel::{self, Setup, Sums, Want};
use crate::linalg;
use nalgebra::{Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};

mod finish;
mod options;
mod refine;
mod subsample;
#[cfg(test)]
pub(crate) mod tests;

use finish::finish;
pub use options::{EllipsoidFit, FitOptions, Method, Model, FIXABLE};
use refine::{polish, polish_once, refine, PolishStart};
use subsample::subsample;

/// Inputs with more points than this are first solved on a subsample.
pub const SUBSAMPLE_ABOVE: usize = 60_000;
/// Size of that subsample: between these, `n / 25` (a larger subsample makes its solution and
/// its `JᵀJ` closer to the full data's, so that fewer passes over all points polish it).
pub const SUBSAMPLE_SIZE: (usize, usize) = (20_000, 40_000);
/// The curvature sample of the one-pass polish (`refine::polish_once`) is this many times the
/// subsample, up to [`CURVATURE_MAX`] points, taken the same way; inputs of fewer than
/// [`CURVATURE_SHARE`] times its size are polished by Gauss-Newton passes instead (for them
/// the sample would cost as much as a pass).
const CURVATURE_TIMES: usize = 5;
/// Most points of the curvature sample.
const CURVATURE_MAX: usize = 200_000;
/// See [`CURVATURE_TIMES`].
const CURVATURE_SHARE: usize = 4;
/// Most polishing passes over all points before falling back to Levenberg-Marquardt.
const MAX_POLISH: usize = 8;

// ----------------------------------------------------------------------------------------
// parameter vectors (normalised coordinates, unit radius)
//   Sphere: [offset_x, offset_y, offset_z, k]
//   Axis:   [offset_x, offset_y, offset_z, diag_x, diag_y, diag_z]
//   Full:   [offset_x, offset_y, offset_z, diag_x, diag_y, diag_z, offdiag_xy, offdiag_xz, offdiag_yz]

fn w_of(th: &[f64]) -> Matrix3<f64> {
    match th.len() {
        4 => Matrix3::identity() * th[3],
        6 => Matrix3::from_diagonal(&Vector3::new(th[3], th[4], th[5])),
        _ => Matrix3::new(
            th[3], th[6], th[7], th[6], th[4], th[8], th[7], th[8], th[5],
        ),
    }
}

fn theta_of<const P: usize>(o: Vector3<f64>, w: &Matrix3<f64>) -> [f64; P] {
    let mut th = [0.0; P];
    th[0] = o.x;
    th[1] = o.y;
    th[2] = o.z;
    match P {
        4 => th[3] = w.trace() / 3.0,
        6 => {
            for a in 0..3 {
                th[3 + a] = w[(a, a)];
            }
        }
        _ => {
            for a in 0..3 {
                th[3 + a] = w[(a, a)];
            }
            th[6] = w[(0, 1)];
            th[7] = w[(0, 2)];
            th[8] = w[(1, 2)];
        }
    }
    th
}

fn setup(norm: Norm, th: &[f64]) -> Setup {
    let w = w_of(th);
    Setup {
        mean: [norm.mean.x, norm.mean.y, norm.mean.z],
        inv_scale: norm.inv_scale,
        offset: [th[0], th[1], th[2]],
        w: [
            [w[(0, 0)], w[(0, 1)], w[(0, 2)]],
            [w[(1, 0)], w[(1, 1)], w[(1, 2)]],
            [w[(2, 0)], w[(2, 1)], w[(2, 2)]],
        ],
        trw2: (w * w).trace(),
    }
}

fn full_matrix<const P: usize>(jtj: &[[f64; P]; P]) -> SMatrix<f64, P, P> {
    SMatrix::<f64, P, P>::from_fn(|i, j| if i <= j { jtj[i][j] } else { jtj[j][i] })
}

/// Solves `(JᵀJ + λ diag JᵀJ) δ = -Jᵀr` for the free parameters (`δ = 0` for fixed ones).
///
/// `jtj` must be exactly symmetric (as [`full_matrix`] makes it): its column-major storage is
/// then read as the row-major array the Cholesky factorisation works on, with no element-wise
/// copy, and only its lower triangle is set up and factored.
fn solve<const P: usize>(
    jtj: &SMatrix<f64, P, P>,
    jtr: &[f64; P],
    lambda: f64,
    free: &[bool; P],
) -> Option<SVector<f64, P>> {
    // data.0[c][r] = JᵀJ[r][c] = JᵀJ[c][r]
    let mut a: [[f64; P]; P] = jtj.data.0;
    let mut x: [f64; P] = std::array::from_fn(|i| -jtr[i]);
    for i in 0..P {
        if free[i] {
            a[i][i] += lambda * a[i][i].max(1e-12);
        } else {
            // row and column i of the identity (lower triangle only)
            for j in 0..i {
                a[i][j] = 0.0;
            }
            for k in i + 1..P {
                a[k][i] = 0.0;
            }
            a[i][i] = 1.0;
            x[i] = 0.0;
        }
    }
    linalg::spd_solve_in_place(&mut a, &mut x).then(|| SVector::<f64, P>::from(x))
}

/// The noise term `h = σ²/2` of the debiased residual: the fixed point `h = Σ(r₀ - h c)² /
/// (2 Σ ûᵀW²û)` of one pass's sums (the estimate hardly depends on `h`: a few steps suffice).
fn half_sigma2<const P: usize>(a: &Sums<P>) -> f64 {
    let wq = a.wq.max(f64::MIN_POSITIVE);
    let mut h = 0.5 * a.r0r0 / wq;
    for _ in 0..4 {
        h = 0.5 * a.cost(h) / wq;
    }
    h
}

// ----------------------------------------------------------------------------------------
// refinement

struct Refined<const P: usize> {
    th: [f64; P],
    iterations: usize,
    converged: bool,
}

/// The noise term of the residual during a refinement.
#[derive(Clone, Copy, Debug)]
enum Noise {
    /// `h` held fixed (0: the plain geometric residual).
    Fixed(f64),
    /// `h` re-estimated from every accepted pass (see [`noise_term`]), for data sets of this
    /// many points.
    Estimated(usize),
}

/// The noise term `h = σ²/2` for a pass over `n` points, or 0 where the O(σ²) bias is buried
/// in the statistical error: correct only when σ² > σ / (10 √n), i.e. σ > 0.1 / √n in
/// unit-radius terms.
fn noise_term<const P: usize>(a: &Sums<P>, n: usize) -> f64 {
    let sigma2 = a.r0r0 / a.wq.max(f64::MIN_POSITIVE);
    if sigma2.sqrt() > 0.1 / (n as f64).sqrt() {
        half_sigma2(a)
    } else {
        0.0
    }
}

/// The state the statistics are computed from.
struct Final<const P: usize> {
    th: [f64; P],
    /// Sums of a pass at (or, after a polishing step, just before) `th`, with `JᵀJ`.
    sums: Sums<P>,
    /// `Σ r²` of the residual the fit minimised, at `th`.
    cost: f64,
    /// `Σ r₀²` (the plain residual) at `th`.
    plain: f64,
    iterations: usize,
    converged: bool,
    coverage: bool,
}

// ----------------------------------------------------------------------------------------

/// Fits an ellipsoid (or sphere) to `points`; see the module documentation for the model.
///
/// Errors: non-finite points, too few points for the model, points on a line or plane, or
/// points that cover too little of the sphere to determine the model's parameters, and results
/// that do not fit in double precision.
#[inline(never)] // a stable symbol for instruction counts (`benches/instructions.py`)
pub fn fit_ellipsoid(points: &[[f64; 3]], opts: &FitOptions) -> Result<EllipsoidFit> {
    if let Some(r) = opts.radius {
        check_positive("radius", r)?;
    }
    if !(opts.tol.is_finite() && opts.tol >= 0.0) {
        return Err(CalError::InvalidArgument(format!(
            "tol must be a finite number >= 0, got {}",
            opts.tol
        )));
    }
    let model = opts.model;
    let p = model.nparams();
    let mut nfixed = 0;
    for (i, v) in opts.fixed.iter().enumerate() {
        let Some(v) = *v else { continue };
        let name = if model == Model::Sphere && i == 3 {
            "gain"
        } else {
            FIXABLE[i]
        };
        if i >= p {
            return Err(CalError::InvalidArgument(format!(
                "{name} cannot be fixed in the {}: it has no such parameter",
                model.label()
            )));
        }
        if !v.is_finite() || ((3..6).contains(&i) && !(v > 0.0)) {
            return Err(CalError::InvalidArgument(format!(
                "fixed {name} must be a finite number{}, got {v}",
                if (3..6).contains(&i) {
                    " greater than zero"
                } else {
                    ""
                }
            )));
        }
        if i >= 3 && opts.radius.is_none() {
            return Err(CalError::InvalidArgument(format!(
                "fixing {name} needs radius: a gain is in calibrated units per raw unit, so give \
                 the magnitude calibrated readings must have (e.g. radius=16384 for counts at \
                 +-2 g, 1.0 for g)"
            )));
        }
        nfixed += 1;
    }
    let nfree = p - nfixed;
    if nfree == 0 {
        return Err(CalError::InvalidArgument(format!(
            "every parameter of the {} is fixed: nothing is left to fit",
            model.label()
        )));
    }
    // a large input is subsampled; the points of the subsample (and of the curvature sample,
    // a superset taken by the same hash) are picked in the same pass as the moments: one read
    // of the points, not two
    let n = points.len();
    let sample_size = (n / 25).clamp(SUBSAMPLE_SIZE.0, SUBSAMPLE_SIZE.1);
    let curv_size = (CURVATURE_TIMES * sample_size).min(CURVATURE_MAX);
    let one_pass = CURVATURE_SHARE * curv_size <= n;
    let (scan, picked) = if n > SUBSAMPLE_ABOVE && opts.method != Method::Algebraic {
        // lists: the subsample, and the two halves of the curvature sample (by the hash's
        // last bit)
        let cut = subsample::hash_cut(sample_size, n);
        let curv_cut = if one_pass {
            subsample::hash_cut(curv_size, n)
        } else {
            0
        };
        let any = cut.max(curv_cut);
        let (scan, lists) =
            geometry::scan_picking::<3, _>(points, opts.parallel, |chunk, lists| {
                // most points hash above both cuts: screened four at a time
                subsample::below_cut(chunk, any, |p, h| {
                    if h < cut {
                        lists[0].push(*p);
                    }
                    if h < curv_cut {
                        lists[1 + (h & 1) as usize].push(*p);
                    }
                });
            })?;
        (scan, Some(lists))
    } else {
        (geometry::scan(points, opts.parallel)?, None)
    };
    if geometry::needs_rescale(scan.max_abs) {
        return fit_rescaled(points, opts, scan.max_abs);
    }
    let need = nfree.max(4);
    if points.len() < need {
        return Err(CalError::TooFewPoints {
            got: points.len(),
            need,
            what: match (model, nfixed) {
                (Model::Sphere, 0) => "the \"sphere\" model (offset + scale, 4 unknowns)",
                (Model::Axis, 0) => "the \"axis\" model (offset + 3 gains, 6 unknowns)",
                (Model::Full, 0) => {
                    "the \"full\" model (offset + symmetric 3x3 matrix, 9 unknowns)"
                }
                _ => "the model with its fixed parameters",
            },
        });
    }
    let sp = geometry::classify(&scan, points.len(), model.label())?;
    let work = picked.map(|[sub, half0, half1]| {
        let (sub, by_hash) = subsample(points, sample_size, sub);
        Samples {
            sub,
            curv: (one_pass && by_hash).then_some((half0, half1)),
        }
    });
    match model {
        Model::Sphere => fit_generic::<4>(points, work, &sp, opts, nfree),
        Model::Axis => fit_generic::<6>(points, work, &sp, opts, nfree),
        Model::Full => fit_generic::<9>(points, work, &sp, opts, nfree),
    }
}

/// Fits readings of magnitude beyond 2^±400 by scaling them with a power of two (exact) and
/// mapping the result back; fails when the result itself does not fit in double precision.
fn fit_rescaled(points: &[[f64; 3]], opts: &FitOptions, max_abs: f64) -> Result<EllipsoidFit> {
    let e = geometry::exponent(max_abs);
    let down = |x: f64| geometry::times_pow2(x, -e);
    let up = |x: f64| geometry::times_pow2(x, e);
    let scaled: Vec<[f64; 3]> = points
        .iter()
        .map(|p| [down(p[0]), down(p[1]), down(p[2])])
        .collect();
    let mut o = *opts;
    for (i, v) in o.fixed.iter_mut().enumerate() {
        if let Some(x) = v {
            // offsets are raw units; gains are calibrated units per raw unit
            *x = if i < 3 { down(*x) } else { up(*x) };
        }
    }
    let mut f = fit_ellipsoid(&scaled, &o)?;
    let own_scale = opts.radius.is_none();
    for k in 0..3 {
        f.offset[k] = up(f.offset[k]);
        f.stderr[k] = up(f.stderr[k]);
    }
    if own_scale {
        f.radius = up(f.radius);
        f.rms = up(f.rms);
    } else {
        for row in f.matrix.iter_mut() {
            for x in row.iter_mut() {
                *x = down(*x);
            }
        }
    }
    for k in 3..f.stderr.len() {
        if f.model == Model::Sphere {
            f.stderr[k] = up(f.stderr[k]); // data_radius, raw units
        } else if !own_scale {
            f.stderr[k] = down(f.stderr[k]);
        }
    }
    let usable = |v: f64| v.is_finite() && v != 0.0;
    let diag_ok = (0..3).all(|k| usable(f.matrix[k][k]));
    let all_finite = f.offset.iter().all(|v| v.is_finite())
        && f.matrix.iter().flatten().all(|v| v.is_finite())
        && usable(f.radius);
    if !(diag_ok && all_finite) {
        return Err(CalError::InvalidArgument(format!(
            "the readings (magnitude up to {max_abs:.3e}) and the radius ({}) are so far apart in \
             scale that the calibration overflows or underflows double precision: express the \
             readings or the radius in other units",
            opts.radius
                .map_or("the data's own".to_string(), |r| format!("{r:e}"))
        )));
    }
    Ok(f)
}

fn not_determined(model: Model, detail: &str) -> CalError {
    let simpler = match model {
        Model::Full => " or use a simpler model (the axis or the sphere model)",
        Model::Axis => " or use the sphere model",
        Model::Sphere => "",
    };
    CalError::Degenerate {
        why: format!(
            "the points do not determine the \"{}\" model ({detail})",
            model.name()
        ),
        fix: format!(
            "they cover too small a part of the sphere: turn the sensor through more orientations, \
             including upside down and on each side,{simpler}"
        ),
    }
}

/// The samples of a large input: the subsample it is solved on first and, when it is polished
/// in one pass, the curvature sample (see `refine::polish_once`).
struct Samples {
    sub: Vec<[f64; 3]>,
    /// The curvature sample in two halves (by a bit of the hash).
    curv: Option<Halves>,
}

/// Two halves of a sample of points.
type Halves = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The fit proper; `sample`: the samples of a large input (None: fit all points directly).
fn fit_generic<const P: usize>(
    points: &[[f64; 3]],
    sample: Option<Samples>,
    sp: &Spread,
    opts: &FitOptions,
    nfree: usize,
) -> Result<EllipsoidFit> {
    let model = opts.model;
    let n = points.len();
    let s = sp.scale;
    let norm = Norm {
        mean: sp.mean,
        inv_scale: 1.0 / s,
    };
    // fixed parameters in normalised coordinates (gain g = W_unit R = W1 R / s)
    let mut fix = [None; P];
    let mut free = [true; P];
    for i in 0..P {
        if let Some(v) = opts.fixed[i] {
            fix[i] = Some(if i < 3 {
                (v - sp.mean[i]) / s
            } else {
                v * s / opts.radius.unwrap_or(1.0)
            });
            free[i] = false;
        }
    }
    let subsampled = sample.is_some();
    let (store, curv) = sample.map_or((Vec::new(), None), |s| (s.sub, s.curv));
    let work: &[[f64; 3]] = if subsampled { &store } else { points };

    // starting point
    let sphere = model == Model::Sphere;
    let start = algebraic::start(work, norm, model == Model::Full, sphere, opts.parallel);
    let (o0, w0) = match start {
        Some(st) => st,
        None if opts.method == Method::Algebraic && !sphere => {
            return Err(not_determined(
                model,
                "the least-squares quadric is not an ellipsoid",
            ))
        }
        None => algebraic::start(work, norm, false, true, opts.parallel)
            .ok_or_else(|| not_determined(model, "no sphere fits them"))?,
    };
    let mut th0 = theta_of::<P>(o0, &w0);
    for i in 0..P {
        if let Some(v) = fix[i] {
            th0[i] = v;
        }
    }

    let fin = if opts.method == Method::Algebraic {
        let want = Want {
            jtj: true,
            debias: false,
            coverage: opts.diagnostics,
        };
        let a = kernel::pass::<P>(points, &setup(norm, &th0), want, opts.parallel);
        Final {
            th: th0,
            cost: a.r0r0,
            plain: a.r0r0,
            sums: a,
            iterations: 0,
            converged: true,
            coverage: opts.diagnostics,
        }
    } else {
        // the geometric fit, debiased with the noise level of its own residuals; large inputs
        // do that on the subsample and polish on all points
        let exact = n == nfree;
        let noise = if opts.debias && !exact {
            Noise::Estimated(work.len())
        } else {
            Noise::Fixed(0.0)
        };
        let (r, acc, h) = refine::<P>(work, norm, th0, opts, noise, &free, opts.max_iter);
        let iterations = r.iterations;
        if subsampled {
            // one pass over all points with a Newton step, or, when that step cannot be
            // taken as converged, Gauss-Newton passes on from it
            let once = match &curv {
                Some((c0, c1)) if opts.max_iter > iterations => {
                    polish_once::<P>(points, [c0, c1], norm, r.th, opts, &free)
                }
                _ => Err(None),
            };
            let polished = match once {
                Ok(f) => Ok(f),
                Err(Some(u)) => {
                    let left = opts.max_iter.saturating_sub(iterations + 1);
                    let start = PolishStart {
                        rho2: u.rho2,
                        heavy: true,
                        prev: Some(u.prev),
                    };
                    polish::<P>(points, norm, u.th, u.jtj, opts, &free, left, start).map(|mut f| {
                        f.iterations += 1;
                        f
                    })
                }
                Err(None) => {
                    let left = opts.max_iter.saturating_sub(iterations);
                    let jtj = full_matrix(&acc.jtj) * (n as f64 / work.len() as f64);
                    // (about 10 / subsample size when the subsample's JᵀJ stands in for all)
                    let start = PolishStart {
                        rho2: 10.0 / work.len() as f64,
                        heavy: false,
                        prev: None,
                    };
                    polish::<P>(points, norm, r.th, jtj, opts, &free, left, start)
                }
            };
            match polished {
                Ok(mut f) => {
                    f.iterations += iterations;
                    f
                }
                Err(th) => {
                    // the polish did not contract: Levenberg-Marquardt on all points, with the
                    // noise level of all points
                    let want = Want {
                        jtj: false,
                        debias: opts.debias,
                        coverage: false,
                    };
                    let a = kernel::pass::<P>(points, &setup(norm, &th), want, opts.parallel);
                    let h = if opts.debias { noise_term(&a, n) } else { 0.0 };
                    let left = opts.max_iter.saturating_sub(iterations + MAX_POLISH);
                    let (r2, acc2, _) =
                        refine::<P>(points, norm, th, opts, Noise::Fixed(h), &free, left);
                    Final {
                        th: r2.th,
                        cost: acc2.cost(h),
                        plain: acc2.r0r0,
                        sums: acc2,
                        iterations: iterations + MAX_POLISH + r2.iterations,
                        converged: r2.converged,
                        coverage: false,
                    }
                }
            }
        } else {
            Final {
                th: r.th,
                cost: acc.cost(h),
                plain: acc.r0r0,
                sums: acc,
                iterations,
                converged: r.converged,
                coverage: false,
            }
        }
    };
    finish::<P>(points, work, sp, norm, opts, fin, &free, nfree)
}

/// One accumulation pass of the "full" model over `points` (normalised by `mean` and `scale`,
/// at the unit sphere): `kind` 0 sums `JᵀJ` and `Jᵀr` (the unit of work that instruction counts
/// are quoted in), 1 only `Jᵀr` and the noise sums (a polishing pass), 2 everything and the
/// coverage. Returns a checksum. For benchmarks.
#[doc(hidden)]
#[inline(never)]
pub fn bench_one_pass(points: &[[f64; 3]], mean: [f64; 3], scale: f64, kind: u8) -> f64 {
    let norm = Norm {
        mean: Vector3::from(mean),
        inv_scale: 1.0 / scale,
    };
    let th = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0];
    let want = Want {
        jtj: kind != 1,
        debias: kind != 0,
        coverage: kind == 2,
    };
    let a = kernel::pass::<9>(points, &setup(norm, &th), want, false);
    a.jtj[0][0] + a.jtr0[0] + a.r0r0
}

/// Applies a fit: `out[i] = W (points[i] - offset)`.
pub fn apply(points: &[[f64; 3]], offset: [f64; 3], matrix: [[f64; 3]; 3], out: &mut [[f64; 3]]) {
    let w = SMatrix::<f64, 3, 3>::from_fn(|i, j| matrix[i][j]);
    for (p, o) in points.iter().zip(out.iter_mut()) {
        let v = w * Vector3::new(p[0] - offset[0], p[1] - offset[1], p[2] - offset[2]);
        *o = [v.x, v.y, v.z];
    }
}
