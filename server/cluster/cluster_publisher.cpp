#include "cluster/cluster_publisher.hpp"

#include <nats/nats.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <nlohmann/json.hpp>

#include "skeleton/euler.hpp"

namespace mocap::cluster {
namespace {

// Raw samples are drained this often: the batch of one JetStream message per subject, and
// about what a killed host loses beyond what was in flight.
constexpr auto kRawDrain = std::chrono::milliseconds(20);
// Longest a stop waits for JetStream to acknowledge the last raw samples.
constexpr std::int64_t kRawFinishWaitMs = 3000;

// The varint length prefix of a delimited frame: NATS messages carry their own length.
std::size_t prefix_bytes(const std::string& bytes) {
    std::size_t n = 0;
    while (n < bytes.size() && (static_cast<unsigned char>(bytes[n]) & 0x80u) != 0)
        ++n;
    return n + 1;
}

// The body model as the heartbeat describes it (docs/outputs.md, "Cluster publisher").
nlohmann::ordered_json body_json(const skeleton::BodyModel& model) {
    nlohmann::ordered_json segments = nlohmann::ordered_json::array();
    for (const auto& s : model.segments) {
        segments.push_back({{"name", s.name},
                            {"parent", s.parent},
                            {"offset_m", {s.offset_m.x(), s.offset_m.y(), s.offset_m.z()}},
                            {"end_m", {s.end_m.x(), s.end_m.y(), s.end_m.z()}}});
    }
    return {{"segments", segments}, {"root_height_m", model.root_height_m}};
}

}  // namespace

std::string pose_subject(const std::string& site, std::uint32_t subject_id) {
    return "mocap." + site + "." + std::to_string(subject_id) + ".pose";
}

std::string host_subject(const std::string& site, const std::string& host_id) {
    return "mocap." + site + ".host." + host_id;
}

ClusterPublisher::ClusterPublisher(ClusterConfig config)
    : config_(std::move(config)),
      raw_(
          RawStreamConfig{
              .site = config_.site, .replicas = config_.raw_replicas, .queue_samples = config_.raw_queue_samples},
          group_) {
    group_.add("frames_queued", frames_queued_);
    group_.add("frames_dropped", frames_dropped_);
    group_.add("frames_published", frames_published_);
    group_.add("publish_errors", publish_errors_);
    group_.add("heartbeats", heartbeats_);
    group_.add("disconnects", disconnects_);
    group_.add("reconnects", reconnects_);
    group_.add("permission_errors", nats_errors_.permission_errors());
}

ClusterPublisher::~ClusterPublisher() {
    std::string ignored;
    stop(&ignored);
}

void ClusterPublisher::on_disconnected(natsConnection* /*nc*/, void* self) {
    auto* p = static_cast<ClusterPublisher*>(self);
    // The client also calls this when it closes: count only losses of a live connection.
    if (p->connected_.exchange(false)) {
        p->disconnects_.add();
        spdlog::warn("cluster: disconnected from NATS; frames are dropped until it reconnects");
    }
}

void ClusterPublisher::on_reconnected(natsConnection* /*nc*/, void* self) {
    auto* p = static_cast<ClusterPublisher*>(self);
    p->reconnects_.add();
    p->connected_.store(true);
    p->wake_.notify_one();
    spdlog::info("cluster: reconnected to NATS");
}

void ClusterPublisher::on_connected(natsConnection* /*nc*/, void* self) {
    auto* p = static_cast<ClusterPublisher*>(self);
    p->connected_.store(true);
    p->wake_.notify_one();
    spdlog::info("cluster: connected to NATS");
}

void ClusterPublisher::on_closed(natsConnection* /*nc*/, void* self) {
    auto* p = static_cast<ClusterPublisher*>(self);
    {
        std::lock_guard lock(p->mutex_);
        p->closed_ = true;
    }
    p->wake_.notify_all();
}

bool ClusterPublisher::start(std::string* error) {
    if (!make_nats_options(config_, &options_, error)) return false;
    const auto& c = config_;
    // Reconnect forever, quickly: the publisher drops frames while disconnected, so a short
    // wait bounds the gap. No reconnect buffer: frames wait in our own queue instead, where
    // the oldest are dropped and counted.
    (void)natsOptions_SetMaxReconnect(options_, -1);
    (void)natsOptions_SetReconnectWait(options_, c.reconnect_wait_ms);
    (void)natsOptions_SetReconnectBufSize(options_, 0);
    // Write each frame at once instead of letting the client's flusher gather them: the
    // gathering cost ~1 ms at p50 (measured: 1.42 -> 0.62 ms, docs/cluster.md); one write per
    // frame is 5 000 writes/s at 50 subjects, on this thread, not the pipeline's.
    (void)natsOptions_SetSendAsap(options_, true);
    (void)natsOptions_SetPingInterval(options_, 1000);
    (void)natsOptions_SetMaxPingsOut(options_, 2);
    (void)natsOptions_SetDisconnectedCB(options_, &ClusterPublisher::on_disconnected, this);
    (void)natsOptions_SetReconnectedCB(options_, &ClusterPublisher::on_reconnected, this);
    // The client runs callbacks on its own thread, after natsConnection_Close returns too:
    // stop() waits for this last one before `this` may go away.
    (void)natsOptions_SetClosedCB(options_, &ClusterPublisher::on_closed, this);
    // A subject the server's permissions refuse is dropped there: the log names it, once.
    nats_errors_.install(options_);
    started_us_ = config_.wall_clock_us();
    {
        std::lock_guard lock(mutex_);
        stopping_ = false;
        closed_ = false;
    }
    // The first connect waits for the server's INFO up to the client's timeout, twice: on the
    // publisher thread, so that a silent server never delays the daemon's start.
    thread_ = std::thread([this] {
        connect_first();
        run();
    });
    return true;
}

void ClusterPublisher::connect_first() {
    const auto& c = config_;
    // A cluster unreachable at start is retried like a lost one: the local pose service runs.
    // The first attempt is made without the retry so that its reason (refused credentials,
    // nothing listening, TLS) reaches the log; the retrying client would only say "not yet
    // connected".
    natsStatus s = natsConnection_Connect(&connection_, options_);
    if (s == NATS_OK) {
        connected_.store(true);
        spdlog::info("cluster: connected to {}; publishing on mocap.{}.<subject>.pose and .raw", c.nats_url, c.site);
    } else {
        spdlog::warn("cluster: cannot connect to {}: {}; retrying in the background", c.nats_url, nats_error_text(s));
        connection_ = nullptr;
        (void)natsOptions_SetRetryOnFailedConnect(options_, true, &ClusterPublisher::on_connected, this);
        s = natsConnection_Connect(&connection_, options_);
        if (s == NATS_OK) {
            connected_.store(true);
            spdlog::info("cluster: connected to {}", c.nats_url);
        } else if (s != NATS_NOT_YET_CONNECTED) {
            spdlog::error("cluster: cannot connect to {}: {}", c.nats_url, nats_error_text(s));
            connection_ = nullptr;
            std::lock_guard lock(mutex_);
            closed_ = true;  // run() tries again as after a refusal
            return;
        }
    }
    std::string error;
    if (!raw_.attach(connection_, &error)) spdlog::error("cluster: raw samples: {}", error);
}

bool ClusterPublisher::stop(std::string* /*error*/) {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_one();
    if (thread_.joinable()) thread_.join();
    if (connection_) {
        // Raw samples still queued are published and their acknowledgements awaited (bounded):
        // a clean stop leaves the take in JetStream complete.
        raw_.finish(connected_.load(), kRawFinishWaitMs);
        if (connected_.load()) (void)natsConnection_FlushTimeout(connection_, 500);
        connected_.store(false);  // the close is not a lost connection: not counted
        natsConnection_Close(connection_);
        {
            std::unique_lock lock(mutex_);
            if (!wake_.wait_for(lock, std::chrono::seconds(5), [this] { return closed_; })) {
                spdlog::warn("cluster: the NATS client did not confirm its close within 5 s");
            }
        }
        natsConnection_Destroy(connection_);
        connection_ = nullptr;
    }
    if (options_) {
        natsOptions_Destroy(options_);
        options_ = nullptr;
    }
    return true;
}

void ClusterPublisher::on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    // Every field: one message serves every subscriber (the pose service encodes once per
    // selection; here there is one selection).
    serve::SharedBytes bytes = encoder_.encode_frame(frame, pose, serve::kFieldAll, config_.wall_clock_us());
    if (!bytes) return;
    {
        std::lock_guard lock(mutex_);
        if (queue_.size() >= config_.queue_frames) {
            queue_.pop_front();
            frames_dropped_.add();
        }
        queue_.push_back({frame.subject_id, std::move(bytes)});
        queued_.store(queue_.size(), std::memory_order_relaxed);
    }
    frames_queued_.add();
    wake_.notify_one();
}

