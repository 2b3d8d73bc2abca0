/* The C library against the Rust core (vectors.h), and its own properties; the same program
 * on the host (gcc, float and double builds), on the ATmega328P (qemu-system-avr) and on a
 * Cortex-M3 (qemu-system-arm). Prints one line per check group and ends with
 *     RESULT <checks> checks, <failures> failures
 * which `make check` (firmware/Makefile) looks for. */
#include <string.h>

#include "tcv.h"

/* Agreement with the core (firmware/README.md, "Equal to the host", says where the float
 * bounds come from). The double build takes the core's path: the descent the same steps to
 * the same centre, the fits the same minimum to round-off. In float the error sum of
 * neighbouring centres can differ by less than float resolves (its round-off is 2^-24 of the
 * sum), so the float descent ends where the sum is within TOL_ERROR of the host's, at a centre
 * that may lie anywhere in the region where the sum is that flat; the fits land on the same
 * minimum to float round-off amplified by the conditioning, a tiny fraction of the fit's own
 * standard error. */
#if TC_DOUBLE
#define TOL_CENTER 1e-12  /* descent centre, times the radius ... */
#define TOL_STEPS 0       /* ... plus this many final steps */
#define TOL_ERROR 1e-12   /* descent error sum, relative */
#define TOL_OFFSET 1e-9   /* fit offset: times the radius ... */
#define TOL_MATRIX 1e-9   /* fit matrix: times its largest entry ... */
#define TOL_SE 1e-5       /* ... plus this many of the host's standard errors */
#define TOL_RMS 1e-9      /* fit RMS, relative */
#else
#define TOL_CENTER 1e-6f /* ... plus TOL_STEPS final steps */
#define TOL_STEPS 5
#define TOL_ERROR 1e-6f
#define TOL_OFFSET 2e-6f
#define TOL_MATRIX 2e-6f
#define TOL_SE 0.01f
#define TOL_RMS 1e-3f
#endif

/* The AVR's 32 KB of flash do not hold the library, the comparisons and the unit tests at
 * once: its build runs them as two programs (TCV_VECTORS=1 TCV_UNITS=0, then 0 and 1). */
#ifndef TCV_VECTORS
#define TCV_VECTORS 1
#endif
#ifndef TCV_UNITS
#define TCV_UNITS 1
#endif

static uint16_t checks, failures;
static union {
    tc_real pts[TCV_MAXN][3]; /* a case's points, or the pose buffer's storage */
} mem;
static struct tcv_case cs;

/* ------------------------------------------------------------------------------ output */

static void put_int(int32_t v)
{
    char d[11];
    uint8_t n = 0;
    uint32_t u = v < 0 ? (uint32_t)(-(v + 1)) + 1u : (uint32_t)v;
    if (v < 0) tcv_putc('-');
    do {
        d[n++] = (char)('0' + u % 10u);
        u /= 10u;
    } while (u);
    while (n) tcv_putc(d[--n]);
}

#if TCV_VECTORS
/* x as d.ddde+XX (display only: the digits are good to about 1e-6) */
static void put_real(tc_real x)
{
    if (x != x) {
        tcv_puts(TCV_STR("nan"));
        return;
    }
    if (x < 0) {
        tcv_putc('-');
        x = -x;
    }
    if (x - x != 0) {
        tcv_puts(TCV_STR("inf"));
        return;
    }
    int16_t e = 0;
    if (x > 0) {
        while (x >= 10) {
            x /= 10;
            e++;
        }
        while (x < 1) {
            x *= 10;
            e--;
        }
    }
    int32_t m = (int32_t)(x * 1000 + TC_R(0.5));
    if (m >= 10000) {
        m /= 10;
        e++;
    }
    put_int(m / 1000);
    tcv_putc('.');
    tcv_putc((char)('0' + m / 100 % 10));
    tcv_putc((char)('0' + m / 10 % 10));
    tcv_putc((char)('0' + m % 10));
    tcv_putc('e');
    if (e < 0) {
        tcv_putc('-');
        e = (int16_t)-e;
    } else {
        tcv_putc('+');
    }
    if (e < 10) tcv_putc('0');
    put_int(e);
}

static void put_name(void)
{
    for (uint8_t i = 0; i < sizeof cs.name && cs.name[i]; i++) tcv_putc(cs.name[i]);
}
#endif

