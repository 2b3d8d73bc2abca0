/* Writes the test vectors as the byte stream the AVR test program reads from its serial port
 * (avr.c): the number of cases, then per case struct tcv_case as the AVR lays it out (fields
 * in order, no padding, little-endian, TCV_NUM a float32) and its points as float32 triples.
 * Built with TC_DOUBLE=0 on the host: vecdump > vectors.bin. */
#include <stdio.h>
#include <string.h>

#include "tcv.h"

#define TCV_STORE
#include "vectors.h"

#if TC_DOUBLE
#error "vecdump writes float32: build it with TC_DOUBLE=0"
#endif

static void bytes(const void *p, size_t n) { fwrite(p, 1, n, stdout); }

static void le(uint32_t v, uint8_t n)
{
    for (uint8_t i = 0; i < n; i++) {
        putchar((int)(v & 0xFF));
        v >>= 8;
    }
}

static void f32s(const float *v, uint8_t n)
{
    for (uint8_t i = 0; i < n; i++) {
        uint32_t u;
        memcpy(&u, &v[i], 4);
        le(u, 4);
    }
}

static void fit(const struct tcv_fit *f)
{
    le((uint8_t)f->code, 1);
    f32s(f->offset, 3);
    f32s(f->matrix, 9);
    f32s(&f->rms, 1);
    le(f->warnings, 2);
    f32s(f->se, 2);
}

int main(void)
{
    le(TCV_NCASES, 1);
    for (uint8_t c = 0; c < TCV_NCASES; c++) {
        const struct tcv_case *k = &TCV_CASES[c];
        bytes(k->name, sizeof k->name);
        le(k->n, 2);
        le(k->first, 2);
        f32s(&k->radius, 1);
        f32s(k->start, 3);
        f32s(&k->step, 1);
        f32s(&k->min_step, 1);
        f32s(&k->shrink, 1);
        le((uint8_t)k->dcode, 1);
        f32s(k->center, 3);
        f32s(&k->error, 1);
        le(k->iterations, 4);
        le(k->converged, 1);
        fit(&k->axis);
        fit(&k->full);
        f32s(&TCV_POINTS[k->first][0], (uint8_t)(3 * k->n));
    }
    return 0;
}
