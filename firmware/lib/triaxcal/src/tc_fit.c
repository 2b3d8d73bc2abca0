/* The geometric fits (triaxcal.h): offset + 3 gains ("axis") or offset + symmetric W ("full").
 *
 * As in rust/ellipsoid: normalised points q = (p - mean) / scale (scale: RMS distance from the
 * mean), unit radius, parameters theta = [offset_x, offset_y, offset_z, diag_x, diag_y, diag_z,
 * offdiag_xy, offdiag_xz, offdiag_yz]; residual r = |W (q - offset)| - 1, Jacobian rows
 * (rust/kernel.rs), with u = q - offset, v = W u, n = |v|:
 *   offset_*    -(W v)^T / n
 *   diag_a      v_a u_a / n
 *   offdiag_ab  (v_a u_b + v_b u_a) / n
 * Start: the linear sphere fit |q|^2 = 2 c.q + d (W = I / sqrt(d + |c|^2)); then Gauss-Newton
 * with step halving (the host's method "gn"; its default Levenberg-Marquardt from an
 * algebraic start reaches the same minimum). Then the host's finish (rust/ellipsoid/
 * finish.rs): conditioning, standard errors, the bounds, the coverage of the sphere. */
#include "tc_internal.h"

#define P_MAX TC_FIT_MAX_P
#define PK_MAX TC_PACKED(TC_FIT_MAX_P)

#if TC_DOUBLE
#define TINY 1e-300
#define STEP_TINY 1e-14 /* the host's: a step below 1e-14 of the parameters ends the fit */
#else
#define TINY 1e-30f
#define STEP_TINY 1e-6f /* a few float epsilons */
#endif
/* Round-off of one residual (a few epsilons of the unit radius): a step whose predicted
 * decrease of the cost is below n times its square cannot be told from round-off. */
#define RES_EPS (TC_R(4.0) * (tc_real)((TC_DOUBLE) ? 2.220446049250313e-16 : 1.1920929e-7))

/* A trial whose cost is above the last by no more than its round-off is taken: near the
 * minimum of a fit with large residuals the decrease a float step brings can be below what
 * the float sum of the squares resolves, while the step itself (from J^T r) is sound. */
#define COST_SLACK (TC_R(4.0) * (tc_real)((TC_DOUBLE) ? 2.220446049250313e-16 : 1.1920929e-7))

void tc_fit_defaults(struct tc_fit_options *o, uint8_t model, tc_real radius)
{
    o->model = model;
    o->radius = radius;
    o->max_iter = 50;
    o->tol = TC_R(1e-10);
}

/* What a pass needs besides the points: the normalisation, the model, and the signs that
 * make an axis model's gains positive for the coverage. */
struct frame {
    tc_real mean[3];
    tc_real inv_scale;
    tc_real sign[3];
    uint8_t p;
};

/* v = W u for theta (W symmetric: diag th[3..5], offdiag xy xz yz th[6..8]). */
static void times_w(const tc_real *th, uint8_t p, const tc_real u[3], tc_real v[3])
{
    for (uint8_t i = 0; i < 3; i++) v[i] = th[3 + i] * u[i];
#if P_MAX == 9
    if (p == 9) {
        v[0] += th[6] * u[1] + th[7] * u[2];
        v[1] += th[6] * u[0] + th[8] * u[2];
        v[2] += th[7] * u[0] + th[8] * u[1];
    }
#else
    (void)p;
#endif
}

/* W[i][j] of theta, an axis model's gains taken positive. */
static tc_real w_entry(const tc_real *th, uint8_t p, uint8_t i, uint8_t j)
{
    if (i == j) return p == TC_MODEL_AXIS ? tc_abs(th[3 + i]) : th[3 + i];
    if (p == TC_MODEL_AXIS) return 0;
    return th[3 + i + j + 2]; /* xy: 6, xz: 7, yz: 8 */
}

/* One pass over the points at theta: J^T J (when jtj), J^T r, sum r^2, and the coverage (when
 * cov). */