static void check(uint8_t ok, const char *what)
{
    checks++;
    if (!ok) {
        failures++;
        tcv_puts(TCV_STR("  FAIL "));
        tcv_puts(what);
        tcv_putc('\n');
    }
}

static tc_real absr(tc_real x) { return x < 0 ? -x : x; }

static uint8_t have_case = 0xFF;

static void load_case(uint8_t c)
{
    if (c != have_case) tcv_case(c, &cs, mem.pts);
    have_case = c;
}

#if TCV_VECTORS
/* ------------------------------------------------------------------- against the core */

static uint32_t cost_descent, cost_axis, cost_full;

static void vs_descent(void)
{
    struct tc_descent_options o;
    struct tc_descent d;
    for (uint8_t k = 0; k < 3; k++) o.start[k] = cs.start[k];
    o.step = cs.step;
    o.min_step = cs.min_step;
    o.shrink = cs.shrink;
    o.max_iter = 1000000UL;
    uint32_t t0 = tcv_clock();
    int8_t code = tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, cs.radius, &o, &d);
    uint32_t t1 = tcv_clock();
    if (!strcmp(cs.name, "globe84")) cost_descent = t1 - t0;
    tcv_puts(TCV_STR(" descent "));
    put_int(code);
    if (code != cs.dcode) {
        tcv_puts(TCV_STR(" (host "));
        put_int(cs.dcode);
        tcv_putc(')');
    }
    check(code == cs.dcode, TCV_STR("descent code"));
    if (code || cs.dcode) return;
    tc_real dc = 0;
    for (uint8_t k = 0; k < 3; k++) {
        tc_real v = absr(d.center[k] - cs.center[k]);
        if (v > dc) dc = v;
    }
    tc_real de = absr(d.error - cs.error) / (cs.error > 0 ? cs.error : 1);
    tcv_puts(TCV_STR(" |dc|/R "));
    put_real(dc / cs.radius);
    tcv_puts(TCV_STR(" steps "));
    put_real(dc / cs.min_step);
    tcv_puts(TCV_STR(" de "));
    put_real(de);
    tcv_puts(TCV_STR(" it "));
    put_int((int32_t)d.iterations);
    tcv_putc('/');
    put_int((int32_t)cs.iterations);
    check(dc <= TOL_CENTER * cs.radius + TOL_STEPS * cs.min_step, TCV_STR("descent centre"));
    check(de <= TOL_ERROR, TCV_STR("descent error sum"));
    check(d.converged == cs.converged, TCV_STR("descent converged"));
#if TC_DOUBLE
    check(d.iterations == cs.iterations, TCV_STR("descent iterations"));
#endif
}

static void vs_fit(uint8_t model, const struct tcv_fit *want)
{
    struct tc_fit_options o;
    struct tc_fit f;
    tc_fit_defaults(&o, model, cs.radius);
#if TC_DOUBLE
    o.tol = 1e-14; /* as the vectors' fits: converged to round-off */
#endif
    uint32_t t0 = tcv_clock();
    int8_t code = tc_fit((const tc_real(*)[3])mem.pts, cs.n, &o, &f);
    uint32_t t1 = tcv_clock();
    if (!strcmp(cs.name, "globe84")) {
        if (model == TC_MODEL_AXIS) cost_axis = t1 - t0;
        else cost_full = t1 - t0;
    }
    tcv_puts(model == TC_MODEL_AXIS ? TCV_STR(" axis ") : TCV_STR(" full "));
    put_int(code);
    if (code != want->code) {
        tcv_puts(TCV_STR(" (host "));
        put_int(want->code);
        tcv_putc(')');
    }
    check(code == want->code, TCV_STR("fit code"));
    if (code || want->code) return;
    tc_real doff = 0, dm = 0, mmax = 0;
    for (uint8_t k = 0; k < 3; k++) {
        tc_real v = absr(f.offset[k] - want->offset[k]);
        if (v > doff) doff = v;
    }
    for (uint8_t k = 0; k < 9; k++) {
        tc_real v = absr(f.matrix[k / 3][k % 3] - want->matrix[k]);
        if (v > dm) dm = v;
        if (absr(want->matrix[k]) > mmax) mmax = absr(want->matrix[k]);
    }
    tc_real drms = absr(f.rms - want->rms);
    tc_real se_o = want->se[0] > 0 ? want->se[0] : 0, se_w = want->se[1] > 0 ? want->se[1] : 0;
    tcv_puts(TCV_STR(" |do|/R "));
    put_real(doff / cs.radius);
    tcv_puts(TCV_STR(" /se "));
    put_real(se_o > 0 ? doff / se_o : 0);
    tcv_puts(TCV_STR(" |dW|/W "));
    put_real(dm / mmax);
    tcv_puts(TCV_STR(" /se "));
    put_real(se_w > 0 ? dm / se_w : 0);
    tcv_puts(TCV_STR(" drms/rms "));
    put_real(want->rms > 0 ? drms / want->rms : drms);
    tcv_puts(TCV_STR(" warn "));
    put_int(f.warnings);
    check(doff <= TOL_OFFSET * cs.radius + TOL_SE * se_o, TCV_STR("fit offset"));
    check(dm <= TOL_MATRIX * mmax + TOL_SE * se_w, TCV_STR("fit matrix"));
    /* an exactly determined fit has residuals of round-off only: its RMS is no figure */
    check(drms <= TOL_RMS * want->rms || (want->warnings & TC_WARN_EXACT),
          TCV_STR("fit rms"));
    check(f.warnings == want->warnings, TCV_STR("fit warnings"));
}

