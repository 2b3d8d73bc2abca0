/* Consistent Overhead Byte Stuffing (encoder only: the device never receives COBS). */
#ifndef TRIAXCAL_COBS_H
#define TRIAXCAL_COBS_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Send the encoding of len bytes of src through put, a byte at a time (no output buffer: the
 * frames of the board's calibration are sent from deep in its stack). The encoding holds no
 * 0x00 byte; the caller sends the 0x00 delimiter. */
void cobs_write(const uint8_t *src, uint16_t len, void (*put)(uint8_t));

#ifdef __cplusplus
}
#endif

#endif
