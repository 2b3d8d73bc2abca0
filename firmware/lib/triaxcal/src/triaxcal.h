/* triaxcal: on-device calibration of a three-axis sensor, the C twin of the Rust core.
 *
 * Portable C99 (avr-gcc, arm-none-eabi-gcc, gcc), no allocation, no library call but sqrt;
 * every buffer is sized at compile time (tc_config.h). The pieces, in the order a board uses
 * them (firmware/README.md, "The C library"):
 *
 *   still.h        the still-pose detector (the sphere-centre method's window rule with the gyro), integers only
 *   tc_poses_*     a buffer of pose means that, once full, keeps the poses that cover the sphere
 *   tc_descend_*   the sphere-centre method's centre search: sum of |error|, 26 neighbours, variable step
 *   tc_fit         offset + 3 gains ("axis") or offset + symmetric matrix ("full"), Gauss-Newton
 *                  on the geometric residual from the linear sphere fit, with the quality
 *                  figures and refusals of the host (rust/bounds.rs, rust/ellipsoid/finish.rs)
 *   tc_apply_*     calibrated = matrix (raw - offset): the matrix multiplies
 *   tc_store.h     the calibration record for non-volatile storage (version + CRC-16)
 *
 * Error model (rust/ellipsoid/mod.rs): a raw reading p and the field f of constant magnitude
 * `radius` (gravity: 16384 counts at +-2 g, or 1 g) are related by f = W (p - offset), with
 * offset the bias and the symmetric W the gains (diagonal) and cross-axis terms. The fits
 * minimise sum (|W (p - offset)| - radius)^2, the host's plain geometric fit (the host's fit
 * with debias=False, which is also what it does by default whenever the noise is below
 * 0.1/sqrt(N) of the radius, as for averaged poses).
 *
 * Every function that can fail returns an int8_t code: TC_OK or one of the refusals below,
 * each of which mirrors an error of the host's fit (the comment names the bound).
 */
#ifndef TRIAXCAL_H
#define TRIAXCAL_H

#include <stdint.h>

#include "still.h"
#include "tc_config.h"
#include "tc_store.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------- codes */

enum tc_code {
    TC_OK = 0,
    /* an option out of range: radius, step, min_step <= 0, shrink <= 1, min_step > step, a
     * start that is not finite, more work than sphere::DESCENT_WORK_LIMIT, an error sum that
     * overflows; readings beyond +-TC_MAGNITUDE_MAX (CalError::InvalidArgument) */
    TC_ERR_ARGUMENT = 1,
    TC_ERR_NON_FINITE = 2,     /* a NaN or infinite coordinate (CalError::NonFinite) */
    TC_ERR_TOO_FEW = 3,        /* fewer points than unknowns: 4 search, 6 axis, 9 full
                                * (CalError::TooFewPoints) */
    TC_ERR_IDENTICAL = 4,      /* all points identical (geometry::classify) */
    TC_ERR_LINE = 5,           /* on a line: middle / largest variance < TC_FLAT_RATIO
                                * (geometry::FLAT_RATIO) */
    TC_ERR_PLANE = 6,          /* on a plane: smallest / largest variance < TC_FLAT_RATIO */
    TC_ERR_NOT_DETERMINED = 7, /* no sphere fits them, a singular normal matrix, condition
                                * number >= TC_MAX_CONDITION, a gain <= 0 (ellipsoid::
                                * not_determined) */
    TC_ERR_GAIN_RATIO = 8,     /* largest / smallest gain > TC_MAX_AXIS_RATIO
                                * (bounds::MAX_AXIS_RATIO, bounds::check_gains) */
    TC_ERR_NO_CONVERGENCE = 9, /* no convergence and an offset standard error above
                                * TC_MAX_UNCONVERGED_OFFSET_SE of the radius
                                * (bounds::MAX_UNCONVERGED_OFFSET_SE) */
    TC_ERR_MODEL = 10          /* a model this build leaves out (TC_FIT_MAX_P) */
};

/* Warnings (struct tc_fit.warnings, bits), as rust/ellipsoid/finish.rs words them. */
#define TC_WARN_EXACT 0x01           /* as many points as unknowns: no residual left */
#define TC_WARN_NOT_CONVERGED 0x02   /* the iteration limit stopped the fit */
#define TC_WARN_OFFSET_SE 0x04       /* offset standard error > TC_WARN_OFFSET_SE_FRACTION
                                      * of the radius (bounds::WARN_OFFSET_SE) */