static void against_the_core(void)
{
    uint8_t ncases = tcv_ncases();
    for (uint8_t c = 0; c < ncases; c++) {
        load_case(c);
        put_name();
        tcv_putc(':');
        vs_descent();
        vs_fit(TC_MODEL_AXIS, &cs.axis);
#if TC_FIT_MAX_P == 9
        vs_fit(TC_MODEL_FULL, &cs.full);
#endif
        tcv_putc('\n');
    }
}

#endif /* TCV_VECTORS */

#if TCV_UNITS
/* ---------------------------------------------------------------- the library alone */

static void refusals(void)
{
    /* a NaN or an infinity is refused before anything else (on the last case's points) */
    load_case(have_case == 0xFF ? 0 : have_case);
    volatile tc_real zero = 0;
    struct tc_descent_options o;
    struct tc_descent d;
    struct tc_fit_options fo;
    struct tc_fit f;
    tc_descent_defaults(&o);
    tc_fit_defaults(&fo, TC_MODEL_AXIS, 16384);
    tc_real keep = mem.pts[2][1];
    mem.pts[2][1] = zero / zero;
    check(tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, 16384, &o, &d) ==
              TC_ERR_NON_FINITE, TCV_STR("NaN refused by the descent"));
    mem.pts[2][1] = 1 / zero;
    check(tc_fit((const tc_real(*)[3])mem.pts, cs.n, &fo, &f) == TC_ERR_NON_FINITE,
          TCV_STR("inf refused by the fit"));
    mem.pts[2][1] = keep;
    /* options out of range */
    o.shrink = 1;
    check(tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, 16384, &o, &d) ==
              TC_ERR_ARGUMENT, TCV_STR("shrink 1 refused"));
    tc_descent_defaults(&o);
    o.min_step = 2000;
    check(tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, 16384, &o, &d) ==
              TC_ERR_ARGUMENT, TCV_STR("min_step > step refused"));
    tc_descent_defaults(&o);
    o.shrink = TC_R(1.0000001); /* 1000 -> 0.01 in steps of 1e-7: more than the work limit */
    check(tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, 16384, &o, &d) ==
              TC_ERR_ARGUMENT, TCV_STR("descent over the work limit refused"));
    check(tc_descend_center((const tc_real(*)[3])mem.pts, cs.n, -1, &o, &d) == TC_ERR_ARGUMENT,
          TCV_STR("negative radius refused"));
    fo.radius = 0;
    check(tc_fit((const tc_real(*)[3])mem.pts, cs.n, &fo, &f) == TC_ERR_ARGUMENT,
          TCV_STR("zero radius refused"));
    tc_fit_defaults(&fo, 7, 16384);
    check(tc_fit((const tc_real(*)[3])mem.pts, cs.n, &fo, &f) == TC_ERR_ARGUMENT,
          TCV_STR("unknown model refused"));
    tcv_puts(TCV_STR("refusals: done\n"));
}

