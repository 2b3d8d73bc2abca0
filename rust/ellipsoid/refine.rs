//! The iterations of the fit: Levenberg-Marquardt (or Gauss-Newton) on a set of points, and
//! the Gauss-Newton polish of a subsample's solution on all points.

use super::*;

/// Steps predicted to lower the cost by less than this fraction are evaluated without `JᵀJ`.
const LIGHT_STEP: f64 = 1e-4;

/// Levenberg-Marquardt (or Gauss-Newton) on `points` with the residual `r₀ - h c`; returns the
/// solution, the sums of the pass at it (with the `JᵀJ` of the last pass that summed it: at
/// the solution, or steps before it so small, at most 1 % of the relative noise level, that
/// the standard errors hardly change) and the `h` in force there. With
/// [`Noise::Estimated`], `h` follows the residuals of each accepted pass (steps are judged with
/// the `h` they were computed for), so that one run converges to the debiased fixed point.
pub(super) fn refine<const P: usize>(
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
        // A step whose predicted decrease is a small fraction f of the cost moves the
        // parameters by about σ√f relative to their size (σ the relative noise), and `JᵀJ`
        // by as little: its pass need not sum `JᵀJ` again (the expensive part), the next
        // step and the statistics use the one already summed.
        let light = predicted <= LIGHT_STEP * cost;
        let mut trial = want;
        trial.jtj = !light;
        let mut scale = 1.0;
        let mut accepted = None;
        // LM tries one step per iteration; GN halves its step up to 10 times
        for _ in 0..if gn { 10 } else { 1 } {
            iterations += 1;
            let mut cand = th;
            for i in 0..P {
                cand[i] += scale * delta[i];
            }
            let mut cacc = kernel::pass::<P>(points, &setup(norm, &cand), trial, par);
            if light {
                cacc.jtj = acc.jtj;
            }
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

/// How [`polish`] starts: its guess of the contraction `rho2` (the factor by which each step
/// shrinks the next one's predicted decrease), and whether its first pass sums `JᵀJ`.
pub(super) struct PolishStart {
    pub rho2: f64,
    pub heavy: bool,
    /// (h, cost, predicted decrease, f) of the step that led to the start, to be checked.
    pub prev: Option<(f64, f64, f64, f64)>,
}

/// Safety factor on the sampling error of the curvature that [`polish_once`] measures (from
/// the disagreement of the two halves of its sample).
const CURVATURE_SAMPLING: f64 = 4.0;

/// The squared relative error of a [`polish_once`] step that grows with the noise (the terms of
/// higher order it leaves out), as this times σ⁴ (σ the RMS residual relative to the radius;
/// measured: below 0.01 σ⁴ up to 10 % noise).
const CURVATURE_NONLINEAR: f64 = 0.05;

/// What [`polish_once`] leaves when its step cannot be taken as converged: the parameters after
/// it, the `JᵀJ` of all points at the start of the step, and the expected contraction.
pub(super) struct Unfinished<const P: usize> {
    pub th: [f64; P],
    pub jtj: SMatrix<f64, P, P>,
    pub rho2: f64,
    /// (h, cost, predicted decrease, f) of the step, for the next pass to check.
    pub prev: (f64, f64, f64, f64),
}

/// One pass over all points, at the subsample's solution `th`: `JᵀJ`, `Jᵀr`, the cost and the
/// noise level of all points, and a Newton step from them. Its Hessian is `JᵀJ` plus the
/// residuals' curvature `S = Σ r ∇²r` (what Gauss-Newton leaves out, and what makes a
/// Gauss-Newton step from the subsample's solution fall short by up to a few hundredths of a
/// standard error), taken along the step from `curv`, a larger sample of `m` points taken by
/// the same hash, in two halves: `S v ≈ (n / m)(g_m(θ + v) - g_m(θ) - J_mᵀJ_m v)`, the change
/// of the sample's gradient along `v` less its own `JᵀJ` part, and likewise the change of the
/// noise term, which follows the residuals (its `Δh` moves the gradient by `-Jᵀc Δh`). Two
/// terms of the Newton series `δ - H⁻¹Sδ + (H⁻¹S)²δ` (`δ` the Gauss-Newton step; three passes
/// over the sample, 200,000 points at most, in cache after the first). The step is converged
/// when what it leaves is below `tol` of the cost, as predicted from: the rest of the series
/// (from the ratio of its two terms), the sampling error of `S` (from how much the two halves
/// disagree) and the terms of higher order in the noise (`CURVATURE_NONLINEAR σ⁴`). Then the
/// fit has read all points once, and the sample once more. Otherwise [`polish`] goes on from
/// there (and checks that the step lowered the cost as predicted).
#[allow(clippy::too_many_arguments)]
pub(super) fn polish_once<const P: usize>(
    points: &[[f64; 3]],
    curv: [&[[f64; 3]]; 2],
    norm: Norm,
    th: [f64; P],
    opts: &FitOptions,
    free: &[bool; P],
) -> std::result::Result<Final<P>, Option<Unfinished<P>>> {
    let n = points.len();
    let want = Want {
        jtj: true,
        debias: opts.debias,
        coverage: false, // from the subsample: see `finish`
    };
    let a = kernel::pass::<P>(points, &setup(norm, &th), want, opts.parallel);
    let h = if opts.debias { noise_term(&a, n) } else { 0.0 };
    let hess = full_matrix(&a.jtj);
    let g = a.jtr(h);
    let cost = a.cost(h);
    let Some(d_gn) = solve(&hess, &g, 0.0, free) else {
        return Err(None);
    };
    let dhd = d_gn.dot(&(hess * d_gn)).max(0.0);
    let f0 = dhd / cost.max(1e-300);
    if !f0.is_finite() {
        return Err(None);
    }
    let mut step = d_gn;
    let mut kappa2 = 0.0; // what the Newton series leaves, relative to f0
    let mut sampled = 0.0; // the sampling error of the curvature, relative to f0
    if f0 > opts.tol {
        // each half of the curvature sample at the start, along the Gauss-Newton step and
        // along its correction
        let at = |half: &[[f64; 3]], t: &[f64; P], jtj: bool| {
            let w = Want {
                jtj,
                debias: opts.debias,
                coverage: false,
            };
            kernel::pass::<P>(half, &setup(norm, t), w, opts.parallel)
        };
        let jtc = SVector::<f64, P>::from(a.jtc);
        let start: Vec<_> = curv.iter().map(|half| at(half, &th, true)).collect();
        // S v from one half's gradient at th + v (its own JᵀJ part taken off), scaled to all
        // points; the noise term follows the residuals: g = Jᵀr₀ - h Jᵀc moves by -Jᵀc Δh
        let curvature = |k: usize, v: &SVector<f64, P>| -> SVector<f64, P> {
            let (half, b0) = (curv[k], &start[k]);
            let mut t = th;
            for i in 0..P {
                t[i] += v[i];
            }
            let b = at(half, &t, false);
            let mut sv = (SVector::<f64, P>::from(b.jtr(h))
                - SVector::<f64, P>::from(b0.jtr(h))
                - full_matrix(&b0.jtj) * v)
                * (n as f64 / half.len() as f64);
            if h != 0.0 {
                sv -= jtc * (half_sigma2(&b) - half_sigma2(b0));
            }
            sv
        };
        let m = (curv[0].len() + curv[1].len()) as f64;
        let w = [curv[0].len() as f64 / m, curv[1].len() as f64 / m];
        let both = |v: &SVector<f64, P>| -> (SVector<f64, P>, SVector<f64, P>) {
            let (sa, sb) = (curvature(0, v), curvature(1, v));
            (sa * w[0] + sb * w[1], sa - sb)
        };
        // solve() returns -H⁻¹ rhs: the Newton step is δ - H⁻¹ S δ + (H⁻¹ S)² δ - ...; two
        // terms of it, and the ratio of the second to the first bounds the rest
        let (s1, diff) = both(&d_gn);
        let Some(c1) = solve(&hess, &s1.into(), 0.0, free) else {
            return Err(None);
        };
        let Some(c2) = solve(&hess, &both(&c1).0.into(), 0.0, free) else {
            return Err(None);
        };
        // the halves' disagreement about the first term measures the sampling error of the
        // whole sample's (half their difference, for independent halves of equal size)
        let Some(e1) = solve(&hess, &diff.into(), 0.0, free) else {
            return Err(None);
        };
        step += c1 + c2;
        let n1 = c1.dot(&(hess * c1)).max(0.0);
        let n2 = c2.dot(&(hess * c2)).max(0.0);
        let rho2 = n2 / n1.max(1e-300);
        // what the series leaves after two terms, relative to the first step's decrease:
        // (|c2| ρ / (1 - ρ))² with ρ = |c2| / |c1| (the H norm)
        kappa2 = if rho2 < 0.25 {
            (n2 / dhd.max(1e-300)) * rho2 / (1.0 - rho2.sqrt()).powi(2)
        } else {
            f64::INFINITY
        };
        sampled = 0.25 * e1.dot(&(hess * e1)).max(0.0) / dhd.max(1e-300);
    }
    let mut next = th;
    for i in 0..P {
        next[i] += step[i];
    }
    let sigma2 = cost / n as f64;
    let sampling = CURVATURE_SAMPLING * sampled + CURVATURE_NONLINEAR * sigma2 * sigma2;
    let left = f0 * (kappa2 + sampling);
    let gv = SVector::<f64, P>::from(g);
    if !(left <= opts.tol) || !kappa2.is_finite() {
        let decrease = (-gv.dot(&step)).max(0.0);
        return Err(Some(Unfinished {
            th: next,
            jtj: hess,
            rho2: (kappa2 + sampling).clamp(1e-8, 0.25),
            prev: (h, cost, decrease, f0),
        }));
    }
    let jtr0 = SVector::<f64, P>::from(a.jtr0);
    let shs = step.dot(&(hess * step)).max(0.0);
    // the cost and the plain cost at the new parameters, from the quadratic models
    let cost_after = (cost + gv.dot(&step)).max(0.0);
    let plain = (a.r0r0 + 2.0 * step.dot(&jtr0) + shs).max(0.0);
    Ok(Final {
        th: next,
        sums: a,
        cost: cost_after,
        plain,
        iterations: 1,
        converged: true,
        coverage: false,
    })
}

/// Gauss-Newton on all points from `th`, with `jtj` standing in for all points' `JᵀJ` until
/// a pass sums it (the subsample's scaled to the full size, or that of [`polish_once`]); see
/// the module documentation. `None` when the passes do not contract (the caller then runs
/// Levenberg-Marquardt on all points).
pub(super) fn polish<const P: usize>(
    points: &[[f64; 3]],
    norm: Norm,
    mut th: [f64; P],
    mut jtj: SMatrix<f64, P, P>,
    opts: &FitOptions,
    free: &[bool; P],
    max_iter: usize,
    start: PolishStart,
) -> std::result::Result<Final<P>, [f64; P]> {
    // ρ²: how much each step shrinks the next one's predicted decrease (guessed until seen)
    let mut rho2 = start.rho2;
    let mut heavy = start.heavy;
    let mut prev: Option<(f64, f64, f64, f64)> = start.prev; // (h, cost, predicted decrease, f) of the last pass
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
