// take_export_queue.hpp — what a take download asks of the daemon (a re-solve of the raw
// file into BVH or joint-angle CSV, daemon/take_export.hpp) and the queue that runs those
// requests off the serve threads.
//
// A re-solve runs the take through a whole pipeline (~90x real time with the default filter,
// so ~40 s for an hour of one subject): far too long for a serve thread, whose other clients
// would wait. The web endpoint hands it to this queue instead: ONE worker thread runs one
// export at a time, at most `max_waiting` more wait, and a request beyond that is refused at
// once (HTTP 503), so a client cannot pile up work or memory. Each job has its own cancel
// flag (an export checks it per sample): its submitter sets it when the job is no longer
// wanted (the HTTP connection that asked for it closed), and a waiting job whose flag is set
// is dropped without running, so abandoned requests neither run nor hold a place. stop() sets
// every running and waiting job's flag, runs what waits (each finds its flag set and returns
// at once) and joins the thread. The thread runs at nice 19 (setpriority on that thread
// alone): a re-solve takes a core only when the live path leaves it idle.
//
// Threads: submit() from any thread; jobs run on the queue's thread; stop() from the owner.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace mocap::serve {

enum class TakeFormat { kRaw, kBvh, kCsv };

struct TakeExportRequest {
    std::string name;
    TakeFormat format = TakeFormat::kBvh;
    std::string filter;         ///< "" = the daemon's configured filter
    std::uint32_t subject = 0;  ///< BVH: 0 = the [outputs].bvh_subject rule
    bool offline = false;       ///< the non-causal re-solve (mocapd --replay --offline)
    /// Non-empty: the exporter calls it while it writes, with the bytes its output holds so
    /// far; false (with *why) stops the export, which answers kTooLarge with that reason (the
    /// web endpoint charges the growth to its export budget, take_export_budget.hpp).
    std::function<bool(std::uint64_t held, std::string* why)> reserve;
};

struct TakeExportResult {
    /// kTooLarge: past a memory limit, refused before it ran or stopped as it grew (HTTP 507,
    /// with the reason).
    enum Status { kOk, kNotFound, kBadRequest, kFailed, kCancelled, kTooLarge } status = kFailed;
    std::string error;
    int fd = -1;  ///< kOk: an open file without a name (a memfd) holding the export; the receiver closes it
};

/// Runs one export on the queue's thread; must return soon after `cancel` becomes true.
using TakeExporter = std::function<TakeExportResult(const TakeExportRequest& request, const std::atomic<bool>& cancel)>;

class TakeExportQueue {
public:
    using Job = std::function<void(const std::atomic<bool>& cancel)>;

    explicit TakeExportQueue(std::size_t max_waiting) : max_waiting_(max_waiting) {}
    ~TakeExportQueue() { stop(); }
    TakeExportQueue(const TakeExportQueue&) = delete;
    TakeExportQueue& operator=(const TakeExportQueue&) = delete;

    /// Queues `job` (the thread starts with the first one); it runs with `cancel` as its flag.
    /// False when max_waiting jobs wait already (jobs whose flag is set are dropped first), or
    /// after stop().
    bool submit(Job job, std::shared_ptr<std::atomic<bool>> cancel);
    bool submit(Job job) { return submit(std::move(job), std::make_shared<std::atomic<bool>>(false)); }
    /// Jobs dropped because their flag was set while they waited.
    [[nodiscard]] std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }
    /// Cancels, runs what waits with the flag set, joins. Idempotent.
    void stop();

private:
    void run();

    std::size_t max_waiting_;
    std::mutex mutex_;
    std::condition_variable wake_;
    struct Waiting {
        Job job;
        std::shared_ptr<std::atomic<bool>> cancel;
    };
    std::deque<Waiting> waiting_;                 // mutex_
    std::shared_ptr<std::atomic<bool>> running_;  // mutex_: the running job's flag
    bool stopping_ = false;                       // mutex_
    std::atomic<std::uint64_t> dropped_{0};
    std::thread thread_;  // started under mutex_
};

}  // namespace mocap::serve
