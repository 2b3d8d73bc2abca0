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
 * The board's own calibration (board_cal.h): 'c' fits the poses collected now, 'K' reports
 * the stored record, 'A' / 'a' calibrated / raw accelerometer counts in the streams, a
 * 74-byte write packet ('w', '1', the record of tc_store.h, which carries its own CRC) stores
 * a host's calibration; answers are 'Q' (the fit) and 'K' (the record) frames.
 */
#ifndef TRIAXCAL_PROTOCOL_H
#define TRIAXCAL_PROTOCOL_H

#include <stdint.h>

#include "still.h"
#include "tc_store.h"
#include "triaxcal_config.h"

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
#define PROTO_CAL_COMPUTE 'c' /* fit the poses collected so far (board_cal.h) */
#define PROTO_CAL_REPORT 'K'  /* send the stored calibration record */
#define PROTO_CAL_APPLY 'A'   /* calibrated accelerometer counts in the streams */
#define PROTO_CAL_RAW 'a'     /* raw counts in the streams (the default at boot) */
#if SIMULATED
#define PROTO_CAL_DAMAGE 'X' /* simulated build only: damage the stored record (tests) */
#endif

#define PROTO_MAX_CHANNELS 16
#define MOTIONCAL_PACKET_LEN 68
#define MOTIONCAL_TIMEOUT_MS 250 /* a packet cut short is given up after this long */
#define PROTO_SETTINGS_START 's'
#define PROTO_SETTINGS_VERSION '1'
#define PROTO_SETTINGS_PACKET_LEN (2 + STILL_SETTINGS_BYTES + 2)
#define PROTO_RECORD_START 'w'
#define PROTO_RECORD_VERSION '1'
#define PROTO_RECORD_PACKET_LEN (2 + TC_STORE_BYTES)

/* Frame types of the still-pose mode (the byte after seq). */
#define PROTO_FRAME_POSE 'P'     /* index u16, n u16, K int32 sums */
#define PROTO_FRAME_STATUS 'W'   /* flags, run, poses u16, accel mean int16 x3, rate int16 x3 */
#define PROTO_FRAME_SETTINGS 'C' /* accepted u8, version u8, the settings' 10 bytes */
#define PROTO_FRAME_RECORD 'K'   /* status u8, flags u8, the stored record (tc_store.h) */
#define PROTO_FRAME_QUALITY 'Q'  /* the board's fit: struct proto_quality */

/* Flags of a 'K' frame: bit 0 the streams are calibrated; bits 4-5 why it was sent. */
#define PROTO_K_APPLIED 0x01
#define PROTO_K_REPORT 0x00        /* in answer to 'K', 'A' or 'a' */
#define PROTO_K_FITTED 0x10        /* after a fit on the board */
#define PROTO_K_WRITTEN 0x20       /* a write packet was stored */
#define PROTO_K_WRITE_REFUSED 0x30 /* a write packet was refused: status says why; the record
                                    * is the one kept */

/* What proto_feed() saw. */
enum proto_event {
    PROTO_EV_NONE = 0,
    PROTO_EV_REQUEST, /* '!': send one legacy binary frame now */
    PROTO_EV_MODE,    /* a mode byte: proto_mode() has the new mode */
    PROTO_EV_CAL,     /* a valid MotionCal packet: proto_cal() has it; Cal1/Cal2 were sent */
    PROTO_EV_SETTINGS, /* valid pose settings: proto_pose_settings() has them; 'C' was sent */
    PROTO_EV_RECORD,   /* a write packet: proto_record_packet() has the record's bytes */
    PROTO_EV_COMMAND   /* a calibration command: proto_command() has its byte */
};

/* The 'Q' frame: what the board's fit gave (board_cal.h). */
struct proto_quality {
    int8_t code;         /* enum tc_code of the fit: 0 fitted (and stored) */
    int8_t descent_code; /* enum tc_code of the sphere-centre method's centre search */
    uint16_t warnings;   /* TC_WARN_* */
    uint16_t n;          /* poses fitted */
    uint8_t iterations;  /* passes of the fit */
    uint16_t descent_iterations;
    float center[3];     /* the sphere-centre method's centre (raw counts) */
    float rms;           /* RMS of |calibrated| - radius, calibrated counts */
    float spread;        /* coverage: 1/3 even, below 0.1 a band */
    uint8_t faces[6];    /* poses nearest +X -X +Y -Y +Z -Z */
    uint16_t stack_free; /* bytes of RAM the stack has never reached (0: not measured) */
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
/* The record of the last write packet (TC_STORE_BYTES bytes). */
const uint8_t *proto_record_packet(void);
/* The byte of the last PROTO_EV_COMMAND. */
uint8_t proto_command(void);

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
/* The board's calibration: a 'K' frame with a record's bytes, a 'Q' frame. */
void proto_send_record(uint8_t status, uint8_t flags, const uint8_t record[TC_STORE_BYTES]);
void proto_send_quality(const struct proto_quality *q);

/* Helpers, exposed for tests and other sketches. */
void proto_put_int(int32_t v);
void proto_put_fixed4(float x); /* x with 4 decimals, no printf float support needed */
void proto_put_str(const char *s);

#ifdef __cplusplus
}
#endif

#endif
