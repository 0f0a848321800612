// publish_backlog.hpp — hands encoded frames from the publishing thread(s) to one serve
// thread: a mutex-guarded vector of at most `capacity` frames, swapped out by the serve
// thread, with one wake-up post each time it turns non-empty. Used by the live BVH
// server and the HTTP server's WebSockets (the pose server's broadcaster has per-lane
// backlogs of multi-selection frames of its own).
//
// Beyond capacity push() refuses the frame (the caller counts it: backlog_dropped):
// the serve thread is not keeping up at all (not a slow client: those drop in their
// own ClientSendQueue), and refusing keeps publish() bounded.
//
// Thread-safety: push() from any thread; `deliver` runs on the io_context's thread, once
// per frame, in push order. Memory: both vectors are reserved at construction; push()
// never allocates. The io_context must outlive this object.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/asio.hpp"

namespace mocap::serve {

/// One encoded frame of one subject (a BVH MOTION line, a WebSocket JSON message).
struct SubjectText {
    std::uint32_t subject_id = 0;
    std::shared_ptr<const std::string> text;
};

class PublishBacklog {
public:
    PublishBacklog(asio::io_context& io, std::size_t capacity, std::function<void(const SubjectText&)> deliver);
    PublishBacklog(const PublishBacklog&) = delete;
    PublishBacklog& operator=(const PublishBacklog&) = delete;

    /// Any thread. False (frame not taken) when `capacity` frames already wait.
    [[nodiscard]] bool push(SubjectText frame);

private:
    void drain();

    asio::io_context& io_;
    std::size_t capacity_;
    std::function<void(const SubjectText&)> deliver_;
    std::mutex mutex_;
    std::vector<SubjectText> pending_;   // guarded by mutex_
    std::vector<SubjectText> draining_;  // serve thread; swapped with pending_
};

}  // namespace mocap::serve