void ClusterPublisher::run() {
    using Clock = std::chrono::steady_clock;
    constexpr auto kHeartbeat = std::chrono::seconds(1);
    // While disconnected, look at the connection this often (the callbacks also wake us).
    constexpr auto kDisconnectedPoll = std::chrono::milliseconds(50);
    auto next_heartbeat = Clock::now() + kHeartbeat;
    auto last_heartbeat = Clock::now();
    std::vector<Queued> batch;
    bool was_up = false;
    auto next_raw = Clock::now() + kRawDrain;
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        const bool up = connected_.load();
        if (was_up && !up) raw_.connection_lost();  // check the stream again once back
        was_up = up;
        // Raw samples do not wake the thread (that would be one wake per sample): they are
        // drained every kRawDrain, so a message carries ~kRawDrain of one subject's samples.
        auto until =
            up ? std::min(next_heartbeat, next_raw) : std::min(next_heartbeat, Clock::now() + kDisconnectedPoll);
        wake_.wait_until(lock, until, [&] { return stopping_ || closed_ || (connected_.load() && !queue_.empty()); });
        if (stopping_) break;
        if (closed_) {
            // The client gave up (it closes a connection the server refused twice for the
            // same reason, e.g. credentials): open a new one, as an operator would restart.
            lock.unlock();
            reopen();
            lock.lock();
            was_up = false;
            continue;
        }
        if (connected_.load() && Clock::now() >= next_raw) {
            lock.unlock();
            raw_.publish_queued();
            lock.lock();
            next_raw = Clock::now() + kRawDrain;
        }
        if (connected_.load() && !queue_.empty()) {
            batch.assign(std::make_move_iterator(queue_.begin()), std::make_move_iterator(queue_.end()));
            queue_.clear();
            queued_.store(0, std::memory_order_relaxed);
            lock.unlock();
            publish_frames(batch);
            batch.clear();
            lock.lock();
        }
        const auto now = Clock::now();
        if (now >= next_heartbeat) {
            lock.unlock();
            publish_heartbeat(config_.wall_clock_us(), std::chrono::duration<double>(now - last_heartbeat).count());
            lock.lock();
            last_heartbeat = now;
            next_heartbeat += kHeartbeat;
            if (next_heartbeat < now) next_heartbeat = now + kHeartbeat;  // after a long stall
        }
    }
}

