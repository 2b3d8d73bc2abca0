/* Non-volatile storage for the calibration record (board_cal.c). The MPU-6050 build keeps it
 * in the ATmega328P's EEPROM (avr-libc <avr/eeprom.h>, at NV_RECORD_ADDR; it survives a reset
 * and a power cycle). QEMU's arduino-uno machine models no EEPROM (its registers are
 * unimplemented devices), so the simulated build backs the same interface with a memory
 * image: a record there lasts until QEMU stops, and a board starts with none. */
#ifndef TRIAXCAL_NVSTORE_H
#define TRIAXCAL_NVSTORE_H

#include <stdint.h>

#include "triaxcal_config.h"

#define NV_RECORD_ADDR 0 /* EEPROM address of the record (TC_STORE_BYTES bytes) */

void nv_read(uint16_t addr, uint8_t *dst, uint8_t n);
void nv_write(uint16_t addr, const uint8_t *src, uint8_t n); /* only bytes that change */
#if SIMULATED
void nv_damage(uint16_t addr); /* flip a bit of the image (tests: a corrupt record) */
#endif

#endif
