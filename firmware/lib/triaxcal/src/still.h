/* On-board still-pose detection (mode 'S'), the sphere-centre method's window method with the gyroscope added.
 * Hardware-free and integer-only: fed one sample at a time (ax ay az gx gy gz temp counts), it
 * says when a window of samples completed and when a pose was registered.
 *
 * Windows of `window` samples are summed. A window "moved" when
 *   - any accelerometer axis of its mean changed by more than `accel_threshold` counts from
 *     the previous window's mean (the sphere-centre method's rule: 0.07 g = 1147 counts at +-2 g), or
 *   - any gyroscope axis of its mean is more than `gyro_threshold` counts away from the bias
 *     (the gyro's mean over the last steady window): a turn, which the accelerometer cannot see
 *     when it is about the vertical (the 12 twists at each pole of the globe scheme).
 * Until the bias is known (the first windows), a window whose gyro mean changed by at most the
 * threshold from the previous one sets it; it is then the gyro mean of the last window of each
 * registered pose. If the gyro stays off the bias by less than STILL_REANCHOR_MAX thresholds
 * but unchanging for STILL_REANCHOR_WINDOWS windows the accelerometer calls steady (the bias
 * drifted, or was taken while the board turned), that mean becomes the bias (the host's
 * detector, triaxcal.detect, does the same). The first bias is provisional (a board twisted
 * about the vertical from the start is steady to both sensors): it is confirmed when the board
 * rests at it again after a move, and until then STILL_REANCHOR_WINDOWS steady windows at one
 * rate on either side of a move replace it, however far off (still.c says why; the host's
 * detector does the same).
 * After a move, the first steady window is not averaged (it may hold the end of the move);
 * the next `hold_windows` steady windows are, and then the pose is registered: its sums and
 * sample count are sent, the buzzer beeps, and for `holdoff_ms` no pose is averaged (the
 * original method's 2 s to let go of the board). Motion is still watched during the hold-off. A pose is
 * registered once: the next one needs a move since -- the accelerometer's or the gyro's
 * window mean changed by more than its threshold, or the gyro is more than STILL_REANCHOR_MAX
 * thresholds off its bias (a gyro a little off but unchanging is a drift, not a move).
 */
#ifndef TRIAXCAL_STILL_H
#define TRIAXCAL_STILL_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define STILL_CHANNELS 7 /* ax ay az gx gy gz temp */
#define STILL_SETTINGS_VERSION 1
#define STILL_SETTINGS_BYTES 10 /* the wire form of struct still_settings */
#define STILL_REANCHOR_WINDOWS 8
#define STILL_REANCHOR_MAX 16
#define STILL_STATUS_MS 100 /* a status frame at most this often (and after each pose) */

/* Defaults: the sphere-centre method's 0.07 g and 2 s at 100 samples per second. */
#define STILL_DEFAULT_PERIOD_MS 10
#define STILL_DEFAULT_WINDOW 25
#define STILL_DEFAULT_HOLD_WINDOWS 4
#define STILL_DEFAULT_HOLDOFF_MS 2000
#define STILL_DEFAULT_ACCEL_THRESHOLD 1147 /* counts: 0.07 g x 16384 counts/g */
#define STILL_DEFAULT_GYRO_THRESHOLD 393   /* counts: 3 deg/s x 131 counts/(deg/s) */
#define STILL_DEFAULT_BEEP_MS 100

struct still_settings {
    uint8_t period_ms;        /* 1..250: one sample every period_ms */
    uint8_t window;           /* 1..250 samples per window */
    uint8_t hold_windows;     /* 1..250 steady windows averaged into a pose */
    uint16_t holdoff_ms;      /* 0..60000: no pose is averaged for this long after a beep */
    uint16_t accel_threshold; /* 1..32767 counts: largest change of a window mean */
    uint16_t gyro_threshold;  /* 0..32767 counts away from the bias; 0: the gyro takes no part */
    uint8_t beep_ms;          /* 0..250: length of the beep; 0: silent */
};

/* What a window said (still_status()). */
#define STILL_FLAG_MOVED 0x01   /* this window moved */
#define STILL_FLAG_HOLDOFF 0x02 /* inside the hold-off after a beep */
#define STILL_FLAG_WAITING 0x04 /* a pose was registered and the board has not moved since */
#define STILL_FLAG_BIAS 0x08    /* the gyro bias is known */

struct still_status {
    uint8_t flags;
    uint8_t run;      /* steady windows averaged into the pose in progress */
    uint16_t poses;   /* poses registered since the mode started */
    int16_t accel[3]; /* the window's accelerometer mean, counts */
    int16_t rate[3];  /* the window's gyro mean minus the bias, counts (clamped to int16) */
};

struct still_pose {
    uint16_t index; /* 0 for the first pose of the mode */
    uint16_t n;     /* samples averaged */
    int32_t sum[STILL_CHANNELS];
};

/* still_feed() results (bits). */
#define STILL_EV_WINDOW 0x01
#define STILL_EV_POSE 0x02

void still_defaults(struct still_settings *s);
uint8_t still_valid(const struct still_settings *s); /* 1 when every field is in range */
/* Little-endian wire form, STILL_SETTINGS_BYTES bytes (firmware/README.md). */
void still_pack(const struct still_settings *s, uint8_t *out);
void still_unpack(const uint8_t *in, struct still_settings *s);

/* Start (or restart) detecting with these settings (copied). */
void still_start(const struct still_settings *s);
const struct still_settings *still_settings(void);
/* One sample: ax ay az gx gy gz temp counts. */
uint8_t still_feed(const int16_t v[STILL_CHANNELS]);
/* A sample is missing (the sensor did not answer): drop the window, count it as motion. */
void still_break(void);
const struct still_status *still_status(void);
const struct still_pose *still_pose(void);

#ifdef __cplusplus
}
#endif

#endif
