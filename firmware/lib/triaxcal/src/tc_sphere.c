/* The sphere-centre descent (the error sum and its 26-neighbour search), as rust/sphere/
 * descend_center does it: the error sum E(c) = sum |(p - c)^2 - R^2|, and the 26-neighbour
 * descent whose step shrinks when no neighbour is better. */
#include "tc_internal.h"

void tc_descent_defaults(struct tc_descent_options *o)
{
    o->start[0] = o->start[1] = o->start[2] = 0;
    o->step = 1000;
    o->min_step = TC_R(0.01);
    o->shrink = 10;
    o->max_iter = 1000000UL;
}

/* The step is divided by shrink again and again; the search stops once it is below min_step.
 * The host does that in double: 1000 / 10^5 comes out at 0.01 and 0.1 / 10^5 at
 * 1.0000000000000002e-6, so it runs the last level. In float the same divisions can land a
 * rounding below min_step and drop that level, so the float build counts a step within
 * LEVEL_SLACK (relative) of min_step as equal to it. */
#if TC_DOUBLE
#define LEVEL_SLACK 0
#define NOISE (8 * 2.220446049250313e-16)
#else
#define LEVEL_SLACK (16 * 1.1920929e-7f)
#define NOISE (8 * 1.1920929e-7f)
#endif

/* R^2 as an unevaluated sum hi + lo (exact in float-float; lo = 0 in double). */
struct sq {
    tc_real hi, lo;
};

#if TC_DOUBLE
static struct sq square(tc_real r)
{
    struct sq s = {r * r, 0};
    return s;
}

/* |p - c|^2 - R^2: double leaves round-off of 1e-16 of R^2, far below anything compared. */
static tc_real e0_of(const tc_real *p, const tc_real c[3], struct sq r2)
{
    tc_real x = p[0] - c[0], y = p[1] - c[1], z = p[2] - c[2];
    return x * x + y * y + z * z - r2.hi;
}
#else
#if defined(__FAST_MATH__)
#error "tc_sphere.c relies on IEEE float arithmetic: do not compile it with -ffast-math"
#endif
#if defined(__FLT_EVAL_METHOD__) && __FLT_EVAL_METHOD__ != 0
#error "tc_sphere.c needs float arithmetic in float (FLT_EVAL_METHOD 0; x87: use -mfpmath=sse)"
#endif
/* In float, |p - c|^2 - R^2 computed plainly carries round-off of about 2^-24 R^2 (16 counts^2
 * at R = 16384 counts), which is more than the error sums of neighbouring centres 0.01 apart
 * differ by: the search would wander inside a region where it cannot tell them apart. So the
 * differences, squares and their sum are carried exactly as float pairs (Knuth's two-sum,
 * Dekker's product with Veltkamp's split) and rounded once at the end: the descent then sees
 * what the double search sees to about 2^-24 of the error itself. (Not with -ffast-math.) */
static tc_real two_sum(tc_real a, tc_real b, tc_real *err)
{
    tc_real s = a + b;
    tc_real bb = s - a;
    *err = (a - (s - bb)) + (b - bb);
    return s;
}

static tc_real two_square(tc_real a, tc_real *err)
{
    tc_real p = a * a;
    tc_real t = 4097.0f * a; /* Veltkamp: 2^12 + 1 splits 24 bits into 12 + 12 */
    tc_real hi = t - (t - a), lo = a - hi;
    *err = ((hi * hi - p) + 2 * hi * lo) + lo * lo;
    return p;
}

static struct sq square(tc_real r)
{
    struct sq s;
    s.hi = two_square(r, &s.lo);
    return s;
}

static tc_real e0_of(const tc_real *p, const tc_real c[3], struct sq r2)
{
    tc_real lo = -r2.lo, acc = -r2.hi, e;
    for (uint8_t k = 0; k < 3; k++) {
        tc_real qlo, qhi = two_sum(p[k], -c[k], &qlo); /* p - c = qhi + qlo exactly */
        tc_real slo, shi = two_square(qhi, &slo);
        lo += slo + (2 * qhi + qlo) * qlo;
        acc = two_sum(acc, shi, &e);
        lo += e;
    }
    return acc + lo;
}
#endif

