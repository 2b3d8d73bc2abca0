/* The buzzer on PB0 (Arduino D8): a beep is a 500 Hz square wave made by toggling the pin from
 * the 1 kHz Timer1 tick (writing 1 to PINB0 toggles PORTB0), so a passive piezo sounds, and
 * an active buzzer module (which has its own oscillator) sounds too, gated at 500 Hz. A beep
 * of N ms is N toggles and leaves the pin low. */
#ifndef TRIAXCAL_BUZZER_H
#define TRIAXCAL_BUZZER_H

#include <stdint.h>

void buzzer_init(void);           /* PB0 output, low */
void buzzer_beep(uint8_t ms);     /* start a beep (0: none); a beep in progress is restarted */
void buzzer_tick(void);           /* call from the 1 kHz timer interrupt */
uint16_t buzzer_beeps(void);      /* beeps started since boot */

#endif
