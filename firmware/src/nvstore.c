#include "nvstore.h"

#if SIMULATED

#include <string.h>

#include "tc_store.h"

/* The memory image standing in for the EEPROM (see nvstore.h): zeros, i.e. no record. */
static uint8_t image[NV_RECORD_ADDR + TC_STORE_BYTES];

void nv_read(uint16_t addr, uint8_t *dst, uint8_t n)
{
    if (addr + n <= sizeof image) memcpy(dst, image + addr, n);
}

void nv_write(uint16_t addr, const uint8_t *src, uint8_t n)
{
    if (addr + n <= sizeof image) memcpy(image + addr, src, n);
}

void nv_damage(uint16_t addr)
{
    if (addr < sizeof image) image[addr] ^= 0x04;
}

#else

#include <avr/eeprom.h>

void nv_read(uint16_t addr, uint8_t *dst, uint8_t n)
{
    eeprom_read_block(dst, (const void *)(uintptr_t)addr, n);
}

void nv_write(uint16_t addr, const uint8_t *src, uint8_t n)
{
    eeprom_update_block(src, (void *)(uintptr_t)addr, n); /* spares unchanged cells */
}

#endif
