#include "fusion/joint_constraints.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace mocap::fusion {

double TrigLinear::value(double delta_rad) const {
    return c * std::cos(delta_rad) + s * std::sin(delta_rad) + k;
}

double TrigLinear::slope(double delta_rad) const {
    return -c * std::sin(delta_rad) + s * std::cos(delta_rad);
}

void TrigQuad::add(const TrigLinear& g, double w) {
    // (C cos δ + S sin δ + K)² expanded with cos² = (1 + cos 2δ)/2, sin² = (1 − cos 2δ)/2.
    a0 += w * (0.5 * (g.c * g.c + g.s * g.s) + g.k * g.k);
    a1 += w * 2.0 * g.c * g.k;
    b1 += w * 2.0 * g.s * g.k;
    a2 += w * 0.5 * (g.c * g.c - g.s * g.s);
    b2 += w * g.c * g.s;
}

void TrigQuad::scale(double f) {
    a0 *= f;
    a1 *= f;
    b1 *= f;
    a2 *= f;
    b2 *= f;
}

void TrigQuad::shift(double s_rad) {
    // a cos(δ − s) + b sin(δ − s) = (a cos s − b sin s) cos δ + (a sin s + b cos s) sin δ
    const auto turn = [](double& a, double& b, double ang) {
        const double c = std::cos(ang), s = std::sin(ang);
        const double na = a * c - b * s, nb = a * s + b * c;
        a = na;
        b = nb;
    };
    turn(a1, b1, s_rad);
    turn(a2, b2, 2.0 * s_rad);
}

double TrigQuad::value(double d) const {
    return a0 + a1 * std::cos(d) + b1 * std::sin(d) + a2 * std::cos(2.0 * d) + b2 * std::sin(2.0 * d);
}

TrigQuad::Minimum TrigQuad::minimum() const {
    constexpr int kGrid = 72;
    constexpr double kStep = 2.0 * std::numbers::pi / kGrid;
    int best = 0;
    for (int i = 1; i < kGrid; ++i) {
        if (value(i * kStep) < value(best * kStep)) best = i;
    }
    Minimum m;
    double d = best * kStep;
    for (int it = 0; it < 8; ++it) {  // Newton on J' = 0, kept within the grid cell
        const double d1 =
            -a1 * std::sin(d) + b1 * std::cos(d) - 2.0 * a2 * std::sin(2.0 * d) + 2.0 * b2 * std::cos(2.0 * d);
        const double d2 =
            -a1 * std::cos(d) - b1 * std::sin(d) - 4.0 * a2 * std::cos(2.0 * d) - 4.0 * b2 * std::sin(2.0 * d);
        if (d2 <= 0.0) break;
        d = std::clamp(d - d1 / d2, best * kStep - kStep, best * kStep + kStep);
    }
    m.delta_rad = math::wrap_pi(d);
    m.value = value(d);
    m.curvature = -a1 * std::cos(d) - b1 * std::sin(d) - 4.0 * a2 * std::cos(2.0 * d) - 4.0 * b2 * std::sin(2.0 * d);
    m.runner_up = 1e300;
    for (int i = 0; i < kGrid; ++i) {
        const double x = i * kStep;
        if (std::abs(math::wrap_pi(x - d)) >= std::numbers::pi / 4.0) m.runner_up = std::min(m.runner_up, value(x));
    }
    return m;
}

TrigLinear dot_rz(const Vec3& x, const Vec3& y) {
    // Rz(δ) y = (cos δ y_x − sin δ y_y, sin δ y_x + cos δ y_y, y_z)
    return {x.x() * y.x() + x.y() * y.y(), x.y() * y.x() - x.x() * y.y(), x.z() * y.z()};
}

Vec3 rotate_z(double delta_rad, const Vec3& v) {
    const double c = std::cos(delta_rad), s = std::sin(delta_rad);
    return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

HeadingMeasurement pair_measurement(const Vec3& a, const Vec3& b, double delta_rad, double sigma,
                                    double min_horizontal) {
    HeadingMeasurement m;
    const double la2 = a.x() * a.x() + a.y() * a.y();
    const double lb2 = b.x() * b.x() + b.y() * b.y();
    const double min2 = min_horizontal * min_horizontal;
    if (la2 < min2 || lb2 < min2) return m;
    const Vec3 br = rotate_z(delta_rad, b);
    // The angle that turns br's horizontal part onto a's.
    m.residual_rad = std::atan2(br.x() * a.y() - br.y() * a.x(), br.x() * a.x() + br.y() * a.y());
    // A vector error of sigma turns a horizontal part of length l by sigma / l.
    m.var_rad2 = sigma * sigma * (1.0 / la2 + 1.0 / lb2);
    m.ok = true;
    return m;
}

bool pair_contradicts(const Vec3& a, const Vec3& b, double delta_rad, double min_horizontal) {
    const HeadingMeasurement m = pair_measurement(a, b, delta_rad, 1.0, min_horizontal);
    return m.ok && std::abs(m.residual_rad) > 0.5 * std::numbers::pi;
}

HeadingMeasurement scalar_measurement(const TrigLinear& g, double delta_rad, double sigma_g, double min_slope) {
    HeadingMeasurement m;
    const double d = g.slope(delta_rad);
    if (std::abs(d) < min_slope) return m;
    m.residual_rad = -g.value(delta_rad) / d;
    m.var_rad2 = sigma_g * sigma_g / (d * d);
    // Far from the root the linearisation says little: a residual beyond ±60° is clipped,
    // the gate of the filter decides what to do with it.
    constexpr double kMax = 1.0471975511965976;
    m.residual_rad = std::clamp(m.residual_rad, -kMax, kMax);
    m.ok = true;
    return m;
}

TrigLinear two_dof_axis_constraint(const Vec3& a_parent, const Vec3& b_child, double cos_alpha) {
    TrigLinear g = dot_rz(a_parent, b_child);
    g.k -= cos_alpha;
    return g;
}

TrigLinear two_dof_rate_constraint(const Vec3& a_parent, const Vec3& b_child, const Vec3& u_parent,
                                   const Vec3& v_child) {
    // (Rz v − u)·(a × Rz b) = aᵀ Rz (b × v) − (u × a)ᵀ Rz b: rotations keep cross products.
    const TrigLinear t1 = dot_rz(a_parent, b_child.cross(v_child));
    const TrigLinear t2 = dot_rz(u_parent.cross(a_parent), b_child);
    return {t1.c - t2.c, t1.s - t2.s, t1.k - t2.k};
}

}  // namespace mocap::fusion
