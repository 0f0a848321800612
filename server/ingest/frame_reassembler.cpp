#include "ingest/frame_reassembler.hpp"

#include <utility>

#include "mocap_wire/mw_scale.h"

namespace mocap::ingest {
namespace {

constexpr std::uint8_t kAllParts = 0x7;

std::uint8_t part_bit(mw_function kind) {
    switch (kind) {
        case MW_FN_ACCEL:
            return 0x1;
        case MW_FN_GYRO:
            return 0x2;
        default:
            return 0x4;  // MW_FN_MAG: mw_raw_decode admits only the three kinds
    }
}

std::size_t part_offset(mw_function kind) {
    switch (kind) {
        case MW_FN_ACCEL:
            return 0;
        case MW_FN_GYRO:
            return 3;
        default:
            return 6;
    }
}

}  // namespace

void ReassemblyCounters::register_in(CounterGroup& group) const {
    group.add("can_frames", frames);
    group.add("sync_frames", sync_frames);
    group.add("status_frames", status_frames);
    group.add("config_frames", config_frames);
    group.add("malformed_frames", malformed_frames);
    group.add("duplicate_frames", duplicate_frames);
    group.add("late_frames", late_frames);
    group.add("incomplete_samples", incomplete_samples);
    group.add("samples", samples);
    group.add("attitude_samples", attitude_samples);
    group.add("samples_no_mag", samples_no_mag);
    group.add("node_error_reports", node_error_reports);
    group.add("sync_wraps", sync_wraps);
}

FrameReassembler::FrameReassembler(std::uint32_t subject_id, Params params, ReassemblyCounters& counters,
                                   SampleSink sink)
    : subject_id_(subject_id), params_(params), counters_(counters), sink_(std::move(sink)) {}

const mw_status* FrameReassembler::node_status(std::uint8_t node_id) const {
    if (node_id > MW_NODE_ID_MAX || !nodes_[node_id].has_status) return nullptr;
    return &nodes_[node_id].status;
}

void FrameReassembler::reset_stream() {
    for (auto& n : nodes_) {
        for (auto& s : n.slots) {
            if (s.used) counters_.incomplete_samples.add();
            s = Slot{};
        }
    }
    have_reference_ = false;
}

// Maps a (partial) counter onto the 64-bit sync line. The signed 32-bit distance to the
// latest counter decides direction, so both the low-bit wrap and the 32-bit wrap are
// handled by the same arithmetic.
std::uint64_t FrameReassembler::extend(std::uint32_t low, unsigned bits) {
    if (!have_reference_) {
        // A new stream (start or reconnect) continues after everything seen before, so the
        // 64-bit sync values a subject's assembler sees never go backwards.
        have_reference_ = true;
        last_sync32_ = low;
        // The first stream starts at 2^32 + counter, so the low 32 bits still read as the
        // sink's counter and 0 is free to mean "before any stream".
        last_sync64_ = last_sync64_ == 0 ? (std::uint64_t{1} << 32) + low : last_sync64_ + 1;
        return last_sync64_;
    }
    const std::uint32_t full = mw_counter_extend(last_sync32_, low, bits);
    const auto delta = static_cast<std::int32_t>(full - last_sync32_);
    if (delta < 0 && static_cast<std::uint64_t>(-static_cast<std::int64_t>(delta)) > last_sync64_) {
        return 0;  // before the start of the stream: callers treat 0 as late
    }
    return last_sync64_ + static_cast<std::uint64_t>(static_cast<std::int64_t>(delta));
}

void FrameReassembler::on_sync(std::uint32_t counter, std::int64_t sink_time_us) {
    counters_.sync_frames.add();
    std::uint64_t s = 0;
    if (!have_reference_) {
        s = extend(counter, 32);
    } else {
        const auto delta = static_cast<std::int32_t>(counter - last_sync32_);
        if (delta > 0) {
            if (counter < last_sync32_) counters_.sync_wraps.add();
            last_sync64_ += static_cast<std::uint64_t>(delta);
            last_sync32_ = counter;
            s = last_sync64_;
        } else if (delta == 0) {
            s = last_sync64_;
        } else {
            // The sink's counter went backwards without a reconnect (it rebooted): start a
            // new stream after the old one rather than mixing instants.
            have_reference_ = false;
            s = extend(counter, 32);
        }
    }
    sync_times_[s % kSyncTimes] = {s, sink_time_us};
}

std::int64_t FrameReassembler::sample_time(std::uint64_t sync, std::int64_t fallback_us) const {
    const auto& [s, t] = sync_times_[sync % kSyncTimes];
    return s == sync && sync != 0 ? t : fallback_us;
}

void FrameReassembler::on_frame(const mw_can_frame& frame, std::int64_t sink_time_us, std::int64_t sink_send_us,
                                std::int64_t received_us) {
    counters_.frames.add();
    mw_message msg;
    if (mw_can_decode(&frame, &msg) < 0) {
        counters_.malformed_frames.add();
        return;
    }
    switch (msg.function) {
        case MW_FN_SYNC:
            on_sync(msg.u.sync.counter, sink_time_us);
            break;
        case MW_FN_ACCEL:
        case MW_FN_GYRO:
        case MW_FN_MAG:
            on_raw(msg.u.raw, sink_time_us, sink_send_us, received_us);
            break;
        case MW_FN_ATTITUDE:
            on_attitude(msg.u.attitude, sink_time_us, sink_send_us, received_us);
            break;
        case MW_FN_STATUS: {
            counters_.status_frames.add();
            if (msg.u.status.error_flags != 0) counters_.node_error_reports.add();
            if (msg.u.status.node_id != MW_NODE_ID_SINK) {
                Node& n = nodes_[msg.u.status.node_id];
                n.status = msg.u.status;
                n.has_status = true;
            }
            break;
        }
        case MW_FN_CONFIG:
            counters_.config_frames.add();
            break;
    }
}

// A frame for an instant at or before the node's last emitted sample can only be late or a
// repeat: the filter must see each node's samples once and in order.
bool FrameReassembler::admit(const Node& node, std::uint64_t s) {
    if (s == 0 || (node.emitted_any && s < node.last_emitted)) {
        counters_.late_frames.add();
        return false;
    }
    if (node.emitted_any && s == node.last_emitted) {
        counters_.duplicate_frames.add();
        return false;
    }
    return true;
}

void FrameReassembler::on_raw(const mw_raw& raw, std::int64_t sink_time_us, std::int64_t sink_send_us,
                              std::int64_t received_us) {
    const std::uint64_t s = extend(raw.counter_low, MW_RAW_COUNTER_BITS);
    Node& node = nodes_[raw.node_id];
    if (!admit(node, s)) return;
    Slot& slot = node.slots[s % kSlots];
    if (slot.used && slot.sync != s) {
        if (slot.sync > s) {  // a newer instant already holds the slot: this one is too old
            counters_.late_frames.add();
            return;
        }
        counters_.incomplete_samples.add();
        slot = Slot{};
    }
    const std::uint8_t bit = part_bit(raw.kind);
    if (slot.used && (slot.parts & bit) != 0) {
        counters_.duplicate_frames.add();
        return;
    }
    if (!slot.used) {
        slot.used = true;
        slot.sync = s;
        slot.first_time_us = sink_time_us;
        slot.sink_send_us = sink_send_us;
    }
    slot.parts |= bit;
    slot.received_us = received_us;
    const std::size_t off = part_offset(raw.kind);
    for (std::size_t i = 0; i < 3; ++i)
        slot.counts[off + i] = raw.xyz[i];
    if (slot.parts == kAllParts) emit_raw(raw.node_id, node, slot);
}

void FrameReassembler::emit_raw(std::uint8_t node_id, Node& node, Slot& slot) {
    const mw_accel_range ar = node.has_status ? node.status.accel_range : params_.default_accel_range;
    const mw_gyro_range gr = node.has_status ? node.status.gyro_range : params_.default_gyro_range;
    float accel[3]{}, gyro[3]{}, mag[3]{};
    SegmentSample out;
    out.subject_id = subject_id_;
    out.node_id = node_id;
    out.sync = slot.sync;
    out.imu.t_us = sample_time(slot.sync, slot.first_time_us);
    // Ranges come from a validated STATUS or the defaults, so scaling cannot fail; the
    // magnetometer is the one part that may be marked invalid by the node.
    mw_accel_to_m_s2(&slot.counts[0], ar, accel);
    mw_gyro_to_rad_s(&slot.counts[3], gr, gyro);
    if (mw_mag_to_ut(&slot.counts[6], mag) != MW_OK) {
        out.imu.flags |= kImuNoMag;
        counters_.samples_no_mag.add();
    }
    for (std::size_t i = 0; i < 3; ++i) {
        out.imu.accel_m_s2[i] = accel[i];
        out.imu.gyro_rad_s[i] = gyro[i];
        out.imu.mag_ut[i] = mag[i];
    }
    out.times.sink_send_us = slot.sink_send_us;
    out.times.received_us = slot.received_us;

    // Order per node is what the filter needs: older unfinished instants can no longer be
    // emitted after this one.
    for (auto& other : node.slots) {
        if (other.used && other.sync < slot.sync) {
            counters_.incomplete_samples.add();
            other = Slot{};
        }
    }
    node.last_emitted = slot.sync;
    node.emitted_any = true;
    slot = Slot{};
    counters_.samples.add();
    sink_(out);
}

void FrameReassembler::on_attitude(const mw_attitude& att, std::int64_t sink_time_us, std::int64_t sink_send_us,
                                   std::int64_t received_us) {
    const std::uint64_t s = extend(att.counter_low, MW_ATT_COUNTER_BITS);
    Node& node = nodes_[att.node_id];
    if (!admit(node, s)) return;
    SegmentSample out;
    out.subject_id = subject_id_;
    out.node_id = att.node_id;
    out.sync = s;
    out.has_node_quat = true;
    out.imu.t_us = sample_time(s, sink_time_us);
    out.imu.flags = kImuNoMag;
    for (std::size_t i = 0; i < 4; ++i)
        out.node_q_wxyz[i] = att.q[i];
    out.times.sink_send_us = sink_send_us;
    out.times.received_us = received_us;
    for (auto& other : node.slots) {
        if (other.used && other.sync <= s) {
            counters_.incomplete_samples.add();
            other = Slot{};
        }
    }
    node.last_emitted = s;
    node.emitted_any = true;
    counters_.attitude_samples.add();
    sink_(out);
}

}  // namespace mocap::ingest
