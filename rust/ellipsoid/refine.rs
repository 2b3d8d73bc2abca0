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

/// Gauss-Newton on all points from the subsample's solution `th`, with the subsample's `JᵀJ`
/// scaled to the full size (`jtj`); see the module documentation. `None` when the passes do
/// not contract (the caller then runs Levenberg-Marquardt on all points).
pub(super) fn polish<const P: usize>(
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
