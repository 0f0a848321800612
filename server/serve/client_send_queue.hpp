// client_send_queue.hpp — one client's bounded queue of outgoing frames: when it is
// full the OLDEST frame is dropped and counted, so a client that reads too slowly sees
// a gap and never slows the pipeline (docs/style.md, "Encode once, drop the oldest"). Used by the pose stream
// (client_session), the live BVH sessions (bvh_server) and the viewer's WebSockets
// (http_server).
//
// Contract:
// - Capacity: fixed at construction (queue_frames from the config; at least 1). The
//   ring is allocated once; push/pop never allocate.
// - What is dropped: only frames, and only the oldest one, when a push finds the queue
//   full. Every drop increments the shared counter given at construction (the server's
//   frames_dropped / ws_frames_dropped) and this queue's own totals.
// - What is never in here: messages a client must receive — the pose stream's Hello and
//   replies, the BVH HIERARCHY greeting, the WebSocket hello. Sessions keep those apart
//   (a reply queue, a "greeted" flag) and write them before queued frames, so no rule
//   in this class has to protect them.
// - Announcing drops is the session's choice: the pose stream writes a DropNotice and a
//   WebSocket a {"type":"drops"} message (take_unreported_drops()); a BVH text client
//   gets no notice, because the BVH text format has no line for it: a gap in the
//   MOTION lines is all it sees (it is counted all the same).
// - clear() discards without counting: the client no longer wants those frames (it
//   switched subject, unsubscribed or is being closed), nothing was lost to lag.
// Thread-safety: none; one session's thread (its io_context) only. The shared drop
// counter is atomic and may be shared by many queues on many threads.
// Cost: push/pop are O(1) shared_ptr moves.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/counters.hpp"

namespace mocap::serve {

class ClientSendQueue {
public:
    using Bytes = std::shared_ptr<const std::string>;  ///< one encoded frame, shared

    /// `capacity` 0 is taken as 1. `dropped_counter` must outlive the queue.
    ClientSendQueue(std::size_t capacity, Counter& dropped_counter);

    /// Appends `frame`; when full, first drops the oldest (counted). Never fails.
    void push(Bytes frame);
    /// Removes and returns the oldest frame. Precondition: !empty().
    Bytes pop();
    /// Moves the oldest frames to `out` until out.size() reaches `max_size` or the queue
    /// is empty (for one batched write). Returns how many were moved.
    std::size_t move_into(std::vector<Bytes>& out, std::size_t max_size);
    /// Discards every queued frame without counting it as dropped.
    void clear();

    [[nodiscard]] std::size_t size() const { return size_; }
    [[nodiscard]] bool empty() const { return size_ == 0; }
    [[nodiscard]] std::size_t capacity() const { return ring_.size(); }

    /// Frames this queue dropped since construction.
    [[nodiscard]] std::uint64_t dropped_total() const { return dropped_total_; }
    /// Frames dropped since the last call (for a drop notice); resets to 0.
    [[nodiscard]] std::uint64_t take_unreported_drops();

private:
    std::vector<Bytes> ring_;
    std::size_t head_ = 0;
    std::size_t size_ = 0;
    Counter& dropped_counter_;
    std::uint64_t dropped_total_ = 0;
    std::uint64_t dropped_unreported_ = 0;
};

}  // namespace mocap::serve
