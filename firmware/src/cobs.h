/* Consistent Overhead Byte Stuffing (encoder only: the device never receives COBS). */
#ifndef TRIAXCAL_COBS_H
#define TRIAXCAL_COBS_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Encode len bytes of src into dst (room for len + len / 254 + 1 bytes); returns the encoded
 * length. The result holds no 0x00 byte; the caller sends the 0x00 delimiter. */
uint16_t cobs_encode(const uint8_t *src, uint16_t len, uint8_t *dst);

#ifdef __cplusplus
}
#endif

#endif