void ClusterPublisher::reopen() {
    constexpr auto kReopenWait = std::chrono::seconds(2);
    constexpr std::uint64_t kLogEvery = 30;  // a refusal that lasts is logged once a minute
    if (reopens_++ % kLogEvery == 0) {
        const char* why = nullptr;
        (void)natsConnection_GetLastError(connection_, &why);
        spdlog::warn("cluster: the NATS client closed its connection to {} ({}); connecting again every {} s",
                     config_.nats_url, why != nullptr && *why != '\0' ? why : "no reason given", kReopenWait.count());
    }
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        // Wait first: a server that refuses us is not asked again at once (stop() cuts it short).
        if (wake_.wait_for(lock, kReopenWait, [this] { return stopping_; })) return;
        lock.unlock();
        raw_.detach();                        // its JetStream context belongs to the old connection
        natsConnection_Destroy(connection_);  // its closed callback has run (closed_ is set)
        connection_ = nullptr;
        lock.lock();
        closed_ = false;
        lock.unlock();
        const natsStatus s = natsConnection_Connect(&connection_, options_);
        if (s == NATS_OK || s == NATS_NOT_YET_CONNECTED) {
            std::string error;
            if (!raw_.attach(connection_, &error)) spdlog::error("cluster: raw samples: {}", error);
        }
        lock.lock();
        if (s == NATS_OK) {
            connected_.store(true);
            spdlog::info("cluster: connected to {}", config_.nats_url);
        }
        if (s == NATS_OK || s == NATS_NOT_YET_CONNECTED) return;
        connection_ = nullptr;  // not even started (it did not retry): wait and try again
    }
}

