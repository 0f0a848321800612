#include "daemon/replay.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <thread>

#include "core/parse_number.hpp"
#include "core/subject_assembler.hpp"
#include "daemon/daemon.hpp"
#include "daemon/filter_processor.hpp"
#include "filter/filter_factory.hpp"
#include "serve/angles_csv.hpp"
#include "serve/bvh_recorder.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::daemon {

namespace {
constexpr double kPi = 3.14159265358979323846;
}  // namespace

serve::BvhOutputOptions bvh_options_from_config(const DaemonConfig& config) {
    serve::BvhOutputOptions o;
    o.write.units_per_m = config.bvh_units_per_m;
    if (const auto order = skeleton::parse_rotation_order(config.bvh_rotation_order)) o.write.order = *order;
    o.frame_time_s = config.bvh_frame_time_s;
    return o;
}

PoseSolverOptions pose_solver_options_from_config(const DaemonConfig& config) {
    PoseSolverOptions so;
    so.calibration_s = config.calibration_s;
    so.calibration_dir = config.calibration_dir;
    so.calibration.heading_mode =
        config.heading_align ? skeleton::HeadingMode::kAlignToForward : skeleton::HeadingMode::kKeepEarth;
    so.calibration.facing_source =
        config.facing_from_sensor ? skeleton::FacingSource::kFromSensorAxis : skeleton::FacingSource::kGiven;
    so.calibration.facing_heading_rad = config.facing_heading_deg * kPi / 180.0;
    so.calibration.facing_sensor_axis = {config.facing_sensor_axis[0], config.facing_sensor_axis[1],
                                         config.facing_sensor_axis[2]};
    so.smoothing.alpha = config.smoothing_alpha;
    if (config.auto_calibrate == "t-pose") so.auto_calibrate = skeleton::CalibrationPose::kTPose;
    if (config.auto_calibrate == "n-pose") so.auto_calibrate = skeleton::CalibrationPose::kNPose;
    return so;
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
    auto model = body_model_from_config(config, error);
    if (!model) return false;
    std::array<std::int16_t, 256> node_to_segment{};
    node_to_segment.fill(-1);
    for (std::size_t i = 0; i < model->size(); ++i) {
        const int node = model->segments[i].node_id;
        if (node >= 0 && node < 256) node_to_segment[static_cast<std::size_t>(node)] = static_cast<std::int16_t>(i);
    }
    const auto segment_count = static_cast<std::uint16_t>(model->size());

    // Outputs: the same encoder and recorder as live.
    serve::BvhFrameEncoder encoder(*model, bvh_options_from_config(config));
    serve::BvhRecorderConfig rc;
    rc.subject = options.bvh_subject != 0 ? options.bvh_subject : config.bvh_subject;
    rc.max_buffer_bytes = std::numeric_limits<std::size_t>::max();  // never drop: the file must be complete
    rc.flush_interval_s = config.record_flush_interval_s;
    serve::BvhRecorder recorder(rc, encoder);
    if (!options.bvh_out.empty() && !recorder.start(options.bvh_out, error)) return false;
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv(nullptr, &std::fclose);
    std::string row;

    PoseSolverOptions so = pose_solver_options_from_config(config);
    so.max_subjects = config.max_subjects;
    for (const auto& can : config.socketcan)
        so.max_subjects = std::max(so.max_subjects, can.subject);
    so.calibration_dir = options.calibration_dir;
    std::vector<std::string> angle_names;
    PoseSolver solver(*model, so, [&](const SubjectFrame& f, const serve::SkeletonPose& p) {
        ++result->frames;
        recorder.publish(f, p);
        if (csv) {
            row.clear();
            serve::append_angles_csv_row(f.subject_id, f.sync, f.sample_us, p.joint_angles_rad.data(),
                                         p.joint_angle_count, row);
            // A failed write sets the stream's error flag, checked once at the end.
            (void)std::fwrite(row.data(), 1, row.size(), csv.get());
        }
    });
    for (const auto& line : solver.load_calibrations())
        spdlog::info("{}", line);
    for (const auto& j : solver.joints()) {
        for (const char* axis : {"flexion", "abduction", "rotation"})
            angle_names.push_back(j.name + "." + axis);
    }
    if (!options.angles_out.empty()) {
        csv.reset(std::fopen(options.angles_out.c_str(), "wx"));
        if (!csv) {
            *error = "cannot create " + options.angles_out + " (it must not exist)";
            return false;
        }
        const std::string header = serve::angles_csv_header(angle_names);
        (void)std::fwrite(header.data(), 1, header.size(), csv.get());  // checked at the end
    }

    AssemblerConfig ac;
    ac.deadline_us = static_cast<std::int64_t>(config.assembly_deadline_ms * 1000.0);
    AssemblerSet assemblers(ac, solver);
    // Filters per (subject, segment), created when a subject first appears.
    std::map<std::uint32_t, std::vector<std::unique_ptr<FilterProcessor>>> filters;
    auto filters_of = [&](std::uint32_t subject) -> std::vector<std::unique_ptr<FilterProcessor>>* {
        auto it = filters.find(subject);
        if (it != filters.end()) return &it->second;
        std::vector<std::unique_ptr<FilterProcessor>> v;
        for (const auto& seg : model->segments) {
            auto f = filter::make_filter(seg.filter, config.filter_params, error);
            if (!f) {
                *error = "filter for segment " + seg.name + ": " + *error;
                return nullptr;
            }
            v.push_back(std::make_unique<FilterProcessor>(std::move(f)));
        }
        assemblers.add_subject(subject, segment_count);
        return &filters.emplace(subject, std::move(v)).first->second;
    };

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
                    const std::string err = solver.request_calibration(it->subject, it->pose);
                    if (!err.empty()) spdlog::warn("replay: calibration: {}", err);
                    it = pending.erase(it);
                } else {
                    ++it;
                }
            }
            const std::int16_t seg = node_to_segment[s.node_id];
            if (seg < 0) {
                ++result->samples_unknown_node;
                continue;
            }
            if (s.subject_id == 0 || s.subject_id > so.max_subjects) {
                ++result->samples_unknown_node;
                continue;
            }
            auto* f = filters_of(s.subject_id);
            if (!f) return false;
            PoseUpdate u;
            u.subject_id = s.subject_id;
            u.segment_index = static_cast<std::uint16_t>(seg);
            u.sync = s.sync;
            u.pose.sample_us = s.imu.t_us;
            u.pose.flags = 0;
            u.times = s.times;
            u.times.dequeued_us = now_us;
            u.times.filtered_us = now_us;
            s.segment_index = u.segment_index;
            assemblers.advance(now_us);
            if (!(*f)[static_cast<std::size_t>(seg)]->process(s, u.pose)) {
                ++result->samples_rejected;
                continue;
            }
            assemblers.on_pose(u, now_us);
        }
        result->truncated = result->truncated || reader.truncated();
    }
    assemblers.flush(now_us);
    if (recorder.recording() && !recorder.stop(error, &result->bvh_frames)) return false;
    // fflush alone misses a write that failed earlier (ENOSPC while a full buffer went out):
    // the stream's error flag keeps it.
    if (csv && (std::fflush(csv.get()) != 0 || std::ferror(csv.get()) != 0)) {
        *error = "write " + options.angles_out + " failed";
        return false;
    }
    return true;
}

}  // namespace mocap::daemon
