// mocap-sim csv --scenario chain: the five-segment arm's readings are its kinematics (gyro
// integrates to the truth, accelerometer = specific force of the positions' second derivative,
// magnetometer = the environment at the sensor), the CHAIN.toml axes are the joints' axes in
// the sensor frames, and the motion has the pauses, single-joint and all-joint episodes the
// scenario promises. Checked without any filter, on ideal sensors.
#include <gtest/gtest.h>

#include <unistd.h>

#include <toml++/toml.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "filter_tool/recording_csv.hpp"
#include "sim/chain_scenario.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;
const Vec3 kGravityUp(0.0, 0.0, 9.81);

Vec3 vec(const Vec3d& a) {
    return {a[0], a[1], a[2]};
}

double percentile(std::vector<double> v, double p) {
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1))];
}

// The lab's furniture without its floor: a disturbed field that costs little to evaluate.
const MagneticEnv& furniture() {
    static const MagneticEnv env = [] {
        MagneticEnvSpec spec = *make_magnetic_env_spec("lab", 3);
        spec.floor.clear();
        return MagneticEnv(spec);
    }();
    return env;
}

// One noiseless recording for the tests of this file: 120 s at 40 Hz covers the still start,
// the five single-group episodes (each joint alone and the base alone) that open every run and
// the one that moves everything.
const ChainRecording& ideal_chain() {
    static const ChainRecording rec = [] {
        ChainOptions o;
        o.seed = 3;
        o.duration_s = 120.0;
        o.noise_scale = 0.0;
        return make_chain_scenario(o, furniture());
    }();
    return rec;
}

TEST(ChainScenario, GyroIntegratesToTheTruthOnIdealSensors) {
    const ChainRecording& rec = ideal_chain();
    ASSERT_EQ(rec.sensors.size(), 5u);
    const double dt = 1.0 / rec.rate_hz;
    for (const ChainSensor& s : rec.sensors) {
        ASSERT_EQ(s.rows.size(), 4801u);
        EXPECT_EQ(s.gyro_bias_rad_s, Vec3::Zero()) << "noise scale 0: no bias either";
        Quat q = s.rows[0].q_earth_sensor;
        double worst = 0.0;
        for (std::size_t k = 1; k < s.rows.size(); ++k) {
            q = (q * math::quat_exp(0.5 * dt * vec(s.rows[k].sample.gyro_rad_s))).normalized();
            worst = std::max(worst, math::angle_rad(math::conj(q) * s.rows[k].q_earth_sensor));
        }
        EXPECT_LT(worst, 1e-9) << s.name;
    }
}

TEST(ChainScenario, AccelerometerIsTheSpecificForceOfThePositionsSecondDerivative) {
    // Numerov's relation between samples of a smooth trajectory,
    //   p[k+1] − 2 p[k] + p[k−1] = dt²/12 (a[k+1] + 10 a[k] + a[k−1]) + O(dt⁶ p⁽⁶⁾),
    // with a[k] = R[k] f[k] − g taken from the accelerometer: independent of how the
    // scenario computes a, and exact to ~1e-4 m/s² at 40 Hz for this motion.
    const ChainRecording& rec = ideal_chain();
    const double dt = 1.0 / rec.rate_hz;
    for (const ChainSensor& s : rec.sensors) {
        std::vector<Vec3> a;
        for (const ChainRow& r : s.rows)
            a.push_back(math::rotate(r.q_earth_sensor, vec(r.sample.accel_m_s2)) - kGravityUp);
        double worst = 0.0, largest = 0.0;
        for (std::size_t k = 1; k + 1 < s.rows.size(); ++k) {
            const Vec3 lhs =
                (s.rows[k + 1].position_m - 2.0 * s.rows[k].position_m + s.rows[k - 1].position_m) / (dt * dt);
            const Vec3 rhs = (a[k + 1] + 10.0 * a[k] + a[k - 1]) / 12.0;
            worst = std::max(worst, (lhs - rhs).norm());
            largest = std::max(largest, a[k].norm());
        }
        EXPECT_LT(worst, 2e-3) << s.name << " m/s²";
        EXPECT_GT(largest, 1.0) << s.name << ": the sensor accelerates";
        // At rest: +9.81 on the up axis, whatever the mounting.
        EXPECT_LT((math::rotate(s.rows[0].q_earth_sensor, vec(s.rows[0].sample.accel_m_s2)) - kGravityUp).norm(), 1e-9);
    }
}

