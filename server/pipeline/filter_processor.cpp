#include "pipeline/filter_processor.hpp"

#include <cmath>

namespace mocap::pipeline {
namespace {

bool finite(const Vec3d& v) {
    return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

bool FilterProcessor::accepts(const ImuSample& s) {
    return finite(s.gyro_rad_s) && finite(s.accel_m_s2) && (!s.has_mag() || finite(s.mag_ut));
}

bool FilterProcessor::process(const SegmentSample& in, SegmentPose& out) {
    if (in.has_node_quat) {
        const auto& q = in.node_q_wxyz;
        const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (!std::isfinite(n) || n < 0.5) return false;
        for (std::size_t i = 0; i < 4; ++i)
            out.q_earth_sensor_wxyz[i] = q[i] / n;
        out.flags |= kSegmentFromNode;
        return true;
    }
    const ImuSample& s = in.imu;
    if (!accepts(s)) return false;
    filter_->update(s);
    const math::Quat q = filter_->orientation();
    out.q_earth_sensor_wxyz = {q.w(), q.x(), q.y(), q.z()};
    const filter::HeadingSplit h = filter_->heading_split();
    if (h.has_mag_heading) {
        out.mag = h.mag_trusted ? SegmentMag::kTrusted : SegmentMag::kRejected;
        out.mag_heading_rad = static_cast<float>(h.mag_heading_rad);
        out.field_norm_ut = static_cast<float>(h.field_norm_ut);
        out.field_heading_rad = static_cast<float>(h.field_heading_rad);
        out.field_usable = h.field_usable;
        out.field_dip_rad = static_cast<float>(h.field_dip_rad);
    }
    out.frame_epoch = static_cast<std::uint8_t>(h.frame_epoch);
    const math::Vec3 rate = math::to_vec3(s.gyro_rad_s) - filter_->gyro_bias_rad_s();
    out.rate_rad_s = {static_cast<float>(rate.x()), static_cast<float>(rate.y()), static_cast<float>(rate.z())};
    out.accel_m_s2 = {static_cast<float>(s.accel_m_s2[0]), static_cast<float>(s.accel_m_s2[1]),
                      static_cast<float>(s.accel_m_s2[2])};
    return true;
}

}  // namespace mocap::pipeline
