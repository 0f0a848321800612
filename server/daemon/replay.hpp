// replay.hpp — `mocapd --replay FILE...` or `mocapd --jetstream URL --subject N`: re-runs a
// raw recording (serve/raw_recorder.hpp), or a durable take read back from JetStream
// (cluster/raw_take_reader.hpp: the same records), through the same Pipeline as live (pipeline/pipeline.hpp, driven
// synchronously): the same node routing, the configured filter per segment, the per-subject assembler with the
// configured deadline and the skeleton solver (calibration, smoothing, kinematics, joint
// angles) — and writes its outputs through the same registry (daemon/outputs.hpp): a BVH
// file through the same recorder and encoder as the live recorder, and the joint-angle CSV.
//
// Order: samples are replayed in the order they were stored, but for a segment's sample stored
// behind a later SYNC of that segment (a take across a frozen host's failover), which is put
// back where its SYNC belongs (daemon/sync_order.hpp).
// Determinism: one thread, samples in file order, and the assembler's clock is the
// recorded received_us of each sample (the daemon's wall clock when it was decoded), so
// deadlines fall as they fell live and the same input + the same config give
// byte-identical files. What differs from live: the worker pool's threads are not used (a
// segment's samples are filtered in the same order either way), and nothing waits on a
// wall clock unless `realtime` is set, which paces samples by their received_us.
// Selection: `subject` and the received_us range [from_us, to_us] pick the samples of either
// source (a take from JetStream is one subject; files may hold many). A subject's frames
// depend only on its own samples in order, so its replay from JetStream equals its replay from
// the raw file recorded beside it.
// Offline (`--offline`): the selected samples, in the order above, are held in memory (about
// 100 bytes each: 54 MB per subject-hour at 15 nodes and 100 Hz); each node's samples are
// re-solved as a whole by the offline smoother (filter/offline_smoother.hpp) with the filter
// and parameters the pipeline would give its segment, and the pipeline then takes each
// sample with its smoothed orientation as a node's own estimate (has_node_quat), so
// assembly, skeleton and outputs are those of the causal replay. Samples a node estimated
// itself, with non-finite readings or not later (in time, or with [fusion] below in SYNC)
// than the previous one of their node keep the causal path.
// With [fusion] heading other than "magnetometer" the joints hold the headings non-causally
// too: per subject, every segment's samples become the chain smoother's inputs
// (pipeline/chain_offline.hpp), grouped by SYNC into instants (a segment missing at an
// instant holds its previous input, not fresh), the body's joints (skeleton/body_chain.hpp)
// take their axes from the subject's calibration in calibration_dir as the replay starts
// (none there, or [fusion] axis = "estimate": the hinges learn theirs from the take), and
// fusion::smooth_chain gives each sample its orientation. The pipeline's own chain stage is
// then set to "magnetometer" for the replay: a second, causal chain over orientations that
// already hold the joints' headings would only add its noise. The chain's inputs and outputs
// add about 250 bytes per sample while it runs (its inputs 144, outputs 48, the two passes'
// joint states ~50: 1.3 GB per subject-hour at 15 nodes and 100 Hz); it runs on the calling
// thread and does not look at `cancel`.
// Calibration: none is loaded or saved unless calibration_dir is given; calibrate_at
// requests one at a sample time (seconds since the first sample), as the control request
// would.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/replay_args.hpp"

namespace mocap::daemon {

struct ReplayOptions {
    std::vector<std::string> files;  ///< raw recordings, replayed in this order
    /// Non-empty: read the take from JetStream at this URL instead of files ([cluster] gives
    /// the credentials; `site`, when set, overrides [cluster].site). Needs `subject`.
    std::string jetstream_url;
    std::string site;
    std::uint32_t subject = 0;                                        ///< 0 = every subject (files only)
    std::int64_t from_us = std::numeric_limits<std::int64_t>::min();  ///< received_us range, inclusive
    std::int64_t to_us = std::numeric_limits<std::int64_t>::max();
    bool realtime = false;
    bool offline = false;           ///< re-solve each node's samples, and [fusion] the joints, as a whole (see above)
    std::string bvh_out;            ///< "" = no BVH file; must not exist
    std::uint32_t bvh_subject = 0;  ///< 0 = [outputs].bvh_subject rule
    std::string angles_out;         ///< "" = no CSV
    /// >= 0: write the BVH / the CSV into this open, empty file instead (a take export's
    /// memfd, daemon/take_export.hpp); the replay writes through a dup and leaves `fd` open.
    /// The path above, when also set, only names it in messages.
    int bvh_out_fd = -1;
    int angles_out_fd = -1;
    std::string calibration_dir;  ///< "" = neither load nor save calibrations
    std::vector<ReplayCalibration> calibrate;
    /// Non-null: checked per sample; once true the replay stops and returns false (a take
    /// export the daemon abandons, daemon/take_export.hpp).
    const std::atomic<bool>* cancel = nullptr;
    /// Non-empty: called every kReplayProgressSamples samples played; false (with *error)
    /// stops the replay, which returns false with that error (a take export whose output
    /// outgrew its memory budget, daemon/take_export.hpp).
    std::function<bool(std::string* error)> progress;
};

inline constexpr std::uint64_t kReplayProgressSamples = 256;

struct ReplayResult {
    std::uint64_t samples = 0;               ///< selected and replayed
    std::uint64_t samples_unknown_node = 0;  ///< node not in the model, or subject not configured
    std::uint64_t samples_rejected = 0;      ///< the filter refused them (non-finite input)
    std::uint64_t samples_reordered = 0;     ///< put back in SYNC order (sync_order.hpp)
    std::uint64_t samples_too_late = 0;      ///< out of SYNC order beyond repair: not replayed
    std::uint64_t samples_smoothed = 0;      ///< offline: replayed with the smoothed orientation
    std::uint64_t frames = 0;                ///< subject frames solved
    std::uint64_t bvh_frames = 0;
    bool truncated = false;  ///< a file ended in a partial record
};

/// Runs the replay. False + error on a bad file, an unwritable output or an invalid config.
bool run_replay(const DaemonConfig& config, const ReplayOptions& options, ReplayResult* result, std::string* error);

}  // namespace mocap::daemon
