/* Simulated MPU-6050 (SIMULATED=1): known offsets and gains (sim_truth.h), deterministic
 * small noise, and a scripted globe of still poses that advances with every sample. Runs with
 * no hardware, e.g. in qemu-system-avr -machine arduino-uno, which has no TWI device. */
#include "triaxcal_config.h"

#if SIMULATED

#include <math.h>

#include "sensor.h"
#include "sim_truth.h"

#define SIM_POSES (SIM_LATITUDES * SIM_TURNS)

static uint32_t sample;
static uint16_t rng_state = 0xACE1u;
static int16_t pose_counts[3]; /* accelerometer reading of the current pose, before noise */
static int16_t pose = -1;

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

static void set_pose(int16_t p)
{
    const float deg = (float)M_PI / 180.0f;
    int16_t lat_i = p / SIM_TURNS;
    int16_t turn_i = p % SIM_TURNS;
    float lat = (-90.0f + 180.0f * (float)lat_i / (float)(SIM_LATITUDES - 1)) * deg;
    float lon = (360.0f / (float)SIM_TURNS) * (float)turn_i * deg;
    float ux = cosf(lat) * cosf(lon);
    float uy = cosf(lat) * sinf(lon);
    float uz = sinf(lat);
    pose_counts[0] = counts(ux, SIM_ACCEL_COUNTS_PER_G_X, SIM_ACCEL_OFFSET_X);
    pose_counts[1] = counts(uy, SIM_ACCEL_COUNTS_PER_G_Y, SIM_ACCEL_OFFSET_Y);
    pose_counts[2] = counts(uz, SIM_ACCEL_COUNTS_PER_G_Z, SIM_ACCEL_OFFSET_Z);
    pose = p;
}

uint8_t sensor_init(void)
{
    sample = 0;
    set_pose(0);
    return 0;
}

uint8_t sensor_read(int16_t out[7])
{
    int16_t p = (int16_t)((sample / SIM_SAMPLES_PER_POSE) % SIM_POSES);
    if (p != pose) set_pose(p);
    sample++;
    out[0] = pose_counts[0] + noise();
    out[1] = pose_counts[1] + noise();
    out[2] = pose_counts[2] + noise();
    out[3] = SIM_GYRO_OFFSET_X + noise();
    out[4] = SIM_GYRO_OFFSET_Y + noise();
    out[5] = SIM_GYRO_OFFSET_Z + noise();
    out[6] = SIM_TEMP_RAW + noise();
    return 0;
}

#else
typedef int sim_sensor_unused; /* ISO C forbids an empty translation unit */
#endif
