#include "cobs.h"

void cobs_write(const uint8_t *src, uint16_t len, void (*put)(uint8_t))
{
    uint16_t i = 0;
    for (;;) {
        /* a block: up to the next 0x00 (or 254 bytes, or the end), after its length code */
        uint16_t j = i;
        while (j < len && src[j] != 0 && j - i < 254) j++;
        put((uint8_t)(j - i + 1));
        for (uint16_t k = i; k < j; k++) put(src[k]);
        if (j == len) {
            if (j - i == 254) put(1); /* a full block at the end: an empty last one follows */
            return;
        }
        i = src[j] == 0 ? j + 1 : j; /* the 0x00 is what the code stands for */
    }
}
