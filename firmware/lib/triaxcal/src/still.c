#include "still.h"

#include <string.h>

static struct still_settings set;
static uint16_t holdoff_samples; /* holdoff_ms in samples */

static int32_t win[STILL_CHANNELS]; /* sums of the window being filled */
static uint8_t win_n;
static int32_t prev[6]; /* the previous window's accelerometer and gyro sums */
static uint8_t have_prev;

static int32_t bias[3]; /* gyro: a still window's sums */
static uint8_t bias_state; /* BIAS_* bits */
static uint8_t reanchor; /* steady windows in a row with the gyro a little off its bias */

/* The first bias is provisional. It is taken from the first window whose accelerometer and
 * gyro both stayed steady, and a board twisted about the vertical at a constant rate from the
 * start looks just that: the twist rate became the bias, every still window after it read as
 * turning, and the way back (the drift rule: 8 unchanging windows in a row) never comes when
 * every rest lasts 4 or 5 windows and each move resets the count. So, as in the host's
 * detector (triaxcal.detect):
 *   - the bias is confirmed (BIAS_SURE) when, after a move, a steady window is back at it --
 *     at the first rest after the first move of a recording that starts still, which then
 *     goes exactly as before;
 *   - until then, the gyro sums of steady windows off it are gathered in two slots, each
 *     holding the windows within the threshold of its first one; when a slot holds
 *     STILL_REANCHOR_WINDOWS windows that lie on either side of a move, the window that filled
 *     it becomes the bias, however far off the old one, and is confirmed. Coming back to one
 *     rate after different moves is the sign of rest the provisional bias lacks (turns by hand
 *     do not repeat a speed to a few tenths of a degree a second), while a turn at constant
 *     speed is one stretch, within one move;
 *   - a confirmed bias (and meanwhile a provisional one) follows a drift as before.
 * The host's detector keeps the last 32 such windows and counts those within the threshold of
 * the newest; two slots do it in 26 bytes of RAM: the windows of the rests outnumber the few
 * steady windows inside a turn, which take the slot with fewer windows. */
#define BIAS_KNOWN 0x01 /* a bias was taken */
#define BIAS_SURE 0x02  /* the board came to rest at it again after a move */
#define BIAS_MOVED 0x04 /* a move since the bias was taken or last replaced */
#define REST_COUNT 0x0F /* rest_n[]: windows in the slot (0: empty) */
#define REST_MOVED 0x40 /* rest_n[]: a move since the slot's first window */
#define REST_TWO 0x80   /* rest_n[]: its windows lie on either side of a move */
#define REST_SLOTS 2    /* rest_again() chooses between two */
static int32_t rest[REST_SLOTS][3]; /* gyro sums of each slot's first window */
static uint8_t rest_n[REST_SLOTS];

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
    bias_state = 0;
    reanchor = 0;
    memset(rest_n, 0, sizeof rest_n);
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

/* A steady window off the provisional bias: into its slot (or the emptier one). 1 when its
 * slot is full and spans a move -- the window is then the bias, confirmed. */
static uint8_t rest_again(int32_t thr_g)
{
    uint8_t i, k, use = REST_SLOTS;
    for (k = 0; k < REST_SLOTS && use == REST_SLOTS; k++) {
        if (!(rest_n[k] & REST_COUNT)) continue;
        use = k;
        for (i = 0; i < 3; i++) {
            if (abs32(win[3 + i] - rest[k][i]) > thr_g) use = REST_SLOTS;
        }
    }
    if (use == REST_SLOTS) {
        /* a rate of its own: the slot with fewer windows (the later one on a tie) starts again */
        use = (rest_n[0] & REST_COUNT) < (rest_n[1] & REST_COUNT) ? 0 : 1;
        memcpy(rest[use], win + 3, sizeof rest[use]);
        rest_n[use] = 1;
        return 0;
    }
    if (rest_n[use] & REST_MOVED) rest_n[use] |= REST_TWO;
    if ((rest_n[use] & REST_COUNT) < STILL_REANCHOR_WINDOWS) rest_n[use]++;
    if ((rest_n[use] & REST_COUNT) < STILL_REANCHOR_WINDOWS || !(rest_n[use] & REST_TWO))
        return 0;
    memcpy(bias, win + 3, sizeof bias);
    bias_state = BIAS_KNOWN | BIAS_SURE;
    memset(rest_n, 0, sizeof rest_n);
    return 1;
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
        if (moved || !g_steady) {
            /* a move (or the first window): the provisional bias and the slots note it */
            bias_state |= BIAS_MOVED;
            for (i = 0; i < REST_SLOTS; i++) {
                if (rest_n[i]) rest_n[i] |= REST_MOVED;
            }
        }
        if (!(bias_state & BIAS_KNOWN)) {
            if (moved || !g_steady) {
                moved = 1;
            } else {
                memcpy(bias, win + 3, sizeof bias);
                bias_state = BIAS_KNOWN; /* provisional */
            }
        } else {
            uint8_t off = 0, near = 1;
            for (i = 0; i < 3; i++) {
                int32_t away = abs32(win[3 + i] - bias[i]);
                if (away > thr_g) off = 1;
                if (away > STILL_REANCHOR_MAX * thr_g) near = 0;
            }
            if (!(bias_state & BIAS_SURE) && !moved && g_steady) {
                if (!off && (bias_state & BIAS_MOVED)) {
                    /* at rest at the bias again after a move: confirmed */
                    bias_state |= BIAS_SURE;
                    memset(rest_n, 0, sizeof rest_n);
                } else if (off && rest_again(thr_g)) {
                    off = 0; /* resting at the bias that replaced it */
                    near = 1;
                }
            }
            if (off && near && !moved && g_steady && ++reanchor >= STILL_REANCHOR_WINDOWS) {
                /* steady for a while, a little off: the bias moved (or was taken while the
                 * board turned), follow it -- the host's detector does the same */
                memcpy(bias, win + 3, sizeof bias);
                bias_state &= (uint8_t)~BIAS_MOVED;
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
                    memcpy(bias, win + 3, sizeof bias);
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
                             (bias_state & BIAS_KNOWN ? STILL_FLAG_BIAS : 0));
    for (i = 0; i < 3; i++) {
        status.accel[i] = clamp16(win[i] / set.window);
        status.rate[i] =
            clamp16((win[3 + i] - (bias_state & BIAS_KNOWN ? bias[i] : 0)) / set.window);
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
