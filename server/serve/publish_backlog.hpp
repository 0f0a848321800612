// publish_backlog.hpp — hands published frames from the publishing thread(s) to the serve
// threads ("lanes") of one server: per lane a mutex-guarded vector of at most `capacity`
// frames, swapped out by that lane's thread, with one wake-up post each time it turns
// non-empty. Every lane gets a copy of the same frame, which holds its encoded bytes by
// shared pointer: a frame is encoded once, whatever the number of lanes and clients.
// Used by the live BVH server and the HTTP server's WebSockets (PublishBacklog: one
// encoded text per frame) and by the pose server's broadcaster (one buffer per field
// selection in use, pose_broadcaster.hpp).
//
// Beyond capacity a lane refuses the frame (push() returns how many lanes refused; the
// caller counts them: backlog_dropped): that lane's thread is not keeping up at all (not
// a slow client: those drop in their own ClientSendQueue), and refusing keeps publish()
// bounded.
//
// Thread-safety: push() from any thread; `deliver(lane, frame)` runs on that lane's
// io_context thread, once per frame and lane, in push order. Memory: both vectors of every
// lane are reserved at construction; push() allocates nothing beyond what copying `Frame`
// does (shared pointers: none). The io_contexts must outlive this object.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "core/asio.hpp"

namespace mocap::serve {

template <class Frame>
class LaneBacklog {
public:
    using Deliver = std::function<void(std::size_t lane, const Frame&)>;

    /// `lanes`: one io_context per serve thread (not owned). `capacity` 0 is taken as 1.
    LaneBacklog(const std::vector<asio::io_context*>& lanes, std::size_t capacity, Deliver deliver)
        : capacity_(std::max<std::size_t>(capacity, 1)), deliver_(std::move(deliver)) {
        for (asio::io_context* io : lanes) {
            auto lane = std::make_unique<Lane>();
            lane->io = io;
            lane->pending.reserve(capacity_);
            lane->draining.reserve(capacity_);
            lanes_.push_back(std::move(lane));
        }
    }
    LaneBacklog(const LaneBacklog&) = delete;
    LaneBacklog& operator=(const LaneBacklog&) = delete;

    /// Any thread. Queues `frame` for every lane; returns the number of lanes that refused
    /// it because `capacity` frames already wait there.
    [[nodiscard]] std::size_t push(const Frame& frame) {
        std::size_t refused = 0;
        for (std::size_t i = 0; i < lanes_.size(); ++i) {
            Lane& lane = *lanes_[i];
            bool wake = false;
            {
                std::lock_guard lock(lane.mutex);
                if (lane.pending.size() >= capacity_) {
                    ++refused;
                    continue;
                }
                wake = lane.pending.empty();
                lane.pending.push_back(frame);
            }
            if (wake) asio::post(*lane.io, [this, i] { drain(i); });
        }
        return refused;
    }

    [[nodiscard]] std::size_t lane_count() const { return lanes_.size(); }

private:
    struct Lane {
        asio::io_context* io = nullptr;
        std::mutex mutex;
        std::vector<Frame> pending;   // guarded by mutex
        std::vector<Frame> draining;  // lane thread; swapped with pending, so neither reallocates
    };

    void drain(std::size_t lane_index) {
        Lane& lane = *lanes_[lane_index];
        {
            std::lock_guard lock(lane.mutex);
            lane.draining.swap(lane.pending);
        }
        for (const Frame& frame : lane.draining)
            deliver_(lane_index, frame);
        lane.draining.clear();
    }

    std::size_t capacity_;
    Deliver deliver_;
    std::vector<std::unique_ptr<Lane>> lanes_;
};

/// One encoded frame of one subject (a BVH MOTION line, a WebSocket JSON message).
struct SubjectText {
    std::uint32_t subject_id = 0;
    std::shared_ptr<const std::string> text;
    double frame_time_s = 0.0;  ///< live BVH: the subject's measured interval (0 = not yet known)
};

using PublishBacklog = LaneBacklog<SubjectText>;

}  // namespace mocap::serve
