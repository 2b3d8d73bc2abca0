/* The sensor behind the protocol: an MPU-6050 over TWI, or the simulated one (SIMULATED=1). */
#ifndef TRIAXCAL_SENSOR_H
#define TRIAXCAL_SENSOR_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Wake and configure the sensor (+-2 g, +-250 deg/s); 0 on success. */
uint8_t sensor_init(void);
/* Read one sample as int16 counts in the order ax ay az gx gy gz temp; 0 on success. */
uint8_t sensor_read(int16_t out[7]);

#ifdef __cplusplus
}
#endif

#endif
