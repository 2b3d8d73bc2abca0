/* Build options. The Makefile passes -DSIMULATED=1 for the simulated variant; an Arduino
 * sketch build edits the default below. */
#ifndef TRIAXCAL_CONFIG_H
#define TRIAXCAL_CONFIG_H

#ifndef SIMULATED
#define SIMULATED 0 /* 1: replace the MPU-6050 with the simulated sensor of sim_sensor.c */
#endif

#define TRIAXCAL_CHANNELS 7        /* ax ay az gx gy gz temp, int16 counts */
#define TRIAXCAL_BAUD 115200UL
#define TRIAXCAL_STREAM_PERIOD_MS 10 /* 100 records per second in the streaming modes */

#endif
