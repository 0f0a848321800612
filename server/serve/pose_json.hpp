// pose_json.hpp — the JSON texts of the web endpoint (http_server.hpp has the message
// formats): the WebSocket hello, frame and drops messages, and the control reply.
//
// Numbers: positions and segment ends with 4 decimals (0.1 mm), quaternion components
// with 5; a non-finite value is written as null (JSON has no NaN). The viewer
// (clients/viewer/viewer.js) and the tests parse these texts.
//
// Written with nlohmann::json. Thread-safety: pure functions. Cost: encode_frame_json runs
// once per published frame (shared by every viewer): ~9 µs CPU for 15 segments, no more
// than the hand-written writer it replaced (docs/performance.md).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "serve/serve_config.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

struct HttpDescription;

struct HelloJsonFields {
    std::uint32_t subject = 0;  ///< the subject this viewer watches (0 = first with a frame)
    std::size_t queue_frames = 0;
    bool control_enabled = false;
    bool control_loopback_only = true;
};

/// {"type":"hello",...}: the skeleton and subjects a viewer needs before frames.
std::string encode_hello_json(const HttpDescription& description, const HelloJsonFields& fields);

/// {"type":"frame",...} for min(frame, pose) segments; encoded_us = wall clock now.
std::string encode_frame_json(const SubjectFrame& frame, const skeleton::SkeletonPose& pose, std::int64_t encoded_us);

/// {"type":"drops",...}: frames dropped for this viewer since the last frame it got.
std::string encode_drops_json(std::uint64_t dropped, std::uint64_t dropped_total);

/// {"ok":..,"error":".."[,"take":".."]} and a newline: the reply to POST /api/... (and
/// DELETE /api/takes/NAME); "take" for the start/stop of a take.
std::string encode_control_reply_json(const ControlResult& result);

}  // namespace mocap::serve
