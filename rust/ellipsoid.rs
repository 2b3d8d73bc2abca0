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
//! number of points.
//!
//! Large inputs are solved first on a subsample of [`SUBSAMPLE_SIZE`] points, taken by a hash
//! of each point's coordinates (so that neither the order nor a period of the data can make it
//! unrepresentative; data with few distinct values fall back to one point at a fixed
//! pseudo-random place in each of that many equal blocks), then polished on all points by
//! Gauss-Newton steps that reuse the subsample's `JᵀJ` (scaled to the full size) and need only
//! `Jᵀr` from each pass; the last pass accumulates the full `JᵀJ` for the standard errors, the
//! residual statistics and the coverage of the sphere. The answer is the minimum over all
//! points, so it does not depend on their order beyond round-off (passes that stop contracting
//! fall back to Levenberg-Marquardt on all points).
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
use rayon::prelude::*;

/// Inputs with more points than this are first solved on a subsample.
pub const SUBSAMPLE_ABOVE: usize = 60_000;
/// Size of that subsample: between these, `n / 25` (a larger subsample makes its solution and
/// its `JᵀJ` closer to the full data's, so that fewer passes over all points polish it).
pub const SUBSAMPLE_SIZE: (usize, usize) = (20_000, 40_000);
/// Most polishing passes over all points before falling back to Levenberg-Marquardt.
const MAX_POLISH: usize = 8;

/// Which parameters are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// Offset and one scale: `W = k I`.
    Sphere,
    /// Offset and three gains: `W = diag(g)`.
    Axis,
    /// Offset and a symmetric `W`: scale, cross-axis, hard and soft iron.
    Full,
}

impl Model {
    /// Parses `"sphere"`, `"axis"` or `"full"`.
    pub fn parse(name: &str) -> Result<Model> {
        match name {
            "sphere" => Ok(Model::Sphere),
            "axis" => Ok(Model::Axis),
            "full" => Ok(Model::Full),
            other => Err(CalError::InvalidArgument(format!(
                "unknown model {other:?}: use \"sphere\" (offset only), \"axis\" (offset + 3 gains) \
                 or \"full\" (offset + symmetric 3x3 matrix)"
            ))),
        }
    }
    /// The name accepted by [`Model::parse`].
    pub fn name(self) -> &'static str {
        match self {
            Model::Sphere => "sphere",
            Model::Axis => "axis",
            Model::Full => "full",
        }
    }
    /// The model's name in quotes followed by "model", for messages.
    fn label(self) -> &'static str {
        match self {
            Model::Sphere => "\"sphere\" model",
            Model::Axis => "\"axis\" model",
            Model::Full => "\"full\" model",
        }
    }
    /// Number of unknowns.
    pub fn nparams(self) -> usize {
        match self {
            Model::Sphere => 4,
            Model::Axis => 6,
            Model::Full => 9,
        }
    }
    /// Names of the parameters whose standard errors [`EllipsoidFit::stderr`] reports.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            Model::Sphere => &["offset_x", "offset_y", "offset_z", "data_radius"],
            Model::Axis => &[
                "offset_x", "offset_y", "offset_z", "diag_x", "diag_y", "diag_z",
            ],
            Model::Full => &FIXABLE,
        }
    }
}

/// Names of the entries of [`FitOptions::fixed`], in order. For the sphere model entry 3 is its
/// one gain (`W = gain I`); entries past the model's parameters must be `None`.
pub const FIXABLE: [&str; 9] = [
    "offset_x",
    "offset_y",
    "offset_z",
    "diag_x",
    "diag_y",
    "diag_z",
    "offdiag_xy",
    "offdiag_xz",
    "offdiag_yz",
];

/// How the parameters are refined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Levenberg-Marquardt (the default).
    LevenbergMarquardt,
    /// Gauss-Newton with step halving.
    GaussNewton,
    /// No refinement: the algebraic (least-squares quadric) fit on all points.
    Algebraic,
}

impl Method {
    /// Parses `"lm"`, `"gn"` or `"algebraic"`.
    pub fn parse(name: &str) -> Result<Method> {
        match name {
            "lm" => Ok(Method::LevenbergMarquardt),
            "gn" => Ok(Method::GaussNewton),
            "algebraic" => Ok(Method::Algebraic),
            other => Err(CalError::InvalidArgument(format!(
                "unknown method {other:?}: use \"lm\" (Levenberg-Marquardt), \"gn\" (Gauss-Newton) \
                 or \"algebraic\" (no refinement)"
            ))),
        }
    }
}