void ClusterPublisher::publish_frames(std::vector<Queued>& batch) {
    std::string subject;
    for (const Queued& q : batch) {
        subject = pose_subject(config_.site, q.subject_id);
        const std::size_t skip = prefix_bytes(*q.bytes);
        const natsStatus s = natsConnection_Publish(connection_, subject.c_str(), q.bytes->data() + skip,
                                                    static_cast<int>(q.bytes->size() - skip));
        if (s == NATS_OK) {
            frames_published_.add();
        } else {
            publish_errors_.add();
        }
        auto it = std::find_if(subject_frames_.begin(), subject_frames_.end(),
                               [&](const auto& e) { return e.first == q.subject_id; });
        if (it == subject_frames_.end()) {
            subject_frames_.emplace_back(q.subject_id, 1);
        } else {
            ++it->second;
        }
    }
}

void ClusterPublisher::publish_heartbeat(std::int64_t now_us, double interval_s) {
    nlohmann::ordered_json subjects = nlohmann::ordered_json::array();
    std::sort(subject_frames_.begin(), subject_frames_.end());
    for (auto& [id, frames] : subject_frames_) {
        subjects.push_back({{"id", id}, {"rate_hz", interval_s > 0 ? static_cast<double>(frames) / interval_s : 0.0}});
    }
    subject_frames_.clear();
    const std::uint64_t dropped = frames_dropped_.value();
    const nlohmann::ordered_json status{
        {"host_id", config_.host_id},
        {"site", config_.site},
        {"time_us", now_us},
        {"uptime_s", static_cast<double>(now_us - started_us_) / 1e6},
        {"health", connected_.load() ? (publish_errors_.value() == 0 ? "ok" : "publish_errors") : "disconnected"},
        {"subjects", subjects},
        {"frames_published", frames_published_.value()},
        {"frames_dropped", dropped},
        {"queued", queued_.load(std::memory_order_relaxed)},
        {"disconnects", disconnects_.value()},
        {"reconnects", reconnects_.value()},
        {"segments", config_.segment_names},
        {"joint_angle_names", config_.joint_angle_names},
        {"body", body_json(config_.model)},
        {"bvh",
         {{"units_per_m", config_.bvh.write.units_per_m},
          {"rotation_order", skeleton::to_string(config_.bvh.write.order)},
          {"decimals", config_.bvh.write.decimals},
          {"frame_time_s", config_.bvh.frame_time_s}}},
    };
    if (!connected_.load()) return;  // nobody would receive it; the counters keep the story
    const std::string text = status.dump();
    const std::string subject = host_subject(config_.site, config_.host_id);
    if (natsConnection_Publish(connection_, subject.c_str(), text.data(), static_cast<int>(text.size())) == NATS_OK) {
        heartbeats_.add();
    } else {
        publish_errors_.add();
    }
}

void ClusterPublisher::register_metrics(MetricsRegistry& registry) const {
    registry.add(group_);
    registry.add_gauge(
        "cluster_connected", "1 while the cluster publisher is connected to NATS",
        [this] { return connected_.load(std::memory_order_relaxed) ? 1.0 : 0.0; }, "cluster");
    registry.add_gauge("cluster_queued_frames", "frames waiting for the cluster publisher thread",
                       [this] { return static_cast<double>(queued_.load(std::memory_order_relaxed)); });
    raw_.register_metrics(registry);
}

}  // namespace mocap::cluster
