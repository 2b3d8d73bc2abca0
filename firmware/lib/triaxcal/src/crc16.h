/* CRC-16 variants used on the wire (see firmware/README.md). */
#ifndef TRIAXCAL_CRC16_H
#define TRIAXCAL_CRC16_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor (framed protocol). */
uint16_t crc16_ccitt(const uint8_t *data, uint16_t len);
/* CRC-16/MODBUS: poly 0xA001 reflected, init 0xFFFF (MotionCal calibration packet). */
uint16_t crc16_modbus(const uint8_t *data, uint16_t len);

#ifdef __cplusplus
}
#endif

#endif
