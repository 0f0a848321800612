#include "math/nwu_frame.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace mocap::math {
namespace {

TEST(NwuFrame, NorthWestUpAxesLandOnTheirEnuDirections) {
    const Quat q = q_enu_nwu();
    EXPECT_NEAR((rotate(q, Vec3::UnitX()) - Vec3::UnitY()).norm(), 0.0, 1e-15);  // north
    EXPECT_NEAR((rotate(q, Vec3::UnitY()) + Vec3::UnitX()).norm(), 0.0, 1e-15);  // west
    EXPECT_NEAR((rotate(q, Vec3::UnitZ()) - Vec3::UnitZ()).norm(), 0.0, 1e-15);  // up
}

TEST(NwuFrame, FromEnuUndoesTheFrameChange) {
    const Quat q_enu_sensor(Eigen::AngleAxisd(0.7, Vec3(1.0, -2.0, 0.5).normalized()));
    const Quat q_nwu_sensor = nwu_from_enu(q_enu_sensor);
    EXPECT_NEAR(angle_rad((q_enu_nwu() * q_nwu_sensor) * q_enu_sensor.conjugate()), 0.0, 1e-12);
    // The ENU identity seen from NWU: -90° about z.
    EXPECT_NEAR(angle_rad(nwu_from_enu(Quat::Identity()) * q_enu_nwu()), 0.0, 1e-15);
}

TEST(NwuFrame, FieldReferenceKeepsTheDipAndPointsNorth) {
    // A field dipping 60° down towards magnetic north, seen by a sensor turned 30° about z.
    const double dip = std::numbers::pi / 3.0;
    const Vec3 field_nwu(std::cos(dip), 0.0, -std::sin(dip));
    const Quat q_nwu_sensor(Eigen::AngleAxisd(std::numbers::pi / 6.0, Vec3::UnitZ()));
    const Vec3 mag_unit = rotate(q_nwu_sensor.conjugate(), field_nwu);
    const Vec3 b = nwu_field_reference(q_nwu_sensor, mag_unit);
    EXPECT_NEAR((b - field_nwu).norm(), 0.0, 1e-12);
    // A heading error moves the measured field off north; the reference stays on north.
    const Quat wrong(Eigen::AngleAxisd(0.4, Vec3::UnitZ()));
    const Vec3 b_wrong = nwu_field_reference(wrong * q_nwu_sensor, mag_unit);
    EXPECT_NEAR((b_wrong - field_nwu).norm(), 0.0, 1e-12);
}

}  // namespace
}  // namespace mocap::math