#define TC_WARN_ILL_CONDITIONED 0x08 /* condition number > TC_WARN_CONDITION (when the
                                      * offset standard error did not warn already) */
#define TC_WARN_RMS 0x10             /* RMS > TC_WARN_RMS_FRACTION of the radius
                                      * (bounds::WARN_RMS_FRACTION) */
#define TC_WARN_EMPTY_FACE 0x20      /* a face of the cube holds < TC_EMPTY_FACE of the
                                      * directions (bounds::EMPTY_FACE) */
#define TC_WARN_BAND 0x40            /* spread < TC_WARN_MIN_SPREAD (bounds::WARN_MIN_SPREAD;
                                      * when no face is empty) */

/* The bounds, with the values of rust/bounds.rs and rust/geometry.rs. */
#define TC_MAX_AXIS_RATIO TC_R(3.0)
#define TC_MAX_UNCONVERGED_OFFSET_SE TC_R(0.1)
#define TC_WARN_OFFSET_SE_FRACTION TC_R(0.01)
#define TC_WARN_RMS_FRACTION TC_R(0.2)
#define TC_WARN_MIN_SPREAD TC_R(0.1)
#define TC_EMPTY_FACE TC_R(0.01)
#define TC_MAX_CONDITION TC_R(1e13)
#define TC_WARN_CONDITION TC_R(1e8)
#define TC_DESCENT_WORK_LIMIT TC_R(5e8)
/* geometry::FLAT_RATIO is 1e-12 in double. A float reading carries round-off of 1e-7 of its
 * magnitude, so the eigenvalues of a float covariance are only known to about 1e-7 of the
 * largest: the float build calls a cloud flat below 1e-6, a cloud whose thinnest spread is a
 * thousandth of its widest (the host would go on to fit it and, typically, refuse its gains). */
#if TC_DOUBLE
#define TC_FLAT_RATIO 1e-12
#define TC_MAGNITUDE_MAX 1e150
#else
#define TC_FLAT_RATIO 1e-6f
#define TC_MAGNITUDE_MAX 1e15f /* squares and their sums stay inside float's range */
#endif

/* ------------------------------------------------------------------------ the poses */

/* Pose means (raw units) in storage the caller provides (TC_POSES_STORAGE sizes it at
 * compile time; 12 bytes per pose in float). Until it is full every pose is kept, in the
 * order given; once full, a new pose takes the place of one of the two stored poses closest
 * to each other if it is farther from every stored pose than those two are from each other,
 * and is dropped otherwise: the smallest distance between stored poses never shrinks, so the
 * buffer keeps the poses that cover the sphere best (distances between raw readings stand for
 * angles: all lie on one ellipsoid). The sphere-centre method's globe (84 poses) repeats each pole 12 times
 * (the twists about the vertical look alike to an accelerometer): a buffer of 62 holds every
 * direction it has. */
struct tc_poses {
    tc_real (*p)[3];   /* the storage: p[0 .. capacity-1] */
    uint16_t capacity;
    uint16_t n;        /* poses held */
    uint16_t seen;     /* poses offered since tc_poses_init */
    uint16_t replaced; /* offered when full and kept in place of another */
};

/* static storage for `count` poses, named `name`: TC_POSES_STORAGE(store, 84); then
 * tc_poses_init(&buf, store, 84) */
#define TC_POSES_STORAGE(name, count) static tc_real name[count][3]

#define TC_POSE_DROPPED (-1)

void tc_poses_init(struct tc_poses *b, tc_real (*storage)[3], uint16_t capacity);
/* Offer a pose; returns the slot it went into, or TC_POSE_DROPPED. */
int16_t tc_poses_add(struct tc_poses *b, const tc_real p[3]);
/* The accelerometer means (channels 0-2) of a pose of the still detector, raw counts. */
void tc_pose_accel(const struct still_pose *pose, tc_real out[3]);
/* Smallest squared distance between two stored poses (0 with fewer than two). */
tc_real tc_poses_min_gap2(const struct tc_poses *b);

/* ------------------------------------------------------------------ the sphere-centre method's search */

