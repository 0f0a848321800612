// chain_recording.cpp — why: chain and pendulum differ only in how the truth moves; the
// readings, the noise and the files are one code path, so a method tested on one scenario
// sees the same sensor model on the other.
#include "sim/chain_recording.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>

#include "filter_tool/filter_run.hpp"
#include "filter_tool/recording_csv.hpp"
#include "sim/scenario.hpp"
#include "sim/sim_rng.hpp"
#include "sim/stream_node.hpp"

namespace mocap::sim {
namespace {

constexpr double kStillRad_s = 1e-9;  // below: the sensor did not turn
constexpr double kStillM_s2 = 1e-6;   // below: no linear acceleration (finite-difference noise)
const Vec3 kGravityUp = scenario_spec(ScenarioKind::realistic).gravity_up_m_s2;

Vec3 noise_vec(SimRng& rng, double sigma) {
    if (sigma <= 0.0) return Vec3::Zero();
    return sigma * Vec3(rng.normal(), rng.normal(), rng.normal());
}

std::string vec_text(const Vec3& v) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "[%.9f, %.9f, %.9f]", v.x(), v.y(), v.z());
    return buf;
}

std::string quat_text(const Quat& q) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "[%.9f, %.9f, %.9f, %.9f]", q.w(), q.x(), q.y(), q.z());
    return buf;
}

bool write_text(const std::filesystem::path& path, const std::string& text, std::string* error) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out || !(out << text) || !out.flush()) {
        *error = "cannot write " + path.string();
        return false;
    }
    return true;
}

}  // namespace

Quat random_rotation(std::uint64_t seed, std::uint64_t stream) {
    SimRng rng(seed, stream);
    for (;;) {
        const Quat q(rng.normal(), rng.normal(), rng.normal(), rng.normal());  // uniform on S³
        if (q.norm() > 1e-6) return math::canonical(q.normalized());
    }
}

void sense_track(const SensorTrack& track, double rate_hz, const MagneticEnv& env, double noise_scale,
                 std::uint64_t seed, std::uint64_t stream, ChainSensor& sensor) {
    const NodeSensorNoise noise = stream_node_noise(noise_scale);
    SimRng bias_rng(seed, stream ^ 0x42494153ull);  // "BIAS": independent of the noise
    SimRng noise_rng(seed, stream);
    for (int i = 0; i < 3; ++i)
        sensor.gyro_bias_rad_s[i] = bias_rng.sign() * bias_rng.uniform(0.25, 1.0) * noise.gyro_bias_max_rad_s;
    const double dt = 1.0 / rate_hz;
    const std::size_t n = track.q_earth_sensor.size();
    sensor.rows.clear();
    sensor.rows.reserve(n);
    for (std::size_t k = 0; k < n; ++k) {
        const Quat& q_prev = k == 0 ? track.q_before : track.q_earth_sensor[k - 1];
        const Quat& q = track.q_earth_sensor[k];
        ChainRow row;
        row.position_m = track.position_m[k];
        row.lin_acc_earth_m_s2 = track.lin_acc_earth_m_s2[k];
        row.mag_earth_ut = env.uniform() ? env.earth_field_ut() : env.field_ut(row.position_m);
        const SensorReading r = ideal_reading(q_prev, q, dt, row.lin_acc_earth_m_s2, row.mag_earth_ut);
        row.q_earth_sensor = math::canonical(q);
        row.gyro_true_rad_s = r.gyro_rad_s;
        row.moving = r.gyro_rad_s.norm() > kStillRad_s || row.lin_acc_earth_m_s2.norm() > kStillM_s2;
        row.sample.t_us = std::llround(static_cast<double>(k) * dt * 1e6);
        row.sample.gyro_rad_s =
            math::to_array(r.gyro_rad_s + sensor.gyro_bias_rad_s + noise_vec(noise_rng, noise.gyro_rad_s));
        // Specific force with the single-sensor scenarios' gravity (scenario_spec), not the
        // wire format's standard gravity that ideal_reading uses for the stream.
        const Vec3 f = math::rotate(math::conj(q), row.lin_acc_earth_m_s2 + kGravityUp);
        row.sample.accel_m_s2 = math::to_array(f + noise_vec(noise_rng, noise.accel_m_s2));
        row.sample.mag_ut = math::to_array(r.mag_ut + noise_vec(noise_rng, noise.mag_ut));
        sensor.rows.push_back(row);
    }
}

