/* The test vectors compiled into the program (host, Cortex-M). */
#include <string.h>

#include "tcv.h"

#define TCV_STORE
#include "vectors.h"

uint8_t tcv_ncases(void) { return TCV_NCASES; }

void tcv_case(uint8_t c, struct tcv_case *cs, tc_real (*pts)[3])
{
    *cs = TCV_CASES[c];
    memcpy(pts, TCV_POINTS[cs->first], sizeof(tc_real) * 3u * cs->n);
}
