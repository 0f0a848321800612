#include "daemon/replay_offline.hpp"

#include <spdlog/spdlog.h>

#include <map>
#include <optional>

#include "daemon/calibration_files.hpp"
#include "filter/filter_factory.hpp"
#include "filter/offline_smoother.hpp"
#include "fusion/chain_smoother.hpp"
#include "pipeline/chain_offline.hpp"
#include "pipeline/filter_processor.hpp"

namespace mocap::daemon {

namespace {

void set_node_quat(SegmentSample& s, const math::Quat& q) {
    s.node_q_wxyz = {q.w(), q.x(), q.y(), q.z()};
    s.has_node_quat = true;
}

/// One subject's take through the chain smoother (replay.hpp, "Offline"): `take` holds, per
/// segment, the indices of its samples in `samples`.
bool smooth_subject_chain(const OfflineSetup& setup, std::uint32_t subject,
                          const std::vector<std::vector<std::size_t>>& take, std::vector<SegmentSample>& samples,
                          std::string* error) {
    const skeleton::BodyModel& model = setup.pipeline.model();
    const std::size_t ns = model.size();
    const filter::OfflineSmoother smoother;
    std::vector<std::vector<std::uint64_t>> sync(ns);
    std::vector<std::vector<std::int64_t>> t_us(ns);
    std::vector<std::vector<fusion::SegmentInput>> in(ns);
    std::vector<pipeline::ChainTrack> tracks(ns);
    std::vector<ImuSample> imu;
    for (std::size_t s = 0; s < ns; ++s) {
        if (take[s].empty()) continue;
        auto f = filter::make_filter(model.segments[s].filter, setup.config.filter_params, error);
        if (!f) return false;
        imu.clear();
        for (const std::size_t i : take[s]) {
            imu.push_back(samples[i].imu);
            sync[s].push_back(samples[i].sync);
            t_us[s].push_back(samples[i].imu.t_us);
        }
        in[s] = pipeline::offline_segment_inputs(smoother, *f, imu);
        tracks[s] = {sync[s], t_us[s], in[s]};
    }
    const pipeline::ChainRows rows = pipeline::chain_rows(tracks);
    // The rows hold their own copies: the per-segment ones go before the passes allocate theirs.
    tracks.clear();
    in.clear();
    sync.clear();
    t_us.clear();
    // The calibration the solver starts the replay with, if any: one made during the replay
    // comes too late for the joints' axes, which the take then gives.
    std::optional<skeleton::Calibration> calibration;
    if (!setup.calibration_dir.empty())
        calibration = CalibrationFiles(setup.calibration_dir).load(model, subject).calibration;
    const std::vector<fusion::JointDef> joints =
        pipeline::body_chain_joints(model, setup.fusion, calibration ? &*calibration : nullptr);
    if (const std::string bad = fusion::ChainEstimator::check(ns, joints); !bad.empty()) {
        *error = "offline chain of subject " + std::to_string(subject) + ": " + bad;
        return false;
    }
    const fusion::ChainSmoothResult sm = fusion::smooth_chain(ns, joints, setup.fusion.chain, rows.t_us, rows.in);
    for (std::size_t s = 0; s < ns; ++s) {
        for (std::size_t k = 0; k < take[s].size(); ++k)
            set_node_quat(samples[take[s][k]], sm.out[rows.row_of[s][k] * ns + s].q_earth_sensor);
    }
    std::size_t constrained = 0, with_axes = 0;
    for (std::size_t j = 0; j < joints.size(); ++j) {
        if (joints[j].type == fusion::JointType::kBall) continue;
        ++constrained;
        if (sm.joints[j].axes_known) ++with_axes;
    }
    spdlog::info(
        "replay: offline chain of subject {} (heading {}): {} instants, axes of {} of {} hinge and 2-DoF "
        "joints ({})",
        subject, fusion::to_string(setup.fusion.chain.mode), rows.sync.size(), with_axes, constrained,
        !calibration                 ? "learned from the take, no calibration before the replay"
        : setup.fusion.estimate_axes ? "hinges learned from the take, the rest from the calibration"
                                     : "from the calibration");
    return true;
}

}  // namespace

bool smooth_offline(const OfflineSetup& setup, std::vector<SegmentSample>& samples, std::uint64_t* smoothed,
                    std::string* error) {
    const bool chain = setup.fusion.chain.mode != fusion::HeadingMode::kMagnetometer;
    const pipeline::Pipeline& pipeline = setup.pipeline;
    // Per subject and segment (one node each), the samples the smoother can take, in order.
    std::map<std::uint32_t, std::vector<std::vector<std::size_t>>> takes;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const SegmentSample& s = samples[i];
        const int segment = pipeline.segment_of(s.node_id);
        if (s.has_node_quat || segment < 0 || !pipeline::FilterProcessor::accepts(s.imu)) continue;
        auto& take = takes[s.subject_id];
        take.resize(pipeline.model().size());
        auto& idx = take[static_cast<std::size_t>(segment)];
        const bool later =
            idx.empty() || (s.imu.t_us > samples[idx.back()].imu.t_us && (!chain || s.sync > samples[idx.back()].sync));
        if (later) idx.push_back(i);
    }
    const filter::OfflineSmoother smoother;
    std::vector<ImuSample> imu;
    for (const auto& [subject, take] : takes) {
        for (const auto& idx : take)
            *smoothed += idx.size();
        if (chain) {
            if (!smooth_subject_chain(setup, subject, take, samples, error)) return false;
            continue;
        }
        for (std::size_t segment = 0; segment < take.size(); ++segment) {
            const auto& idx = take[segment];
            if (idx.empty()) continue;
            auto f = filter::make_filter(pipeline.model().segments[segment].filter, setup.config.filter_params, error);
            if (!f) return false;
            imu.clear();
            for (const std::size_t i : idx)
                imu.push_back(samples[i].imu);
            const filter::OfflineResult r = smoother.smooth(*f, imu);
            for (std::size_t k = 0; k < idx.size(); ++k)
                set_node_quat(samples[idx[k]], r.orientation[k]);
        }
    }
    return true;
}

}  // namespace mocap::daemon
