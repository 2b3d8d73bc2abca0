/* Simulated MPU-6050 (SIMULATED=1): known offsets and gains (sim_truth.h), deterministic
 * small noise, and two scripts: the quick globe of still poses that advances with every sample
 * (the streaming modes), and the globe with moves between held poses (the still-pose mode).
 * Runs with no hardware, e.g. in qemu-system-avr -machine arduino-uno, which has no TWI
 * device. */
#include "triaxcal_config.h"

#if SIMULATED

#include <math.h>

#include "sensor.h"
#include "sim_truth.h"

#define SIM_POSES (SIM_LATITUDES * SIM_TURNS)
#define SIM_SEGMENT ((uint32_t)SIM_HOLD_SAMPLES + SIM_MOVE_SAMPLES)

static uint32_t sample;        /* quick globe: samples so far */
static uint32_t moving_sample; /* globe with moves: samples since it started */
static uint8_t moving;
static uint16_t rng_state = 0xACE1u;
static int16_t pose_counts[3]; /* accelerometer reading of the current pose, before noise */
static int16_t pose = -1;      /* the pose pose_counts holds (quick: p, moving: SIM_POSES + q) */
static int16_t rate_counts[3]; /* gyro rate of the current sample, before offset and noise */

static int16_t noise(void)
{
    /* 16-bit xorshift: deterministic, the same on every run */
    uint16_t x = rng_state;
    x ^= (uint16_t)(x << 7);
    x ^= (uint16_t)(x >> 9);
    x ^= (uint16_t)(x << 8);
    rng_state = x;
    return (int16_t)(x % (2 * SIM_NOISE_COUNTS + 1)) - SIM_NOISE_COUNTS;
}

static int16_t counts(float g, int32_t per_g, int32_t offset)
{
    float v = (float)offset + g * (float)per_g;
    return (int16_t)lroundf(v);
}

static float lat_deg(int16_t lat_i)
{
    return -90.0f + 180.0f * (float)lat_i / (float)(SIM_LATITUDES - 1);
}

static float lon_deg(int16_t turn_i) { return (360.0f / (float)SIM_TURNS) * (float)turn_i; }

static float cos_lon, sin_lon; /* of the last set_direction() */

static void set_direction(float lat, float lon) /* degrees */
{
    const float deg = (float)M_PI / 180.0f;
    float cl = cosf(lat * deg);
    cos_lon = cosf(lon * deg);
    sin_lon = sinf(lon * deg);
    float ux = cl * cos_lon;
    float uy = cl * sin_lon;
    float uz = sinf(lat * deg);
    pose_counts[0] = counts(ux, SIM_ACCEL_COUNTS_PER_G_X, SIM_ACCEL_OFFSET_X);
    pose_counts[1] = counts(uy, SIM_ACCEL_COUNTS_PER_G_Y, SIM_ACCEL_OFFSET_Y);
    pose_counts[2] = counts(uz, SIM_ACCEL_COUNTS_PER_G_Z, SIM_ACCEL_OFFSET_Z);
}

/* Snake order of the globe with moves: the turn index of pose q. */
static int16_t snake_turn(int16_t q)
{
    int16_t lat_i = q / SIM_TURNS, j = q % SIM_TURNS;
    return (lat_i & 1) ? (int16_t)(SIM_TURNS - 1 - j) : j;
}

static void quick_step(void)
{
    int16_t p = (int16_t)((sample / SIM_SAMPLES_PER_POSE) % SIM_POSES);
    sample++;
    if (p != pose) {
        set_direction(lat_deg(p / SIM_TURNS), lon_deg(p % SIM_TURNS));
        pose = p;
    }
    rate_counts[0] = rate_counts[1] = rate_counts[2] = 0;
}

static void moving_step(void)
{
    uint32_t s = moving_sample++;
    uint32_t q32 = s / SIM_SEGMENT;
    uint16_t k = (uint16_t)(s % SIM_SEGMENT);
    rate_counts[0] = rate_counts[1] = rate_counts[2] = 0;
    if (q32 >= SIM_POSES - 1 || k < SIM_HOLD_SAMPLES) { /* holding a pose */
        int16_t q = q32 >= SIM_POSES - 1 ? SIM_POSES - 1 : (int16_t)q32;
        if (pose != SIM_POSES + q) {
            set_direction(lat_deg(q / SIM_TURNS), lon_deg(snake_turn(q)));
            pose = (int16_t)(SIM_POSES + q);
        }
        return;
    }
    /* moving from pose q to q + 1 at a constant rate; the sample shows the middle of its step */
    int16_t q = (int16_t)q32;
    float f = ((float)(k - SIM_HOLD_SAMPLES) + 0.5f) / (float)SIM_MOVE_SAMPLES;
    float lat0 = lat_deg(q / SIM_TURNS), lat1 = lat_deg((q + 1) / SIM_TURNS);
    float lon0 = lon_deg(snake_turn(q)), lon1 = lon_deg(snake_turn(q + 1));
    set_direction(lat0 + f * (lat1 - lat0), lon0 + f * (lon1 - lon0));
    pose = -1;
    /* body rate (deg/s): d(lat)/dt about e_lon = (-sin lon, cos lon, 0), -d(lon)/dt about z */
    const float per_s = (float)SIM_NOMINAL_RATE_HZ / (float)SIM_MOVE_SAMPLES;
    const float c = (float)SIM_GYRO_COUNTS_PER_DPS;
    float dlat = (lat1 - lat0) * per_s, dlon = (lon1 - lon0) * per_s;
    rate_counts[0] = (int16_t)lroundf(-dlat * sin_lon * c);
    rate_counts[1] = (int16_t)lroundf(dlat * cos_lon * c);
    rate_counts[2] = (int16_t)lroundf(-dlon * c);
}

void sim_select_script(uint8_t moving_script)
{
    moving = moving_script;
    pose = -1;
    if (moving) {
        moving_sample = 0;
        rng_state = 0xACE1u; /* the same noise on every run of the script */
    }
}

uint8_t sensor_init(void)
{
    sample = 0;
    moving = 0;
    pose = -1;
    return 0;
}

uint8_t sensor_read(int16_t out[7])
{
    if (moving) {
        moving_step();
    } else {
        quick_step();
    }
    out[0] = pose_counts[0] + noise();
    out[1] = pose_counts[1] + noise();
    out[2] = pose_counts[2] + noise();
    out[3] = SIM_GYRO_OFFSET_X + rate_counts[0] + noise();
    out[4] = SIM_GYRO_OFFSET_Y + rate_counts[1] + noise();
    out[5] = SIM_GYRO_OFFSET_Z + rate_counts[2] + noise();
    out[6] = SIM_TEMP_RAW + noise();
    return 0;
}

#else
typedef int sim_sensor_unused; /* ISO C forbids an empty translation unit */
#endif
