/* USART0 at 115200 baud (U2X), interrupt-driven receive ring, blocking transmit. */
#ifndef TRIAXCAL_UART_H
#define TRIAXCAL_UART_H

#include <stdint.h>

void uart_init(uint32_t baud);
void uart_putc(uint8_t byte);
int16_t uart_getc(void); /* -1 when nothing has arrived */

#endif
