/* The calibration record a board keeps in non-volatile storage (EEPROM on the ATmega328P),
 * and sends to the host in a 'K' frame (firmware/README.md). TC_STORE_BYTES bytes, integers
 * and IEEE-754 binary32 floats little-endian:
 *
 *   0   'T' 'C'          magic
 *   2   version u8       TC_STORE_VERSION (1)
 *   3   sensor u8        1: accelerometer
 *   4   model u8         TC_MODEL_AXIS (6), TC_MODEL_FULL (9), 0 other (written by the host)
 *   5   origin u8        1: fitted on the board, 2: written by the host
 *   6   n u16            poses (readings) fitted; 0 when unknown
 *   8   warnings u16     TC_WARN_* bits of the fit
 *   10  radius f32       magnitude of calibrated readings, in calibrated units
 *   14  offset 3 x f32   raw units (counts)
 *   26  matrix 9 x f32   row-major; calibrated = matrix (raw - offset): the matrix multiplies,
 *                        calibrated units per raw unit
 *   62  rms f32          RMS of |calibrated| - radius over the poses, calibrated units
 *   66  spread f32       smallest eigenvalue of mean(d d^T) of the calibrated directions
 *   70  crc u16          CRC-16/CCITT-FALSE (crc16.h) of bytes 0..69
 *
 * The board's calibrated units are counts at the sensor's nominal scale: radius 16384 for an
 * MPU-6050 at +-2 g, i.e. calibrated counts / 16384 = g.
 */
#ifndef TRIAXCAL_TC_STORE_H
#define TRIAXCAL_TC_STORE_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define TC_STORE_BYTES 72
#define TC_STORE_VERSION 1
#define TC_STORE_SENSOR_ACCEL 1
#define TC_STORE_ORIGIN_BOARD 1
#define TC_STORE_ORIGIN_HOST 2

struct tc_record {
    uint8_t sensor, model, origin;
    uint16_t n;
    uint16_t warnings;
    float radius;
    float offset[3];
    float matrix[3][3];
    float rms;
    float spread;
};

/* What tc_store_unpack found. */
enum tc_store_status {
    TC_STORE_OK = 0,
    TC_STORE_ABSENT = 1,  /* never written: every byte 0xFF (erased EEPROM) or 0x00 */
    TC_STORE_CORRUPT = 2, /* wrong magic or CRC */
    TC_STORE_VERSION_UNKNOWN = 3, /* a newer record than this firmware reads */
    TC_STORE_INVALID = 4  /* intact, but unusable values (non-finite, radius <= 0, singular) */
};

/* The record's bytes, with magic, version and CRC. */
void tc_store_pack(const struct tc_record *r, uint8_t out[TC_STORE_BYTES]);
/* Check and read a record; r holds it when TC_STORE_OK (and is undefined otherwise). */
uint8_t tc_store_unpack(const uint8_t in[TC_STORE_BYTES], struct tc_record *r);
/* The float32 (little-endian) at p: read single fields of a stored record. */
float tc_store_f32(const uint8_t *p);
#define TC_STORE_AT_OFFSET 14 /* byte offset of the offsets, then the matrix at 26 */
#define TC_STORE_AT_MATRIX 26
/* The checks of tc_store_unpack on the values alone (TC_STORE_OK or TC_STORE_INVALID). */
uint8_t tc_store_check(const struct tc_record *r);

#ifdef __cplusplus
}
#endif

#endif