TEST(ChainScenario, MagnetometerReadsTheEnvironmentAtTheSensor) {
    const ChainRecording& rec = ideal_chain();
    double largest_turn = 0.0;
    for (const ChainSensor& s : rec.sensors) {
        for (std::size_t k = 0; k < s.rows.size(); k += 7) {
            const ChainRow& r = s.rows[k];
            const Vec3 b = furniture().field_ut(r.position_m);
            EXPECT_LT((math::rotate(r.q_earth_sensor, vec(r.sample.mag_ut)) - b).norm(), 1e-9);
            largest_turn = std::max(largest_turn, (b - furniture().earth_field_ut()).norm());
        }
    }
    EXPECT_GT(largest_turn, 5.0) << "µT: the sensors pass near the workbench's steel";
}

TEST(ChainScenario, ChainAxesAreTheJointAxesInTheSensorFrames) {
    const ChainRecording& rec = ideal_chain();
    ASSERT_EQ(rec.joints.size(), 4u);
    for (std::size_t j = 0; j < rec.joints.size(); ++j) {
        const ChainJoint& joint = rec.joints[j];
        const ChainSensor& p = rec.sensors[j];
        const ChainSensor& c = rec.sensors[j + 1];
        EXPECT_EQ(joint.parent, p.name);
        EXPECT_EQ(joint.child, c.name);
        EXPECT_EQ(joint.type, j == 3 ? "2dof" : "hinge");
        EXPECT_NEAR(joint.axis_parent.norm(), 1.0, 1e-12);
        EXPECT_NEAR(joint.axis_child.norm(), 1.0, 1e-12);
        double worst_axis = 0.0, worst_centre = 0.0, dot_min = 1.0, dot_max = -1.0, bend = 0.0, spread = 0.0;
        const Quat q_rel0 = math::conj(p.rows[0].q_earth_sensor) * c.rows[0].q_earth_sensor;
        const Vec3 mapped0 = math::rotate(q_rel0, joint.axis_child);
        for (std::size_t k = 0; k < p.rows.size(); ++k) {
            const Quat& qp = p.rows[k].q_earth_sensor;
            const Quat& qc = c.rows[k].q_earth_sensor;
            const Quat q_rel = math::conj(qp) * qc;
            const Vec3 mapped = math::rotate(q_rel, joint.axis_child);
            worst_axis = std::max(worst_axis, (mapped - joint.axis_parent).norm());
            const double d = math::rotate(qp, joint.axis_parent).dot(math::rotate(qc, joint.axis_child));
            dot_min = std::min(dot_min, d);
            dot_max = std::max(dot_max, d);
            bend = std::max(bend, math::angle_rad(math::conj(q_rel0) * q_rel));
            spread = std::max(spread, std::acos(std::clamp(mapped.dot(mapped0), -1.0, 1.0)));
            // The joint centre is one point seen from both sensors.
            const Vec3 from_parent = p.rows[k].position_m + math::rotate(qp, joint.r_parent_m);
            const Vec3 from_child = c.rows[k].position_m + math::rotate(qc, joint.r_child_m);
            worst_centre = std::max(worst_centre, (from_parent - from_child).norm());
        }
        EXPECT_LT(worst_centre, 1e-9) << joint.parent << "-" << joint.child;
        EXPECT_GT(bend, 20.0 * kDeg) << joint.parent << "-" << joint.child << " moves";
        if (joint.type == "hinge") {
            // The relative rotation keeps the child's axis on the parent's.
            EXPECT_LT(worst_axis, 1e-9) << joint.parent << "-" << joint.child;
        } else {
            // 2-DoF: each axis is fixed in its own segment and the two stay orthogonal, but the
            // child's axis moves in the parent's frame (the second degree of freedom).
            EXPECT_NEAR(dot_min, 0.0, 1e-9);
            EXPECT_NEAR(dot_max, 0.0, 1e-9);
            EXPECT_GT(spread, 30.0 * kDeg);
        }
    }
    // Two parallel hinges and one perpendicular: seg2 carries the first two axes, seg3 the
    // second and the third.
    EXPECT_LT((rec.joints[0].axis_child - rec.joints[1].axis_parent).norm(), 1e-12);
    EXPECT_NEAR(rec.joints[1].axis_child.dot(rec.joints[2].axis_parent), 0.0, 1e-12);
}