/// Options of [`fit_ellipsoid`].
#[derive(Debug, Clone, Copy)]
pub struct FitOptions {
    /// The model.
    pub model: Model,
    /// Magnitude calibrated readings must have (1.0 for g, 9.80665 for m/s², the local field in
    /// µT); `None` keeps the data's own scale (`det W = 1`).
    pub radius: Option<f64>,
    /// Most iterations (trial steps and polishing passes) of the refinement.
    pub max_iter: usize,
    /// Converged when an accepted step lowers the cost by less than this fraction.
    pub tol: f64,
    /// How to refine.
    pub method: Method,
    /// Use rayon inside the fit (off in batches, which parallelise over data sets).
    pub parallel: bool,
    /// Correct the geometric residual for the bias that noise adds to vector lengths (see
    /// the module documentation). Off: the plain geometric least-squares fit.
    pub debias: bool,
    /// Compute the coverage of the sphere and the plain-language warnings. Batches, which
    /// report no warnings, turn it off.
    pub diagnostics: bool,
    /// Parameters held at these values instead of fitted, named by [`FIXABLE`]: offsets in raw
    /// units, gains (`diag`, `offdiag`, the sphere's gain) in calibrated units per raw unit,
    /// which needs `radius`.
    pub fixed: [Option<f64>; 9],
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            model: Model::Full,
            radius: None,
            max_iter: 100,
            tol: 1e-10,
            method: Method::LevenbergMarquardt,
            parallel: true,
            debias: true,
            diagnostics: true,
            fixed: [None; 9],
        }
    }
}

