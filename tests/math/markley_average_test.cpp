#include "math/markley_average.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace mocap::math {
namespace {

Quat random_quat(std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

Vec3 random_vec(std::mt19937& rng, double sigma) {
    std::normal_distribution<double> n(0.0, sigma);
    return {n(rng), n(rng), n(rng)};
}

double qdist(const Quat& a, const Quat& b) {
    return angle_rad(a * b.conjugate());
}

Quat neg(const Quat& q) {
    return Quat(-q.w(), -q.x(), -q.y(), -q.z());
}

TEST(MarkleyAverage, XiMatrixIsTheConjugateProductAndOrthonormal) {
    std::mt19937 rng(3);
    for (int i = 0; i < 50; ++i) {
        const Quat q = random_quat(rng), p = random_quat(rng);
        const Mat43 xi = xi_matrix(q);
        EXPECT_LT((xi.transpose() * to_wxyz(p) - (q.conjugate() * p).vec()).norm(), 1e-12);
        EXPECT_LT((xi.transpose() * xi - Mat3::Identity()).norm(), 1e-12);
        EXPECT_LT((xi.transpose() * to_wxyz(q)).norm(), 1e-12);
    }
}

TEST(MarkleyAverage, IdenticalQuaternionsAverageToThemselves) {
    std::mt19937 rng(1);
    for (int i = 0; i < 20; ++i) {
        const Quat q = random_quat(rng);
        const std::vector<Quat> qs(7, q);
        EXPECT_LT(qdist(average_quaternions(qs), q), 1e-9);
    }
}

TEST(MarkleyAverage, SignOfInputsDoesNotMatter) {
    std::mt19937 rng(2);
    const Quat center = random_quat(rng);
    std::vector<Quat> qs, flipped;
    std::vector<double> w;
    for (int i = 0; i < 9; ++i) {
        const Quat q = center * quat_from_rotvec(random_vec(rng, 0.3));
        qs.push_back(q);
        flipped.push_back(i % 2 ? neg(q) : q);
        w.push_back(0.5 + i);
    }
    const Quat a = average_quaternions(qs, w);
    const Quat b = average_quaternions(flipped, w);
    EXPECT_LT(qdist(a, b), 1e-12);
    EXPECT_GE(a.w(), 0.0);
    // A normalised sum would be wrecked by the flips; the eigenvector is not.
    EXPECT_LT(qdist(a, center), 0.3);
}

TEST(MarkleyAverage, SymmetricSpreadAveragesToCenter) {
    std::mt19937 rng(4);
    for (int t = 0; t < 10; ++t) {
        const Quat center = random_quat(rng);
        std::vector<Quat> qs;
        for (int i = 0; i < 5; ++i) {
            const Vec3 d = random_vec(rng, 0.4);
            qs.push_back(center * quat_from_rotvec(d));
            qs.push_back(center * quat_from_rotvec(-d));
        }
        EXPECT_LT(qdist(average_quaternions(qs), center), 1e-9);
    }
}

TEST(MarkleyAverage, TwoQuaternionClosedFormEqualsEigenSolution) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.05, 3.0);
    for (int i = 0; i < 200; ++i) {
        const Quat q1 = random_quat(rng);
        Quat q2 = random_quat(rng);
        if (i % 3 == 0) q2 = neg(q2);
        const double w1 = u(rng), w2 = u(rng);
        const std::vector<Quat> qs{q1, q2};
        const std::vector<double> w{w1, w2};
        const Quat eig = average_quaternions(qs, w);
        const Quat cf = average_two(q1, w1, q2, w2);
        EXPECT_LT(qdist(eig, cf), 1e-7) << i;
    }
    // Equal weights: the midpoint of the shortest arc.
    const Quat a = quat_from_rotvec(Vec3(0, 0, 0.2));
    const Quat b = quat_from_rotvec(Vec3(0, 0, 1.0));
    EXPECT_LT(qdist(average_two(a, 1.0, neg(b), 1.0), quat_from_rotvec(Vec3(0, 0, 0.6))), 1e-12);
}

