#include "math/nwu_frame.hpp"

#include <cmath>
#include <numbers>

namespace mocap::math {

Quat q_enu_nwu() {
    return Quat(std::numbers::sqrt2 / 2.0, 0.0, 0.0, std::numbers::sqrt2 / 2.0);
}

Quat nwu_from_enu(const Quat& q_enu_sensor) {
    return q_enu_nwu().conjugate() * q_enu_sensor;
}

Vec3 nwu_field_reference(const Quat& q_nwu_sensor, const Vec3& mag_unit) {
    const Vec3 h = rotate(q_nwu_sensor, mag_unit);
    return {std::hypot(h.x(), h.y()), 0.0, h.z()};
}

}  // namespace mocap::math