static tc_real error_sum(const tc_real (*pts)[3], uint16_t n, const tc_real c[3], struct sq r2)
{
    tc_real s = 0;
    for (uint16_t i = 0; i < n; i++) s += tc_abs(e0_of(pts[i], c, r2));
    return s;
}

int8_t tc_sphere_error(const tc_real (*pts)[3], uint16_t n, const tc_real center[3],
                       tc_real radius, tc_real *out)
{
    int8_t code = tc_check_points(pts, n);
    if (code) return code;
    if (!tc_finite(radius) || radius < 0 || radius > TC_MAGNITUDE_MAX) return TC_ERR_ARGUMENT;
    for (uint8_t k = 0; k < 3; k++) {
        if (!tc_finite(center[k])) return TC_ERR_ARGUMENT;
    }
    tc_real e = error_sum(pts, n, center, square(radius));
    if (!tc_finite(e)) return TC_ERR_ARGUMENT;
    *out = e;
    return TC_OK;
}

/* How much the error sum changes from the centre c to each of its 26 neighbours c + h (i, j,
 * k), in x-major order skipping the centre (rust/sphere/neighbours.rs). With q = p - c,
 * e0 = |q|^2 - R^2 and (a, b, g) = 2 h q, the error at a neighbour is e = e0 - i a - j b -
 * k g + h^2 (i^2 + j^2 + k^2). A point whose error keeps its sign over the whole neighbourhood
 * changes the sum by a term linear in (i, j, k): such points are summed as moments, and only
 * points near the surface are evaluated 26 times (at small steps, nearly none).
 *
 * The host compares the sums themselves (E at a neighbour against E at the centre); here
 * their differences are summed, which is the same comparison in exact arithmetic. The
 * difference of one point is of the size of 2 h |q|, its error sum of the size of |e0|, many
 * times more: summed as differences, the comparison keeps its precision in float, where the
 * sums themselves (2^-24 of E) could not tell neighbours 0.01 count apart. */
/* The error at the neighbour (i, j, k) less the error at the centre, v = (e0, a, b, g). */
static tc_real error_at(const tc_real v[4], tc_real i, tc_real j, tc_real k, tc_real h2)
{
    return v[0] - i * v[1] - j * v[2] - k * v[3] + h2 * (i * i + j * j + k * k);
}

static tc_real neighbour_changes(const tc_real (*pts)[3], uint16_t n, const tc_real c[3],
                                 struct sq r2, tc_real h, tc_real d[26])
{
    tc_real h2 = h * h, bound = 0;
    /* signed moments of the points of stable sign: a, b, g, count; as the e0 of error_at,
     * 0, so that error_at gives their change */
    tc_real m[4] = {0, 0, 0, 0}, v[4];
    uint8_t t;
    for (t = 0; t < 26; t++) d[t] = 0;
    for (uint16_t p = 0; p < n; p++) {
        v[0] = e0_of(pts[p], c, r2);
        for (t = 0; t < 3; t++) v[1 + t] = 2 * h * (pts[p][t] - c[t]);
        tc_real reach = tc_abs(v[1]) + tc_abs(v[2]) + tc_abs(v[3]);
        bound += reach + 3 * h2; /* no change of this point's error is larger */
        tc_real sign = v[0] > reach ? 1 : (v[0] < -reach - 3 * h2 ? -1 : 0);
        if (sign != 0) {
            for (t = 0; t < 3; t++) m[t] += sign * v[1 + t];
            m[3] += sign;
            continue;
        }
        tc_real here = tc_abs(v[0]);
        t = 0;
        for (tc_real i = -1; i <= 1; i++) {
            for (tc_real j = -1; j <= 1; j++) {
                for (tc_real k = -1; k <= 1; k++) {
                    if (i == 0 && j == 0 && k == 0) continue;
                    d[t++] += tc_abs(error_at(v, i, j, k, h2)) - here;
                }
            }
        }
    }
    /* the moments: sum over the points of sign * (e - e0) = -i a - j b - k g + h^2 n count */
    v[0] = 0;
    for (t = 0; t < 3; t++) v[1 + t] = m[t];
    t = 0;
    for (tc_real i = -1; i <= 1; i++) {
        for (tc_real j = -1; j <= 1; j++) {
            for (tc_real k = -1; k <= 1; k++) {
                if (i == 0 && j == 0 && k == 0) continue;
                d[t++] += error_at(v, i, j, k, h2 * m[3]);
            }
        }
    }
    return bound;
}

