#include "daemon/replay.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <limits>
#include <thread>

#include "cluster/raw_take_reader.hpp"
#include "daemon/calibration_files.hpp"
#include "daemon/outputs.hpp"
#include "daemon/pipeline_config.hpp"
#include "daemon/replay_offline.hpp"
#include "daemon/sync_order.hpp"
#include "daemon/wall_clock.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::daemon {

namespace {

/// Reads the take of one subject from JetStream into `feed`.
bool replay_jetstream(const DaemonConfig& config, const ReplayOptions& options,
                      const std::function<void(const SegmentSample&)>& feed, std::string* error) {
    cluster::ClusterConfig cc = cluster_config_from_config(config);
    cc.nats_url = options.jetstream_url;
    if (!options.site.empty()) cc.site = options.site;
    cluster::RawTakeReader reader(std::move(cc),
                                  {.subject_id = options.subject, .from_us = options.from_us, .to_us = options.to_us});
    if (!reader.open(error)) return false;
    SegmentSample s;
    for (;;) {
        const int r = reader.next(s, error);
        if (r < 0) return false;
        if (r == 0) break;
        feed(s);
    }
    spdlog::info("replay: read {} JetStream messages of {}", reader.messages(), reader.subject());
    return true;
}

}  // namespace

bool run_replay(const DaemonConfig& config, const ReplayOptions& options, ReplayResult* result, std::string* error) {
    *result = ReplayResult{};
    if (!options.jetstream_url.empty() && (options.subject == 0 || !options.files.empty())) {
        *error = "--jetstream reads one subject's take: give --subject N, and no --replay files";
        return false;
    }
    if (options.from_us > options.to_us) {
        *error = "--from is after --to";
        return false;
    }
    auto pc = pipeline_config_from_config(config, error);
    if (!pc) return false;
    // Offline, the chain stage runs over the whole take before the pipeline (smooth_offline):
    // the smoothed orientations already hold the joints' headings, and the pipeline's causal
    // chain stage over them would only add its own noise.
    const skeleton::FusionOptions fusion_options = pc->solver.fusion;
    if (options.offline) pc->solver.fusion.chain.mode = fusion::HeadingMode::kMagnetometer;
    pc->calibration_store = calibration_files(options.calibration_dir);
    // The pipeline's own clock is read only by the live stages (worker pool, assembler
    // thread); the synchronous mode runs on the recorded received_us below.
    const WallClock clock;
    auto pipeline = pipeline::Pipeline::create(std::move(*pc), clock, error);
    if (!pipeline) return false;
    // Outputs: the registry's file outputs, the same encoder and recorder as live.
    OutputContext outputs{config, *pipeline, clock, {}, {}, {}, &options};
    add_outputs(outputs, *pipeline);
    pipeline->solver().load_calibrations();
    if (!pipeline->start_outputs(error)) return false;

    std::vector<ReplayCalibration> pending = options.calibrate;
    std::int64_t first_t_us = std::numeric_limits<std::int64_t>::min();
    std::int64_t first_received_us = 0;
    std::int64_t now_us = 0;
    const auto wall_start = std::chrono::steady_clock::now();
    std::string stopped;  // progress() said stop: why
    const auto play = [&](const SegmentSample& s) {
        if (!stopped.empty()) return;
        if (options.progress && result->samples % kReplayProgressSamples == 0 && !options.progress(&stopped)) {
            if (stopped.empty()) stopped = "stopped";
            return;
        }
        ++result->samples;
        if (first_t_us == std::numeric_limits<std::int64_t>::min()) {
            first_t_us = s.imu.t_us;
            first_received_us = s.times.received_us;
        }
        // The assembler's clock never runs backwards (received_us is a wall clock).
        now_us = std::max(now_us, s.times.received_us);
        if (options.realtime) {
            std::this_thread::sleep_until(wall_start + std::chrono::microseconds(now_us - first_received_us));
        }
        for (auto it = pending.begin(); it != pending.end();) {
            if (static_cast<double>(s.imu.t_us - first_t_us) * 1e-6 >= it->at_s) {
                const std::string err = pipeline->solver().request_calibration(it->subject, it->pose);
                if (!err.empty()) spdlog::warn("replay: calibration: {}", err);
                it = pending.erase(it);
            } else {
                ++it;
            }
        }
        switch (pipeline->process(s, now_us)) {
            case pipeline::RouteResult::kProcessed:
                break;
            case pipeline::RouteResult::kUnknownNode:
                ++result->samples_unknown_node;
                break;
            case pipeline::RouteResult::kRejected:
                ++result->samples_rejected;
                break;
        }
    };
    // Selected samples go through SyncOrder (sync_order.hpp) on their way to the pipeline;
    // offline, they are held until every one is in, smoothed, then played.
    std::vector<SegmentSample> held;
    SyncOrder order(options.offline ? SyncOrder::Emit([&](const SegmentSample& s) { held.push_back(s); })
                                    : SyncOrder::Emit(play));
    const auto feed = [&](const SegmentSample& s) {
        if ((options.subject != 0 && s.subject_id != options.subject) || s.times.received_us < options.from_us ||
            s.times.received_us > options.to_us)
            return;
        order.push(s);
    };
    if (!options.jetstream_url.empty() && !replay_jetstream(config, options, feed, error)) return false;
    SegmentSample s;
    for (const std::string& path : options.files) {
        serve::RawRecordingReader reader;
        if (!reader.open(path, error)) return false;
        for (;;) {
            if (options.cancel != nullptr && options.cancel->load(std::memory_order_relaxed)) {
                *error = "cancelled";
                return false;
            }
            if (!stopped.empty()) {
                *error = stopped;
                return false;
            }
            const int r = reader.next(s, error);
            if (r < 0) {
                *error = path + ": " + *error;
                return false;
            }
            if (r == 0) break;
            feed(s);
        }
        if (reader.truncated()) {
            // What a crash or a full disk leaves: the file replays up to its last whole record.
            spdlog::warn("replay: {}: {}", path, reader.truncation());
            result->truncated = true;
        }
    }
    order.flush();
    if (options.offline) {
        const OfflineSetup setup{config, *pipeline, fusion_options, options.calibration_dir};
        if (!smooth_offline(setup, held, &result->samples_smoothed, error)) return false;
        spdlog::info("replay: offline re-solve of {} of {} samples", result->samples_smoothed, held.size());
        for (const SegmentSample& h : held)
            play(h);
    }
    if (!stopped.empty()) {
        *error = stopped;
        return false;
    }
    result->samples_reordered = order.reordered();
    result->samples_too_late = order.too_late();
    if (order.reordered() + order.too_late() > 0)
        spdlog::info("replay: {} samples put back in SYNC order, {} dropped as too late (sync_order.hpp)",
                     order.reordered(), order.too_late());
    pipeline->flush(now_us);
    result->frames = pipeline->solver().counters().value("frames_solved").value_or(0);
    if (!pipeline->stop_outputs(error)) return false;
    for (const auto& o : pipeline->outputs()) {
        if (const auto* bvh = dynamic_cast<const BvhRecorderOutput*>(o.get()))
            result->bvh_frames = bvh->frames_written();
    }
    return true;
}

}  // namespace mocap::daemon
