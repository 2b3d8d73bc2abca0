/* The test program on an ATmega328P (qemu-system-avr -machine arduino-uno): USART0 at
 * 115200 baud, polled, both ways (the vectors come in, the report goes out); Timer1 at the
 * CPU clock with its overflows counted. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>

#include "tcv.h"

/* QEMU's AVR machine takes no -icount ("Bad icount read" in 7.2): its timers then run on
 * the host's clock and count nothing worth reporting. TCV_AVR_CYCLES=1 builds the program
 * for a cycle-accurate simulator (simavr), where Timer1 counts the CPU's cycles. */
#if defined(TCV_AVR_CYCLES) && TCV_AVR_CYCLES
const char tcv_clock_what[] = "cycles at 16 MHz, Timer1";
#else
const char tcv_clock_what[] = "";
#endif

static volatile uint16_t overflows;

ISR(TIMER1_OVF_vect) { overflows++; }

void tcv_init(void)
{
    UBRR0H = 0;
    UBRR0L = 16; /* 115200 baud with U2X at 16 MHz */
    UCSR0A = _BV(U2X0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(TXEN0) | _BV(RXEN0);
    TCCR1A = 0;
    TCCR1B = _BV(CS10); /* normal mode, no prescaler */
    TIMSK1 = _BV(TOIE1);
    sei();
}

void tcv_putc(char c)
{
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = (uint8_t)c;
}

void tcv_puts(const char *s)
{
    char c;
    while ((c = (char)pgm_read_byte(s++))) tcv_putc(c);
}

/* The vectors arrive on the serial line (vecdump.c writes them; QEMU hands the guest one
 * byte at a time, when the receive register is free, so nothing is lost). */
static uint8_t getb(void)
{
    while (!(UCSR0A & _BV(RXC0))) {
    }
    return UDR0;
}

static void get(void *dst, uint16_t n)
{
    uint8_t *p = (uint8_t *)dst;
    while (n--) *p++ = getb();
}

static uint8_t ncases = 0xFF, next_case;

uint8_t tcv_ncases(void)
{
    if (ncases == 0xFF) ncases = getb();
    return ncases;
}

void tcv_case(uint8_t c, struct tcv_case *cs, tc_real (*pts)[3])
{
    tcv_ncases();
    while (next_case <= c && next_case < ncases) { /* in order, each once */
        get(cs, sizeof *cs);
        get(pts, (uint16_t)(sizeof(tc_real) * 3u * cs->n));
        next_case++;
    }
}

uint32_t tcv_clock(void)
{
    uint8_t sreg = SREG;
    cli();
    uint16_t lo = TCNT1, hi = overflows;
    if ((TIFR1 & _BV(TOV1)) && lo < 0x8000) hi++; /* an overflow not yet counted */
    SREG = sreg;
    return ((uint32_t)hi << 16) | lo;
}

uint32_t tcv_clock_scale(uint32_t ticks) { return ticks; }

void tcv_exit(int failures)
{
    (void)failures;
    while (!(UCSR0A & _BV(TXC0)) && (UCSR0B & _BV(TXEN0))) {
    }
    cli();
    for (;;) sleep_cpu(); /* the runner stops QEMU when it has seen the RESULT line */
}
