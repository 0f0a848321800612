#include "truth_check.hpp"

#include <algorithm>
#include <numbers>
#include <sstream>

#include "harness.hpp"
#include "math/quaternion.hpp"

namespace mocap::itest {
using math::Quat;

// t_us,subject,segment,node,counter,seg_qw,seg_qx,seg_qy,seg_qz,sensor_qw,...
std::map<TruthKey, Quat> read_truth(const std::string& path) {
    std::map<TruthKey, Quat> out;
    std::istringstream in(read_file(path));
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
        std::vector<std::string> f;
        std::stringstream ls(line);
        for (std::string x; std::getline(ls, x, ',');)
            f.push_back(x);
        if (f.size() < 9) continue;
        out[{static_cast<std::uint32_t>(std::stoul(f[1])), static_cast<std::uint32_t>(std::stoul(f[4])), f[2]}] =
            Quat(std::stod(f[5]), std::stod(f[6]), std::stod(f[7]), std::stod(f[8]));
    }
    return out;
}

Quat segment_q(const v1::SkeletonFrame& f, int i) {
    return Quat(f.q_world_segment_wxyz(4 * i), f.q_world_segment_wxyz(4 * i + 1), f.q_world_segment_wxyz(4 * i + 2),
                f.q_world_segment_wxyz(4 * i + 3))
        .normalized();
}

std::uint32_t counter_of(const v1::SkeletonFrame& f) {
    return static_cast<std::uint32_t>(f.sync() & 0xFFFFFFFFu);
}

TruthErrors truth_errors(const std::vector<v1::SkeletonFrame>& frames, const std::vector<std::string>& segment_names,
                         const std::string& truth_csv_path, std::uint32_t subject, std::uint32_t motion_start) {
    TruthErrors out;
    const auto truth = read_truth(truth_csv_path);
    if (truth.empty()) return out;
    const Quat pelvis0 = truth.begin()->second;
    const double psi = math::to_euler_zyx(pelvis0).yaw_rad;
    const Quat rz_psi(Eigen::AngleAxisd(psi, math::Vec3::UnitZ()));
    const auto n = static_cast<int>(segment_names.size());
    for (const auto& f : frames) {
        if (f.subject_id() != subject || f.flags_size() == 0) continue;
        if ((f.flags(0) & v1::SEGMENT_CALIBRATED) == 0) continue;
        ++out.calibrated_frames;
        if (static_cast<int>(f.segment_count()) != n || f.q_world_segment_wxyz_size() != 4 * n || f.flags_size() != n) {
            ++out.malformed;
            continue;
        }
        if (counter_of(f) < motion_start) continue;
        ++out.motion_frames;
        for (int i = 0; i < n; ++i) {
            if ((f.flags(i) & v1::SEGMENT_STALE) != 0) ++out.stale;
            const auto it = truth.find({subject, counter_of(f), segment_names[static_cast<std::size_t>(i)]});
            if (it == truth.end()) continue;
            const Quat q_err = segment_q(f, i) * rz_psi * it->second.conjugate();
            out.err_deg.push_back(math::error_total_rad(q_err) * 180.0 / std::numbers::pi);
        }
    }
    std::sort(out.err_deg.begin(), out.err_deg.end());
    return out;
}

}  // namespace mocap::itest
