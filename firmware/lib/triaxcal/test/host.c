/* The test program on the host (gcc): stdout, no instruction count (use callgrind). */
#include <stdio.h>
#include <stdlib.h>

#include "tcv.h"

const char tcv_clock_what[] = "";

void tcv_init(void) {}
void tcv_putc(char c) { putchar(c); }
void tcv_puts(const char *s) { fputs(s, stdout); }
uint32_t tcv_clock(void) { return 0; }
uint32_t tcv_clock_scale(uint32_t ticks) { return ticks; }
void tcv_exit(int failures)
{
    fflush(stdout);
    exit(failures ? 1 : 0);
}
