/* Mahony-style attitude filter in the ENU frame. Why this one on the node: it is the
 * cheapest 9-axis filter with bias compensation (no matrix inversions, no iterations), which
 * matters on a Cortex-M3 without FPU; the host runs the accurate filters on raw data anyway.
 * The magnetometer reference is rebuilt every step from the measurement's own inclination
 * (horizontal part turned to north), so no local dip angle has to be configured. */
#include "sensor_node/attitude.h"

#include <math.h>
#include <stddef.h>

#define DEFAULT_KP 1.0f
#define DEFAULT_KI 0.05f

void attitude_reset(attitude_filter* f) {
    f->kp = DEFAULT_KP;
    f->ki = DEFAULT_KI;
    f->q[0] = 1.0f;
    f->q[1] = f->q[2] = f->q[3] = 0.0f;
    f->bias_rad_s[0] = f->bias_rad_s[1] = f->bias_rad_s[2] = 0.0f;
    f->initialized = 0;
}

static float norm3(const float v[3]) {
    return sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

static int normalize3(const float in[3], float out[3]) {
    const float n = norm3(in);
    if (!(n > 1e-6f)) {
        return 0;
    }
    out[0] = in[0] / n;
    out[1] = in[1] / n;
    out[2] = in[2] / n;
    return 1;
}

static void cross3(const float a[3], const float b[3], float out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Rows of R (earth <- sensor) are the earth axes expressed in the sensor frame. */
static void quat_from_rows(const float e[3], const float n[3], const float u[3], float q[4]) {
    const float r00 = e[0], r01 = e[1], r02 = e[2];
    const float r10 = n[0], r11 = n[1], r12 = n[2];
    const float r20 = u[0], r21 = u[1], r22 = u[2];
    const float trace = r00 + r11 + r22;
    if (trace > 0.0f) {
        const float s = 2.0f * sqrtf(1.0f + trace);
        q[0] = 0.25f * s;
        q[1] = (r21 - r12) / s;
        q[2] = (r02 - r20) / s;
        q[3] = (r10 - r01) / s;
    } else if (r00 > r11 && r00 > r22) {
        const float s = 2.0f * sqrtf(1.0f + r00 - r11 - r22);
        q[0] = (r21 - r12) / s;
        q[1] = 0.25f * s;
        q[2] = (r01 + r10) / s;
        q[3] = (r02 + r20) / s;
    } else if (r11 > r22) {
        const float s = 2.0f * sqrtf(1.0f + r11 - r00 - r22);
        q[0] = (r02 - r20) / s;
        q[1] = (r01 + r10) / s;
        q[2] = 0.25f * s;
        q[3] = (r12 + r21) / s;
    } else {
        const float s = 2.0f * sqrtf(1.0f + r22 - r00 - r11);
        q[0] = (r10 - r01) / s;
        q[1] = (r02 + r20) / s;
        q[2] = (r12 + r21) / s;
        q[3] = 0.25f * s;
    }
    if (q[0] < 0.0f) {
        q[0] = -q[0];
        q[1] = -q[1];
        q[2] = -q[2];
        q[3] = -q[3];
    }
}

/* v_sensor = R^T v_earth for q = q_earth_sensor. */
static void earth_to_sensor(const float q[4], const float v[3], float out[3]) {
    const float w = q[0], x = q[1], y = q[2], z = q[3];
    out[0] = (1.0f - 2.0f * (y * y + z * z)) * v[0] + 2.0f * (x * y + w * z) * v[1] + 2.0f * (x * z - w * y) * v[2];
    out[1] = 2.0f * (x * y - w * z) * v[0] + (1.0f - 2.0f * (x * x + z * z)) * v[1] + 2.0f * (y * z + w * x) * v[2];
    out[2] = 2.0f * (x * z + w * y) * v[0] + 2.0f * (y * z - w * x) * v[1] + (1.0f - 2.0f * (x * x + y * y)) * v[2];
}

/* v_earth = R v_sensor. */
static void sensor_to_earth(const float q[4], const float v[3], float out[3]) {
    const float conj[4] = {q[0], -q[1], -q[2], -q[3]};
    earth_to_sensor(conj, v, out);
}

static int initialise(attitude_filter* f, const float up[3], const float* mag) {
    float m[3] = {0.0f, 0.0f, 0.0f};
    float east[3] = {0.0f, 0.0f, 0.0f};
    float east_n[3] = {0.0f, 0.0f, 0.0f};
    float north[3] = {0.0f, 0.0f, 0.0f};
    if (mag != NULL && normalize3(mag, m)) {
        cross3(m, up, east); /* E = m x U: the field points north (and down or up) */
        if (!normalize3(east, east_n)) {
            return 0; /* field parallel to gravity: no heading information */
        }
    } else {
        /* No heading: put the sensor's x axis (its y axis if x is vertical) on east. */
        const float x_axis[3] = {1.0f, 0.0f, 0.0f};
        const float y_axis[3] = {0.0f, 1.0f, 0.0f};
        float n_raw[3];
        cross3(up, x_axis, n_raw); /* N = U x E */
        if (!normalize3(n_raw, north)) {
            cross3(up, y_axis, n_raw);
            (void)normalize3(n_raw, north);
        }
        cross3(north, up, east_n); /* E = N x U */
    }
    cross3(up, east_n, north);
    quat_from_rows(east_n, north, up, f->q);
    f->initialized = 1;
    return 1;
}

void attitude_update(attitude_filter* f, const float gyro_rad_s[3], const float accel[3], const float* mag,
                     float dt_s) {
    float up[3];
    const int have_accel = normalize3(accel, up);
    if (!f->initialized) {
        if (have_accel) {
            (void)initialise(f, up, mag);
        }
        return;
    }
    float err[3] = {0.0f, 0.0f, 0.0f};
    if (have_accel) {
        const float up_earth[3] = {0.0f, 0.0f, 1.0f};
        float up_est[3];
        earth_to_sensor(f->q, up_earth, up_est);
        cross3(up, up_est, err);
        float m[3];
        if (mag != NULL && normalize3(mag, m)) {
            /* Reference: the measured field's horizontal part turned to north, its own dip. */
            float h[3];
            sensor_to_earth(f->q, m, h);
            const float b[3] = {0.0f, sqrtf(h[0] * h[0] + h[1] * h[1]), h[2]};
            float m_est[3], e_m[3];
            earth_to_sensor(f->q, b, m_est);
            cross3(m, m_est, e_m);
            err[0] += e_m[0];
            err[1] += e_m[1];
            err[2] += e_m[2];
        }
    }
    float w[3];
    for (int i = 0; i < 3; ++i) {
        f->bias_rad_s[i] += f->ki * err[i] * dt_s;
        w[i] = gyro_rad_s[i] + f->kp * err[i] + f->bias_rad_s[i];
    }
    /* q <- q + 0.5 dt q (x) (0, w), then renormalise. */
    const float qw = f->q[0], qx = f->q[1], qy = f->q[2], qz = f->q[3];
    const float h = 0.5f * dt_s;
    f->q[0] = qw + h * (-qx * w[0] - qy * w[1] - qz * w[2]);
    f->q[1] = qx + h * (qw * w[0] + qy * w[2] - qz * w[1]);
    f->q[2] = qy + h * (qw * w[1] - qx * w[2] + qz * w[0]);
    f->q[3] = qz + h * (qw * w[2] + qx * w[1] - qy * w[0]);
    const float n = sqrtf(f->q[0] * f->q[0] + f->q[1] * f->q[1] + f->q[2] * f->q[2] + f->q[3] * f->q[3]);
    if (n > 1e-6f) {
        for (int i = 0; i < 4; ++i) {
            f->q[i] /= n;
        }
    } else {
        attitude_reset(f); /* cannot happen with finite input; start over rather than emit NaN */
    }
}
