#include "fusion/joint_constraints.hpp"

#include <algorithm>
#include <cmath>

namespace mocap::fusion {

double TrigLinear::value(double delta_rad) const {
    return c * std::cos(delta_rad) + s * std::sin(delta_rad) + k;
}

double TrigLinear::slope(double delta_rad) const {
    return -c * std::sin(delta_rad) + s * std::cos(delta_rad);
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