/// The result of [`fit_ellipsoid`].
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidFit {
    /// The model fitted.
    pub model: Model,
    /// Offset (bias, hard iron), in raw units.
    pub offset: [f64; 3],
    /// `W`, row-major: `calibrated = W (raw - offset)`.
    pub matrix: [[f64; 3]; 3],
    /// Magnitude of calibrated readings: the requested radius, or the data's own.
    pub radius: f64,
    /// RMS of `‖calibrated‖ - radius`, in calibrated units.
    pub rms: f64,
    /// Standard errors of the parameters named by [`Model::param_names`] (offset in raw units,
    /// matrix terms in calibrated units per raw unit, `data_radius` in raw units); 0 for a
    /// fixed parameter, NaN for all when the solve is exactly determined.
    pub stderr: Vec<f64>,
    /// Trial steps and polishing passes taken by the refinement (0 for the algebraic method).
    pub iterations: usize,
    /// Whether the refinement met its tolerance.
    pub converged: bool,
    /// Condition number (Frobenius norm) of the column-scaled normal matrix at the solution.
    pub condition: f64,
    /// Number of points.
    pub n: usize,
    /// Plain-language warnings and notes (poor coverage, no convergence, exactly determined).
    pub warnings: Vec<String>,
}

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
fn solve<const P: usize>(
    jtj: &SMatrix<f64, P, P>,
    jtr: &[f64; P],
    lambda: f64,
    free: &[bool; P],
) -> Option<SVector<f64, P>> {
    let mut a = *jtj;
    let mut g = SVector::<f64, P>::from_fn(|i, _| -jtr[i]);
    for i in 0..P {
        if free[i] {
            a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
        } else {
            for j in 0..P {
                a[(i, j)] = 0.0;
                a[(j, i)] = 0.0;
            }
            a[(i, i)] = 1.0;
            g[i] = 0.0;
        }
    }
    let arr: [[f64; P]; P] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
    let l = linalg::cholesky(&arr)?;
    let x = linalg::cholesky_solve(&l, &std::array::from_fn(|i| g[i]));
    Some(SVector::<f64, P>::from_column_slice(&x))
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

/// Levenberg-Marquardt (or Gauss-Newton) on `points` with the residual `r₀ - h c`; returns the
/// solution, the sums of the pass at it (with `JᵀJ`) and the `h` in force there. With
/// [`Noise::Estimated`], `h` follows the residuals of each accepted pass (steps are judged with
/// the `h` they were computed for), so that one run converges to the debiased fixed point.
fn refine<const P: usize>(
    points: &[[f64; 3]],
    norm: Norm,
    mut th: [f64; P],
    opts: &FitOptions,
    noise: Noise,
    free: &[bool; P],
    max_iter: usize,
) -> (Refined<P>, Sums<P>, f64) {
    let par = opts.parallel;
    let (estimate, mut h) = match noise {
        Noise::Fixed(h) => (None, h),
        Noise::Estimated(n) => (Some(n), 0.0),
    };
    // the noise sums (Jᵀc...) are gathered after the first pass only if the noise matters
    let mut want = Want {
        jtj: true,
        debias: estimate.is_some() || h != 0.0,
        coverage: false,
    };
    let gn = opts.method == Method::GaussNewton;
    let mut acc = kernel::pass::<P>(points, &setup(norm, &th), want, par);
    if let Some(n) = estimate {
        h = noise_term(&acc, n);
        want.debias = h > 0.0;
    }
    let mut cost = acc.cost(h);
    let mut lambda = if gn { 0.0 } else { 1e-3 };
    let mut iterations = 0;
    let mut converged = false;
    while iterations < max_iter {
        let jtj = full_matrix(&acc.jtj);
        let g = acc.jtr(h);
        let step = if gn {
            solve(&jtj, &g, 0.0, free).or_else(|| solve(&jtj, &g, 1e-9, free))
        } else {
            solve(&jtj, &g, lambda, free)
        };
        let Some(delta) = step else {
            if gn || lambda > 1e12 {
                break;
            }
            lambda = (lambda * 10.0).max(1e-6);
            iterations += 1;
            continue;
        };
        // the linear model's predicted decrease of Σr²: -2 δᵀJᵀr - δᵀJᵀJδ; when even that is
        // below the tolerance, no step can help: converged without spending another pass
        let gv = SVector::<f64, P>::from_column_slice(&g);
        let predicted = -2.0 * delta.dot(&gv) - delta.dot(&(jtj * delta));
        if predicted <= opts.tol * cost + 1e-300 {
            converged = true;
            break;
        }
        let mut scale = 1.0;
        let mut accepted = None;
        // LM tries one step per iteration; GN halves its step up to 10 times
        for _ in 0..if gn { 10 } else { 1 } {
            iterations += 1;
            let mut cand = th;
            for i in 0..P {
                cand[i] += scale * delta[i];
            }
            let cacc = kernel::pass::<P>(points, &setup(norm, &cand), want, par);
            let ccost = cacc.cost(h);
            if ccost.is_finite() && ccost <= cost {
                accepted = Some((cand, cacc, ccost));
                break;
            }
            scale *= 0.5;
            if iterations >= max_iter {
                break;
            }
        }
        match accepted {
            Some((cand, cacc, ccost)) => {
                let decrease = cost - ccost;
                let dnorm: f64 = delta.iter().map(|d| d * d).sum::<f64>().sqrt() * scale;
                let tnorm: f64 = th.iter().map(|t| t * t).sum::<f64>().sqrt();
                th = cand;
                acc = cacc;
                cost = ccost;
                let mut steady = true;
                if let Some(n) = estimate {
                    let h_new = noise_term(&acc, n);
                    if want.debias {
                        // a change of h moves the minimum by about (Δh)² Σc² in cost
                        steady = (h_new - h).powi(2) * acc.cc <= opts.tol * cost;
                        h = h_new;
                        cost = acc.cost(h);
                    } else if h_new > 0.0 {
                        // the noise matters after all: gather its sums from the next pass on
                        want.debias = true;
                        steady = false;
                    }
                }
                lambda = (lambda / 10.0).max(if lambda == 0.0 { 0.0 } else { 1e-12 });
                if steady
                    && (decrease <= opts.tol * cost.max(1e-300) + 1e-300
                        || dnorm <= 1e-14 * (tnorm + 1e-14))
                {
                    converged = true;
                    break;
                }
            }
            None => {
                if gn {
                    // no half step lowers the cost: a minimum to working precision
                    converged = true;
                    break;
                }
                lambda *= 10.0;
                if lambda > 1e10 {
                    converged = true; // no step lowers the cost: at a minimum to working precision
                    break;
                }
            }
        }
    }
    (
        Refined {
            th,
            iterations,
            converged,
        },
        acc,
        h,
    )
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

/// Gauss-Newton on all points from the subsample's solution `th`, with the subsample's `JᵀJ`
/// scaled to the full size (`jtj`); see the module documentation. `None` when the passes do
/// not contract (the caller then runs Levenberg-Marquardt on all points).
fn polish<const P: usize>(
    points: &[[f64; 3]],
    n_work: usize,
    norm: Norm,
    mut th: [f64; P],
    mut jtj: SMatrix<f64, P, P>,
    opts: &FitOptions,
    free: &[bool; P],
    max_iter: usize,
) -> std::result::Result<Final<P>, [f64; P]> {
    // ρ²: how much each step shrinks the next one's predicted decrease (guessed until seen:
    // about 10 / subsample size when the subsample's JᵀJ stands in for the full one)
    let mut rho2 = 10.0 / n_work as f64;
    let mut heavy = false;
    let mut prev: Option<(f64, f64, f64, f64)> = None; // (h, cost, predicted decrease, f) of the last pass
    for k in 0..MAX_POLISH.min(max_iter.max(1)) {
        let last_chance = k + 1 >= MAX_POLISH.min(max_iter.max(1));
        heavy |= last_chance;
        let want = Want {
            jtj: heavy,
            debias: opts.debias,
            coverage: false, // from the subsample: see `finish`
        };
        let a = kernel::pass::<P>(points, &setup(norm, &th), want, opts.parallel);
        let h = if opts.debias {
            noise_term(&a, points.len())
        } else {
            0.0
        };
        if let Some((hp, before, decrease, _)) = prev {
            // the last step must have achieved at least half the decrease it promised
            let now = a.cost(hp);
            if !(now <= before - 0.5 * decrease + 1e-12 * before + 1e-300) {
                return Err(th);
            }
        }
        if heavy {
            jtj = full_matrix(&a.jtj);
        }
        let g = a.jtr(h);
        let cost = a.cost(h);
        let Some(delta) = solve(&jtj, &g, 0.0, free) else {
            return Err(th);
        };
        let hd = jtj * delta;
        let dhd = delta.dot(&hd).max(0.0);
        let f = dhd / cost.max(1e-300);
        if !f.is_finite() {
            return Err(th);
        }
        if let Some((_, _, _, fp)) = prev {
            if fp > 0.0 {
                let seen = f / fp;
                if seen > 0.25 {
                    return Err(th); // not contracting
                }
                rho2 = seen.max(1e-4);
            }
        }
        let mut next = th;
        for i in 0..P {
            next[i] += delta[i];
        }
        let done = rho2 * f <= opts.tol || f <= 1e-28;
        if heavy && done {
            let jtr0 = SVector::<f64, P>::from_column_slice(&a.jtr0);
            let plain = (a.r0r0 + 2.0 * delta.dot(&jtr0) + dhd).max(0.0);
            return Ok(Final {
                th: next,
                sums: a,
                cost: (cost - dhd).max(0.0),
                plain,
                iterations: k + 1,
                converged: true,
                coverage: false,
            });
        }
        // the next pass is the last when this step leaves too little for another to matter,
        // or when its own step is expected to
        heavy = done || rho2 * rho2 * f <= opts.tol;
        prev = Some((h, cost, dhd, f));
        th = next;
    }
    Err(th)
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
    let scan = geometry::scan(points, opts.parallel)?;
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
    match model {
        Model::Sphere => fit_generic::<4>(points, &sp, opts, nfree),
        Model::Axis => fit_generic::<6>(points, &sp, opts, nfree),
        Model::Full => fit_generic::<9>(points, &sp, opts, nfree),
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
        Model::Full => " or use a simpler model (model=\"axis\" or \"sphere\")",
        Model::Axis => " or use model=\"sphere\"",
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

/// A subsample of about `size` points that depends only on the *set* of points, not on their
/// order: a point is taken when a hash of its coordinates falls below `size / n` of the hash
/// range. Heavily repeated data (few distinct values: a tiled pattern) would give a few values
/// many times over; then one point is drawn at a fixed pseudo-random position inside each of
/// `size` equal blocks instead (no period in the data can line up with that pick).
fn subsample(points: &[[f64; 3]], size: usize, parallel: bool) -> Vec<[f64; 3]> {
    let n = points.len();
    let cut = ((size as f64 / n as f64) * 18_446_744_073_709_551_616.0) as u64;
    let part = |c: &[[f64; 3]]| -> Vec<[f64; 3]> {
        c.iter().filter(|p| point_hash(p) < cut).copied().collect()
    };
    let picked: Vec<[f64; 3]> = if parallel && n > 4 * kernel::CHUNK {
        points
            .par_chunks(4 * kernel::CHUNK)
            .map(part)
            .reduce(Vec::new, |mut a, b| {
                a.extend_from_slice(&b);
                a
            })
    } else {
        part(points)
    };
    if distinct_at_least(&picked, MIN_DISTINCT.min(size / 2)) && picked.len() >= size / 2 {
        return picked;
    }
    let nb = size.min(n).max(1);
    (0..nb)
        .map(|b| {
            let lo = b * n / nb;
            let hi = (b + 1) * n / nb;
            let r = splitmix64(b as u64 ^ 0x7472_6961_7863_616c) % (hi - lo) as u64;
            points[lo + r as usize]
        })
        .collect()
}

/// A subsample by content needs at least this many distinct points (else it is drawn by
/// position, see [`subsample`]).
const MIN_DISTINCT: usize = 2000;

/// A hash of a point's bits (multiplicative hashing, twice: the high bits depend on all the
/// bits of all three coordinates).
#[inline(always)]
fn point_hash(p: &[f64; 3]) -> u64 {
    let h = p[0].to_bits() ^ p[1].to_bits().rotate_left(21) ^ p[2].to_bits().rotate_left(42);
    let h = h.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    (h ^ (h >> 32)).wrapping_mul(0xd6e8_feb8_6659_fd93)
}

/// Whether `points` hold at least `want` distinct values, estimated by linear counting over a
/// 65,536-bit map of their hashes (exact enough for the few thousand this is asked about).
fn distinct_at_least(points: &[[f64; 3]], want: usize) -> bool {
    const BITS: usize = 1 << 16;
    let mut map = vec![0u64; BITS / 64];
    for p in points {
        let h = (point_hash(p) >> 16) as usize & (BITS - 1);
        map[h / 64] |= 1 << (h % 64);
    }
    let empty = BITS - map.iter().map(|w| w.count_ones() as usize).sum::<usize>();
    let estimate = if empty == 0 {
        f64::INFINITY
    } else {
        -(BITS as f64) * (empty as f64 / BITS as f64).ln()
    };
    estimate >= want as f64
}

/// SplitMix64: a well-mixed 64-bit hash of `x`.
#[inline(always)]
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn fit_generic<const P: usize>(
    points: &[[f64; 3]],
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
    let subsampled = n > SUBSAMPLE_ABOVE && opts.method != Method::Algebraic;
    let store;
    let work: &[[f64; 3]] = if subsampled {
        store = subsample(
            points,
            (n / 25).clamp(SUBSAMPLE_SIZE.0, SUBSAMPLE_SIZE.1),
            opts.parallel,
        );
        &store
    } else {
        points
    };

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
            let left = opts.max_iter.saturating_sub(iterations);
            let jtj = full_matrix(&acc.jtj) * (n as f64 / work.len() as f64);
            match polish::<P>(points, work.len(), norm, r.th, jtj, opts, &free, left) {
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

/// Standard errors, physical bounds, coverage and the mapping back to raw units. The coverage
/// of the sphere is measured on `sample` (the subsample of a large input: its face counts are
/// scaled to all points).
fn finish<const P: usize>(
    points: &[[f64; 3]],
    sample: &[[f64; 3]],
    sp: &Spread,
    norm: Norm,
    opts: &FitOptions,
    mut fin: Final<P>,
    free: &[bool; P],
    nfree: usize,
) -> Result<EllipsoidFit> {
    let model = opts.model;
    let n = points.len();
    let th = fin.th;
    // W and -W (or any sign flip of an eigenvalue) give the same residuals: take |W|
    // (W itself when it is positive definite, the usual case).
    let w_raw = w_of(&th);
    let ev = geometry::sym3_eigenvalues(&w_raw);
    let w1 = if ev[2] > 1e-9 * ev[0] && ev.iter().all(|v| v.is_finite()) {
        w_raw
    } else {
        let e = SymmetricEigen::new(w_raw);
        let abs_l = e.eigenvalues.map(f64::abs);
        if abs_l.min() <= 1e-9 * abs_l.max() || !abs_l.iter().all(|v| v.is_finite()) {
            return Err(not_determined(model, "a gain went to zero"));
        }
        let w = e.eigenvectors * Matrix3::from_diagonal(&abs_l) * e.eigenvectors.transpose();
        (w + w.transpose()) * 0.5
    };

    // conditioning and standard errors in normalised coordinates (fixed parameters: rows and
    // columns of the identity, standard error 0)
    let mut jtj = full_matrix(&fin.sums.jtj);
    for i in 0..P {
        if !free[i] {
            for j in 0..P {
                jtj[(i, j)] = 0.0;
                jtj[(j, i)] = 0.0;
            }
            jtj[(i, i)] = 1.0;
        }
    }
    let dscale: [f64; P] = std::array::from_fn(|i| 1.0 / jtj[(i, i)].max(1e-300).sqrt());
    let scaled: [[f64; P]; P] =
        std::array::from_fn(|i| std::array::from_fn(|j| jtj[(i, j)] * dscale[i] * dscale[j]));
    let Some(inv) = linalg::cholesky(&scaled).map(|l| linalg::cholesky_inverse(&l)) else {
        return Err(not_determined(model, "singular normal matrix"));
    };
    // Frobenius-norm condition number: at most P times the 2-norm one, and cheap
    let frob = |m: &[[f64; P]; P]| m.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
    let condition = frob(&scaled) * frob(&inv);
    if !(condition < 1e13) {
        return Err(not_determined(
            model,
            &format!("condition number {condition:.1e}"),
        ));
    }
    let exact = n == nfree;
    let sigma2 = if exact {
        f64::NAN
    } else {
        fin.cost / (n - nfree) as f64
    };
    let mut se_th = [0.0; P];
    for i in 0..P {
        if free[i] {
            se_th[i] = (inv[i][i] * dscale[i] * dscale[i] * sigma2).max(0.0).sqrt();
            if exact {
                se_th[i] = f64::NAN;
            }
        }
    }

    // back to raw units: p = mean + scale q, so offset = mean + scale o, W_unit = W1 / scale
    let s = sp.scale;
    let o = Vector3::new(th[0], th[1], th[2]);
    let offset = sp.mean + o * s;
    let w_unit = w1 / s;
    let radius = match opts.radius {
        Some(r) => r,
        // det(W_unit)^(-1/3) = s det(W1)^(-1/3), without forming s³
        None => s * w1.determinant().abs().powf(-1.0 / 3.0),
    };
    let mut matrix = if model == Model::Sphere && opts.radius.is_none() {
        Matrix3::identity()
    } else {
        w_unit * radius
    };
    let mut offset = offset;
    // fixed values come back exactly as given (not through the normalisation's round-off)
    for (i, v) in opts.fixed.iter().enumerate().take(P) {
        let Some(v) = *v else { continue };
        match i {
            0..=2 => offset[i] = v,
            3 if model == Model::Sphere => matrix = Matrix3::identity() * v,
            3..=5 => matrix[(i - 3, i - 3)] = v,
            _ => {
                let (a, b) = [(0, 1), (0, 2), (1, 2)][i - 6];
                matrix[(a, b)] = v;
                matrix[(b, a)] = v;
            }
        }
    }
    let mut stderr: Vec<f64> = se_th[..3].iter().map(|v| v * s).collect();
    if model == Model::Sphere {
        let k = th[3].abs();
        stderr.push(s / (k * k) * se_th[3]); // data radius = s / k
    } else {
        stderr.extend(se_th[3..].iter().map(|v| v / s * radius));
    }

    // physical bounds (rust/bounds.rs): implausible gains, or a run-away unconverged fit
    bounds::check_axis_ratio(&w1, model.name())?;
    let raw_radius = radius / matrix.norm() * 3f64.sqrt();
    let worst = if exact {
        0.0
    } else {
        stderr[..3].iter().cloned().fold(0.0, f64::max) / raw_radius
    };
    if !fin.converged && worst > bounds::MAX_UNCONVERGED_OFFSET_SE {
        return Err(not_determined(
            model,
            &format!(
                "no convergence in {} iterations and an offset standard error of {:.0}% of the radius",
                opts.max_iter,
                100.0 * worst
            ),
        ));
    }
    let rms = (fin.plain / n as f64).sqrt() * radius;
    let mut warnings = Vec::new();
    if opts.diagnostics {
        if exact {
            warnings.push(format!(
                "{n} readings for {nfree} unknowns: an exactly determined solve, so no residual \
                 is left to estimate the noise or the standard errors from (they are NaN); add \
                 readings in more orientations to get them"
            ));
        }
        if !fin.converged {
            warnings.push(format!(
                "the fit did not converge in {} iterations: the result may be inaccurate; raise \
                 max_iter or check the data",
                opts.max_iter
            ));
        }
        if worst > bounds::WARN_OFFSET_SE {
            warnings.push(format!(
                "the offset is poorly determined (standard error up to {:.1}% of the radius): the \
                 points cover only part of the sphere; turn the sensor through more orientations",
                100.0 * worst
            ));
        } else if condition > 1e8 {
            warnings.push(format!(
                "the fit is ill-conditioned (condition number {condition:.1e}): the points cover \
                 only part of the sphere; turn the sensor through more orientations"
            ));
        }
        if !exact && rms > bounds::WARN_RMS_FRACTION * radius {
            warnings.push(format!(
                "the residuals are {:.0}% of the radius: the readings do not lie on {} at all (a \
                 sensor that hardly turned, readings of more than one sensor, or the wrong \
                 columns), so neither the offset nor the coverage means anything; turn the \
                 sensor through many orientations",
                100.0 * rms / radius,
                if model.name() == "sphere" {
                    "a sphere"
                } else {
                    "an ellipsoid"
                },
            ));
        }
        // coverage of the sphere by the calibrated directions
        if !fin.coverage {
            let want = Want {
                jtj: false,
                debias: false,
                coverage: true,
            };
            let mut th1 = th;
            let w1t = theta_of::<9>(o, &w1);
            th1[3..P].copy_from_slice(&w1t[3..P]);
            let c = kernel::pass::<P>(sample, &setup(norm, &th1), want, opts.parallel);
            let up = n as f64 / sample.len() as f64;
            fin.sums.dd = c.dd;
            fin.sums.faces = c.faces.map(|f| (f * up).round());
            fin.sums.count = c.count * up;
        }
        let a = &fin.sums;
        let cnt = a.count.max(1.0);
        let t = Matrix3::new(
            a.dd[0], a.dd[3], a.dd[4], a.dd[3], a.dd[1], a.dd[5], a.dd[4], a.dd[5], a.dd[2],
        ) / cnt;
        let min_spread = geometry::sym3_eigenvalues(&t)[2];
        // the weakest direction is only needed for a warning
        let weak = if min_spread < bounds::WARN_MIN_SPREAD {
            let e = SymmetricEigen::new(t);
            e.eigenvectors.column(e.eigenvalues.imin()).into_owned()
        } else {
            Vector3::z()
        };
        let faces = a.faces.map(|c| c as usize);
        warnings.extend(bounds::coverage_warnings(&faces, min_spread, &weak));
    }
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = matrix[(i, j)];
        }
    }
    Ok(EllipsoidFit {
        model,
        offset: [offset.x, offset.y, offset.z],
        matrix: m,
        radius,
        rms,
        stderr,
        iterations: fin.iterations,
        converged: fin.converged,
        condition,
        n,
        warnings,
    })
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Fibonacci sphere mapped through `W⁻¹` and shifted by `offset`.
    pub(crate) fn ellipsoid_points(
        offset: [f64; 3],
        w: Matrix3<f64>,
        r: f64,
        n: usize,
    ) -> Vec<[f64; 3]> {
        let winv = w.try_inverse().unwrap();
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let rr = (1.0 - z * z).sqrt();
                let t = golden * i as f64;
                let f = Vector3::new(rr * t.cos(), rr * t.sin(), z) * r;
                let p = winv * f + Vector3::from(offset);
                [p.x, p.y, p.z]
            })
            .collect()
    }

    #[test]
    fn recovers_exact_full_model() {
        let w = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.05) / 16384.0;
        let pts = ellipsoid_points([300.0, -200.0, 150.0], w, 1.0, 400);
        let f = fit_ellipsoid(
            &pts,
            &FitOptions {
                radius: Some(1.0),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(f.converged);
        for k in 0..3 {
            assert!(
                (f.offset[k] - [300.0, -200.0, 150.0][k]).abs() < 1e-6,
                "{:?}",
                f.offset
            );
            for j in 0..3 {
                assert!((f.matrix[k][j] - w[(k, j)]).abs() < 1e-12, "{:?}", f.matrix);
            }
        }
        assert!(f.rms < 1e-10);
    }

    #[test]
    fn large_input_takes_the_subsample_path() {
        let w = Matrix3::new(1.02, 0.01, 0.0, 0.01, 0.98, 0.0, 0.0, 0.0, 1.0);
        let pts = ellipsoid_points([0.1, 0.2, -0.3], w, 9.80665, 100_000);
        let f = fit_ellipsoid(
            &pts,
            &FitOptions {
                radius: Some(9.80665),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(f.converged && f.rms < 1e-9, "{f:?}");
    }

    #[test]
    fn own_scale_has_unit_determinant() {
        let w = Matrix3::from_diagonal(&Vector3::new(1.5, 1.0, 0.7));
        let pts = ellipsoid_points([1.0, 2.0, 3.0], w, 5.0, 200);
        let f = fit_ellipsoid(
            &pts,
            &FitOptions {
                model: Model::Axis,
                ..Default::default()
            },
        )
        .unwrap();
        let m = Matrix3::from_fn(|i, j| f.matrix[i][j]);
        assert!((m.determinant() - 1.0).abs() < 1e-9);
        let want = 5.0 / w.determinant().cbrt(); // W_unit = w / 5, radius = det(W_unit)^(-1/3)
        assert!((f.radius - want).abs() < 1e-9, "{} vs {want}", f.radius);
    }

    #[test]
    fn too_few_points_and_cap_errors() {
        let pts = ellipsoid_points([0.0; 3], Matrix3::identity(), 1.0, 8);
        assert!(matches!(
            fit_ellipsoid(&pts, &FitOptions::default()),
            Err(CalError::TooFewPoints { need: 9, .. })
        ));
        // a thin cap: all points within ~3 degrees of the north pole
        let cap: Vec<[f64; 3]> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.7;
                let a = 0.05 * ((i % 7) as f64 / 7.0 + 0.1);
                [a * t.cos(), a * t.sin(), (1.0 - a * a).sqrt()]
            })
            .collect();
        let e = fit_ellipsoid(&cap, &FitOptions::default()).unwrap_err();
        assert!(matches!(e, CalError::Degenerate { .. }), "{e}");
    }

    #[test]
    fn six_points_solve_the_axis_model_exactly() {
        let w = Matrix3::from_diagonal(&Vector3::new(1.02, 0.97, 1.01)) / 16384.0;
        let winv = w.try_inverse().unwrap();
        let faces = [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
            -Vector3::z(),
        ];
        let pts: Vec<[f64; 3]> = faces
            .iter()
            .map(|f| {
                let p = winv * (f + Vector3::new(0.01, -0.02, 0.015)).normalize()
                    + Vector3::new(300.0, -200.0, 50.0);
                [p.x, p.y, p.z]
            })
            .collect();
        let opts = FitOptions {
            model: Model::Axis,
            radius: Some(1.0),
            ..Default::default()
        };
        let f = fit_ellipsoid(&pts, &opts).unwrap();
        assert!(
            f.rms < 1e-12 && f.stderr.iter().all(|v| v.is_nan()),
            "{f:?}"
        );
        assert!(f.warnings.iter().any(|w| w.contains("exactly determined")));
        assert!(matches!(
            fit_ellipsoid(&pts[..5], &opts),
            Err(CalError::TooFewPoints { need: 6, .. })
        ));
    }

    #[test]
    fn fixed_gain_sphere_fits_the_centre_only() {
        let pts = ellipsoid_points([10.0, -20.0, 30.0], Matrix3::identity() / 100.0, 1.0, 200);
        // a 60 degree cap around +z
        let cap: Vec<[f64; 3]> = pts.iter().filter(|p| p[2] - 30.0 > 50.0).copied().collect();
        let mut fixed = [None; 9];
        fixed[3] = Some(1.0);
        let opts = FitOptions {
            model: Model::Sphere,
            radius: Some(100.0),
            fixed,
            ..Default::default()
        };
        let f = fit_ellipsoid(&cap, &opts).unwrap();
        for k in 0..3 {
            assert!(
                (f.offset[k] - [10.0, -20.0, 30.0][k]).abs() < 1e-8,
                "{:?}",
                f.offset
            );
        }
        assert_eq!(
            f.matrix,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(f.stderr[3], 0.0);
    }

    #[test]
    fn large_inputs_do_not_depend_on_point_order() {
        let w = Matrix3::new(1.02, 0.01, 0.0, 0.01, 0.98, 0.0, 0.0, 0.0, 1.0);
        let mut pts = ellipsoid_points([0.1, 0.2, -0.3], w, 1.0, 70_001);
        // a little deterministic "noise" so that the minimum is not exact
        for (i, p) in pts.iter_mut().enumerate() {
            p[0] += 1e-3 * ((i * 7919 % 1000) as f64 / 500.0 - 1.0);
        }
        let a = fit_ellipsoid(&pts, &FitOptions::default()).unwrap();
        pts.reverse();
        pts.rotate_left(12_345);
        let b = fit_ellipsoid(&pts, &FitOptions::default()).unwrap();
        for k in 0..3 {
            assert!((a.offset[k] - b.offset[k]).abs() < 1e-12, "{a:?} {b:?}");
            for j in 0..3 {
                assert!((a.matrix[k][j] - b.matrix[k][j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn huge_and_tiny_magnitudes_are_rescaled_exactly() {
        let w = Matrix3::from_diagonal(&Vector3::new(1.1, 0.9, 1.0));
        let pts = ellipsoid_points([0.1, 0.2, -0.3], w, 1.0, 300);
        let base = fit_ellipsoid(
            &pts,
            &FitOptions {
                radius: Some(1.0),
                ..Default::default()
            },
        )
        .unwrap();
        for k in [1e200, 1e-200, 1e300] {
            let big: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|v| v * k)).collect();
            let f = fit_ellipsoid(
                &big,
                &FitOptions {
                    radius: Some(1.0),
                    ..Default::default()
                },
            )
            .unwrap();
            for i in 0..3 {
                assert!((f.offset[i] / k - base.offset[i]).abs() < 1e-9);
                assert!((f.matrix[i][i] * k - base.matrix[i][i]).abs() < 1e-9);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn recovers_random_offset_and_matrix(
            ox in -500.0..500.0f64, oy in -500.0..500.0f64, oz in -500.0..500.0f64,
            d in proptest::array::uniform3(0.8..1.25f64), e in proptest::array::uniform3(-0.08..0.08f64),
        ) {
            let w = Matrix3::new(d[0], e[0], e[1], e[0], d[1], e[2], e[1], e[2], d[2]) / 1000.0;
            let pts = ellipsoid_points([ox, oy, oz], w, 1.0, 300);
            let f = fit_ellipsoid(&pts, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
            for k in 0..3 {
                prop_assert!((f.offset[k] - [ox, oy, oz][k]).abs() < 1e-6);
                for j in 0..3 {
                    prop_assert!((f.matrix[k][j] - w[(k, j)]).abs() < 1e-10);
                }
            }
        }

        #[test]
        fn invariant_under_translation_and_rotation(tx in -1e4..1e4f64, angle in 0.0..std::f64::consts::TAU) {
            let w = Matrix3::new(1.1, 0.0, 0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 1.0);
            let pts = ellipsoid_points([0.0; 3], w, 1.0, 200);
            let f0 = fit_ellipsoid(&pts, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
            let rot = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), angle);
            let moved: Vec<[f64; 3]> = pts.iter().map(|p| {
                let v = rot * Vector3::new(p[0], p[1], p[2]) + Vector3::new(tx, -tx, 0.5 * tx);
                [v.x, v.y, v.z]
            }).collect();
            let f1 = fit_ellipsoid(&moved, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
            let want = rot * Vector3::from(f0.offset) + Vector3::new(tx, -tx, 0.5 * tx);
            for k in 0..3 { prop_assert!((f1.offset[k] - want[k]).abs() < 1e-6 * (1.0 + tx.abs())); }
            let w0 = Matrix3::from_fn(|i, j| f0.matrix[i][j]);
            let w1 = Matrix3::from_fn(|i, j| f1.matrix[i][j]);
            let w0r = rot.matrix() * w0 * rot.matrix().transpose();
            prop_assert!((w1 - w0r).norm() < 1e-8);
            prop_assert!((f1.rms - f0.rms).abs() < 1e-9);
        }
    }
}
