/* Build-time sizes and the number type of the triaxcal C library (triaxcal.h).
 *
 * Every buffer is sized here, at compile time: the library never allocates. Override a size
 * with -D on the compiler's command line (the Arduino IDE cannot pass -D to a library: edit
 * this file there).
 *
 *   TC_DOUBLE        1: compute in double (host tests against the Rust core); 0 (default):
 *                    float, the only floating type an AVR has (avr-gcc's double is 32 bits)
 *   TC_POSES_MAX     poses a struct tc_poses holds (default 84: the seed's globe scheme, 7
 *                    latitudes x 12 turns); 12 bytes of RAM each in float
 *   TC_FIT_MAX_P     largest model the fits are built for: 9 (offset + symmetric matrix,
 *                    default) or 6 (offset + 3 gains only, which saves 39 floats of stack)
 */
#ifndef TRIAXCAL_TC_CONFIG_H
#define TRIAXCAL_TC_CONFIG_H

#include <stdint.h>

#ifndef TC_DOUBLE
#define TC_DOUBLE 0
#endif

#ifndef TC_POSES_MAX
#define TC_POSES_MAX 84
#endif

#ifndef TC_FIT_MAX_P
#define TC_FIT_MAX_P 9
#endif

#if TC_POSES_MAX < 4 || TC_POSES_MAX > 4096
#error "TC_POSES_MAX must be 4..4096"
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
