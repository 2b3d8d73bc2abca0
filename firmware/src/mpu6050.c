/* MPU-6050 over TWI (I2C) at 400 kHz with avr-libc registers: wake it, set +-2 g and
 * +-250 deg/s, read the 14 bytes from ACCEL_XOUT_H (0x3B) and reorder them to
 * ax ay az gx gy gz temp. Every wait has a bound, so a missing sensor gives an error, not a
 * hang. Not built with SIMULATED=1. */
#include "triaxcal_config.h"

#if !SIMULATED

#include <avr/io.h>
#include <util/twi.h>

#include "sensor.h"

#define MPU_ADDR 0x68 /* AD0 low */
#define REG_SMPLRT_DIV 0x19
#define REG_CONFIG 0x1A
#define REG_GYRO_CONFIG 0x1B
#define REG_ACCEL_CONFIG 0x1C
#define REG_ACCEL_XOUT_H 0x3B
#define REG_PWR_MGMT_1 0x6B
#define TWI_SPINS 20000u

static uint8_t twi_wait(void)
{
    uint16_t n = TWI_SPINS;
    while (!(TWCR & _BV(TWINT))) {
        if (!--n) return 1;
    }
    return 0;
}

static uint8_t twi_start(uint8_t addr_rw)
{
    TWCR = _BV(TWINT) | _BV(TWSTA) | _BV(TWEN);
    if (twi_wait()) return 1;
    if (TW_STATUS != TW_START && TW_STATUS != TW_REP_START) return 1;
    TWDR = addr_rw;
    TWCR = _BV(TWINT) | _BV(TWEN);
    if (twi_wait()) return 1;
    return !(TW_STATUS == TW_MT_SLA_ACK || TW_STATUS == TW_MR_SLA_ACK);
}

static uint8_t twi_write(uint8_t b)
{
    TWDR = b;
    TWCR = _BV(TWINT) | _BV(TWEN);
    if (twi_wait()) return 1;
    return TW_STATUS != TW_MT_DATA_ACK;
}

static void twi_stop(void) { TWCR = _BV(TWINT) | _BV(TWSTO) | _BV(TWEN); }

static uint8_t write_reg(uint8_t reg, uint8_t value)
{
    uint8_t err = twi_start((MPU_ADDR << 1) | TW_WRITE) || twi_write(reg) || twi_write(value);
    twi_stop();
    return err;
}

uint8_t sensor_init(void)
{
    TWSR = 0;                             /* prescaler 1 */
    TWBR = (uint8_t)((F_CPU / 400000UL - 16) / 2); /* 400 kHz */
    uint8_t err = write_reg(REG_PWR_MGMT_1, 0x01); /* wake, clock from gyro X PLL */
    err |= write_reg(REG_SMPLRT_DIV, 0x00);
    err |= write_reg(REG_CONFIG, 0x03);           /* DLPF 44 Hz */
    err |= write_reg(REG_GYRO_CONFIG, 0x00);      /* +-250 deg/s: 131 counts per deg/s */
    err |= write_reg(REG_ACCEL_CONFIG, 0x00);     /* +-2 g: 16384 counts per g */
    return err;
}

uint8_t sensor_read(int16_t out[7])
{
    uint8_t raw[14];
    if (twi_start((MPU_ADDR << 1) | TW_WRITE) || twi_write(REG_ACCEL_XOUT_H) ||
        twi_start((MPU_ADDR << 1) | TW_READ)) {
        twi_stop();
        return 1;
    }
    for (uint8_t i = 0; i < 14; i++) {
        TWCR = _BV(TWINT) | _BV(TWEN) | (i < 13 ? _BV(TWEA) : 0);
        if (twi_wait()) {
            twi_stop();
            return 1;
        }
        raw[i] = TWDR;
    }
    twi_stop();
    /* registers: AX AY AZ TEMP GX GY GZ, big-endian; out: ax ay az gx gy gz temp */
    static const uint8_t order[7] = {0, 1, 2, 4, 5, 6, 3};
    for (uint8_t i = 0; i < 7; i++) {
        uint8_t j = (uint8_t)(2 * order[i]);
        out[i] = (int16_t)(((uint16_t)raw[j] << 8) | raw[j + 1]);
    }
    return 0;
}

#else
typedef int mpu6050_unused; /* ISO C forbids an empty translation unit */
#endif
