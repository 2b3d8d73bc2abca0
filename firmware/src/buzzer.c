#include "buzzer.h"

#include <avr/interrupt.h>
#include <avr/io.h>

static volatile uint8_t left;  /* toggles still to make */
static volatile uint8_t level; /* the pin's level, kept here (no read-back needed) */
static uint16_t beeps;

void buzzer_init(void)
{
    PORTB &= (uint8_t)~_BV(PB0);
    DDRB |= _BV(PB0);
    level = 0;
}

void buzzer_beep(uint8_t ms)
{
    if (!ms) return;
    uint8_t sreg = SREG;
    cli();
    /* about ms toggles, an even number from low (an odd one from high) so it ends low */
    uint8_t n = (uint8_t)(ms + (ms & 1u));
    left = (uint8_t)(n + level);
    beeps++;
    SREG = sreg;
}

void buzzer_tick(void)
{
    if (!left) return;
    PINB = _BV(PB0); /* toggle PORTB0 (ATmega48/88/168/328 datasheet, 13.2.2) */
    level ^= 1u;
    left--;
}

uint16_t buzzer_beeps(void) { return beeps; }
