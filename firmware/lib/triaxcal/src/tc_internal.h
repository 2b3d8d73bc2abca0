/* Internal helpers of the triaxcal C library, shared by its .c files (not part of the API). */
#ifndef TRIAXCAL_TC_INTERNAL_H
#define TRIAXCAL_TC_INTERNAL_H

#include "triaxcal.h"

/* Float code is large on an 8-bit AVR (every operation a call with its operands moved into
 * place): the library's own functions are not inlined there, which keeps it about 2 KB
 * smaller whatever flags the build uses (the Arduino IDE's -Os inlines). Only the library's
 * .c files include this header, so a sketch's code is not affected. */
#if defined(__AVR__) && defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("no-inline")
#endif

/* Packed lower triangle of a symmetric P x P matrix: element (i, j), j <= i. */
#define TC_PK(i, j) ((uint8_t)((uint8_t)((i) * ((i) + 1u) / 2u) + (j)))
#define TC_PACKED(p) ((uint8_t)((p) * ((p) + 1u) / 2u))

/* 1 when x is neither NaN nor infinite (no libm: inf - inf and NaN - NaN are NaN). */
static inline uint8_t tc_finite(tc_real x) { return (uint8_t)((x - x) == 0); }

static inline tc_real tc_abs(tc_real x) { return x < 0 ? -x : x; }

tc_real tc_sqrt(tc_real x);

/* The working memory of a fit and of the descent, static rather than on the stack, and shared
 * (one search or fit at a time: the library is not reentrant). On the AVR a stack frame larger
 * than 63 bytes costs extra instructions at every access; and the two never run at once. */
struct tc_sums {
    tc_real jtj[TC_PACKED(TC_FIT_MAX_P)]; /* packed lower triangle of J^T J */
    tc_real jtr[TC_FIT_MAX_P];            /* J^T r */
    tc_real cost;                         /* sum r^2 */
};

struct tc_coverage {
    tc_real dd[6]; /* sum d d^T: xx yy zz xy xz yz */
    uint16_t faces[6];
    uint16_t count;
};

union tc_work {
    struct {
        struct tc_sums a;
        struct tc_coverage cov;
        tc_real cand[TC_FIT_MAX_P], delta[TC_FIT_MAX_P];
    } fit;
    tc_real change[26]; /* the descent: how the error sum changes at each neighbour */
};
extern union tc_work tc_work;

/* Cholesky factor of the packed symmetric a (p x p) in place; 0 unless positive definite
 * (every pivot positive and finite, as rust/linalg.rs cholesky_in_place). */
uint8_t tc_cholesky(tc_real *a, uint8_t p);
/* Solves L L^T x = b in place with the factor of tc_cholesky. */
void tc_cholesky_solve(const tc_real *l, uint8_t p, tc_real *x);

/* Smallest and largest eigenvalue of the symmetric 3 x 3 matrix s = xx yy zz xy xz yz. */
void tc_sym3_extremes(const tc_real s[6], tc_real *lo, tc_real *hi);

/* Validation shared by the searches and the fits: every coordinate finite (TC_ERR_NON_FINITE)
 * and within +-TC_MAGNITUDE_MAX (TC_ERR_ARGUMENT). */
int8_t tc_check_points(const tc_real (*pts)[3], uint16_t n);

/* Mean, scale (RMS distance from the mean) and the rust/geometry.rs classify() checks:
 * TC_ERR_IDENTICAL, TC_ERR_LINE, TC_ERR_PLANE. */
int8_t tc_classify(const tc_real (*pts)[3], uint16_t n, tc_real mean[3], tc_real *scale);

#endif
