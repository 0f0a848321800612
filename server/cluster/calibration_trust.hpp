// calibration_trust.hpp — what a host checks before it takes a calibration from the shared
// bucket (calibration_bucket.hpp; docs/cluster.md, "Who may write a calibration"):
//
//   signature    HMAC-SHA256, keyed with the site's calibration key (a file the operator
//                gives every host, [cluster] calibration_key_file), over the value's site,
//                subject, host_id, time_us and calibration text; hex in "hmac_sha256". Only
//                a holder of the key makes a value that verifies, whatever the NATS server
//                lets anyone publish.
//   plausibility a calibration is taken standing upright in its pose: q_world_earth must be
//                the pure heading turn its heading mode and facing heading give (world up =
//                earth up), the pose a T- or N-pose. Segment lengths are not shared (each
//                host's body model is its own config), so a value cannot change them.
//
// The key file must be a regular file that only its owner (and group) may read: no access
// for others, no group write. Its content (blanks trimmed) is the key, at least 32 bytes.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "skeleton/calibration.hpp"

namespace mocap::cluster {

inline constexpr std::size_t kMinCalibrationKeyBytes = 32;

/// The key in `path`, or nullopt and *error (unreadable, not a regular file, readable or
/// writable by others, shorter than kMinCalibrationKeyBytes).
std::optional<std::string> read_calibration_key(const std::string& path, std::string* error);

/// What is signed: the fields, one per line, in this order.
struct SignedFields {
    std::string site;
    std::uint32_t subject = 0;
    std::string host_id;
    std::int64_t time_us = 0;
    std::string calibration_text;
};

/// Lower-case hex HMAC-SHA256 of the fields under `key`.
std::string calibration_signature(const std::string& key, const SignedFields& fields);
/// Whether `signature` is the fields' signature under `key` (compared in constant time).
bool signature_matches(const std::string& key, const SignedFields& fields, const std::string& signature);

/// "" for a calibration a standing subject could have given, else why not.
std::string implausible_calibration(const skeleton::Calibration& calibration);

}  // namespace mocap::cluster
