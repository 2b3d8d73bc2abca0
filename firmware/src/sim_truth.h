/* Ground truth of the simulated sensor (SIMULATED=1). tests/test_firmware.py parses this file:
 * keep one "#define NAME value" per line, plain integers.
 *
 * Accelerometer model, per axis a in {X, Y, Z}:
 *     raw_a = SIM_ACCEL_OFFSET_a + u_a * SIM_ACCEL_COUNTS_PER_G_a + noise
 * where u is the unit gravity vector of the current pose and noise is uniform integer in
 * [-SIM_NOISE_COUNTS, +SIM_NOISE_COUNTS]. A fit with radius 16384 (counts per g at +-2 g)
 * recovers offset = SIM_ACCEL_OFFSET_a and a gain matrix (multiplies) with diagonal
 * 16384 / SIM_ACCEL_COUNTS_PER_G_a.
 * Gyroscope: still in every pose, raw_g = SIM_GYRO_OFFSET_g + noise (counts, 131 per deg/s).
 * Temperature: SIM_TEMP_RAW + noise (MPU-6050: T_degC = raw / 340 + 36.53).
 *
 * Poses: the globe scheme, SIM_LATITUDES latitudes from -90 to +90 degrees in equal steps,
 * SIM_TURNS turns of 360 / SIM_TURNS degrees about the vertical at each, pose index
 * p = (sample / SIM_SAMPLES_PER_POSE) % (SIM_LATITUDES * SIM_TURNS), latitude index
 * p / SIM_TURNS, turn index p % SIM_TURNS; u = (cos(lat) cos(lon), cos(lat) sin(lon), sin(lat)).
 * Every sample (polled or streamed) advances the sample counter by one.
 *
 * The still-pose mode ('S') switches to the globe with moves, from its start: the same 84
 * poses in snake order (pose index q: latitude index q / SIM_TURNS, turn index q % SIM_TURNS
 * on even latitude indices and SIM_TURNS - 1 - q % SIM_TURNS on odd ones), so that every move
 * is one step of 30 degrees: a twist about the board's z axis (seen by the accelerometer
 * except at the poles, always by the gyroscope) or a step of latitude. Pose q is held for
 * SIM_HOLD_SAMPLES samples from sample q * (SIM_HOLD_SAMPLES + SIM_MOVE_SAMPLES), then the
 * board turns at a constant rate for SIM_MOVE_SAMPLES samples to pose q + 1; the last pose is
 * held for ever. During a move the accelerometer reads the interpolated gravity direction
 * (latitude and turn linear in time, no linear acceleration) and the gyroscope its offsets
 * plus the body rate in counts (SIM_GYRO_COUNTS_PER_DPS per deg/s) for a sample rate of
 * SIM_NOMINAL_RATE_HZ: 30 degrees in 75 samples at 100 Hz is 40 deg/s, 5240 counts; sampled
 * faster, the script runs faster (the readings do not change). Leaving the mode goes back to
 * the quick globe where it was.
 */
#ifndef TRIAXCAL_SIM_TRUTH_H
#define TRIAXCAL_SIM_TRUTH_H

#define SIM_ACCEL_OFFSET_X 180
#define SIM_ACCEL_OFFSET_Y -240
#define SIM_ACCEL_OFFSET_Z 350
#define SIM_ACCEL_COUNTS_PER_G_X 16630
#define SIM_ACCEL_COUNTS_PER_G_Y 16120
#define SIM_ACCEL_COUNTS_PER_G_Z 16450

#define SIM_GYRO_OFFSET_X 42
#define SIM_GYRO_OFFSET_Y -17
#define SIM_GYRO_OFFSET_Z 9

#define SIM_TEMP_RAW -1500

#define SIM_NOISE_COUNTS 3
#define SIM_LATITUDES 7
#define SIM_TURNS 12
#define SIM_SAMPLES_PER_POSE 4

#define SIM_HOLD_SAMPLES 250
#define SIM_MOVE_SAMPLES 75
#define SIM_NOMINAL_RATE_HZ 100
#define SIM_GYRO_COUNTS_PER_DPS 131

#endif
