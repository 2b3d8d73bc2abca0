/* Build-time sizes and the number type of the triaxcal C library (triaxcal.h).
 *
 * The library never allocates: its working memory is sized here at compile time, the pose
 * buffer by the caller (TC_POSES_STORAGE). Override with -D on the compiler's command line
 * (the Arduino IDE cannot pass -D to a library: edit this file there).
 *
 *   TC_DOUBLE      1: compute in double (host tests against the Rust core); 0 (default):
 *                  float, the only floating type an AVR has (avr-gcc's double is 32 bits)
 *   TC_FIT_MAX_P   largest model the fits are built for: 9 (offset + symmetric matrix) or 6
 *                  (offset + 3 gains only: 39 floats less of static working memory, and
 *                  about 2 KB less code on an AVR). Default 9, and 6 on an AVR (2 KB of RAM)
 */
#ifndef TRIAXCAL_TC_CONFIG_H
#define TRIAXCAL_TC_CONFIG_H

#include <stdint.h>

#ifndef TC_DOUBLE
#define TC_DOUBLE 0
#endif

#ifndef TC_FIT_MAX_P
#if defined(__AVR__)
#define TC_FIT_MAX_P 6
#else
#define TC_FIT_MAX_P 9
#endif
#endif

#if TC_FIT_MAX_P != 6 && TC_FIT_MAX_P != 9
#error "TC_FIT_MAX_P must be 6 (axis model only) or 9 (axis and full models)"
#endif

#if TC_DOUBLE
typedef double tc_real;
#define TC_R(x) (x)
#else
typedef float tc_real;
#define TC_R(x) (x##f)
#endif

#endif