static void pass(const tc_real (*pts)[3], uint16_t n, const struct frame *fr, const tc_real *th,
                 uint8_t jtj, struct tc_sums *a, struct tc_coverage *cov)
{
    uint8_t i, j, p = fr->p;
    for (i = 0; i < TC_PACKED(p); i++) a->jtj[i] = 0;
    for (i = 0; i < p; i++) a->jtr[i] = 0;
    a->cost = 0;
    if (cov) {
        for (i = 0; i < 6; i++) {
            cov->dd[i] = 0;
            cov->faces[i] = 0;
        }
        cov->count = 0;
    }
    for (uint16_t pt = 0; pt < n; pt++) {
        tc_real u[3], v[3], wv[3], jr[P_MAX];
        for (i = 0; i < 3; i++) u[i] = (pts[pt][i] - fr->mean[i]) * fr->inv_scale - th[i];
        times_w(th, p, u, v);
        times_w(th, p, v, wv);
        tc_real nrm = tc_sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        tc_real iv = nrm > 0 ? 1 / nrm : 0;
        tc_real r = nrm - 1;
        for (i = 0; i < 3; i++) {
            v[i] *= iv;             /* the unit direction */
            jr[i] = -wv[i] * iv;    /* offset_x, offset_y, offset_z */
            jr[3 + i] = v[i] * u[i]; /* diag_x, diag_y, diag_z */
        }
#if P_MAX == 9
        if (p == 9) {
            jr[6] = v[0] * u[1] + v[1] * u[0]; /* offdiag_xy */
            jr[7] = v[0] * u[2] + v[2] * u[0]; /* offdiag_xz */
            jr[8] = v[1] * u[2] + v[2] * u[1]; /* offdiag_yz */
        }
#endif
        a->cost += r * r;
        for (i = 0; i < p; i++) {
            a->jtr[i] += jr[i] * r;
            if (jtj) {
                for (j = 0; j <= i; j++) a->jtj[TC_PK(i, j)] += jr[i] * jr[j];
            }
        }
        if (cov && nrm > 0) {
            for (i = 0; i < 3; i++) v[i] *= fr->sign[i];
            cov->dd[0] += v[0] * v[0];
            cov->dd[1] += v[1] * v[1];
            cov->dd[2] += v[2] * v[2];
            cov->dd[3] += v[0] * v[1];
            cov->dd[4] += v[0] * v[2];
            cov->dd[5] += v[1] * v[2];
            /* the face the direction is closest to; ties go to the lower axis */
            tc_real ax = tc_abs(v[0]), ay = tc_abs(v[1]), az = tc_abs(v[2]);
            uint8_t axis = (ax >= ay && ax >= az) ? 0 : (ay >= az ? 1 : 2);
            cov->faces[2 * axis + (v[axis] >= 0 ? 0 : 1)]++;
            cov->count++;
        }
    }
}

/* The linear sphere fit on normalised points: theta = [c, 1/r, 1/r, 1/r, 0...]. */
static uint8_t sphere_start(const tc_real (*pts)[3], uint16_t n, const tc_real mean[3],
                            tc_real inv_scale, tc_real *th, uint8_t p)
{
    tc_real a[10] = {0}, b[4] = {0, 0, 0, 0};
    uint8_t i, j;
    for (uint16_t pt = 0; pt < n; pt++) {
        tc_real q[3], row[4];
        for (i = 0; i < 3; i++) q[i] = (pts[pt][i] - mean[i]) * inv_scale;
        for (i = 0; i < 3; i++) row[i] = 2 * q[i];
        row[3] = 1;
        tc_real rhs = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
        for (i = 0; i < 4; i++) {
            b[i] += row[i] * rhs;
            for (j = 0; j <= i; j++) a[TC_PK(i, j)] += row[i] * row[j];
        }
    }
    if (!tc_cholesky(a, 4)) return 0;
    tc_cholesky_solve(a, 4, b);
    tc_real r2 = b[3] + b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
    if (!(r2 > 0) || !tc_finite(r2)) return 0;
    tc_real k = 1 / tc_sqrt(r2);
    for (i = 0; i < 3; i++) {
        th[i] = b[i];
        th[3 + i] = k;
    }
    for (i = 6; i < p; i++) th[i] = 0;
    return 1;
}

/* Solve (J^T J) delta = -J^T r with J^T J factored in place (a->jtj becomes its factor);
 * predicted: the decrease of the cost the linear model promises, 2 |L^T delta|^2 - ... */