static void apply_and_round(void)
{
    const tc_real off[3] = {10, -10, 0};
    tc_real m[3][3] = {{2, 0, 0}, {0, TC_R(0.5), 0}, {0, 0, 1}};
    int16_t raw[3] = {20000, -13, 7}, out[3];
    tc_apply_counts(off, (const tc_real(*)[3])m, raw, out);
    check(out[0] == 32767 && out[1] == -2 && out[2] == 7, TCV_STR("apply: clamp and round"));
    raw[0] = -20000;
    raw[1] = -7;
    tc_apply_counts(off, (const tc_real(*)[3])m, raw, out);
    check(out[0] == -32768 && out[1] == 2, TCV_STR("apply: clamp low, round half away"));
    tc_real in[3] = {11, -9, 5}, c[3];
    tc_apply(off, (const tc_real(*)[3])m, in, c);
    check(c[0] == 2 && c[1] == TC_R(0.5) && c[2] == 5, TCV_STR("apply: matrix multiplies"));
    tcv_puts(TCV_STR("apply: done\n"));
}

static void store(void)
{
    struct tc_record r, back;
    uint8_t b[TC_STORE_BYTES];
    memset(&r, 0, sizeof r);
    r.sensor = TC_STORE_SENSOR_ACCEL;
    r.model = TC_MODEL_AXIS;
    r.origin = TC_STORE_ORIGIN_BOARD;
    r.n = 84;
    r.warnings = TC_WARN_BAND;
    r.radius = 16384.0f;
    r.offset[0] = 180.25f;
    r.offset[1] = -240.5f;
    r.offset[2] = 350.125f;
    for (uint8_t i = 0; i < 3; i++) r.matrix[i][i] = 0.985f + 0.01f * (float)i;
    r.matrix[0][1] = r.matrix[1][0] = 0.002f;
    r.rms = 3.5f;
    r.spread = 0.31f;
    tc_store_pack(&r, b);
    check(b[0] == 'T' && b[1] == 'C' && b[2] == TC_STORE_VERSION, TCV_STR("store: header"));
    uint8_t same = tc_store_unpack(b, &back) == TC_STORE_OK && back.sensor == r.sensor &&
                   back.model == r.model && back.origin == r.origin && back.n == r.n &&
                   back.warnings == r.warnings && back.radius == r.radius &&
                   back.rms == r.rms && back.spread == r.spread &&
                   !memcmp(back.offset, r.offset, sizeof r.offset) &&
                   !memcmp(back.matrix, r.matrix, sizeof r.matrix);
    check(same, TCV_STR("store: round trip"));
    b[30] ^= 0x10;
    check(tc_store_unpack(b, &back) == TC_STORE_CORRUPT, TCV_STR("store: a flipped bit"));
    memset(b, 0xFF, sizeof b);
    check(tc_store_unpack(b, &back) == TC_STORE_ABSENT, TCV_STR("store: erased"));
    r.matrix[2][2] = 0; /* a singular matrix, with a good CRC */
    r.matrix[2][0] = r.matrix[2][1] = 0;
    tc_store_pack(&r, b);
    check(tc_store_unpack(b, &back) == TC_STORE_INVALID, TCV_STR("store: singular"));
    tcv_puts(TCV_STR("store: done\n"));
}

/* uniform numbers and unit vectors without a math library: a 32-bit LCG, rejection in the
 * unit ball */
static uint32_t rng = 12345u;
static tc_real uniform(void)
{
    rng = rng * 1664525u + 1013904223u;
    return (tc_real)(rng >> 8) / (tc_real)16777216.0;
}

static void unit(tc_real u[3])
{
    for (;;) {
        tc_real x = 2 * uniform() - 1, y = 2 * uniform() - 1, z = 2 * uniform() - 1;
        tc_real r2 = x * x + y * y + z * z;
        if (r2 > TC_R(0.01) && r2 <= 1) {
            tc_real r = 1;
            while (absr(r * r - r2) > TC_R(1e-6) * r2) r = (r + r2 / r) / 2; /* sqrt */
            u[0] = x / r;
            u[1] = y / r;
            u[2] = z / r;
            return;
        }
    }
}

