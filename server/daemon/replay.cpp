#include "daemon/replay.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <limits>
#include <thread>

#include "core/parse_number.hpp"
#include "daemon/calibration_files.hpp"
#include "daemon/outputs.hpp"
#include "daemon/pipeline_config.hpp"
#include "daemon/wall_clock.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::daemon {

bool parse_replay_calibration(std::string_view spec, ReplayCalibration* out, std::string* error) {
    const auto f = core::split_fields(spec, ':');
    ReplayCalibration c;
    bool ok = f.size() <= 3 && core::parse_number(f[0], c.at_s) && c.at_s >= 0.0;
    if (ok && f.size() >= 2) ok = core::parse_number(f[1], c.subject) && c.subject >= 1;
    if (ok && f.size() == 3) {
        if (f[2] == "N" || f[2] == "n")
            c.pose = skeleton::CalibrationPose::kNPose;
        else
            ok = f[2] == "T" || f[2] == "t";
    }
    if (!ok) {
        *error = "--calibrate-at " + std::string(spec) +
                 ": expected SECONDS[:SUBJECT[:T|N]] with SECONDS >= 0 and SUBJECT >= 1";
        return false;
    }
    *out = c;
    return true;
}

bool run_replay(const DaemonConfig& config, const ReplayOptions& options, ReplayResult* result, std::string* error) {
    *result = ReplayResult{};
    auto pc = pipeline_config_from_config(config, error);
    if (!pc) return false;
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
    SegmentSample s;
    for (const std::string& path : options.files) {
        serve::RawRecordingReader reader;
        if (!reader.open(path, error)) return false;
        for (;;) {
            const int r = reader.next(s, error);
            if (r < 0) {
                *error = path + ": " + *error;
                return false;
            }
            if (r == 0) break;
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
        }
        if (reader.truncated()) {
            // What a crash or a full disk leaves: the file replays up to its last whole record.
            spdlog::warn("replay: {}: {}", path, reader.truncation());
            result->truncated = true;
        }
    }
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