TEST(ChainScenario, MotionPausesAndMovesOneJointOrAll) {
    const ChainRecording& rec = ideal_chain();
    const std::size_t n = rec.sensors[0].rows.size();
    const double dt = 1.0 / rec.rate_hz;
    // Rate of each degree-of-freedom group: the base, and each joint's relative rate.
    auto world_rate = [&](std::size_t i, std::size_t k) {
        return math::rotate(rec.sensors[i].rows[k].q_earth_sensor, rec.sensors[i].rows[k].gyro_true_rad_s);
    };
    std::size_t still_rows = 0, one_joint_rows = 0, all_rows = 0, still_runs = 0, run = 0;
    for (std::size_t k = 1; k < n; ++k) {
        const bool still = std::none_of(rec.sensors.begin(), rec.sensors.end(),
                                        [&](const ChainSensor& s) { return s.rows[k].moving; });
        if (still) {
            // movement = 0 means exactly still: no rotation, no acceleration.
            for (const ChainSensor& s : rec.sensors) {
                EXPECT_LT(s.rows[k].gyro_true_rad_s.norm(), 1e-9);
                EXPECT_LT(s.rows[k].lin_acc_earth_m_s2.norm(), 1e-6);
            }
            ++still_rows;
            if (++run == static_cast<std::size_t>(2.0 / dt)) ++still_runs;  // a pause of 2 s
            continue;
        }
        run = 0;
        // Clearly moving (well inside an episode's ramps): the base, and each joint.
        bool moving[5];
        moving[0] = world_rate(0, k).norm() > 1e-3 || rec.sensors[0].rows[k].lin_acc_earth_m_s2.norm() > 1e-2;
        for (std::size_t j = 1; j < 5; ++j)
            moving[j] = (world_rate(j, k) - world_rate(j - 1, k)).norm() > 1e-3;
        const auto count = std::count(std::begin(moving), std::end(moving), true);
        if (count == 1 && !moving[0]) ++one_joint_rows;
        if (count == 5) ++all_rows;
    }
    for (const ChainSensor& s : rec.sensors) {
        for (std::size_t k = 0; k * dt < 3.0; ++k)
            ASSERT_FALSE(s.rows[k].moving) << s.name << ": still for at least 3 s at the start";
    }
    EXPECT_GE(still_runs, 4u) << "the start and pauses between episodes";
    EXPECT_GT(one_joint_rows * dt, 20.0) << "s with only one joint moving";
    EXPECT_GT(all_rows * dt, 5.0) << "s with the base and every joint moving";
    EXPECT_GT(still_rows * dt, 15.0);
}

TEST(ChainScenario, ArmMovesAtTableHeightInTheLabsDisturbedField) {
    // What the scenario is for: five sensors a joint apart that disagree on heading.
    ChainOptions o;
    o.noise_scale = 0.0;
    const ChainRecording rec = make_chain_scenario(o, *MagneticEnv::load("lab", 1, nullptr));  // the default run
    std::vector<double> heights, spread, lin_acc_base;
    const double earth = field_heading_rad(earth_field_enu_ut(50.0, 60.0));
    for (std::size_t k = 0; k < rec.sensors[0].rows.size(); ++k) {
        double lo = 1e9, hi = -1e9;
        for (const ChainSensor& s : rec.sensors) {
            heights.push_back(s.rows[k].position_m.z());
            const double h = math::wrap_pi(field_heading_rad(s.rows[k].mag_earth_ut) - earth) / kDeg;
            lo = std::min(lo, h);
            hi = std::max(hi, h);
        }
        spread.push_back(hi - lo);
        lin_acc_base.push_back(rec.sensors[0].rows[k].lin_acc_earth_m_s2.norm());
    }
    std::cout << "[ metrics  ] sensor height p1 " << percentile(heights, 0.01) << " p50 " << percentile(heights, 0.5)
              << " p99 " << percentile(heights, 0.99) << " m; heading spread over the 5 sensors p50 "
              << percentile(spread, 0.5) << " p95 " << percentile(spread, 0.95) << " max " << percentile(spread, 1.0)
              << " deg; base |a| p95 " << percentile(lin_acc_base, 0.95) << " max " << percentile(lin_acc_base, 1.0)
              << " m/s²\n";
    // The hand turns the base about the arm's length by up to ±70°, so the hinges swing the far
    // segments below and above the bench (measured p1 0.46 m, p99 1.36 m, seed 1).
    EXPECT_GT(percentile(heights, 0.01), 0.3);
    EXPECT_LT(percentile(heights, 0.99), 1.6);
    // docs/simulator.md, "chain": the sensors disagree by ~14° typically, up to ±30–45°.
    EXPECT_GT(percentile(spread, 0.5), 8.0);
    EXPECT_GT(percentile(spread, 0.95), 15.0);
    EXPECT_GT(percentile(spread, 1.0), 40.0);
    EXPECT_LT(percentile(spread, 1.0), 120.0);
    EXPECT_GT(percentile(lin_acc_base, 0.95), 1.0) << "a hand moves the base";
}

