// outputs.hpp — every output of mocapd (pipeline/output.hpp) and the one registry that
// creates them from the config (docs/outputs.md, "Outputs").
//
// Adding an output: a class implementing pipeline::Output (here, or in serve/ when the
// server class itself implements it), a config section read by its factory, and one line
// in the registry table (outputs.cpp). The daemon and replay create outputs only through
// add_outputs(), so neither changes.
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "daemon/config.hpp"
#include "daemon/replay.hpp"
#include "pipeline/output.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "serve/bvh_recorder.hpp"
#include "serve/http_server.hpp"
#include "serve/pose_server.hpp"
#include "serve/take_recorder.hpp"

namespace mocap::daemon {

/// What a factory may read: the config, the built pipeline (model, subjects, joints), the
/// clock, and the daemon's control and metrics callbacks for the network services.
struct OutputContext {
    const DaemonConfig& config;
    const pipeline::Pipeline& pipeline;
    const Clock& clock;
    serve::ControlHandlers control;
    std::function<serve::MetricsSnapshot()> metrics;
    std::function<serve::HealthStatus()> health;
    /// Non-null in `mocapd --replay`: only the file outputs its command line asks for.
    const ReplayOptions* replay = nullptr;
    /// Failed control attempts, counted once for the pose service and HTTP together.
    std::shared_ptr<serve::ControlAttemptLimiter> control_attempts = nullptr;  ///< null: each server makes its own
    /// The takes (live only): recorded by the take_record output, served by HTTP.
    std::shared_ptr<serve::TakeStore> takes = nullptr;
    serve::TakeExporter export_take = nullptr;  ///< BVH/CSV downloads of takes (daemon/take_export.hpp)
};

/// Returns the output, or nullptr when its config section leaves it off.
using OutputFactory = std::unique_ptr<pipeline::Output> (*)(const OutputContext& context);

struct OutputEntry {
    const char* name;
    OutputFactory make;
};

/// The registry, in the order outputs receive frames.
std::span<const OutputEntry> output_registry();

/// Runs every factory of the registry; adds what they return to the pipeline.
void add_outputs(const OutputContext& context, pipeline::Pipeline& pipeline);

/// BVH file recorder (serve/bvh_recorder.hpp): live, started and stopped by control
/// requests; in replay, records the whole run to the --bvh-out file.
class BvhRecorderOutput final : public pipeline::Output {
public:
    /// start_path: opened by start() (replay); "" = wait for start_recording(). start_fd >= 0:
    /// start() writes into that open file instead, named start_path in messages.
    BvhRecorderOutput(const serve::BvhRecorderConfig& config, const skeleton::BodyModel& model,
                      const serve::BvhOutputOptions& options, std::string start_path, int start_fd = -1);
    [[nodiscard]] std::string_view name() const override { return "bvh_record"; }
    bool start(std::string* error) override;
    /// Finishes an open recording (patches its frame count).
    bool stop(std::string* error) override;
    void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) override {
        recorder_.publish(frame, pose);
    }
    void register_metrics(MetricsRegistry& registry) const override { recorder_.register_metrics(registry); }

    /// Control requests (any thread).
    bool start_recording(const std::string& path, std::string* error) { return recorder_.start(path, error); }
    bool stop_recording(std::string* error) { return recorder_.stop(error); }
    /// Frames in the file the last stop() finished.
    [[nodiscard]] std::uint64_t frames_written() const { return frames_written_; }

private:
    serve::BvhFrameEncoder encoder_;
    serve::BvhRecorder recorder_;
    std::string start_path_;
    int start_fd_ = -1;
    std::uint64_t frames_written_ = 0;
};

/// Takes (serve/take_recorder.hpp): every sample of a running take into its raw file; started
/// and stopped by control requests. Live, whenever the daemon has a take store.
class TakeRecorderOutput final : public pipeline::Output {
public:
    TakeRecorderOutput(serve::TakeStore& store, const serve::TakeRecorderConfig& config, const Clock& clock)
        : recorder_(store, config, clock) {}
    [[nodiscard]] std::string_view name() const override { return "take_record"; }
    bool start(std::string* /*error*/) override { return true; }
    /// Stops a running take (ingest, its producer, has stopped).
    bool stop(std::string* error) override {
        if (!recorder_.running()) return true;
        const serve::ControlResult r = recorder_.stop();
        if (!r.ok) *error = r.error;
        return r.ok;
    }
    void on_frame(const SubjectFrame& /*frame*/, const skeleton::SkeletonPose& /*pose*/) override {}
    [[nodiscard]] bool wants_samples() const override { return true; }
    void on_sample(const SegmentSample& sample) override { recorder_.push(sample); }
    void register_metrics(MetricsRegistry& registry) const override { recorder_.register_metrics(registry); }

    /// Control requests (any thread).
    serve::ControlResult start_take(const std::string& name, const std::string& notes) {
        return recorder_.start(name, notes);
    }
    serve::ControlResult stop_take() { return recorder_.stop(); }

private:
    serve::TakeRecorder recorder_;
};

}  // namespace mocap::daemon
