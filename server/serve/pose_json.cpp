// pose_json.cpp — the web endpoint's JSON texts (pose_json.hpp).
#include "serve/pose_json.hpp"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "serve/http_server.hpp"

namespace mocap::serve {

namespace {

// `v` rounded to `decimals` places, so the shortest text nlohmann prints has at most that
// many (0.1 mm for lengths); a non-finite value stays so and is written as null.
double round_to(double v, int decimals) {
    const double scale = std::pow(10.0, decimals);
    return std::isfinite(v) ? std::round(v * scale) / scale : v;
}

// Names come from the configuration: invalid UTF-8 becomes U+FFFD rather than an exception.
std::string dump(const nlohmann::ordered_json& j) {
    return j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

}  // namespace

std::string encode_hello_json(const HttpDescription& description, const HelloJsonFields& fields) {
    nlohmann::ordered_json segments = nlohmann::ordered_json::array();
    for (const HttpSegment& s : description.segments) {
        segments.push_back({{"name", s.name},
                            {"parent", s.parent},
                            {"end_m", {round_to(s.end_m[0], 4), round_to(s.end_m[1], 4), round_to(s.end_m[2], 4)}}});
    }
    const nlohmann::ordered_json hello{
        {"type", "hello"},
        {"subject", fields.subject},
        {"subjects", description.subjects},
        {"world_frame", description.world_frame},
        {"queue_frames", fields.queue_frames},
        {"control", {{"enabled", fields.control_enabled}, {"loopback_only", fields.control_loopback_only}}},
        {"segments", std::move(segments)}};
    return dump(hello);
}

std::string encode_frame_json(const SubjectFrame& frame, const skeleton::SkeletonPose& pose, std::int64_t encoded_us) {
    // Built as a json value and dumped: measured no slower than the hand-written fmt writer
    // it replaced (pose_json_bench, docs/performance.md "WebSocket frame JSON").
    const std::size_t n = std::min<std::size_t>(frame.segment_count, pose.segment_count);
    const StageTimes& t = frame.times;
    nlohmann::ordered_json j{{"type", "frame"},
                             {"subject", frame.subject_id},
                             {"sync", frame.sync},
                             {"sample_us", frame.sample_us},
                             {"stamps",
                              {{"sink_send_us", t.sink_send_us},
                               {"received_us", t.received_us},
                               {"filtered_us", t.filtered_us},
                               {"assembled_us", t.assembled_us},
                               {"encoded_us", encoded_us}}}};
    nlohmann::ordered_json pos = nlohmann::ordered_json::array();
    nlohmann::ordered_json q = nlohmann::ordered_json::array();
    nlohmann::ordered_json flags = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 3; ++k)
            pos.push_back(round_to(pose.position_m[i][k], 4));
        for (std::size_t k = 0; k < 4; ++k)
            q.push_back(round_to(pose.q_world_segment_wxyz[i][k], 5));
        flags.push_back(static_cast<unsigned>(frame.segments[i].flags | pose.extra_flags[i]));
    }
    j["pos"] = std::move(pos);
    j["q"] = std::move(q);
    j["flags"] = std::move(flags);
    return dump(j);
}

std::string encode_drops_json(std::uint64_t dropped, std::uint64_t dropped_total) {
    return dump(nlohmann::ordered_json{{"type", "drops"}, {"dropped", dropped}, {"dropped_total", dropped_total}});
}

std::string encode_control_reply_json(const ControlResult& result) {
    nlohmann::ordered_json j{{"ok", result.ok}, {"error", result.error}};
    if (!result.take.empty()) j["take"] = result.take;
    return dump(j) + "\n";
}

}  // namespace mocap::serve
