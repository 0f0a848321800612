#include "skeleton/euler.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace mocap::skeleton {

std::optional<RotationOrder> parse_rotation_order(std::string_view text) {
    if (text.size() != 3) return std::nullopt;
    RotationOrder order;
    bool seen[3] = {false, false, false};
    for (std::size_t i = 0; i < 3; ++i) {
        const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(text[i])));
        if (c < 'X' || c > 'Z') return std::nullopt;
        const int idx = c - 'X';
        if (seen[idx]) return std::nullopt;
        seen[idx] = true;
        order.axes[i] = static_cast<Axis>(idx);
    }
    return order;
}

char axis_letter(Axis a) {
    return static_cast<char>('X' + static_cast<int>(a));
}

std::string to_string(const RotationOrder& order) {
    return {axis_letter(order.axes[0]), axis_letter(order.axes[1]), axis_letter(order.axes[2])};
}

Quat axis_rotation(Axis a, double angle_rad) {
    const double h = 0.5 * angle_rad;
    const double s = std::sin(h);
    const double c = std::cos(h);
    switch (a) {
        case Axis::kX:
            return Quat(c, s, 0.0, 0.0);
        case Axis::kY:
            return Quat(c, 0.0, s, 0.0);
        case Axis::kZ:
            return Quat(c, 0.0, 0.0, s);
    }
    return Quat::Identity();
}

Quat from_euler(const RotationOrder& order, const std::array<double, 3>& angles_rad) {
    return axis_rotation(order.axes[0], angles_rad[0]) * axis_rotation(order.axes[1], angles_rad[1]) *
           axis_rotation(order.axes[2], angles_rad[2]);
}

std::array<double, 3> to_euler(const RotationOrder& order, const Quat& q) {
    // For R = R_i(a) R_j(b) R_k(c) with (i, j, k) a permutation, s = +1 when (i, j, k) is a
    // cyclic order (XYZ, YZX, ZXY) and -1 otherwise:
    //   sin b = s R[i][k],  a = atan2(-s R[j][k], R[k][k]),  c = atan2(-s R[i][j], R[i][i]).
    const int i = static_cast<int>(order.axes[0]);
    const int j = static_cast<int>(order.axes[1]);
    const int k = static_cast<int>(order.axes[2]);
    const double s = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
    const Mat3 r = q.normalized().toRotationMatrix();
    const double sb = std::clamp(s * r(i, k), -1.0, 1.0);
    std::array<double, 3> out{};
    out[1] = std::asin(sb);
    // cos b from the other two entries of the row is more accurate than sqrt(1 - sb²).
    const double cb = std::hypot(r(i, i), r(i, j));
    if (cb > 1e-9) {
        out[0] = std::atan2(-s * r(j, k), r(k, k));
        out[2] = std::atan2(-s * r(i, j), r(i, i));
    } else {
        // Gimbal lock: with c = 0, column j of R is R_i(a) e_j = cos a e_j + s sin a e_k.
        out[0] = std::atan2(s * r(k, j), r(j, j));
        out[2] = 0.0;
    }
    return out;
}

}  // namespace mocap::skeleton
