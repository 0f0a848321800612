// angles_csv.hpp — the joint-angle CSV export (docs/outputs.md), shared by `mocapd
// --replay --angles-out` and `mocap-client angles`, so both write the same format:
//
//   subject,sync,t_s,<joint>.flexion_deg,<joint>.abduction_deg,<joint>.rotation_deg,...
//   1,1042,10.420000,12.345,-3.210,0.500,...
//
// t_s = sample instant (sink clock) in seconds; angles in degrees with 3 decimals, in the
// order of the joint-angle names (Hello.skeleton.joint_angle_names: "<joint>.<axis>").
// Header-only, no dependencies; pure functions.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace mocap::serve {

inline std::string angles_csv_header(const std::vector<std::string>& joint_angle_names) {
    std::string h = "subject,sync,t_s";
    for (const auto& n : joint_angle_names)
        h += "," + n + "_deg";
    h += '\n';
    return h;
}

/// Appends one row; `angles_rad` holds `count` values (double or float).
template <typename T>
void append_angles_csv_row(std::uint32_t subject, std::uint64_t sync, std::int64_t sample_us, const T* angles_rad,
                           std::size_t count, std::string& out) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%u,%llu,%.6f", subject, static_cast<unsigned long long>(sync),
                  static_cast<double>(sample_us) * 1e-6);
    out += buf;
    constexpr double kDeg = 57.29577951308232;
    for (std::size_t i = 0; i < count; ++i) {
        std::snprintf(buf, sizeof buf, ",%.3f", static_cast<double>(angles_rad[i]) * kDeg);
        out += buf;
    }
    out += '\n';
}

}  // namespace mocap::serve