struct tc_descent_options {
    tc_real start[3]; /* where the search starts */
    tc_real step;     /* first step along each axis */
    tc_real min_step; /* stop once the step falls below this (== step: fixed-step descent) */
    tc_real shrink;   /* the step is divided by this when no neighbour is better (> 1) */
    uint32_t max_iter; /* most neighbourhoods examined */
};

struct tc_descent {
    tc_real center[3];    /* raw units */
    tc_real error;        /* sum |(p - center)^2 - radius^2| at center */
    tc_real step;         /* the step in force at the end */
    uint32_t iterations;  /* neighbourhoods examined */
    uint32_t evaluations; /* error sums evaluated */
    uint8_t converged;    /* 0 when max_iter stopped it before the step fell below min_step */
};

/* The sphere-centre method's values (sphere::DescentOptions::default): start 0, step 1000, min_step 0.01,
 * shrink 10, max_iter 1000000. */
void tc_descent_defaults(struct tc_descent_options *o);
/* sum_i |(x_i - c_x)^2 + (y_i - c_y)^2 + (z_i - c_z)^2 - radius^2| (sphere::sphere_error). */
int8_t tc_sphere_error(const tc_real (*pts)[3], uint16_t n, const tc_real center[3],
                       tc_real radius, tc_real *out);
/* The 26-neighbour variable-step descent of sphere::descend_center: from start, move to the
 * best of the 26 neighbours one step away while one is better (ties: the first in x-major
 * order), otherwise divide the step by shrink; stop when it falls below min_step. */
int8_t tc_descend_center(const tc_real (*pts)[3], uint16_t n, tc_real radius,
                         const struct tc_descent_options *o, struct tc_descent *out);

/* ------------------------------------------------------------------------- the fits */

#define TC_MODEL_AXIS 6 /* offset + 3 gains: W = diag(g) */
#define TC_MODEL_FULL 9 /* offset + symmetric W */

struct tc_fit_options {
    uint8_t model;    /* TC_MODEL_AXIS or TC_MODEL_FULL */
    tc_real radius;   /* magnitude calibrated readings must have (16384 counts, 1 g, ...) */
    uint8_t max_iter; /* most passes over the points after the start (default 50) */
    tc_real tol;      /* converged when a step lowers the cost by less than this fraction */
};

struct tc_fit {
    tc_real offset[3];    /* raw units */
    tc_real matrix[3][3]; /* calibrated = matrix (raw - offset); calibrated units per raw unit */
    tc_real radius;       /* as asked */
    tc_real rms;          /* RMS of |calibrated| - radius over the points, calibrated units */
    tc_real spread;       /* smallest eigenvalue of mean(d d^T) of the calibrated directions
                           * d: 1/3 when even, 0 for a ring (bounds::direction_spread) */
    tc_real condition;    /* Frobenius condition number of the scaled normal matrix */
    tc_real offset_se;    /* largest offset standard error / the raw radius */
    uint16_t faces[6];    /* directions nearest +X -X +Y -Y +Z -Z (bounds::face_counts) */
    uint16_t n;           /* points fitted */
    uint16_t warnings;    /* TC_WARN_* bits */
    uint8_t model;
    uint8_t iterations; /* passes over the points */
    uint8_t converged;
};

/* Defaults: model and radius as given, max_iter 50, tol 1e-10 (the host's). A float fit also
 * stops once a step's predicted decrease of the cost is below what float round-off of the
 * residuals (16 n eps^2 at unit radius) lets it see. */
void tc_fit_defaults(struct tc_fit_options *o, uint8_t model, tc_real radius);
/* Fit; out holds the result when TC_OK (and the figures computed so far otherwise). */
int8_t tc_fit(const tc_real (*pts)[3], uint16_t n, const struct tc_fit_options *o,
              struct tc_fit *out);

/* ----------------------------------------------------------------------- applying it */

/* out = matrix (raw - offset) (out may be raw). */
void tc_apply(const tc_real offset[3], const tc_real matrix[3][3], const tc_real raw[3],
              tc_real out[3]);
/* The same on int16 counts: rounded to the nearest count and clamped to int16. */
void tc_apply_counts(const tc_real offset[3], const tc_real matrix[3][3], const int16_t raw[3],
                     int16_t out[3]);

#ifdef __cplusplus
}
#endif

#endif
