/* triaxcal firmware for the ATmega328P (Arduino Uno): an MPU-6050 (or, with SIMULATED=1,
 * the simulated sensor) served over USART0 at 115200 baud in the protocols of protocol.h.
 * Boots in polled mode: '!' asks for one legacy binary frame; 'B', 'F', 'T', 'R' stream at
 * 100 records per second; 'S' detects still poses on the board and sends one framed record
 * per pose, beeping the buzzer on PB0 (still.h, buzzer.h), and after the 84th pose fits,
 * stores and applies the accelerometer's calibration (board_cal.h); 'P' stops. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "board_cal.h"
#include "buzzer.h"
#include "protocol.h"
#include "sensor.h"
#include "still.h"
#include "triaxcal_config.h"
#include "uart.h"

static volatile uint16_t ms; /* free-running milliseconds from Timer1 */

ISR(TIMER1_COMPA_vect)
{
    ms++;
    buzzer_tick();
}

static uint16_t millis16(void)
{
    uint8_t sreg = SREG;
    cli();
    uint16_t now = ms;
    SREG = sreg;
    return now;
}

static void timer1_init(void)
{
    /* CTC, prescaler 64: 16 MHz / 64 / 250 = 1 kHz. Timer1 (16-bit) is also the timer that
     * QEMU's arduino-uno machine emulates. */
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);
    OCR1A = (uint16_t)(F_CPU / 64UL / 1000UL - 1);
    TIMSK1 = _BV(OCIE1A);
}

static void sample_and(uint8_t how)
{
    int16_t v[TRIAXCAL_CHANNELS] = {0};
    if (sensor_read(v)) {
        for (uint8_t i = 0; i < TRIAXCAL_CHANNELS; i++) v[i] = 0; /* keep the framing */
    } else {
        cal_apply(v); /* calibrated accelerometer counts, when switched on */
    }
    if (how == PROTO_REQUEST) {
        proto_send_binary(v, TRIAXCAL_CHANNELS);
    } else {
        proto_send_stream(v, TRIAXCAL_CHANNELS);
    }
}

static uint16_t last_status;

/* The stored record in a 'K' frame; flags says why it is sent (PROTO_K_*). */
static void report(uint8_t flags)
{
    uint8_t rec[TC_STORE_BYTES];
    uint8_t st = cal_stored(rec);
    proto_send_record(st, (uint8_t)(flags | (cal_applied() ? PROTO_K_APPLIED : 0)), rec);
}

/* The board's fit of the poses it holds: a 'Q' frame, then the record. */
static void fit_now(void)
{
    struct proto_quality q;
    cal_compute(&q);
    proto_send_quality(&q);
    report(PROTO_K_FITTED);
}

/* A write packet: store its record if it is good; answer with what is stored now. */
static void write_record(void)
{
    uint8_t st = cal_write(proto_record_packet());
    uint8_t rec[TC_STORE_BYTES];
    cal_stored(rec);
    proto_send_record(st, (uint8_t)((st ? PROTO_K_WRITE_REFUSED : PROTO_K_WRITTEN) |
                                    (cal_applied() ? PROTO_K_APPLIED : 0)),
                      rec);
}

static void command(uint8_t c)
{
    switch (c) {
    case PROTO_CAL_COMPUTE: fit_now(); return;
    case PROTO_CAL_APPLY: cal_set_apply(1); break;
    case PROTO_CAL_RAW: cal_set_apply(0); break;
#if SIMULATED
    case PROTO_CAL_DAMAGE: cal_damage(); break;
#endif
    default: break; /* PROTO_CAL_REPORT */
    }
    report(PROTO_K_REPORT);
}

static void start_poses(uint16_t now)
{
    cal_start();
    still_start(proto_pose_settings());
    proto_send_settings(1, still_settings());
    last_status = now;
}

/* One sample of the still-pose mode: a pose frame and a beep when a pose is registered, a
 * status frame after a window at most every STILL_STATUS_MS (and after each pose). */
static void pose_step(uint16_t now)
{
    int16_t v[TRIAXCAL_CHANNELS];
    if (sensor_read(v)) {
        still_break(); /* a missing sample is never averaged into a pose */
        return;
    }
    uint8_t ev = still_feed(v);
    if (ev & STILL_EV_POSE) {
        proto_send_pose(still_pose(), TRIAXCAL_CHANNELS);
        buzzer_beep(still_settings()->beep_ms);
        if (cal_pose(still_pose())) fit_now(); /* the 84th pose: the sphere-centre method's program ends */
    }
    if ((ev & STILL_EV_POSE) ||
        ((ev & STILL_EV_WINDOW) && (uint16_t)(now - last_status) >= STILL_STATUS_MS)) {
        last_status = now;
        proto_send_status(still_status());
    }
}

int main(void)
{
    uart_init(TRIAXCAL_BAUD);
    timer1_init();
    buzzer_init();
    proto_set_writer(uart_putc);
    sei();
    sensor_init();
    cal_init();

    uint16_t last = millis16();
    for (;;) {
        int16_t c;
        while ((c = uart_getc()) >= 0) {
            enum proto_event ev = proto_feed((uint8_t)c, millis16());
            if (ev == PROTO_EV_REQUEST) {
                sample_and(PROTO_REQUEST);
            } else if (ev == PROTO_EV_MODE) {
#if SIMULATED
                sim_select_script(proto_mode() == PROTO_MODE_POSES);
#endif
                if (proto_mode() == PROTO_MODE_POSES) start_poses(millis16());
            } else if (ev == PROTO_EV_SETTINGS && proto_mode() == PROTO_MODE_POSES) {
                start_poses(millis16()); /* new settings take effect at once */
            } else if (ev == PROTO_EV_COMMAND) {
                command(proto_command());
            } else if (ev == PROTO_EV_RECORD) {
                write_record();
            }
        }
        uint16_t now = millis16();
        uint8_t mode = proto_mode();
        if (mode == PROTO_MODE_POSES) {
            if ((uint16_t)(now - last) >= still_settings()->period_ms) {
                last = now;
                pose_step(now);
            }
        } else if (mode != PROTO_MODE_POLLED &&
                   (uint16_t)(now - last) >= TRIAXCAL_STREAM_PERIOD_MS) {
            last = now;
            sample_and(0);
        }
    }
}
