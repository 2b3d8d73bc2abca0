#include "still.h"

#include <string.h>

static struct still_settings set;
static uint16_t holdoff_samples; /* holdoff_ms in samples */

static int32_t win[STILL_CHANNELS]; /* sums of the window being filled */
static uint8_t win_n;
static int32_t prev[6]; /* the previous window's accelerometer and gyro sums */
static uint8_t have_prev;

static int32_t bias[3]; /* gyro: a still window's sums */
static uint8_t bias_known;
static uint8_t reanchor; /* steady windows in a row with the gyro a little off its bias */

static uint8_t armed;   /* moved since the last pose (or no pose yet) */
static uint8_t settled; /* the first steady window after a move was seen (not averaged) */
static uint16_t holdoff_left;

static struct still_status status;
static struct still_pose pose; /* the pose in progress, then the last registered one */

void still_defaults(struct still_settings *s)
{
    s->period_ms = STILL_DEFAULT_PERIOD_MS;
    s->window = STILL_DEFAULT_WINDOW;
    s->hold_windows = STILL_DEFAULT_HOLD_WINDOWS;
    s->holdoff_ms = STILL_DEFAULT_HOLDOFF_MS;
    s->accel_threshold = STILL_DEFAULT_ACCEL_THRESHOLD;
    s->gyro_threshold = STILL_DEFAULT_GYRO_THRESHOLD;
    s->beep_ms = STILL_DEFAULT_BEEP_MS;
}

uint8_t still_valid(const struct still_settings *s)
{
    /* window x hold_windows <= 62500 samples keeps every sum of int16 counts in int32 */
    return s->period_ms >= 1 && s->period_ms <= 250 && s->window >= 1 && s->window <= 250 &&
           s->hold_windows >= 1 && s->hold_windows <= 250 && s->holdoff_ms <= 60000u &&
           s->accel_threshold >= 1 && s->accel_threshold <= 32767u &&
           s->gyro_threshold <= 32767u && s->beep_ms <= 250;
}

static void put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
}

static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }

void still_pack(const struct still_settings *s, uint8_t *out)
{
    out[0] = s->period_ms;
    out[1] = s->window;
    out[2] = s->hold_windows;
    put16(out + 3, s->holdoff_ms);
    put16(out + 5, s->accel_threshold);
    put16(out + 7, s->gyro_threshold);
    out[9] = s->beep_ms;
}

void still_unpack(const uint8_t *in, struct still_settings *s)
{
    s->period_ms = in[0];
    s->window = in[1];
    s->hold_windows = in[2];
    s->holdoff_ms = get16(in + 3);
    s->accel_threshold = get16(in + 5);
    s->gyro_threshold = get16(in + 7);
    s->beep_ms = in[9];
}

void still_start(const struct still_settings *s)
{
    set = *s;
    holdoff_samples = (uint16_t)(set.holdoff_ms / set.period_ms);
    memset(win, 0, sizeof win);
    win_n = 0;
    have_prev = 0;
    bias_known = 0;
    reanchor = 0;
    armed = 1;
    settled = 0;
    holdoff_left = 0;
    memset(&status, 0, sizeof status);
    memset(&pose, 0, sizeof pose);
}

const struct still_settings *still_settings(void) { return &set; }

const struct still_status *still_status(void) { return &status; }

const struct still_pose *still_pose(void) { return &pose; }

static int32_t abs32(int32_t v) { return v < 0 ? -v : v; }

static int16_t clamp16(int32_t v)
{
    return v > 32767 ? 32767 : v < -32768 ? -32768 : (int16_t)v;
}

