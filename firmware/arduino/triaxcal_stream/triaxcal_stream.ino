// triaxcal_stream: the triaxcal firmware as an Arduino sketch (Uno / Nano, ATmega328P).
//
// It reuses the firmware's own protocol code. Before opening the sketch, copy the shared
// files next to it (they are not kept in git here, so there is one copy to edit):
//
//     make -C firmware arduino          # copies src/protocol.[ch], still.[ch], cobs.[ch],
//                                       # crc16.[ch], sensor.h, mpu6050.c, sim_sensor.c,
//                                       # sim_truth.h, triaxcal_config.h into this folder
//
// (or symlink them: ln -s ../../src/protocol.c . and so on). Then build and upload with the
// Arduino IDE or `arduino-cli compile --upload -b arduino:avr:uno -p /dev/ttyACM0 .`.
// For a board with no sensor, set SIMULATED to 1 in the copied triaxcal_config.h.
//
// Wiring: MPU-6050 SDA -> A4, SCL -> A5, VCC -> 5V (GY-521 board) or 3.3V, GND, AD0 low.
// Buzzer (still-pose mode): D8 (PB0) to a piezo or buzzer module, other side to GND.
// Serial: 115200 baud. Boots polled: '!' returns one legacy binary frame; 'B' 'F' 'T' 'R'
// stream legacy binary / framed / text / Raw: at 100 records per second; 'S' finds still
// poses on the board and sends one framed record per pose, with a beep (firmware/README.md);
// 'P' stops. A MotionCal calibration packet is answered with Cal1:/Cal2: lines, a settings
// packet for the still-pose mode with a 'C' frame.

#include "triaxcal_config.h"
#include "protocol.h"
#include "sensor.h"
#include "still.h"

static const uint8_t BUZZER_PIN = 8;  // PB0, as in the avr-libc build
static const unsigned int BEEP_HZ = 2000;  // tone(): a square wave on Timer2

static unsigned long last_ms;
static unsigned long last_status_ms;

static void serial_put(uint8_t byte) { Serial.write(byte); }

static void send_sample(bool requested)
{
    int16_t v[TRIAXCAL_CHANNELS] = {0};
    if (sensor_read(v)) {
        for (uint8_t i = 0; i < TRIAXCAL_CHANNELS; i++) v[i] = 0;  // keep the framing
    }
    if (requested) {
        proto_send_binary(v, TRIAXCAL_CHANNELS);
    } else {
        proto_send_stream(v, TRIAXCAL_CHANNELS);
    }
}

static void start_poses()
{
    still_start(proto_pose_settings());
    proto_send_settings(1, still_settings());
    last_status_ms = millis();
}

// One sample of the still-pose mode (as pose_step() in src/main.c).
static void pose_step()
{
    int16_t v[TRIAXCAL_CHANNELS];
    if (sensor_read(v)) {
        still_break();  // a missing sample is never averaged into a pose
        return;
    }
    uint8_t ev = still_feed(v);
    if (ev & STILL_EV_POSE) {
        proto_send_pose(still_pose(), TRIAXCAL_CHANNELS);
        uint8_t ms = still_settings()->beep_ms;
        if (ms) tone(BUZZER_PIN, BEEP_HZ, ms);
    }
    unsigned long now = millis();
    if ((ev & STILL_EV_POSE) ||
        ((ev & STILL_EV_WINDOW) && now - last_status_ms >= STILL_STATUS_MS)) {
        last_status_ms = now;
        proto_send_status(still_status());
    }
}

void setup()
{
    Serial.begin(TRIAXCAL_BAUD);
    proto_set_writer(serial_put);
    pinMode(BUZZER_PIN, OUTPUT);
    digitalWrite(BUZZER_PIN, LOW);
    sensor_init();  // uses the TWI registers directly; no Wire library needed
    last_ms = millis();
}

void loop()
{
    while (Serial.available() > 0) {
        uint8_t byte = (uint8_t)Serial.read();
        enum proto_event ev = proto_feed(byte, (uint16_t)millis());
        if (ev == PROTO_EV_REQUEST) {
            send_sample(true);
        } else if (ev == PROTO_EV_MODE) {
#if SIMULATED
            sim_select_script(proto_mode() == PROTO_MODE_POSES);
#endif
            if (proto_mode() == PROTO_MODE_POSES) start_poses();
        } else if (ev == PROTO_EV_SETTINGS && proto_mode() == PROTO_MODE_POSES) {
            start_poses();
        }
    }
    if (proto_mode() == PROTO_MODE_POSES) {
        if (millis() - last_ms >= still_settings()->period_ms) {
            last_ms = millis();
            pose_step();
        }
    } else if (proto_mode() != PROTO_MODE_POLLED &&
               millis() - last_ms >= TRIAXCAL_STREAM_PERIOD_MS) {
        last_ms = millis();
        send_sample(false);
    }
}
