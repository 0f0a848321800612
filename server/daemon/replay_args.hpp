// replay_args.hpp — the command-line values of `mocapd --replay` and `mocapd --jetstream`
// (daemon/replay.hpp) that need more than a number: the calibration requests of
// --calibrate-at and the --from/--to times. Pure functions of their text: thread-safe, no
// I/O, a few small allocations for the error messages.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "skeleton/calibration.hpp"

namespace mocap::daemon {

struct ReplayCalibration {
    double at_s = 0.0;  ///< seconds after the first sample's t_us
    std::uint32_t subject = 1;
    skeleton::CalibrationPose pose = skeleton::CalibrationPose::kTPose;
};

/// Parses `--calibrate-at SECONDS[:SUBJECT[:T|N]]` (subject defaults to 1, pose to T).
/// False + error naming the argument for anything else (a negative or non-finite time,
/// subject 0, trailing characters, a pose other than T or N).
bool parse_replay_calibration(std::string_view spec, ReplayCalibration* out, std::string* error);

/// Parses a --from/--to time: seconds since the epoch (fraction allowed) or RFC 3339
/// ("2026-12-02T04:10:00Z", "2026-12-02T05:10:00.250+01:00"). Microseconds since the epoch;
/// false + error naming the argument otherwise.
bool parse_replay_time(std::string_view text, std::int64_t* us, std::string* error);

}  // namespace mocap::daemon
