//! From the converged parameters to the result: standard errors, physical bounds, warnings,
//! coverage and the mapping back to raw units.

use super::*;

/// Standard errors, physical bounds, coverage and the mapping back to raw units. The coverage
/// of the sphere is measured on `sample` (the subsample of a large input: its face counts are
/// scaled to all points).
pub(super) fn finish<const P: usize>(
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
    // The usual case needs no eigenvalues: when the bounds mean ± ‖W - mean I‖ on them are
    // positive and within the bound on their ratio (rust/bounds.rs; gains within about 1 ± 0.5
    // of their mean), W is positive definite and its gains plausible for certain, with a
    // margin far above the round-off of `sym3_eigenvalues`.
    let (lo, hi) = geometry::sym3_eigenvalue_bounds(&w_raw);
    let clearly_plausible = lo > 0.0 && hi <= (1.0 - 1e-6) * bounds::MAX_AXIS_RATIO * lo;
    // (W1, its eigenvalues for the bound on the gains below unless it certainly holds)
    let (w1, gains) = if clearly_plausible {
        (w_raw, None)
    } else {
        let ev = geometry::sym3_eigenvalues(&w_raw);
        if ev[2] > 1e-9 * ev[0] && ev.iter().all(|v| v.is_finite()) {
            (w_raw, Some(ev))
        } else {
            let e = SymmetricEigen::new(w_raw);
            let abs_l = e.eigenvalues.map(f64::abs);
            if abs_l.min() <= 1e-9 * abs_l.max() || !abs_l.iter().all(|v| v.is_finite()) {
                return Err(not_determined(model, "a gain went to zero"));
            }
            let w = e.eigenvectors * Matrix3::from_diagonal(&abs_l) * e.eigenvectors.transpose();
            let w = (w + w.transpose()) * 0.5;
            (w, Some(geometry::sym3_eigenvalues(&w)))
        }
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
    // Frobenius-norm condition number: at most P times the 2-norm one, and cheap (a sum per
    // column, added at the end: with one running sum of the P² squares, each of its 81
    // additions waited for the one before)
    let frob = |m: &[[f64; P]; P]| {
        let mut col = [0.0; P];
        for row in m {
            for (c, v) in col.iter_mut().zip(row) {
                *c += v * v;
            }
        }
        col.iter().sum::<f64>().sqrt()
    };
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
    // at its final length at once (growing it from 3 to P entries cost a reallocation)
    let mut stderr: Vec<f64> = Vec::with_capacity(P);
    stderr.extend(se_th[..3].iter().map(|v| v * s));
    if model == Model::Sphere {
        let k = th[3].abs();
        stderr.push(s / (k * k) * se_th[3]); // data radius = s / k
    } else {
        stderr.extend(se_th[3..].iter().map(|v| v / s * radius));
    }

    // physical bounds (rust/bounds.rs): implausible gains, or a run-away unconverged fit
    if let Some(gains) = gains {
        bounds::check_gains(gains, model.name())?;
    }
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
                "the fit did not converge in {} iterations: the result may be inaccurate; check \
                 that the data determine the model (or allow more iterations)",
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
            // scaled to all points: the scatter sums and the count alike (the spread is their
            // ratio; scaling the count alone divided it by n / sample.len() and reported
            // evenly spread readings as a band of the sphere)
            let up = n as f64 / sample.len() as f64;
            fin.sums.dd = c.dd.map(|d| d * up);
            fin.sums.faces = c.faces.map(|f| (f * up).round());
            fin.sums.count = c.count * up;
        }
        let a = &fin.sums;
        let cnt = a.count.max(1.0);
        let t = Matrix3::new(
            a.dd[0], a.dd[3], a.dd[4], a.dd[3], a.dd[1], a.dd[5], a.dd[4], a.dd[5], a.dd[2],
        ) / cnt;
        // only compared with WARN_MIN_SPREAD (and shown when below it): a lower bound clearly
        // above it (directions spread evenly: eigenvalues near 1/3) serves as well
        let (lo, _) = geometry::sym3_eigenvalue_bounds(&t);
        let min_spread = if lo > bounds::WARN_MIN_SPREAD + 1e-9 {
            lo
        } else {
            geometry::sym3_eigenvalues(&t)[2]
        };
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
