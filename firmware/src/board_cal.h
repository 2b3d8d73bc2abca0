/* The board calibrates itself (mode 'S' end to end, the sphere-centre method's sensors_calibrate_program):
 * the accelerometer means of the poses the still detector registers go into a pose buffer
 * (tc_poses) of CAL_POSES; after the 84th pose (or on the command 'c') the board runs
 * the sphere-centre method's centre search and the offset + 3 gains fit of the triaxcal library, stores the
 * fit as a record with version and CRC (tc_store.h) in non-volatile storage (nvstore.h), and
 * from then on applies it to the accelerometer counts of the streams ('A' / 'a' switch it on
 * and off). Calibrated counts are at the nominal scale: CAL_RADIUS counts per g.
 * Hardware-free apart from nvstore.h; the frames are protocol.h's 'Q' and 'K'. */
#ifndef TRIAXCAL_BOARD_CAL_H
#define TRIAXCAL_BOARD_CAL_H

#include <stdint.h>

#include "protocol.h"
#include "still.h"
#include "triaxcal_config.h"

#define CAL_AUTO_POSES 84 /* the sphere-centre method's globe: fit after this many poses */
#ifndef CAL_POSES
/* Poses held (12 bytes of RAM each): the ATmega328P's 2 KB hold 60 beside the protocol, the
 * still detector and the deepest stack of a fit (firmware/README.md). The globe's 84 repeat
 * each pole 12 times; the buffer keeps the 60 that cover the sphere best. */
#define CAL_POSES 60
#endif
#define CAL_RADIUS 16384  /* counts per g at +-2 g: the magnitude calibrated counts have */

/* Read the stored record (at boot); the streams stay raw until 'A' or a fit. */
void cal_init(void);
/* Forget the poses (on entering mode 'S'). */
void cal_start(void);
/* A registered pose; 1 when it was the CAL_AUTO_POSES-th and the fit should run now. */
uint8_t cal_pose(const struct still_pose *pose);
/* Fit the poses held, store the result if it passes, fill q; returns the fit's code, or
 * CAL_ERR_STORAGE when storage did not keep the record. */
#define CAL_ERR_STORAGE (-1)
int8_t cal_compute(struct proto_quality *q);
/* A write packet's record: stored when intact and usable; returns its tc_store_status. */
uint8_t cal_write(const uint8_t record[TC_STORE_BYTES]);
/* Switch the streams to calibrated (1) or raw (0) counts; calibrated needs a good record. */
void cal_set_apply(uint8_t on);
uint8_t cal_applied(void);
/* The stored record as its bytes, and what tc_store_unpack says of them. */
uint8_t cal_stored(uint8_t out[TC_STORE_BYTES]);
/* Replace ax ay az (v[0..2]) by calibrated counts when applying. */
void cal_apply(int16_t *v);
#if SIMULATED
/* Damage the stored record (the command 'X' of the simulated build, for tests). */
void cal_damage(void);
#endif
/* Bytes of RAM between the data and the lowest the stack has reached (0 where unknown). */
uint16_t cal_stack_free(void);

#endif
