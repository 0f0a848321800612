// nwu_frame.hpp — the north-west-up earth frame of the published Madgwick and Mahony
// formulations (filter/madgwick.hpp, filter/mahony.hpp): x is the horizontal magnetic field,
// z is up. Those filters keep their estimate in this frame and report it in ENU.
//
// All functions are pure and cheap (no allocation); thread-safe.
#pragma once

#include "math/quaternion.hpp"

namespace mocap::math {

/// q_enu_nwu: +90° about z, from the north-west-up frame (x = magnetic north, z up) to ENU.
Quat q_enu_nwu();

/// q_nwu_sensor of an attitude given in ENU: q_enu_nwu* ⊗ q_enu_sensor.
Quat nwu_from_enu(const Quat& q_enu_sensor);

/// The published algorithms' earth-field reference b = [|h_xy|, 0, h_z], h the unit field
/// mag_unit rotated into the NWU frame by q_nwu_sensor.
Vec3 nwu_field_reference(const Quat& q_nwu_sensor, const Vec3& mag_unit);

}  // namespace mocap::math
