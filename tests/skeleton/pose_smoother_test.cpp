#include "skeleton/pose_smoother.hpp"

#include <gtest/gtest.h>

#include <random>

namespace mocap::skeleton {
namespace {

double deg(double r) {
    return r * 180.0 / M_PI;
}

TEST(PoseSmoother, AlphaOneIsIdentity) {
    PoseSmoother s(PoseSmootherParams{1.0, 0.0, 500'000});
    std::mt19937 rng(2);
    std::normal_distribution<double> n;
    for (int f = 0; f < 50; ++f) {
        std::array<Quat, 15> q, in;
        for (auto& x : q)
            x = Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
        in = q;
        s.apply(f * 10'000, q);
        for (std::size_t i = 0; i < q.size(); ++i)
            EXPECT_EQ(q[i].coeffs(), in[i].coeffs());
    }
}

TEST(PoseSmoother, ConvergesToAConstantInput) {
    PoseSmoother s(PoseSmootherParams{0.2, 0.0, 500'000});
    std::array<Quat, 2> q{Quat::Identity(), Quat::Identity()};
    s.apply(0, q);
    const Quat target(Eigen::AngleAxisd(1.0, Vec3(1, 2, 3).normalized()));
    double prev = 1e9;
    for (int f = 1; f <= 60; ++f) {
        std::array<Quat, 2> in{target, target};
        s.apply(f * 10'000, in);
        const double e = deg(in[0].angularDistance(target));
        EXPECT_LT(e, prev);
        prev = e;
        if (f == 1) {
            EXPECT_NEAR(e, 0.8 * deg(1.0), 1e-6);  // one step covers α of the way
        }
    }
    EXPECT_LT(prev, 0.01);
}

TEST(PoseSmoother, TimeConstantIsRateIndependent) {
    const Quat target(Eigen::AngleAxisd(0.5, Vec3::UnitZ()));
    auto run = [&](int rate_hz) {
        PoseSmoother s(PoseSmootherParams{1.0, 0.1, 500'000});
        std::array<Quat, 1> q{Quat::Identity()};
        s.apply(0, q);
        const int frames = rate_hz / 10;  // 0.1 s = one time constant
        for (int f = 1; f <= frames; ++f) {
            q[0] = target;
            s.apply(static_cast<std::int64_t>(f) * 1'000'000 / rate_hz, q);
        }
        return q[0].angularDistance(target);
    };
    EXPECT_NEAR(run(100), 0.5 * std::exp(-1.0), 1e-3);
    EXPECT_NEAR(run(200), run(100), 1e-3);
}

TEST(PoseSmoother, RestartsOnGapsAndBackwardTime) {
    PoseSmoother s(PoseSmootherParams{0.1, 0.0, 100'000});
    std::array<Quat, 1> q{Quat::Identity()};
    s.apply(0, q);
    const Quat target(Eigen::AngleAxisd(1.0, Vec3::UnitX()));
    q[0] = target;
    s.apply(1'000'000, q);  // gap > reset_gap_us: passes through
    EXPECT_LT(q[0].angularDistance(target), 1e-12);
    q[0] = Quat::Identity();
    s.apply(500'000, q);  // backwards: passes through
    EXPECT_LT(q[0].angularDistance(Quat::Identity()), 1e-12);
}

}  // namespace
}  // namespace mocap::skeleton
