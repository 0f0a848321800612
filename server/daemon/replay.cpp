#include "daemon/replay.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <thread>

#include "cluster/raw_take_reader.hpp"
#include "core/parse_number.hpp"
#include "daemon/calibration_files.hpp"
#include "daemon/outputs.hpp"
#include "daemon/pipeline_config.hpp"
#include "daemon/sync_order.hpp"
#include "daemon/wall_clock.hpp"
#include "filter/filter_factory.hpp"
#include "filter/offline_smoother.hpp"
#include "fusion/chain_smoother.hpp"
#include "pipeline/chain_offline.hpp"
#include "pipeline/filter_processor.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::daemon {

namespace {

bool is_digits(std::string_view s) {
    return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

/// "SSS" or "SSS.ffffff" (digits only; up to 6 fraction digits count) → µs.
bool parse_epoch_us(std::string_view text, std::int64_t* us) {
    const std::size_t dot = text.find('.');
    const std::string_view whole = text.substr(0, dot);
    const std::string_view frac = dot == std::string_view::npos ? std::string_view{} : text.substr(dot + 1);
    std::int64_t seconds = 0;
    if (!is_digits(whole) || !core::parse_number(whole, seconds) || seconds > 1'000'000'000'000) return false;
    if (dot != std::string_view::npos && !is_digits(frac)) return false;
    std::int64_t frac_us = 0;
    for (std::size_t i = 0; i < 6; ++i)
        frac_us = frac_us * 10 + (i < frac.size() ? frac[i] - '0' : 0);
    *us = seconds * 1'000'000 + frac_us;
    return true;
}

/// RFC 3339 date-time: YYYY-MM-DDTHH:MM:SS[.frac](Z|+HH:MM|-HH:MM) → µs since the epoch.
bool parse_rfc3339_us(std::string_view t, std::int64_t* us) {
    auto num = [&](std::size_t at, std::size_t n, int* out) {
        return at + n <= t.size() && is_digits(t.substr(at, n)) && core::parse_number(t.substr(at, n), *out);
    };
    int year = 0, month = 0, day = 0, hour = 0, minute = 0, second = 0;
    if (t.size() < 20 || !num(0, 4, &year) || t[4] != '-' || !num(5, 2, &month) || t[7] != '-' || !num(8, 2, &day) ||
        (t[10] != 'T' && t[10] != 't' && t[10] != ' ') || !num(11, 2, &hour) || t[13] != ':' || !num(14, 2, &minute) ||
        t[16] != ':' || !num(17, 2, &second))
        return false;
    if (month < 1 || month > 12 || day < 1 || day > 31 || hour > 23 || minute > 59 || second > 60) return false;
    std::size_t i = 19;
    std::int64_t frac_us = 0;
    if (t[i] == '.') {
        const std::size_t start = ++i;
        while (i < t.size() && t[i] >= '0' && t[i] <= '9')
            ++i;
        if (i == start || !parse_epoch_us("0" + std::string(t.substr(start - 1, i - start + 1)), &frac_us))
            return false;
    }
    std::int64_t offset_s = 0;
    if (i < t.size() && (t[i] == 'Z' || t[i] == 'z')) {
        ++i;
    } else if (i < t.size() && (t[i] == '+' || t[i] == '-')) {
        int oh = 0, om = 0;
        if (!num(i + 1, 2, &oh) || i + 3 >= t.size() || t[i + 3] != ':' || !num(i + 4, 2, &om) || oh > 23 || om > 59)
            return false;
        offset_s = (t[i] == '-' ? -1 : 1) * (static_cast<std::int64_t>(oh) * 3600 + static_cast<std::int64_t>(om) * 60);
        i += 6;
    } else {
        return false;  // RFC 3339 requires the offset
    }
    if (i != t.size()) return false;
    std::tm tm{};
    tm.tm_year = year - 1900;
    tm.tm_mon = month - 1;
    tm.tm_mday = day;
    tm.tm_hour = hour;
    tm.tm_min = minute;
    tm.tm_sec = second;
    const std::time_t utc = timegm(&tm);
    *us = (static_cast<std::int64_t>(utc) - offset_s) * 1'000'000 + frac_us;
    return true;
}

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

/// What the offline re-solve of a take needs besides its samples.
struct OfflineSetup {
    const DaemonConfig& config;
    const pipeline::Pipeline& pipeline;
    const skeleton::FusionOptions& fusion;  ///< [fusion] as configured (the pipeline's chain stage is off)
    const std::string& calibration_dir;     ///< "" = no calibration before the replay
};

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

/// Offline: gives each selected sample its smoothed orientation as its node's own estimate
/// (replay.hpp, "Offline"). *smoothed counts them; false + error if a filter cannot be built.
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

}  // namespace

bool parse_replay_time(std::string_view text, std::int64_t* us, std::string* error) {
    if (parse_epoch_us(text, us) || parse_rfc3339_us(text, us)) return true;
    *error = "time " + std::string(text) +
             ": expected seconds since the epoch (e.g. 1764648000.25) or RFC 3339 (e.g. 2026-12-02T04:10:00Z)";
    return false;
}

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
    const auto play = [&](const SegmentSample& s) {
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
