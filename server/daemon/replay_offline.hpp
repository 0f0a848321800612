// replay_offline.hpp — the offline re-solve of `mocapd --replay --offline` (daemon/replay.hpp,
// "Offline"): the selected samples of a take, held in memory, get each node's orientation
// re-solved over the whole take by the offline smoother (filter/offline_smoother.hpp), or with
// [fusion] heading other than "magnetometer" by the chain smoother over each subject's joints
// (fusion/chain_smoother.hpp), as the node's own estimate (has_node_quat); the replay then
// plays them through its pipeline.
// Runs on the calling thread and allocates per take (replay.hpp, "Offline", has the sizes).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "daemon/config.hpp"
#include "pipeline/pipeline.hpp"
#include "skeleton/body_chain.hpp"

namespace mocap::daemon {

/// What the offline re-solve of a take needs besides its samples.
struct OfflineSetup {
    const DaemonConfig& config;
    const pipeline::Pipeline& pipeline;
    const skeleton::FusionOptions& fusion;  ///< [fusion] as configured (the pipeline's chain stage is off)
    const std::string& calibration_dir;     ///< "" = no calibration before the replay
};

/// Offline: gives each selected sample its smoothed orientation as its node's own estimate
/// (replay.hpp, "Offline"). *smoothed counts them; false + error if a filter cannot be built.
bool smooth_offline(const OfflineSetup& setup, std::vector<SegmentSample>& samples, std::uint64_t* smoothed,
                    std::string* error);

}  // namespace mocap::daemon