TEST(ChainScenario, FilesAreChainTomlAndOneRecordingCsvPerSegment) {
    ChainOptions o;
    o.duration_s = 20.0;
    const ChainRecording rec = make_chain_scenario(o, *MagneticEnv::load("clean", 1, nullptr));
    const auto dir = std::filesystem::temp_directory_path() / ("mocap_chain_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    std::string error;
    ASSERT_TRUE(write_chain_files(rec, dir / "arm.toml", false, &error)) << error;
    const toml::table chain = toml::parse_file((dir / "arm.toml").string());
    const auto* segments = chain["segment"].as_array();
    ASSERT_NE(segments, nullptr);
    ASSERT_EQ(segments->size(), 5u);
    for (std::size_t i = 0; i < 5; ++i) {
        const toml::table& t = *segments->get(i)->as_table();
        EXPECT_EQ(t.size(), 2u) << "name and csv only";
        EXPECT_EQ(t["name"].value_or(std::string()), rec.sensors[i].name);
        const std::string csv = t["csv"].value_or(std::string());
        EXPECT_EQ(csv, rec.sensors[i].name + ".csv");
        std::ifstream in(dir / csv);
        tools::Recording r;
        const auto err = tools::read_recording_csv(in, r);
        ASSERT_FALSE(err) << err->to_string();
        EXPECT_TRUE(r.has_reference);
        EXPECT_TRUE(r.has_movement);
        ASSERT_EQ(r.rows.size(), rec.sensors[i].rows.size());
        EXPECT_LT(math::angle_rad(math::conj(r.rows.back().q_ref) * rec.sensors[i].rows.back().q_earth_sensor), 1e-9);
    }
    const auto* joints = chain["joint"].as_array();
    ASSERT_NE(joints, nullptr);
    ASSERT_EQ(joints->size(), 4u);
    for (std::size_t j = 0; j < 4; ++j) {
        const toml::table& t = *joints->get(j)->as_table();
        EXPECT_EQ(t.size(), 5u) << "parent, child, type, axis_parent, axis_child";
        EXPECT_EQ(t["parent"].value_or(std::string()), rec.joints[j].parent);
        EXPECT_EQ(t["child"].value_or(std::string()), rec.joints[j].child);
        EXPECT_EQ(t["type"].value_or(std::string()), rec.joints[j].type);
        for (const char* key : {"axis_parent", "axis_child"}) {
            const auto* a = t[key].as_array();
            ASSERT_NE(a, nullptr);
            ASSERT_EQ(a->size(), 3u);
            const Vec3 axis = std::string(key) == "axis_parent" ? rec.joints[j].axis_parent : rec.joints[j].axis_child;
            for (std::size_t c = 0; c < 3; ++c)
                EXPECT_NEAR(a->get(c)->value_or(0.0), axis[static_cast<Eigen::Index>(c)], 1e-9);
        }
    }
    const toml::table truth = toml::parse_file((dir / "truth.toml").string());
    EXPECT_EQ(truth["scenario"].value_or(std::string()), "chain");
    EXPECT_EQ(truth["segment"].as_array()->size(), 5u);
    EXPECT_NEAR(truth["segment"][0]["length_m"].value_or(0.0), rec.sensors[0].length_m, 1e-6);
    std::filesystem::remove_all(dir);
    EXPECT_FALSE(write_chain_files(rec, dir / "arm.toml", false, &error)) << "the folder is gone";
}

TEST(ChainScenario, SameSeedSameRecording) {
    ChainOptions o;
    o.duration_s = 15.0;
    const MagneticEnv env = *MagneticEnv::load("lab", 1, nullptr);
    const ChainRecording a = make_chain_scenario(o, env);
    const ChainRecording b = make_chain_scenario(o, env);
    o.seed = 2;
    const ChainRecording c = make_chain_scenario(o, env);
    EXPECT_EQ(vec(a.sensors[4].rows.back().sample.gyro_rad_s), vec(b.sensors[4].rows.back().sample.gyro_rad_s));
    EXPECT_EQ(a.joints[2].axis_child, b.joints[2].axis_child);
    EXPECT_NE(a.joints[2].axis_child, c.joints[2].axis_child);
}

}  // namespace
}  // namespace mocap::sim