static uint8_t gn_step(struct tc_sums *a, uint8_t p, tc_real *delta, tc_real *predicted)
{
    uint8_t i, k;
    if (!tc_cholesky(a->jtj, p)) return 0;
    for (i = 0; i < p; i++) delta[i] = -a->jtr[i];
    tc_cholesky_solve(a->jtj, p, delta);
    /* -2 delta.g - delta^T H delta, with H = L L^T: |L^T delta|^2 */
    tc_real dg = 0, dhd = 0;
    for (i = 0; i < p; i++) {
        dg += delta[i] * a->jtr[i];
        tc_real s = 0;
        for (k = i; k < p; k++) s += a->jtj[TC_PK(k, i)] * delta[k];
        dhd += s * s;
    }
    *predicted = -2 * dg - dhd;
    return 1;
}

/* Gauss-Newton with step halving from th (rust/ellipsoid/refine.rs, method "gn"); th
 * becomes the solution. Returns 1 when converged; *passes counts the passes. */
static uint8_t gauss_newton(const tc_real (*pts)[3], uint16_t n, const struct frame *fr,
                            tc_real *th, const struct tc_fit_options *o, uint8_t *passes)
{
    struct tc_sums *a = &tc_work.fit.a;
    tc_real *cand = tc_work.fit.cand, *delta = tc_work.fit.delta;
    uint8_t p = fr->p, i, it = 0, converged = 0;
    pass(pts, n, fr, th, 1, a, 0);
    tc_real cost = a->cost;
    tc_real floor = (tc_real)n * RES_EPS * RES_EPS;
    while (it < o->max_iter) {
        tc_real predicted;
        if (!gn_step(a, p, delta, &predicted)) {
            /* not positive definite: once more with the diagonal raised by 1e-9 of itself */
            pass(pts, n, fr, th, 1, a, 0);
            for (i = 0; i < p; i++) {
                tc_real d = a->jtj[TC_PK(i, i)];
                a->jtj[TC_PK(i, i)] = d + TC_R(1e-9) * (d > TC_R(1e-12) ? d : TC_R(1e-12));
            }
            if (!gn_step(a, p, delta, &predicted)) break;
        }
        if (predicted <= o->tol * cost + floor + TINY) {
            converged = 1; /* no step can help */
            break;
        }
        tc_real scale_step = 1;
        uint8_t accepted = 0;
        for (uint8_t half = 0; half < 10; half++) {
            it++;
            for (i = 0; i < p; i++) cand[i] = th[i] + scale_step * delta[i];
            pass(pts, n, fr, cand, 1, a, 0);
            if (tc_finite(a->cost) && a->cost <= cost + COST_SLACK * cost) {
                accepted = 1;
                break;
            }
            scale_step *= TC_R(0.5);
            if (it >= o->max_iter) break;
        }
        if (!accepted) {
            converged = 1; /* no half step lowers the cost: a minimum to working precision */
            break;
        }
        tc_real decrease = cost - a->cost, dn = 0, tn = 0;
        for (i = 0; i < p; i++) {
            dn += delta[i] * delta[i];
            tn += th[i] * th[i];
            th[i] = cand[i];
        }
        cost = a->cost;
        if (decrease <= o->tol * (cost > TINY ? cost : TINY) + floor + TINY ||
            tc_sqrt(dn) * scale_step <= STEP_TINY * (tc_sqrt(tn) + STEP_TINY)) {
            converged = 1;
            break;
        }
    }
    *passes = (uint8_t)(it + 1);
    return converged;
}

/* From the solution th to the result (rust/ellipsoid/finish.rs): the gains, conditioning,
 * standard errors, back to raw units, the bounds, RMS and coverage. */
