/* triaxcal firmware for the ATmega328P (Arduino Uno): an MPU-6050 (or, with SIMULATED=1,
 * the simulated sensor) served over USART0 at 115200 baud in the protocols of protocol.h.
 * Boots in polled mode: '!' asks for one legacy binary frame; 'B', 'F', 'T', 'R' stream at
 * 100 records per second; 'P' stops streaming. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "protocol.h"
#include "sensor.h"
#include "triaxcal_config.h"
#include "uart.h"

static volatile uint16_t ms; /* free-running milliseconds from Timer1 */

ISR(TIMER1_COMPA_vect) { ms++; }

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
    }
    if (how == PROTO_REQUEST) {
        proto_send_binary(v, TRIAXCAL_CHANNELS);
    } else {
        proto_send_stream(v, TRIAXCAL_CHANNELS);
    }
}

int main(void)
{
    uart_init(TRIAXCAL_BAUD);
    timer1_init();
    proto_set_writer(uart_putc);
    sei();
    sensor_init();

    uint16_t last = millis16();
    for (;;) {
        int16_t c;
        while ((c = uart_getc()) >= 0) {
            if (proto_feed((uint8_t)c, millis16()) == PROTO_EV_REQUEST) {
                sample_and(PROTO_REQUEST);
            }
        }
        uint16_t now = millis16();
        if (proto_mode() != PROTO_MODE_POLLED &&
            (uint16_t)(now - last) >= TRIAXCAL_STREAM_PERIOD_MS) {
            last = now;
            sample_and(0);
        }
    }
}
