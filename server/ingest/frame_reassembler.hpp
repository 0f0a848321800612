// frame_reassembler.hpp — CAN frames of one bus -> one sample per node per SYNC instant.
//
// The same reassembler serves both transports (docs/design.md, "Data flow"): the sink tunnels
// CAN frames over TCP, SocketCAN reads them from the bus; either way ingest hands every frame
// with a receive time to the bus's FrameReassembler.
//
// Per node, the ACCEL, GYRO and MAG frames of one SYNC instant (recognised by the low 16
// counter bits they carry, extended against the bus's latest SYNC with mw_counter_extend)
// become one ImuSample in SI units, scaled with the ranges the node last reported in its
// STATUS (defaults until then); an ATT frame becomes one on-node orientation sample.
// Counters classify everything that does not become a sample:
//   malformed_frames  frame the wire library rejects (bad DLC, unknown ID, field range)
//   duplicate_frames  same part of the same instant twice (first copy kept)
//   late_frames       part of an instant older than the node's last emitted sample
//   incomplete_samples an instant that never got all three parts (superseded by newer
//                     instants or too old); the parts it had are dropped
//   samples_no_mag    samples emitted with the MAG part marked invalid (kImuNoMag)
// The 32-bit SYNC counter is extended to 64 bits (SegmentSample::sync) across its wrap.
//
// Time: sample t_us is the sink timestamp of that instant's SYNC frame when it was seen,
// else the receive time of the sample's first frame. Nothing here reads a clock.
// Threading: one bus's reassembler is used by one thread (the ingest thread); counters
// may be read from any thread. The counters are SingleWriterCounter (core/counters.hpp: no
// locked instruction per frame): every reassembler sharing one ReassemblyCounters must run
// on the same single thread. Cost: O(1) per frame, no allocation after construction.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include "core/counters.hpp"
#include "core/frame.hpp"
#include "mocap_wire/mw_can.h"

namespace mocap::ingest {

/// Counters shared by every bus of one transport (add them to a CounterGroup once).
/// Single writer: the one thread that runs all of that transport's reassemblers.
struct ReassemblyCounters {
    SingleWriterCounter frames;
    SingleWriterCounter sync_frames;
    SingleWriterCounter status_frames;
    SingleWriterCounter config_frames;
    SingleWriterCounter malformed_frames;
    SingleWriterCounter duplicate_frames;
    SingleWriterCounter late_frames;
    SingleWriterCounter incomplete_samples;
    SingleWriterCounter samples;
    SingleWriterCounter attitude_samples;
    SingleWriterCounter samples_no_mag;
    SingleWriterCounter node_error_reports;  ///< STATUS frames carrying any error flag
    SingleWriterCounter sync_wraps;

    void register_in(CounterGroup& group) const;
};

/// A finished sample for one node. segment_index is left 0: the router maps node ids to
/// segments. times.sink_send_us and times.received_us are filled.
using SampleSink = std::function<void(const SegmentSample&)>;

class FrameReassembler {
public:
    /// Ranges assumed for a node until its STATUS says otherwise (the firmware default).
    struct Params {
        mw_accel_range default_accel_range = MW_ACCEL_16G;
        mw_gyro_range default_gyro_range = MW_GYRO_2000DPS;
    };

    /// `counters` must outlive the reassembler; `sink` is called synchronously from
    /// on_frame() for every finished sample.
    FrameReassembler(std::uint32_t subject_id, Params params, ReassemblyCounters& counters, SampleSink sink);

    /// One CAN frame. sink_time_us: the sink's timestamp of the frame (packet timestamp +
    /// offset, or the kernel receive time for SocketCAN); sink_send_us: the packet's
    /// timestamp (0 for SocketCAN); received_us: when the daemon got it (host clock).
    void on_frame(const mw_can_frame& frame, std::int64_t sink_time_us, std::int64_t sink_send_us,
                  std::int64_t received_us);

    /// Forgets partial samples and the counter reference (a sink reconnected: its SYNC
    /// counter may have restarted). Node ranges and the 64-bit epoch are kept, so sync
    /// values stay monotonic when the new stream continues past the old one.
    void reset_stream();

    [[nodiscard]] std::uint32_t subject_id() const { return subject_id_; }
    /// Latest extended SYNC counter seen on this bus (0 before any).
    [[nodiscard]] std::uint64_t last_sync() const { return last_sync64_; }
    /// Last STATUS of a node (nullptr if none received yet).
    [[nodiscard]] const mw_status* node_status(std::uint8_t node_id) const;

private:
    static constexpr std::size_t kSlots = 4;  // instants in flight per node (power of two)
    static constexpr std::size_t kSyncTimes = 64;

    struct Slot {
        std::uint64_t sync = 0;
        std::uint8_t parts = 0;  // bit 0 accel, 1 gyro, 2 mag
        bool used = false;
        std::int64_t first_time_us = 0;
        std::int64_t sink_send_us = 0;
        std::int64_t received_us = 0;
        std::array<std::int16_t, 9> counts{};
    };
    struct Node {
        std::array<Slot, kSlots> slots{};
        std::uint64_t last_emitted = 0;
        bool emitted_any = false;
        bool has_status = false;
        mw_status status{};
    };

    std::uint64_t extend(std::uint32_t low, unsigned bits);
    bool admit(const Node& node, std::uint64_t sync);  // false (counted) if late or repeated
    void on_sync(std::uint32_t counter, std::int64_t sink_time_us);
    void on_raw(const mw_raw& raw, std::int64_t sink_time_us, std::int64_t sink_send_us, std::int64_t received_us);
    void on_attitude(const mw_attitude& att, std::int64_t sink_time_us, std::int64_t sink_send_us,
                     std::int64_t received_us);
    void emit_raw(std::uint8_t node_id, Node& node, Slot& slot);
    std::int64_t sample_time(std::uint64_t sync, std::int64_t fallback_us) const;

    std::uint32_t subject_id_;
    Params params_;
    ReassemblyCounters& counters_;
    SampleSink sink_;
    std::array<Node, MW_NODE_ID_MAX + 1> nodes_{};
    bool have_reference_ = false;
    std::uint32_t last_sync32_ = 0;
    std::uint64_t last_sync64_ = 0;
    std::array<std::pair<std::uint64_t, std::int64_t>, kSyncTimes> sync_times_{};
};

}  // namespace mocap::ingest