static int8_t finish(const tc_real (*pts)[3], uint16_t n, struct frame *fr, const tc_real *th,
                     tc_real scale, tc_real radius, struct tc_fit *out)
{
    uint8_t p = fr->p, i, j;
    /* the gains: the eigenvalues of W, by magnitude (W and -W, or any sign flip of an
     * eigenvalue, give the same residuals: the host goes on with |W|). An axis model takes
     * |diag|; a full model whose W is not positive definite is refused below unless its gains
     * are refused anyway (the host forms |W| from an eigendecomposition, which the board does
     * not carry; a fit started from a sphere does not get there) */
    tc_real glo, ghi;
    uint8_t indefinite = 0;
    if (p == TC_MODEL_AXIS) {
        glo = ghi = tc_abs(th[3]);
        for (i = 0; i < 3; i++) {
            tc_real g = tc_abs(th[3 + i]);
            if (th[3 + i] < 0) fr->sign[i] = -1;
            if (g < glo) glo = g;
            if (g > ghi) ghi = g;
        }
    } else {
#if P_MAX == 9
        tc_real lo, hi;
        tc_sym3_extremes(th + 3, &lo, &hi); /* theta's xx yy zz xy xz yz */
        tc_real mid = th[3] + th[4] + th[5] - lo - hi;
        indefinite = !(lo > 0);
        glo = ghi = tc_abs(lo);
        if (tc_abs(mid) < glo) glo = tc_abs(mid);
        if (tc_abs(hi) < glo) glo = tc_abs(hi);
        if (tc_abs(mid) > ghi) ghi = tc_abs(mid);
        if (tc_abs(hi) > ghi) ghi = tc_abs(hi);
#else
        return TC_ERR_MODEL; /* not reached: tc_fit refuses the full model first */
#endif
    }
    if (!(glo > TC_R(1e-9) * ghi) || !tc_finite(ghi)) return TC_ERR_NOT_DETERMINED;
    /* the sums at the solution: J^T J for the conditioning, the cost, the coverage */
    struct tc_sums *a = &tc_work.fit.a;
    struct tc_coverage *cov = &tc_work.fit.cov;
    pass(pts, n, fr, th, 1, a, cov);
    tc_real cost = a->cost;

    /* conditioning: J^T J scaled to a unit diagonal, its Frobenius condition number */
    tc_real *dscale = tc_work.fit.cand, *col = tc_work.fit.delta;
    for (i = 0; i < p; i++) {
        tc_real d = a->jtj[TC_PK(i, i)];
        dscale[i] = 1 / tc_sqrt(d > TINY ? d : TINY);
    }
    tc_real frob = 0;
    for (i = 0; i < p; i++) {
        for (j = 0; j <= i; j++) {
            tc_real v = a->jtj[TC_PK(i, j)] * dscale[i] * dscale[j];
            a->jtj[TC_PK(i, j)] = v;
            frob += (i == j ? 1 : 2) * v * v;
        }
    }
    /* A normal matrix float cannot factor (condition beyond about 1e7, against the host's
     * 1e13 in double) is one the host still gets past, on to the bound on the gains: the
     * float build reports that bound when it fails, and "not determined" otherwise. */
    uint8_t implausible = ghi > TC_MAX_AXIS_RATIO * glo;
    int8_t singular = TC_DOUBLE || !implausible ? TC_ERR_NOT_DETERMINED : TC_ERR_GAIN_RATIO;
    if (!tc_cholesky(a->jtj, p)) return singular; /* a singular normal matrix */
    tc_real inv_frob = 0, inv_diag[3];
    for (i = 0; i < p; i++) {
        for (j = 0; j < p; j++) col[j] = j == i ? 1 : 0;
        tc_cholesky_solve(a->jtj, p, col);
        for (j = 0; j < p; j++) inv_frob += col[j] * col[j];
        if (i < 3) inv_diag[i] = col[i];
    }
    tc_real condition = tc_sqrt(frob) * tc_sqrt(inv_frob);
    out->condition = condition;
    if (!(condition < TC_MAX_CONDITION)) return singular;

    /* back to raw units: offset = mean + scale o, matrix = W / scale * radius */
    tc_real mf = 0;
    for (i = 0; i < 3; i++) {
        out->offset[i] = fr->mean[i] + th[i] * scale;
        for (j = 0; j < 3; j++) {
            tc_real m = w_entry(th, p, i, j) * fr->inv_scale * radius;
            out->matrix[i][j] = m;
            mf += m * m;
        }
    }
    out->radius = radius;

    /* standard errors of the offsets, as a fraction of the raw radius */
    uint8_t exact = n == p;
    tc_real worst = 0;
    if (exact) {
        out->warnings |= TC_WARN_EXACT;
    } else {
        tc_real sigma2 = cost / (tc_real)(n - p);
        for (i = 0; i < 3; i++) {
            tc_real v = inv_diag[i] * dscale[i] * dscale[i] * sigma2;
            tc_real se = tc_sqrt(v > 0 ? v : 0) * scale;
            if (se > worst) worst = se;
        }
        worst /= radius / tc_sqrt(mf) * tc_sqrt(3); /* the raw radius */
    }
    out->offset_se = worst;

    /* the physical bounds (rust/bounds.rs) */
    if (implausible) return TC_ERR_GAIN_RATIO;
    if (indefinite) return TC_ERR_NOT_DETERMINED;
    if (!out->converged && worst > TC_MAX_UNCONVERGED_OFFSET_SE) return TC_ERR_NO_CONVERGENCE;

    /* quality and warnings */
    out->rms = tc_sqrt(cost / (tc_real)n) * radius;
    if (worst > TC_WARN_OFFSET_SE_FRACTION) {
        out->warnings |= TC_WARN_OFFSET_SE;
    } else if (condition > TC_WARN_CONDITION) {
        out->warnings |= TC_WARN_ILL_CONDITIONED;
    }
    if (!exact && out->rms > TC_WARN_RMS_FRACTION * radius) out->warnings |= TC_WARN_RMS;
    tc_real cnt = cov->count ? (tc_real)cov->count : 1;
    for (i = 0; i < 6; i++) cov->dd[i] /= cnt; /* its smallest eigenvalue: in tc_fit */
    uint16_t total = 0;
    uint8_t empty = 0;
    for (i = 0; i < 6; i++) {
        out->faces[i] = cov->faces[i];
        total = (uint16_t)(total + cov->faces[i]);
    }
    for (i = 0; i < 6; i++) {
        if ((tc_real)cov->faces[i] < TC_EMPTY_FACE * (tc_real)total) empty = 1;
    }
    if (empty) out->warnings |= TC_WARN_EMPTY_FACE;
    return TC_OK;
}

