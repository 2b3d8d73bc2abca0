// triaxcal_stream: the triaxcal firmware as an Arduino sketch (Uno / Nano, ATmega328P).
//
// It reuses the firmware's own protocol code. Before opening the sketch, copy the shared
// files next to it (they are not kept in git here, so there is one copy to edit):
//
//     make -C firmware arduino          # copies src/protocol.[ch], cobs.[ch], crc16.[ch],
//                                       # sensor.h, mpu6050.c, sim_sensor.c, sim_truth.h,
//                                       # triaxcal_config.h into this folder
//
// (or symlink them: ln -s ../../src/protocol.c . and so on). Then build and upload with the
// Arduino IDE or `arduino-cli compile --upload -b arduino:avr:uno -p /dev/ttyACM0 .`.
// For a board with no sensor, set SIMULATED to 1 in the copied triaxcal_config.h.
//
// Wiring: MPU-6050 SDA -> A4, SCL -> A5, VCC -> 5V (GY-521 board) or 3.3V, GND, AD0 low.
// Serial: 115200 baud. Boots polled: '!' returns one legacy binary frame; 'B' 'F' 'T' 'R'
// stream legacy binary / framed / text / Raw: at 100 records per second; 'P' stops.
// A MotionCal calibration packet is answered with Cal1:/Cal2: lines.

#include "triaxcal_config.h"
#include "protocol.h"
#include "sensor.h"

static unsigned long last_ms;

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

void setup()
{
    Serial.begin(TRIAXCAL_BAUD);
    proto_set_writer(serial_put);
    sensor_init();  // uses the TWI registers directly; no Wire library needed
    last_ms = millis();
}

void loop()
{
    while (Serial.available() > 0) {
        uint8_t byte = (uint8_t)Serial.read();
        if (proto_feed(byte, (uint16_t)millis()) == PROTO_EV_REQUEST) send_sample(true);
    }
    if (proto_mode() != PROTO_MODE_POLLED && millis() - last_ms >= TRIAXCAL_STREAM_PERIOD_MS) {
        last_ms = millis();
        send_sample(false);
    }
}