bool write_chain_files(const ChainRecording& rec, const std::filesystem::path& toml_path, bool ned,
                       std::string* error) {
    const std::filesystem::path dir = toml_path.parent_path();
    std::string chain = "# mocap-sim csv --scenario " + rec.scenario + " --seed " + std::to_string(rec.seed) +
                        ": the true joint axes (delete them to test axis estimation); truth.toml has the rest.\n";
    for (const ChainSensor& s : rec.sensors) {
        chain += "\n[[segment]]\nname = \"" + s.name + "\"\ncsv = \"" + s.name + ".csv\"\n";
        tools::Recording csv;
        csv.has_reference = true;
        csv.has_movement = true;
        csv.rows.reserve(s.rows.size());
        for (const ChainRow& row : s.rows) {
            tools::RecordingRow r;
            r.sample = row.sample;
            r.q_ref = math::canonical(
                tools::from_enu(row.q_earth_sensor, ned ? tools::EarthFrame::ned : tools::EarthFrame::enu));
            r.ref_valid = true;
            r.movement = row.moving;
            csv.rows.push_back(r);
        }
        const std::filesystem::path csv_path = dir / (s.name + ".csv");
        std::ofstream out(csv_path, std::ios::binary | std::ios::trunc);
        if (!out || !tools::write_recording_csv(out, csv) || !out.flush()) {
            *error = "cannot write " + csv_path.string();
            return false;
        }
    }
    for (const ChainJoint& j : rec.joints) {
        chain += "\n[[joint]]\nparent = \"" + j.parent + "\"\nchild = \"" + j.child + "\"\ntype = \"" + j.type +
                 "\"\naxis_parent = " + vec_text(j.axis_parent) + "\naxis_child = " + vec_text(j.axis_child) + "\n";
    }
    if (!write_text(toml_path, chain, error)) return false;

    char head[512];
    std::snprintf(head, sizeof head,
                  "# The truth behind %s (docs/simulator.md, \"Chain files\"). Sensor frames: the sensor's own axes;\n"
                  "# segment frames: x along the segment from its proximal to its distal joint.\n"
                  "scenario = \"%s\"\nseed = %llu\nrate_hz = %.6g\nduration_s = %.6g\nmagnetic_env = \"%s\"\n"
                  "reference_frame = \"%s\"\n",
                  toml_path.filename().string().c_str(), rec.scenario.c_str(),
                  static_cast<unsigned long long>(rec.seed), rec.rate_hz, rec.duration_s, rec.magnetic_env.c_str(),
                  ned ? "ned" : "enu");
    std::string truth = head;
    for (const ChainSensor& s : rec.sensors) {
        char buf[128];
        std::snprintf(buf, sizeof buf, "%.6f", s.length_m);
        truth += "\n[[segment]]\nname = \"" + s.name + "\"\nlength_m = " + buf +
                 "\nq_segment_sensor = " + quat_text(s.q_segment_sensor) +
                 "  # w, x, y, z: the mounting, sensor frame into segment frame\ngyro_bias_rad_s = " +
                 vec_text(s.gyro_bias_rad_s) + "\n";
    }
    for (const ChainJoint& j : rec.joints) {
        truth += "\n[[joint]]\nparent = \"" + j.parent + "\"\nchild = \"" + j.child + "\"\ntype = \"" + j.type +
                 "\"\naxis_parent = " + vec_text(j.axis_parent) + "\naxis_child = " + vec_text(j.axis_child) +
                 "\nr_parent_m = " + vec_text(j.r_parent_m) + "  # joint centre from the parent's sensor, its frame" +
                 "\nr_child_m = " + vec_text(j.r_child_m) + "  # joint centre from the child's sensor, its frame\n";
        if (j.axis_wander_deg > 0.0) {
            char buf[64];
            std::snprintf(buf, sizeof buf, "%.3f", j.axis_wander_deg);
            truth += std::string("axis_wander_deg = ") + buf + "\n";
        }
        if (!j.note.empty()) truth += "# " + j.note + "\n";
    }
    return write_text(dir / "truth.toml", truth, error);
}

}  // namespace mocap::sim