// Orthogonal as 4-vectors = the same attitude turned 180°. The largest eigenvalue of M is then
// double; average_two returns (q1 + s q2)/√2 with s the sign of q1ᵀq2 (+ for an exact 0),
// the arc's midpoint, 90° from each (it used to return (0, 0, 0, 0) for an exact 0).
TEST(MarkleyAverage, TwoOrthogonalQuaternionsWithEqualWeightsGiveTheArcMidpoint) {
    const auto expect_midpoint = [](const Quat& q1, const Quat& q2, double w) {
        const Quat m = average_two(q1, w, q2, w);
        ASSERT_TRUE(m.coeffs().allFinite());
        EXPECT_NEAR(m.norm(), 1.0, 1e-12);
        EXPECT_GE(m.w(), 0.0);
        EXPECT_NEAR(qdist(m, q1), 0.5 * std::numbers::pi, 1e-9);
        EXPECT_NEAR(qdist(m, q2), 0.5 * std::numbers::pi, 1e-9);
        const double s = q1.coeffs().dot(q2.coeffs()) < 0.0 ? -1.0 : 1.0;
        EXPECT_LT(qdist(m, from_wxyz((to_wxyz(q1) + s * to_wxyz(q2)).normalized())), 1e-9);
        // Still an average: an eigenvector of M for its largest eigenvalue.
        QuatAccumulator acc;
        acc.add(q1, w);
        acc.add(q2, w);
        const Vec4 x = to_wxyz(m);
        EXPECT_NEAR(x.dot(acc.matrix() * x), max_eigenvector(acc.matrix()).eigenvalue, 1e-9 * w);
    };
    // q1ᵀq2 exactly 0.
    const Quat a(0.6, 0.8, 0.0, 0.0), b(0.0, 0.0, -0.8, 0.6);
    ASSERT_EQ(a.coeffs().dot(b.coeffs()), 0.0);
    for (const double w : {1.0, 0.37, 4e7}) {
        expect_midpoint(a, b, w);
        expect_midpoint(b, a, w);
        expect_midpoint(a, neg(b), w);
        expect_midpoint(Quat::Identity(), Quat(0.0, 0.0, 0.0, 1.0), w);
    }
    EXPECT_LT(qdist(average_two(a, 2.0, b, 2.0), from_wxyz((to_wxyz(a) + to_wxyz(b)).normalized())), 1e-12);
    // q1 ⊗ (0, n): orthogonal up to rounding, q1ᵀq2 of either sign.
    std::mt19937 rng(8);
    for (int i = 0; i < 50; ++i) {
        const Quat q1 = random_quat(rng);
        const Vec3 n = random_vec(rng, 1.0).normalized();
        const Quat q2 = q1 * Quat(0.0, n.x(), n.y(), n.z());
        ASSERT_LT(std::abs(q1.coeffs().dot(q2.coeffs())), 1e-12);
        expect_midpoint(q1, q2, 1.0);
        // The limit from inputs slightly closer than orthogonal.
        const Quat q2_near = (q1 * quat_from_rotvec(n * (std::numbers::pi - 1e-7))).normalized();
        ASSERT_GT(q1.coeffs().dot(q2_near.coeffs()), 0.0);
        EXPECT_LT(qdist(average_two(q1, 1.0, q2_near, 1.0), from_wxyz((to_wxyz(q1) + to_wxyz(q2)).normalized())), 1e-6);
    }
}

TEST(MarkleyAverage, TwoQuaternionWeightsThatAreNotPositiveAreDefined) {
    const Quat a = quat_from_rotvec(Vec3(0.3, -0.2, 0.1));
    const Quat b = quat_from_rotvec(Vec3(-0.5, 0.4, 1.2));
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    const struct {
        double w1, w2;
        Quat expected;
    } cases[] = {
        {0.0, 1.0, b},
        {1.0, 0.0, a},
        {-1.0, 2.0, b},
        {3.0, -0.5, a},
        {nan, 1.0, b},
        {1.0, nan, a},
        {0.0, 0.0, Quat::Identity()},
        {-1.0, -1.0, Quat::Identity()},
        {nan, nan, Quat::Identity()},
        {inf, 1.0, a},
        {1.0, inf, b},
        {-inf, 2.0, b},
        {inf, inf, average_two(a, 1.0, b, 1.0)},
        {1e300, 1e300, average_two(a, 1.0, b, 1.0)},
    };
    for (const auto& c : cases) {
        const Quat m = average_two(a, c.w1, b, c.w2);
        ASSERT_TRUE(m.coeffs().allFinite()) << c.w1 << ' ' << c.w2;
        EXPECT_NEAR(m.norm(), 1.0, 1e-12) << c.w1 << ' ' << c.w2;
        EXPECT_LT(qdist(m, c.expected), 1e-9) << c.w1 << ' ' << c.w2;
    }
}

TEST(MarkleyAverage, MatrixWeightsScaledIdentityReduceToScalarWeights) {
    std::mt19937 rng(6);
    std::uniform_real_distribution<double> u(0.1, 5.0);
    for (int t = 0; t < 20; ++t) {
        std::vector<Quat> qs;
        std::vector<double> w;
        std::vector<Mat3> info;
        const Quat center = random_quat(rng);
        for (int i = 0; i < 6; ++i) {
            qs.push_back(center * quat_from_rotvec(random_vec(rng, 0.5)));
            w.push_back(u(rng));
            info.push_back(w.back() * Mat3::Identity());
        }
        EXPECT_LT(qdist(average_quaternions(qs, w), average_quaternions(qs, info)), 1e-9);
    }
}

