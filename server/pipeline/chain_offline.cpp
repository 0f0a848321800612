#include "pipeline/chain_offline.hpp"

#include <algorithm>
#include <cmath>

#include "math/quaternion.hpp"

namespace mocap::pipeline {
namespace {

/// The field's norm and dip seen through a 0.5 s low-pass, per sample (0 where none): what
/// the chain compares between two segments before it trusts their fields' difference.
void field_of(std::span<const ImuSample> samples, std::vector<double>& norm_ut, std::vector<double>& dip_rad) {
    norm_ut.assign(samples.size(), 0.0);
    dip_rad.assign(samples.size(), 0.0);
    math::Vec3 m_lp = math::Vec3::Zero(), a_lp = math::Vec3::Zero();
    bool started = false;
    for (std::size_t k = 0; k < samples.size(); ++k) {
        const ImuSample& s = samples[k];
        if (!s.has_mag()) continue;
        const math::Vec3 m = math::to_vec3(s.mag_ut), a = math::to_vec3(s.accel_m_s2);
        const double dt = k > 0 ? static_cast<double>(s.t_us - samples[k - 1].t_us) * 1e-6 : 0.0;
        const double g = started ? 1.0 - std::exp(-std::max(dt, 0.0) / 0.5) : 1.0;
        m_lp += g * (m - m_lp);
        a_lp += g * (a - a_lp);
        started = true;
        const double n = m_lp.norm(), an = a_lp.norm();
        if (n <= 0.0 || an <= 0.0) continue;
        norm_ut[k] = n;
        // Positive down: the field against the measured up.
        dip_rad[k] = -std::asin(std::clamp(m_lp.dot(a_lp) / (n * an), -1.0, 1.0));
    }
}

/// The part of q about the vertical, rad.
double heading_of(const math::Quat& q) {
    return 2.0 * std::atan2(q.z(), q.w());
}

}  // namespace

std::vector<fusion::SegmentInput> offline_segment_inputs(const filter::OfflineSmoother& smoother,
                                                         filter::OrientationFilter& filter,
                                                         std::span<const ImuSample> samples) {
    const std::size_t n = samples.size();
    std::vector<ImuSample> samples_6d(samples.begin(), samples.end());
    for (ImuSample& s : samples_6d)
        s.flags |= kImuNoMag;
    const filter::OfflineResult r6 = smoother.smooth(filter, samples_6d);
    const bool with_mag = std::any_of(samples.begin(), samples.end(), [](const ImuSample& s) { return s.has_mag(); });
    filter::OfflineResult r9;
    if (with_mag) r9 = smoother.smooth(filter, samples);
    std::vector<double> norm_ut, dip_rad;
    field_of(samples, norm_ut, dip_rad);
    // A constant bias: what the raw rate has that the re-solved motion does not.
    math::Vec3 bias = math::Vec3::Zero();
    std::size_t steps = 0;
    for (std::size_t k = 1; k < n; ++k) {
        const double dt = static_cast<double>(samples[k].t_us - samples[k - 1].t_us) * 1e-6;
        if (dt <= 0.0) continue;
        const math::Vec3 w = math::rotvec_from_quat(r6.orientation[k - 1].conjugate() * r6.orientation[k]) / dt;
        bias += math::to_vec3(samples[k].gyro_rad_s) - w;
        ++steps;
    }
    if (steps > 0) bias /= static_cast<double>(steps);
    std::vector<fusion::SegmentInput> in(n);
    for (std::size_t k = 0; k < n; ++k) {
        fusion::SegmentInput& x = in[k];
        x.fresh = true;
        x.q6 = r6.orientation[k];
        x.gyro_rad_s = math::to_vec3(samples[k].gyro_rad_s) - bias;
        x.accel_m_s2 = math::to_vec3(samples[k].accel_m_s2);
        x.mag_available = with_mag;
        if (with_mag) {
            x.mag_heading_rad = heading_of(r9.orientation[k] * r6.orientation[k].conjugate());
            x.mag_trusted = r9.mag_used[k] != 0;
            // The re-solve's heading has no correction lag to take out: it is the field's.
            x.field_heading_rad = x.mag_heading_rad;
            x.field_usable = x.mag_trusted;
            x.field_norm_ut = norm_ut[k];
            x.field_dip_rad = dip_rad[k];
        }
    }
    return in;
}

ChainRows chain_rows(std::span<const ChainTrack> tracks) {
    const std::size_t ns = tracks.size();
    ChainRows rows;
    for (const ChainTrack& t : tracks)
        rows.sync.insert(rows.sync.end(), t.sync.begin(), t.sync.end());
    std::sort(rows.sync.begin(), rows.sync.end());
    rows.sync.erase(std::unique(rows.sync.begin(), rows.sync.end()), rows.sync.end());
    const std::size_t nr = rows.sync.size();
    rows.t_us.assign(nr, 0);
    rows.in.assign(nr * ns, fusion::SegmentInput{});
    rows.row_of.resize(ns);
    std::vector<char> timed(nr, 0);
    for (std::size_t s = 0; s < ns; ++s) {
        const ChainTrack& t = tracks[s];
        std::vector<std::size_t>& row_of = rows.row_of[s];
        row_of.resize(t.sync.size());
        std::size_t k = 0;  // the track's next sample
        for (std::size_t r = 0; r < nr; ++r) {
            fusion::SegmentInput& x = rows.in[r * ns + s];
            const std::size_t first = k;
            for (; k < t.sync.size() && t.sync[k] == rows.sync[r]; ++k) {  // a repeated instant: its last sample
                x = t.in[k];
                row_of[k] = r;
            }
            if (k > first) {
                if (!timed[r]) rows.t_us[r] = t.t_us[first];
                timed[r] = 1;
            } else if (r > 0) {
                x = rows.in[(r - 1) * ns + s];
                x.fresh = false;
            }
        }
    }
    for (std::size_t r = 1; r < nr; ++r)
        rows.t_us[r] = std::max(rows.t_us[r], rows.t_us[r - 1]);
    return rows;
}

std::vector<fusion::JointDef> body_chain_joints(const skeleton::BodyModel& model,
                                                const skeleton::FusionOptions& options,
                                                const skeleton::Calibration* calibration) {
    std::vector<fusion::JointDef> defs;
    for (const skeleton::BodyJoint& b : skeleton::body_joints(model)) {
        fusion::JointDef d = b.def;
        const auto p = static_cast<std::size_t>(d.parent), c = static_cast<std::size_t>(d.child);
        if (calibration != nullptr && d.type != fusion::JointType::kBall && calibration->calibrated[p] &&
            calibration->calibrated[c]) {
            // As the live chain stage takes them (skeleton::BodyChain::on_calibration).
            d.axis_parent = math::rotate(calibration->q_sensor_segment[p], b.axis_parent_segment).normalized();
            d.axis_child = math::rotate(calibration->q_sensor_segment[c], b.axis_child_segment).normalized();
            d.axes_known = true;
        }
        d.estimate_axes = d.type == fusion::JointType::kHinge && (options.estimate_axes || !d.axes_known);
        defs.push_back(d);
    }
    return defs;
}

}  // namespace mocap::pipeline
