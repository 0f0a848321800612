#include "sim/stream_truth.hpp"

#include "serve/angles_csv.hpp"

namespace mocap::sim {

TruthAngles::TruthAngles(const skeleton::BodyModel& model)
    : joints_(skeleton::default_joint_specs(model)), angles_(joints_.size()), values_rad_(3 * joints_.size()) {
    // The names the daemon announces (server/daemon/outputs.cpp, joint_angle_names).
    for (const skeleton::JointSpec& j : joints_) {
        for (const char* axis : {"flexion", "abduction", "rotation"})
            names_.push_back(j.name + "." + axis);
    }
}

std::string TruthAngles::header() const {
    return serve::angles_csv_header(names_);
}

void TruthAngles::append_row(std::uint32_t subject, std::uint64_t sync, std::int64_t t_us,
                             std::span<const skeleton::Quat> q_earth_segment, std::string& out) {
    skeleton::compute_joint_angles(joints_, q_earth_segment, std::span(angles_));
    for (std::size_t i = 0; i < angles_.size(); ++i) {
        values_rad_[3 * i] = angles_[i].flexion_rad;
        values_rad_[3 * i + 1] = angles_[i].abduction_rad;
        values_rad_[3 * i + 2] = angles_[i].rotation_rad;
    }
    serve::append_angles_csv_row(subject, sync, t_us, values_rad_.data(), values_rad_.size(), out);
}

}  // namespace mocap::sim