TEST(MarkleyAverage, MatrixWeightsTrustEachInputAlongItsGoodAxis) {
    // Input a is precise about x and vague about z, b the opposite: the average takes
    // each axis from the input that is sure about it.
    const Quat truth = Quat::Identity();
    const Quat a = quat_from_rotvec(Vec3(0.0, 0.0, 0.2));  // error on z only
    const Quat b = quat_from_rotvec(Vec3(0.2, 0.0, 0.0));  // error on x only
    const Mat3 ia = Vec3(1e4, 1.0, 1e-4).asDiagonal();     // sure about x, not z
    const Mat3 ib = Vec3(1e-4, 1.0, 1e4).asDiagonal();     // sure about z, not x
    const std::vector<Quat> qs{a, b};
    const std::vector<Mat3> info{ia, ib};
    EXPECT_LT(qdist(average_quaternions(qs, info), truth), 1e-3);
    // With equal scalar weights the result is half-way between.
    EXPECT_GT(qdist(average_quaternions(qs), truth), 0.09);
}

TEST(MarkleyAverage, CovarianceExactAndApproximationAgreeForSmallSpread) {
    std::mt19937 rng(7);
    const Quat center = random_quat(rng);
    std::vector<Quat> qs;
    std::vector<Mat3> info;
    for (int i = 0; i < 8; ++i) {
        qs.push_back(center * quat_from_rotvec(random_vec(rng, 1e-3)));
        const Vec3 s(0.01 + 0.01 * i, 0.02, 0.05);  // rad
        info.push_back(s.cwiseInverse().cwiseAbs2().asDiagonal());
    }
    const Mat3 p38 = average_covariance(qs, info);
    const Mat3 p39 = average_covariance_approx(info);
    EXPECT_LT((p38 - p39).norm() / p39.norm(), 1e-3);
    // Identical inputs: exact equality.
    const std::vector<Quat> same(8, center);
    EXPECT_LT((average_covariance(same, info) - p39).norm() / p39.norm(), 1e-9);
}

TEST(MarkleyAverage, CovarianceMatchesMonteCarloSpreadOfTheAverage) {
    // Averages of N noisy copies with R = σ²I: the average's error covariance is σ²/N I.
    std::mt19937 rng(8);
    const double sigma = 0.02;
    const int n = 10, trials = 2000;
    const Quat truth = random_quat(rng);
    Mat3 emp = Mat3::Zero();
    for (int t = 0; t < trials; ++t) {
        std::vector<Quat> qs;
        for (int i = 0; i < n; ++i)
            qs.push_back(truth * quat_from_rotvec(random_vec(rng, sigma)));
        const Vec3 e = rotvec_from_quat(truth.conjugate() * average_quaternions(qs));
        emp += e * e.transpose() / trials;
    }
    const std::vector<Mat3> info(n, Mat3::Identity() / (sigma * sigma));
    const Mat3 p = average_covariance_approx(info);
    EXPECT_NEAR(emp.trace() / p.trace(), 1.0, 0.1);
}

TEST(MarkleyAverage, AccumulatorPowerIterationMatchesEigenSolver) {
    std::mt19937 rng(9);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int t = 0; t < 50; ++t) {
        const Quat center = random_quat(rng);
        // From tight clouds (fast path) to almost uniform ones (fallback path).
        const double spread = t < 25 ? 0.05 : 2.0;
        QuatAccumulator acc;
        for (int i = 0; i < 256; ++i) {
            Quat q = center * quat_from_rotvec(random_vec(rng, spread));
            if (i % 2) q = neg(q);
            acc.add(q.w(), q.x(), q.y(), q.z(), u(rng));
        }
        const Quat ref = max_eigenvector(acc.matrix()).q;
        EXPECT_LT(qdist(acc.mean(center), ref), 1e-8) << t;
        // A hint orthogonal to the answer still ends at the largest eigenvalue.
        const Quat orth = center * Quat(0, 1, 0, 0);
        EXPECT_LT(qdist(acc.mean(orth), ref), 1e-8) << t;
    }
}

TEST(MarkleyAverage, StructureOfArraysAddEqualsOneByOne) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<double> qw, qx, qy, qz, w;
    QuatAccumulator one;
    for (int i = 0; i < 37; ++i) {
        const Quat q = random_quat(rng);
        qw.push_back(q.w());
        qx.push_back(q.x());
        qy.push_back(q.y());
        qz.push_back(q.z());
        w.push_back(u(rng));
        one.add(q, w.back());
    }
    QuatAccumulator soa;
    soa.add(qw.data(), qx.data(), qy.data(), qz.data(), w.data(), 37);
    EXPECT_LT((soa.matrix() - one.matrix()).norm(), 1e-12);
    EXPECT_NEAR(soa.weight_sum(), one.weight_sum(), 1e-12);
}

TEST(MarkleyAverage, PowerIterationHandlesNegativeSemidefiniteMatrixForm) {
    std::mt19937 rng(10);
    const Quat center = random_quat(rng);
    QuatAccumulator acc;
    for (int i = 0; i < 5; ++i)
        acc.add(center * quat_from_rotvec(random_vec(rng, 0.1)), Mat3(Vec3(1, 2, 3).asDiagonal()));
    const MaxEigen ref = max_eigenvector(acc.matrix());
    EXPECT_LE(ref.eigenvalue, 1e-12);
    EXPECT_LT(qdist(acc.mean(center), ref.q), 1e-8);
}

}  // namespace
}  // namespace mocap::math
