/* The test program of the C library (test_lib.c): the test vectors' types and what the
 * program needs from the machine it runs on -- host.c (gcc), avr.c (ATmega328P in
 * qemu-system-avr), arm.c (Cortex-M3 in qemu-system-arm). */
#ifndef TCV_H
#define TCV_H

#include <stddef.h>
#include <stdint.h>

#include "triaxcal.h"

#ifdef __AVR__
#include <avr/pgmspace.h>
#define TCV_STR(s) PSTR(s) /* text stays in flash */
#else
#define TCV_STR(s) (s)
#endif

#define TCV_NUM tc_real
#define TCV_MAXN 84 /* points of the largest case */

/* What the core made of a case (vectors.rs): a fit ... */
struct tcv_fit {
    int8_t code; /* enum tc_code */
    TCV_NUM offset[3];
    TCV_NUM matrix[9]; /* row-major */
    TCV_NUM rms;
    uint16_t warnings; /* TC_WARN_* */
    TCV_NUM se[2];     /* largest standard error: offsets, matrix terms (-1: none) */
};

/* ... and a case: its points, the descent's options and result, the two fits. */
struct tcv_case {
    char name[12];
    uint16_t n, first; /* points, and the first of them in TCV_POINTS */
    TCV_NUM radius;
    TCV_NUM start[3], step, min_step, shrink;
    int8_t dcode;
    TCV_NUM center[3], error;
    uint32_t iterations;
    uint8_t converged;
    struct tcv_fit axis, full;
};

void tcv_init(void);
void tcv_putc(char c);
void tcv_puts(const char *s); /* a TCV_STR string */
/* The cases: compiled in (tcv_arrays.c: host, Cortex-M), or sent over the serial line (the
 * AVR, whose flash does not hold them; vecdump.c writes the stream). */
uint8_t tcv_ncases(void);
void tcv_case(uint8_t c, struct tcv_case *cs, tc_real (*pts)[3]);
/* A free-running count for the cost figures, and the count in the unit tcv_clock_what names
 * (tcv_clock_what empty: this platform does not count). */
uint32_t tcv_clock(void);
extern const char tcv_clock_what[];
uint32_t tcv_clock_scale(uint32_t ticks);
void tcv_exit(int failures);

#endif
