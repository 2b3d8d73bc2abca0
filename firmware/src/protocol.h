/* Device side of the triaxcal wire protocols (firmware/README.md), independent of the hardware:
 * every byte goes out through the writer set with proto_set_writer(), every received byte
 * comes in through proto_feed(). Shared by the avr-libc firmware and the Arduino sketch.
 *
 *  legacy binary  K int16 little-endian, then '\n'
 *  framed         COBS(seq, K int16 LE, CRC-16/CCITT-FALSE LE) then 0x00
 *  text           "v0,v1,...\r\n"
 *  Raw:           "Raw:ax,ay,az,gx,gy,gz,mx,my,mz\r\n" at MotionCal's scales
 *  still poses    framed, one frame per pose and status frames (mode 'S', still.h):
 *                 COBS(seq, type, fields, CRC-16/CCITT-FALSE LE) then 0x00, where type is
 *                 'P' pose, 'W' window status or 'C' settings; every such frame has an odd
 *                 number of bytes between seq and CRC, so it never passes for a K-int16 frame
 *
 * Commands: '!' one legacy frame (any mode); 'P' polled (no streaming), 'B', 'F', 'T', 'R'
 * streaming modes; 'S' still-pose mode; a 68-byte MotionCal calibration packet (117, 84,
 * 16 float32 LE, CRC-16/MODBUS LE) is answered with Cal1:/Cal2: lines; a 14-byte settings
 * packet ('s', '1', 10 settings bytes, CRC-16/CCITT-FALSE LE) with a 'C' frame.
 */
#ifndef TRIAXCAL_PROTOCOL_H
#define TRIAXCAL_PROTOCOL_H

#include <stdint.h>

#include "still.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef void (*proto_writer)(uint8_t byte);

#define PROTO_MODE_POLLED 'P'
#define PROTO_MODE_BINARY 'B'
#define PROTO_MODE_FRAMED 'F'
#define PROTO_MODE_TEXT 'T'
#define PROTO_MODE_RAW 'R'
#define PROTO_MODE_POSES 'S'
#define PROTO_REQUEST '!'

#define PROTO_MAX_CHANNELS 16
#define MOTIONCAL_PACKET_LEN 68
#define MOTIONCAL_TIMEOUT_MS 250 /* a packet cut short is given up after this long */
#define PROTO_SETTINGS_START 's'
#define PROTO_SETTINGS_VERSION '1'
#define PROTO_SETTINGS_PACKET_LEN (2 + STILL_SETTINGS_BYTES + 2)

/* Frame types of the still-pose mode (the byte after seq). */
#define PROTO_FRAME_POSE 'P'     /* index u16, n u16, K int32 sums */
#define PROTO_FRAME_STATUS 'W'   /* flags, run, poses u16, accel mean int16 x3, rate int16 x3 */
#define PROTO_FRAME_SETTINGS 'C' /* accepted u8, version u8, the settings' 10 bytes */

/* What proto_feed() saw. */
enum proto_event {
    PROTO_EV_NONE = 0,
    PROTO_EV_REQUEST, /* '!': send one legacy binary frame now */
    PROTO_EV_MODE,    /* a mode byte: proto_mode() has the new mode */
    PROTO_EV_CAL,     /* a valid MotionCal packet: proto_cal() has it; Cal1/Cal2 were sent */
    PROTO_EV_SETTINGS /* valid pose settings: proto_pose_settings() has them; 'C' was sent */
};

/* MotionCal calibration: offsets in the sensor's units as MotionCal sends them. */
struct motioncal {
    float accel[3];   /* accelerometer offsets */
    float gyro[3];    /* gyroscope offsets */
    float mag[3];     /* magnetometer hard iron, uT */
    float field;      /* magnetic field strength, uT */
    float soft[6];    /* soft iron: xx, yy, zz, xy, xz, yz */
};

void proto_set_writer(proto_writer writer);

/* Feed one received byte; now_ms is a free-running millisecond counter (wraps). */
enum proto_event proto_feed(uint8_t byte, uint16_t now_ms);
uint8_t proto_mode(void);
const struct motioncal *proto_cal(void);
/* Settings of the still-pose mode: the defaults until a valid settings packet came. */
const struct still_settings *proto_pose_settings(void);

void proto_send_binary(const int16_t *values, uint8_t k);
void proto_send_framed(const int16_t *values, uint8_t k); /* seq advances per frame */
void proto_send_text(const int16_t *values, uint8_t k);
/* Raw: line from MPU-6050 counts (ax ay az gx gy gz [temp]) at +-2 g and +-250 deg/s:
 * accel / 2 -> 8192 counts/g, gyro * 16 / 131 -> 16 counts/(deg/s), no magnetometer (0). */
void proto_send_raw_mpu(const int16_t *mpu);
/* Send values in the current streaming mode (nothing in polled mode). */
void proto_send_stream(const int16_t *values, uint8_t k);
void proto_send_cal_lines(const struct motioncal *cal);
/* Still-pose mode frames (seq advances per frame, shared with proto_send_framed). */
void proto_send_pose(const struct still_pose *pose, uint8_t k);
void proto_send_status(const struct still_status *st);
void proto_send_settings(uint8_t accepted, const struct still_settings *s);

/* Helpers, exposed for tests and other sketches. */
void proto_put_int(int32_t v);
void proto_put_fixed4(float x); /* x with 4 decimals, no printf float support needed */
void proto_put_str(const char *s);

#ifdef __cplusplus
}
#endif

#endif
