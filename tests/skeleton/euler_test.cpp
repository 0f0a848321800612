#include "skeleton/euler.hpp"

#include <gtest/gtest.h>

#include <random>

namespace mocap::skeleton {
namespace {

const char* kOrders[] = {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"};

TEST(Euler, ParseOrder) {
    EXPECT_EQ(to_string(*parse_rotation_order("zxy")), "ZXY");
    EXPECT_FALSE(parse_rotation_order("ZZY"));
    EXPECT_FALSE(parse_rotation_order("ZX"));
    EXPECT_FALSE(parse_rotation_order("ZXW"));
}

TEST(Euler, ComposesInListedOrder) {
    // ZXY means Rz · Rx · Ry (intrinsic), as BVH channels are applied.
    const auto o = *parse_rotation_order("ZXY");
    const Quat q = from_euler(o, {0.3, -0.2, 0.7});
    const Quat ref = Quat(Eigen::AngleAxisd(0.3, Vec3::UnitZ())) * Quat(Eigen::AngleAxisd(-0.2, Vec3::UnitX())) *
                     Quat(Eigen::AngleAxisd(0.7, Vec3::UnitY()));
    EXPECT_LT(q.angularDistance(ref), 1e-12);
}

TEST(Euler, RoundTripAllOrdersRandom) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-3.1, 3.1);
    std::uniform_real_distribution<double> m(-1.5, 1.5);
    for (const char* name : kOrders) {
        const auto o = *parse_rotation_order(name);
        for (int i = 0; i < 2000; ++i) {
            const std::array<double, 3> a{u(rng), m(rng), u(rng)};
            const Quat q = from_euler(o, a);
            const auto b = to_euler(o, q);
            EXPECT_NEAR(b[0], a[0], 1e-9) << name;
            EXPECT_NEAR(b[1], a[1], 1e-9) << name;
            EXPECT_NEAR(b[2], a[2], 1e-9) << name;
        }
    }
}

TEST(Euler, GimbalLockStillReproducesTheRotation) {
    for (const char* name : kOrders) {
        const auto o = *parse_rotation_order(name);
        for (const double mid : {M_PI / 2, -M_PI / 2}) {
            const Quat q = from_euler(o, {0.4, mid, -0.9});
            const Quat back = from_euler(o, to_euler(o, q));
            EXPECT_LT(q.angularDistance(back), 1e-6) << name;
        }
    }
}

}  // namespace
}  // namespace mocap::skeleton