#define CAP TCV_MAXN /* poses in the buffer under test */

static void pose_buffer(void)
{
    struct tc_poses buf, *b = &buf;
    have_case = 0xFF; /* the storage is the case's: forget it */
    tc_poses_init(b, mem.pts, CAP);
    tc_real p[3];
    /* first a crowd: CAP poses within about 25 degrees of +Z */
    while (b->n < CAP) {
        unit(p);
        if (p[2] < TC_R(0.9)) continue;
        for (uint8_t k = 0; k < 3; k++) p[k] = 100 + 16384 * p[k];
        tc_poses_add(b, p);
    }
    tc_real gap = tc_poses_min_gap2(b), g;
    uint8_t never_shrinks = 1;
    uint16_t kept = 0;
    /* then poses from everywhere: the buffer spreads out over the sphere */
    for (uint16_t i = 0; i < 3 * CAP; i++) {
        unit(p);
        for (uint8_t k = 0; k < 3; k++) p[k] = 100 + 16384 * p[k];
        if (tc_poses_add(b, p) != TC_POSE_DROPPED) kept++;
        g = tc_poses_min_gap2(b);
        if (g < gap) never_shrinks = 0;
        gap = g;
    }
    check(b->n == CAP && b->replaced == kept && kept > 0, TCV_STR("poses: counts"));
    check(never_shrinks, TCV_STR("poses: the smallest gap never shrinks"));
    uint16_t faces[6] = {0, 0, 0, 0, 0, 0};
    for (uint16_t i = 0; i < b->n; i++) {
        uint8_t axis = 0;
        for (uint8_t k = 1; k < 3; k++) {
            if (absr(b->p[i][k] - 100) > absr(b->p[i][axis] - 100)) axis = k;
        }
        faces[2 * axis + (b->p[i][axis] >= 100 ? 0 : 1)]++;
    }
    uint8_t all = 1;
    for (uint8_t k = 0; k < 6; k++) {
        if (faces[k] < CAP / 24) all = 0;
    }
    tcv_puts(TCV_STR("poses: kept "));
    put_int(kept);
    tcv_puts(TCV_STR(" of "));
    put_int(3 * CAP);
    tcv_puts(TCV_STR(", faces"));
    for (uint8_t k = 0; k < 6; k++) {
        tcv_putc(' ');
        put_int(faces[k]);
    }
    tcv_putc('\n');
    check(all, TCV_STR("poses: every face of the cube holds a share"));
    /* a pose of the still detector: means of its sums */
    struct still_pose sp;
    memset(&sp, 0, sizeof sp);
    sp.n = 100;
    sp.sum[0] = 1800050;
    sp.sum[1] = -24000;
    sp.sum[2] = -5;
    tc_pose_accel(&sp, p);
    check(p[0] == TC_R(18000.5) && p[1] == -240 && p[2] == TC_R(-0.05) * 1,
          TCV_STR("poses: means of a still pose"));
}

/* One sample of a board flat on a table (gyro bias 60 -40 25 counts), turning about the
 * vertical at `rate` counts, with +-3 counts of noise from a linear congruential generator. */
static void flat(int16_t v[STILL_CHANNELS], int16_t rate, uint32_t *seed)
{
    static const int16_t base[STILL_CHANNELS] = {0, 0, 16384, 60, -40, 25, -1500};
    for (uint8_t k = 0; k < STILL_CHANNELS; k++) {
        *seed = *seed * 1664525UL + 1013904223UL;
        v[k] = (int16_t)(base[k] + (k < 6 ? (int16_t)((*seed >> 24) % 7u) - 3 : 0));
    }
    v[5] = (int16_t)(v[5] + rate);
}