static uint8_t window_done(void)
{
    const int32_t thr_a = (int32_t)set.accel_threshold * set.window;
    const int32_t thr_g = (int32_t)set.gyro_threshold * set.window;
    const uint8_t gyro = set.gyro_threshold != 0;
    uint8_t moved = !have_prev; /* not averaged; the first window has nothing to compare with */
    uint8_t g_steady = have_prev; /* the gyro mean changed by at most the threshold */
    uint8_t i, ev = STILL_EV_WINDOW;

    for (i = 0; i < 3 && have_prev; i++) {
        if (abs32(win[i] - prev[i]) > thr_a) moved = 1;
        if (abs32(win[3 + i] - prev[3 + i]) > thr_g) g_steady = 0;
    }
    /* A move, which allows the next pose: the accelerometer changed, the gyro rate changed, or
     * the gyro is far off its bias. A gyro only a little off its bias but unchanging (a drift)
     * is not averaged, but is no move: the pose after it would be the same pose again. */
    uint8_t arm = moved;
    if (gyro && !g_steady) arm = 1;
    if (gyro) {
        if (!bias_known) {
            if (moved || !g_steady) {
                moved = 1;
            } else {
                for (i = 0; i < 3; i++) bias[i] = win[3 + i];
                bias_known = 1;
            }
        } else {
            uint8_t off = 0, near = 1;
            for (i = 0; i < 3; i++) {
                int32_t away = abs32(win[3 + i] - bias[i]);
                if (away > thr_g) off = 1;
                if (away > STILL_REANCHOR_MAX * thr_g) near = 0;
            }
            if (off && near && !moved && g_steady && ++reanchor >= STILL_REANCHOR_WINDOWS) {
                /* steady for a while, a little off: the bias moved (or was taken while the
                 * board turned), follow it -- the host's detector does the same */
                for (i = 0; i < 3; i++) bias[i] = win[3 + i];
                off = 0;
            }
            if (!off || !near || moved || !g_steady) reanchor = 0;
            if (off) moved = 1;
            if (!near) arm = 1;
        }
    }
    for (i = 0; i < 6; i++) prev[i] = win[i];
    have_prev = 1;

    if (arm) armed = 1;
    if (moved) {
        settled = 0;
        status.run = 0;
    } else if (holdoff_left) {
        settled = 0;
        status.run = 0;
    } else if (armed) {
        if (!settled) {
            settled = 1; /* it may hold the end of the move: not averaged */
        } else {
            if (status.run == 0) memset(pose.sum, 0, sizeof pose.sum);
            for (i = 0; i < STILL_CHANNELS; i++) pose.sum[i] += win[i];
            if (++status.run >= set.hold_windows) {
                pose.index = status.poses++;
                pose.n = (uint16_t)((uint16_t)status.run * set.window);
                if (gyro) {
                    for (i = 0; i < 3; i++) bias[i] = win[3 + i];
                }
                armed = 0;
                settled = 0;
                status.run = 0;
                holdoff_left = holdoff_samples;
                ev |= STILL_EV_POSE;
            }
        }
    }

    status.flags = (uint8_t)((moved ? STILL_FLAG_MOVED : 0) |
                             (holdoff_left ? STILL_FLAG_HOLDOFF : 0) |
                             (armed ? 0 : STILL_FLAG_WAITING) |
                             (bias_known ? STILL_FLAG_BIAS : 0));
    for (i = 0; i < 3; i++) {
        status.accel[i] = clamp16(win[i] / set.window);
        status.rate[i] = clamp16((win[3 + i] - (bias_known ? bias[i] : 0)) / set.window);
    }
    memset(win, 0, sizeof win);
    win_n = 0;
    return ev;
}

void still_break(void)
{
    memset(win, 0, sizeof win);
    win_n = 0;
    have_prev = 0;
    armed = 1;
    settled = 0;
    status.run = 0;
    status.flags |= STILL_FLAG_MOVED;
}

uint8_t still_feed(const int16_t v[STILL_CHANNELS])
{
    if (!set.window) return 0; /* still_start() not called */
    if (holdoff_left) holdoff_left--;
    for (uint8_t i = 0; i < STILL_CHANNELS; i++) win[i] += v[i];
    if (++win_n < set.window) return 0;
    return window_done();
}
