#include "cobs.h"

uint16_t cobs_encode(const uint8_t *src, uint16_t len, uint8_t *dst)
{
    uint16_t out = 1;      /* next free byte in dst */
    uint16_t code_at = 0;  /* where the current block's code byte goes */
    uint8_t code = 1;
    for (uint16_t i = 0; i < len; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = src[i];
            if (++code == 0xFF) {
                dst[code_at] = code;
                code_at = out++;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    return out;
}