static void still_twist_first(void)
{
    /* twisted at 10 deg/s (1310 counts) from the first sample for 3 s, then 12 rests of 1 s
     * joined by twists of 0.5 s (a triangle up to 30..69 deg/s, each its own; its two windows
     * average 15..35 deg/s, never the first twist's rate). The twist is steady to both
     * sensors and was taken for the gyro bias, after which every rest was a turn (1 pose).
     * The first bias is provisional: 8 steady windows at one rate after different moves
     * replace it (3 in each of the first two rests, 2 in the third), and the rests from the
     * fourth on are poses. */
    struct still_settings s;
    still_defaults(&s);
    s.holdoff_ms = 0;
    s.hold_windows = 2; /* 4-window rests: a moving window, a skipped one, 2 averaged */
    still_start(&s);
    int16_t v[STILL_CHANNELS];
    uint32_t seed = 5;
    uint8_t poses = 0, at_bias = 1;
    for (uint16_t i = 0; i < 300; i++) {
        flat(v, 1310, &seed);
        poses += (still_feed(v) & STILL_EV_POSE) != 0;
    }
    check(poses == 1, TCV_STR("still: the twist at the start is a pose"));
    for (uint8_t m = 0; m < 12; m++) {
        int32_t peak = 131L * (30 + (37 * m) % 40);
        for (uint8_t i = 0; i < 150; i++) {
            int32_t up = i < 100 ? 0 : i < 125 ? i - 100 : 150 - i; /* 0..25..0 */
            flat(v, (int16_t)(peak * up / 25), &seed);
            if (still_feed(v) & STILL_EV_POSE) {
                poses++;
                /* a rest: the gyro's mean at the bias within 2 counts, the turn not in it */
                int32_t n = still_pose()->n, gz = still_pose()->sum[5];
                if (i < 100 && (gz - 25 * n > 2 * n || 25 * n - gz > 2 * n)) at_bias = 0;
                if (i >= 100) at_bias = 0;
            }
        }
    }
    put_int(poses);
    tcv_puts(TCV_STR(" poses after a twist at the start\n"));
    check(poses >= 10 && at_bias, TCV_STR("still: the twist is not the gyro bias"));
}

static void still_rule(void)
{
    /* the detector the library shares with the firmware: a board held still gives one pose of
     * window x hold_windows samples, a move and a new still pose give the next */
    struct still_settings s;
    still_defaults(&s);
    s.holdoff_ms = 0;
    still_start(&s);
    int16_t v[STILL_CHANNELS] = {100, -200, 16384, 5, -3, 2, -1500};
    uint8_t poses = 0;
    for (uint16_t i = 0; i < 400; i++) {
        if (still_feed(v) & STILL_EV_POSE) poses++;
    }
    check(poses == 1 && still_pose()->n == 100 && still_pose()->sum[2] == 1638400L,
          TCV_STR("still: one pose"));
    v[2] = 0;
    v[0] = 16384;
    for (uint16_t i = 0; i < 400; i++) {
        if (still_feed(v) & STILL_EV_POSE) poses++;
    }
    check(poses == 2 && still_pose()->index == 1 && still_pose()->sum[0] == 1638400L,
          TCV_STR("still: the next pose after a move"));
    still_twist_first();
    tcv_puts(TCV_STR("still: done\n"));
}

#endif /* TCV_UNITS */

#if TCV_VECTORS
static void costs(void)
{
    if (!tcv_clock_what[0]) return;
    tcv_puts(TCV_STR("cost globe84 ("));
    tcv_puts(tcv_clock_what);
    tcv_puts(TCV_STR("): descent "));
    put_int((int32_t)tcv_clock_scale(cost_descent));
    tcv_puts(TCV_STR(" axis "));
    put_int((int32_t)tcv_clock_scale(cost_axis));
#if TC_FIT_MAX_P == 9
    tcv_puts(TCV_STR(" full "));
    put_int((int32_t)tcv_clock_scale(cost_full));
#endif
    tcv_putc('\n');
}
#endif

int main(void)
{
    tcv_init();
    tcv_puts(TCV_STR("triaxcal C library: "));
    tcv_puts(TC_DOUBLE ? TCV_STR("double") : TCV_STR("float"));
    tcv_puts(TCV_STR(", TC_FIT_MAX_P "));
    put_int(TC_FIT_MAX_P);
    tcv_putc('\n');
#if TCV_VECTORS
    against_the_core();
    costs();
#endif
#if TCV_UNITS
    refusals();
    apply_and_round();
    store();
    pose_buffer();
    still_rule();
#endif
    tcv_puts(TCV_STR("RESULT "));
    put_int(checks);
    tcv_puts(TCV_STR(" checks, "));
    put_int(failures);
    tcv_puts(TCV_STR(" failures\n"));
    tcv_exit(failures);
    return 0;
}
