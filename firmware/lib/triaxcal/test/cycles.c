/* The cost of the search and the fits on the ATmega328P, in CPU cycles: the globe of the
 * vectors (84 poses) fitted once each, timed with Timer1 at the CPU clock. Built with
 * TCV_AVR_CYCLES=1 for simavr (cycle-accurate; `make cycles-avr`): QEMU's AVR machine runs
 * its timers on the host's clock. */
#include <string.h>

#include "tcv.h"

#define TCV_STORE PROGMEM
#include "vectors.h"

static tc_real pts[TCV_MAXN][3];
static struct tcv_case cs;

static void put_u(uint32_t v)
{
    char b[11];
    uint8_t n = 0;
    do {
        b[n++] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v);
    while (n) tcv_putc(b[--n]);
}

static void report(const char *what, uint32_t ticks, int8_t code)
{
    tcv_puts(what);
    put_u(tcv_clock_scale(ticks));
    tcv_puts(code ? TCV_STR(" (refused)\n") : TCV_STR("\n"));
}

int main(void)
{
    tcv_init();
    memcpy_P(&cs, &TCV_CASES[0], sizeof cs);
    memcpy_P(pts, TCV_POINTS[cs.first], sizeof(tc_real) * 3u * cs.n);
    const tc_real(*p)[3] = (const tc_real(*)[3])pts;
    struct tc_descent_options o;
    struct tc_descent d;
    struct tc_fit_options fo;
    struct tc_fit f;
    tc_descent_defaults(&o);
    uint32_t t0 = tcv_clock();
    int8_t code = tc_descend_center(p, cs.n, cs.radius, &o, &d);
    report(TCV_STR("cycles descent "), tcv_clock() - t0, code);
    tc_fit_defaults(&fo, TC_MODEL_AXIS, cs.radius);
    t0 = tcv_clock();
    code = tc_fit(p, cs.n, &fo, &f);
    report(TCV_STR("cycles axis "), tcv_clock() - t0, code);
    tc_fit_defaults(&fo, TC_MODEL_FULL, cs.radius);
    t0 = tcv_clock();
    code = tc_fit(p, cs.n, &fo, &f);
    report(TCV_STR("cycles full "), tcv_clock() - t0, code);
    tcv_puts(TCV_STR("RESULT 0 checks, 0 failures\n"));
    tcv_exit(0);
    return 0;
}
