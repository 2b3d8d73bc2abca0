/* The sensor behind the protocol: an MPU-6050 over TWI, or the simulated one (SIMULATED=1). */
#ifndef TRIAXCAL_SENSOR_H
#define TRIAXCAL_SENSOR_H

#include <stdint.h>

#include "triaxcal_config.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Wake and configure the sensor (+-2 g, +-250 deg/s); 0 on success. */
uint8_t sensor_init(void);
/* Read one sample as int16 counts in the order ax ay az gx gy gz temp; 0 on success. */
uint8_t sensor_read(int16_t out[7]);

#if SIMULATED
/* The simulated sensor's script (sim_truth.h): 0 the quick globe (SIM_SAMPLES_PER_POSE still
 * samples per pose, going on where it was), 1 the globe with moves, from its first pose. */
void sim_select_script(uint8_t moving);
#endif

#ifdef __cplusplus
}
#endif

#endif