/* floor(log(ratio) / log(shrink)) + 1 for ratio >= 1, shrink > 1: the number of times the
 * step shrinks at least, capped at cap + 1 (by doubling exponents, no logarithm). */
static tc_real shrink_levels(tc_real ratio, tc_real shrink, tc_real cap)
{
    tc_real levels = 0, acc = 1;
    while (levels <= cap) {
        /* the largest shrink^(2^e) with acc * shrink^(2^e) <= ratio */
        tc_real pw = shrink, count = 1;
        if (!(acc * pw <= ratio)) break;
        while (acc * pw * pw <= ratio && count <= cap) {
            pw *= pw;
            count *= 2;
        }
        acc *= pw;
        levels += count;
    }
    return levels + 1;
}

int8_t tc_descend_center(const tc_real (*pts)[3], uint16_t n, tc_real radius,
                         const struct tc_descent_options *o, struct tc_descent *out)
{
    /* the host's order of checks (sphere::descend_center) */
    int8_t code = tc_check_points(pts, n);
    if (code) return code;
    if (!tc_finite(radius) || !(radius > 0) || radius > TC_MAGNITUDE_MAX) return TC_ERR_ARGUMENT;
    if (!tc_finite(o->step) || !(o->step > 0)) return TC_ERR_ARGUMENT;
    if (!tc_finite(o->min_step) || !(o->min_step > 0)) return TC_ERR_ARGUMENT;
    if (!tc_finite(o->shrink) || !(o->shrink > 1)) return TC_ERR_ARGUMENT;
    if (o->min_step > o->step) return TC_ERR_ARGUMENT;
    for (uint8_t k = 0; k < 3; k++) {
        if (!tc_finite(o->start[k])) return TC_ERR_ARGUMENT;
    }
    if (n < 4) return TC_ERR_TOO_FEW;
    tc_real cap = TC_DESCENT_WORK_LIMIT / (tc_real)n;
    if (!(shrink_levels(o->step / o->min_step, o->shrink, cap) <= cap)) return TC_ERR_ARGUMENT;
    tc_real mean[3], scale;
    code = tc_classify(pts, n, mean, &scale);
    if (code) return code;

    struct sq r2 = square(radius);
    tc_real c[3] = {o->start[0], o->start[1], o->start[2]};
    uint32_t evaluations = 1, iterations = 0;
    tc_real step = o->step;
    uint8_t converged = 0;
    uint32_t limit = o->max_iter;
    if ((tc_real)limit > cap) limit = (uint32_t)cap;
    tc_real *change = tc_work.change;
    while (!converged && iterations < limit) {
        iterations++;
        /* a change within the round-off of its sum is no change: otherwise two centres could
         * each seem better than the other, and the search would go back and forth */
        tc_real noise = NOISE * neighbour_changes(pts, n, c, r2, step, change);
        evaluations += 26;
        uint8_t best = 26;
        tc_real best_change = 0;
        for (uint8_t t = 0; t < 26; t++) {
            if (change[t] == change[t] && (best == 26 || change[t] < best_change)) {
                best = t;
                best_change = change[t];
            }
        }
        if (best < 26 && best_change < -noise) {
            uint8_t idx = (uint8_t)(best < 13 ? best : best + 1); /* skip the centre (13) */
            c[0] += step * (tc_real)((int8_t)(idx / 9) - 1);
            c[1] += step * (tc_real)((int8_t)(idx / 3 % 3) - 1);
            c[2] += step * (tc_real)((int8_t)(idx % 3) - 1);
        } else {
            step /= o->shrink;
            converged = step < o->min_step * (1 - LEVEL_SLACK);
        }
    }
    /* the exact sum at the final centre (the neighbour sums add in another order) */
    tc_real e = error_sum(pts, n, c, r2);
    if (!tc_finite(e)) return TC_ERR_ARGUMENT;
    for (uint8_t k = 0; k < 3; k++) out->center[k] = c[k];
    out->error = e;
    out->step = step;
    out->iterations = iterations;
    out->evaluations = evaluations + 1;
    out->converged = converged;
    return TC_OK;
}