int8_t tc_fit(const tc_real (*pts)[3], uint16_t n, const struct tc_fit_options *o,
              struct tc_fit *out)
{
    uint8_t p = o->model;
    tc_real radius = o->radius;
    out->n = n;
    out->model = p;
    out->warnings = 0;
    out->iterations = 0;
    out->converged = 0;
    /* the host's order of checks (ellipsoid::fit_ellipsoid) */
    if (p != TC_MODEL_AXIS && p != TC_MODEL_FULL) return TC_ERR_ARGUMENT;
    if (p > P_MAX) return TC_ERR_MODEL;
    if (!tc_finite(radius) || !(radius > 0) || radius > TC_MAGNITUDE_MAX) return TC_ERR_ARGUMENT;
    if (!tc_finite(o->tol) || o->tol < 0) return TC_ERR_ARGUMENT;
    int8_t code = tc_check_points(pts, n);
    if (code) return code;
    if (n < p) return TC_ERR_TOO_FEW;
    struct frame fr;
    tc_real scale;
    code = tc_classify(pts, n, fr.mean, &scale);
    if (code) return code;
    fr.inv_scale = 1 / scale;
    fr.p = p;
    fr.sign[0] = fr.sign[1] = fr.sign[2] = 1;
    tc_real th[P_MAX];
    if (!sphere_start(pts, n, fr.mean, fr.inv_scale, th, p)) return TC_ERR_NOT_DETERMINED;
    out->converged = gauss_newton(pts, n, &fr, th, o, &out->iterations);
    if (!out->converged) out->warnings |= TC_WARN_NOT_CONVERGED;
    code = finish(pts, n, &fr, th, scale, radius, out);
    if (code) return code;
    /* the coverage: the smallest eigenvalue of mean(d d^T) (here, not in finish, so that the
     * two frames are not on the stack together) */
    tc_real hi;
    tc_sym3_extremes(tc_work.fit.cov.dd, &out->spread, &hi);
    if (!(out->warnings & TC_WARN_EMPTY_FACE) && out->spread < TC_WARN_MIN_SPREAD) {
        out->warnings |= TC_WARN_BAND;
    }
    return TC_OK;
}

void tc_apply(const tc_real offset[3], const tc_real matrix[3][3], const tc_real raw[3],
              tc_real out[3])
{
    tc_real d[3] = {raw[0] - offset[0], raw[1] - offset[1], raw[2] - offset[2]};
    for (uint8_t i = 0; i < 3; i++) {
        out[i] = matrix[i][0] * d[0] + matrix[i][1] * d[1] + matrix[i][2] * d[2];
    }
}

void tc_apply_counts(const tc_real offset[3], const tc_real matrix[3][3], const int16_t raw[3],
                     int16_t out[3])
{
    tc_real in[3] = {raw[0], raw[1], raw[2]}, c[3];
    tc_apply(offset, matrix, in, c);
    for (uint8_t i = 0; i < 3; i++) {
        tc_real v = c[i];
        if (!(v > TC_R(-32768.5))) v = TC_R(-32768.0); /* NaN too */
        if (v > TC_R(32767.0)) v = TC_R(32767.0);
        out[i] = (int16_t)(v < 0 ? v - TC_R(0.5) : v + TC_R(0.5));
    }
}
