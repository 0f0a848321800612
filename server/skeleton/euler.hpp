// euler.hpp — Tait-Bryan (Cardan) angles in any of the six axis orders.
//
// Convention: an order (a0, a1, a2) with three distinct axes means the intrinsic
// sequence R = R_a0(angle0) · R_a1(angle1) · R_a2(angle2): rotate about a0, then about the
// once-rotated a1, then about the twice-rotated a2. This is how BVH applies a joint's
// rotation channels in the order they are listed ("Zrotation Xrotation Yrotation" is
// R = Rz·Rx·Ry) and how the joint-angle sequences (joint_angles.hpp) are defined.
// Pure functions, no allocation, thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "math/quaternion.hpp"

namespace mocap::skeleton {

using math::Mat3;
using math::Quat;
using math::Vec3;

enum class Axis : std::uint8_t { kX = 0, kY = 1, kZ = 2 };

/// Three distinct axes, applied left to right (see the file comment).
struct RotationOrder {
    std::array<Axis, 3> axes{Axis::kZ, Axis::kX, Axis::kY};

    friend bool operator==(const RotationOrder&, const RotationOrder&) = default;
};

/// "ZXY" -> {Z, X, Y}; case-insensitive; nullopt unless three distinct letters of XYZ.
std::optional<RotationOrder> parse_rotation_order(std::string_view text);
/// {Z, X, Y} -> "ZXY".
std::string to_string(const RotationOrder& order);
/// 'X', 'Y' or 'Z'.
char axis_letter(Axis a);

/// Rotation by angle_rad about one frame axis.
Quat axis_rotation(Axis a, double angle_rad);

/// R = R_a0(angles[0]) · R_a1(angles[1]) · R_a2(angles[2]).
Quat from_euler(const RotationOrder& order, const std::array<double, 3>& angles_rad);

/// The inverse of from_euler: angles[1] in [-π/2, π/2], the others in (-π, π].
/// At gimbal lock (|angles[1]| = π/2) angles[2] is set to 0 and angles[0] takes the
/// whole rotation about the (then shared) outer axis.
std::array<double, 3> to_euler(const RotationOrder& order, const Quat& q);

}  // namespace mocap::skeleton
