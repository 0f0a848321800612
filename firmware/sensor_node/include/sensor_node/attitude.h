/* On-node attitude filter for MW_MODE_ATTITUDE / MW_MODE_RAW_ATTITUDE: a Mahony-style
 * complementary filter (gyro integration corrected by the directions of gravity and of the
 * horizontal magnetic field, with an integral term that absorbs gyro bias), initialised from
 * the first accelerometer + magnetometer sample (TRIAD) so it needs no convergence time.
 *
 * Output q_earth_sensor (w, x, y, z), Hamilton, unit norm, earth frame ENU (x east, y north,
 * z up), as the ATT frame carries it. Inputs: gyro rad/s, accelerometer specific force (any
 * unit: only its direction is used; +z up at rest), magnetometer (any unit, NULL if invalid).
 * Single precision; about 150 float operations per update (soft-float on the Cortex-M3:
 * roughly 0.2 ms at 72 MHz). No state outside the struct; the caller allocates it. */
#ifndef MOCAP_SENSOR_NODE_ATTITUDE_H
#define MOCAP_SENSOR_NODE_ATTITUDE_H

#ifdef __cplusplus
extern "C" {
#endif

typedef struct attitude_filter {
    float kp;            /* proportional gain, rad/s per unit direction error (default 1.0) */
    float ki;            /* integral gain, rad/s^2 per unit error (default 0.05) */
    float q[4];          /* q_earth_sensor, w x y z */
    float bias_rad_s[3]; /* integral term: minus the estimated gyro bias */
    int initialized;     /* 0 until the first sample with a valid accelerometer */
} attitude_filter;

/* Resets to "not initialised" with the default gains. */
void attitude_reset(attitude_filter* f);

/* One update over dt_s seconds. The first call with a usable accelerometer (and a magnetometer
 * not parallel to it) sets q from the measurement; later calls integrate the gyro and correct.
 * Without a magnetometer, heading is only integrated. Degenerate input (zero accelerometer)
 * skips the correction, never produces NaN. */
void attitude_update(attitude_filter* f, const float gyro_rad_s[3], const float accel[3],
                     const float* mag /* 3 values or NULL */, float dt_s);

#ifdef __cplusplus
}
#endif

#endif
