/* The test program on a Cortex-M3 (qemu-system-arm -machine mps2-an385): output and exit by
 * semihosting, SysTick at the CPU clock (25 MHz on the MPS2) with its wraps counted. QEMU
 * does not model the DWT cycle counter; with -icount shift=0 its virtual clock advances 1 ns
 * per instruction, so one SysTick count (40 ns) is 40 instructions. */
#include "tcv.h"

const char tcv_clock_what[] = "instructions, QEMU -icount";

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)

static volatile uint32_t wraps;

void SysTick_Handler(void);
void SysTick_Handler(void) { wraps++; }

static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void tcv_init(void)
{
    SYST_RVR = 0x00FFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 7u; /* processor clock, interrupt, enable */
    while (SYST_CVR == 0) { /* the first reload: from here on every wrap is counted */
    }
}

void tcv_putc(char c) { semihost(0x03, &c); } /* SYS_WRITEC */
void tcv_puts(const char *s) { semihost(0x04, s); } /* SYS_WRITE0 */

uint32_t tcv_clock(void)
{
    uint32_t w, v;
    do {
        w = wraps;
        v = SYST_CVR;
    } while (w != wraps);
    return (w << 24) | (0x00FFFFFFu - v);
}

uint32_t tcv_clock_scale(uint32_t ticks) { return ticks * 40u; }

void tcv_exit(int failures)
{
    /* SYS_EXIT with ADP_Stopped_ApplicationExit: QEMU exits with status 0; any other
     * reason (RunTimeErrorUnknown) with status 1 */
    semihost(0x18, (const void *)(failures ? 0x20023u : 0x20026u));
    for (;;) {
    }
}
