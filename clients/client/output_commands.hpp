// output_commands.hpp — mocap-client's file exports (docs/outputs.md):
//
//   mocap-client --connect HOST:7002 record --out FILE.bvh --frames N [--subject ID]
//       reads the LIVE BVH port: HIERARCHY, MOTION, Frame Time, then N MOTION lines, and
//       writes a complete BVH file with "Frames: N". Every line's value count is checked
//       against the CHANNELS of the hierarchy (a wrong count fails: exit 1).
//   mocap-client --nats URL [--site S] record --out FILE.bvh --frames N [--subject ID]
//       the same file from the poses mocapd publishes to a NATS cluster: the HIERARCHY and
//       Frame Time are built from the host heartbeat's body and BVH settings with the live
//       port's encoder (serve::BvhFrameEncoder), and each MOTION line from a pose frame's
//       orientations and root position (floats on the wire: values agree with the live
//       port's to the float's precision). Without --subject, the subject of the first frame.
//   mocap-client --connect HOST:7001 angles --out FILE.csv --frames N [--subject ID]
//       subscribes to joint angles on the protobuf port and writes the joint-angle CSV
//       (serve/angles_csv.hpp), the same format as `mocapd --replay --angles-out`.
//
// Both refuse to overwrite an existing file, give up after `timeout` without data, and
// return 0 (done), 1 (bad data / file error) or 2 (connection problem).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "nats_pose_client.hpp"

namespace mocap::client {

struct ExportOptions {
    std::string host;
    std::uint16_t port = 0;
    std::string out;
    std::uint64_t frames = 100;
    std::uint32_t subject = 0;  ///< 0 = the server's choice (BVH) / every subject (angles)
    std::chrono::milliseconds timeout{10000};
};

int run_record_bvh(const ExportOptions& options);
int run_record_bvh_nats(const NatsOptions& nats, const ExportOptions& options);
int run_angles_csv(const ExportOptions& options);

/// Sum of the CHANNELS counts of a HIERARCHY text (the values per MOTION line).
std::size_t bvh_channel_count(const std::string& hierarchy);

}  // namespace mocap::client
