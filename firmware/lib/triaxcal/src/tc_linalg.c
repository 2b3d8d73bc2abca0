/* Small dense linear algebra for the fits (packed Cholesky, the extreme eigenvalues of a
 * symmetric 3 x 3 matrix) and the checks every search and fit starts with. */
#include <math.h>

#include "tc_internal.h"

union tc_work tc_work;

tc_real tc_sqrt(tc_real x)
{
#if TC_DOUBLE
    return sqrt(x);
#else
    return sqrtf(x);
#endif
}

uint8_t tc_cholesky(tc_real *a, uint8_t p)
{
    for (uint8_t j = 0; j < p; j++) {
        tc_real d = a[TC_PK(j, j)];
        for (uint8_t k = 0; k < j; k++) d -= a[TC_PK(j, k)] * a[TC_PK(j, k)];
        if (!(d > 0) || !tc_finite(d)) return 0;
        tc_real djj = tc_sqrt(d);
        a[TC_PK(j, j)] = djj;
        tc_real inv = 1 / djj;
        for (uint8_t i = (uint8_t)(j + 1); i < p; i++) {
            tc_real s = a[TC_PK(i, j)];
            for (uint8_t k = 0; k < j; k++) s -= a[TC_PK(i, k)] * a[TC_PK(j, k)];
            a[TC_PK(i, j)] = s * inv;
        }
    }
    return 1;
}

void tc_cholesky_solve(const tc_real *l, uint8_t p, tc_real *x)
{
    for (uint8_t i = 0; i < p; i++) {
        tc_real s = x[i];
        for (uint8_t k = 0; k < i; k++) s -= l[TC_PK(i, k)] * x[k];
        x[i] = s / l[TC_PK(i, i)];
    }
    for (uint8_t i = p; i-- > 0;) {
        tc_real s = x[i];
        for (uint8_t k = (uint8_t)(i + 1); k < p; k++) s -= l[TC_PK(k, i)] * x[k];
        x[i] = s / l[TC_PK(i, i)];
    }
}

/* The smallest root of the characteristic polynomial p(x) = x^3 - t x^2 + m x - d of a
 * symmetric matrix with mean eigenvalue q = t / 3, from x0 = q - r, r the Frobenius norm of
 * A - q I (which bounds every |lambda - q|, so p(x0) <= 0). Below q the cubic is increasing
 * and concave, so Newton's steps from x0 rise monotonically to the root, with no overshoot:
 * no trigonometry (the host's sym3_eigenvalues uses acos and cos). */
/* x^3 - t x^2 + m x - d, the characteristic polynomial of a symmetric 3 x 3 matrix, with
 * q = t / 3 and r the Frobenius norm of A - q I. */
struct cubic {
    tc_real t, m, d, q, r;
};

static tc_real smallest_root(const struct cubic *c)
{
    tc_real x = c->q - c->r;
    for (uint8_t it = 0; it < 100; it++) {
        tc_real px = ((x - c->t) * x + c->m) * x - c->d;
        tc_real dp = (3 * x - 2 * c->t) * x + c->m;
        if (!(px < 0) || !(dp > 0)) break; /* on (or, by round-off, past) the root */
        tc_real nx = x - px / dp;
        if (!(nx > x) || nx > c->q) break; /* no progress left */
        x = nx;
    }
    return x;
}

void tc_sym3_extremes(const tc_real s[6], tc_real *lo, tc_real *hi)
{
    /* scaled to a largest entry of 1, so that no cube overflows or underflows */
    tc_real big = 0, sum = 0;
    uint8_t i;
    for (i = 0; i < 6; i++) {
        sum += s[i];
        if (tc_abs(s[i]) > big) big = tc_abs(s[i]);
    }
    if (big == 0 || !tc_finite(sum)) {
        *lo = *hi = big == 0 ? 0 : sum; /* zero; or NaN / inf */
        return;
    }
    tc_real a[6];
    for (i = 0; i < 6; i++) a[i] = s[i] / big;
    struct cubic c;
    c.t = a[0] + a[1] + a[2];
    c.q = c.t / 3;
    c.r = 2 * (a[3] * a[3] + a[4] * a[4] + a[5] * a[5]);
    for (i = 0; i < 3; i++) c.r += (a[i] - c.q) * (a[i] - c.q);
    c.r = tc_sqrt(c.r);
    c.m = a[0] * a[1] - a[3] * a[3] + a[0] * a[2] - a[4] * a[4] + a[1] * a[2] - a[5] * a[5];
    c.d = a[0] * (a[1] * a[2] - a[5] * a[5]) - a[3] * (a[3] * a[2] - a[5] * a[4]) +
          a[4] * (a[3] * a[5] - a[1] * a[4]);
    *lo = smallest_root(&c) * big;
    /* the largest of A is minus the smallest of -A: x^3 + t x^2 + m x + d */
    c.t = -c.t;
    c.q = -c.q;
    c.d = -c.d;
    *hi = -smallest_root(&c) * big;
}

int8_t tc_check_points(const tc_real (*pts)[3], uint16_t n)
{
    for (uint16_t i = 0; i < n; i++) {
        for (uint8_t k = 0; k < 3; k++) {
            tc_real v = pts[i][k];
            if (!tc_finite(v)) return TC_ERR_NON_FINITE;
        }
    }
    for (uint16_t i = 0; i < n; i++) {
        for (uint8_t k = 0; k < 3; k++) {
            if (tc_abs(pts[i][k]) > TC_MAGNITUDE_MAX) return TC_ERR_ARGUMENT;
        }
    }
    return TC_OK;
}

int8_t tc_classify(const tc_real (*pts)[3], uint16_t n, tc_real mean[3], tc_real *scale)
{
    tc_real c[6] = {0, 0, 0, 0, 0, 0}; /* covariance: xx yy zz xy xz yz */
    uint8_t k;
    for (k = 0; k < 3; k++) {
        tc_real s = 0;
        for (uint16_t i = 0; i < n; i++) s += pts[i][k];
        mean[k] = s / (tc_real)n;
    }
    for (uint16_t i = 0; i < n; i++) {
        tc_real x = pts[i][0] - mean[0], y = pts[i][1] - mean[1], z = pts[i][2] - mean[2];
        c[0] += x * x;
        c[1] += y * y;
        c[2] += z * z;
        c[3] += x * y;
        c[4] += x * z;
        c[5] += y * z;
    }
    for (k = 0; k < 6; k++) c[k] /= (tc_real)n;
    tc_real tr = c[0] + c[1] + c[2];
    *scale = tc_sqrt(tr > 0 ? tr : 0);
    tc_real l3, l1;
    tc_sym3_extremes(c, &l3, &l1);
    if (l3 < 0) l3 = 0;
    tc_real l2 = tr - l1 - l3; /* the middle one from the trace */
    if (l2 < 0) l2 = 0;
    if (!(l1 > 0) || *scale == 0) return TC_ERR_IDENTICAL;
    if (l2 / l1 < TC_FLAT_RATIO) return TC_ERR_LINE;
    if (l3 / l1 < TC_FLAT_RATIO) return TC_ERR_PLANE;
    return TC_OK;
}
