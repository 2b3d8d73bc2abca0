#include "uart.h"

#include <avr/interrupt.h>
#include <avr/io.h>

#define RX_SIZE 128 /* a power of two; holds a whole 68-byte MotionCal packet */

static volatile uint8_t rx_buf[RX_SIZE];
static volatile uint8_t rx_head, rx_tail;

ISR(USART_RX_vect)
{
    uint8_t b = UDR0;
    uint8_t next = (uint8_t)((rx_head + 1) & (RX_SIZE - 1));
    if (next != rx_tail) { /* full: drop the byte */
        rx_buf[rx_head] = b;
        rx_head = next;
    }
}

void uart_init(uint32_t baud)
{
    uint16_t ubrr = (uint16_t)((F_CPU / 8UL + baud / 2) / baud - 1); /* U2X: 16 at 115200 */
    UBRR0H = (uint8_t)(ubrr >> 8);
    UBRR0L = (uint8_t)ubrr;
    UCSR0A = _BV(U2X0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

void uart_putc(uint8_t byte)
{
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = byte;
}

int16_t uart_getc(void)
{
    if (rx_head == rx_tail) return -1;
    uint8_t b = rx_buf[rx_tail];
    rx_tail = (uint8_t)((rx_tail + 1) & (RX_SIZE - 1));
    return b;
}
