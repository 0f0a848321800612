#include "cluster/raw_stream.hpp"

#include <nats/nats.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

#include "cluster/cluster_config.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::cluster {
namespace {

std::int64_t steady_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

/// How long a failed stream check waits before the next attempt (a lost connection resets it).
constexpr std::int64_t kEnsureRetryUs = 5'000'000;
/// JetStream API requests (stream info, create) wait this long for the server.
constexpr std::int64_t kApiWaitMs = 2000;

std::string js_error(natsStatus s, jsErrCode code) {
    std::string text = natsStatus_GetText(s);
    if (const char* last = nats_GetLastError(nullptr); last != nullptr && *last != '\0')
        text += std::string(" (") + last + ")";
    if (code != 0) text += " [JetStream error " + std::to_string(static_cast<int>(code)) + "]";
    return text;
}

}  // namespace

std::string raw_subject(const std::string& site, std::uint32_t subject_id) {
    return "mocap." + site + "." + std::to_string(subject_id) + ".raw";
}

std::string raw_subject_pattern(const std::string& site) {
    return "mocap." + site + ".*.raw";
}

RawStreamPublisher::RawStreamPublisher(RawStreamConfig config, CounterGroup& group)
    : config_(std::move(config)), pattern_(raw_subject_pattern(config_.site)) {
    group.add("raw_samples_queued", samples_queued_);
    group.add("raw_samples_dropped", samples_dropped_);
    group.add("raw_messages_sent", messages_sent_);
    group.add("raw_bytes_sent", bytes_sent_);
    group.add("raw_messages_acked", messages_acked_);
    group.add("raw_samples_acked", samples_acked_);
    group.add("raw_messages_failed", messages_failed_);
    group.add("raw_samples_failed", samples_failed_);
    group.add("raw_stream_errors", stream_errors_);
}

RawStreamPublisher::~RawStreamPublisher() {
    finish(false, 0);
}

void RawStreamPublisher::push(const SegmentSample& sample) {
    {
        std::lock_guard lock(queue_mutex_);
        if (queue_.size() >= config_.queue_samples) {
            queue_.pop_front();
            samples_dropped_.add();
        }
        queue_.push_back(sample);
        queued_.store(queue_.size(), std::memory_order_relaxed);
    }
    samples_queued_.add();
}

bool RawStreamPublisher::attach(natsConnection* connection, std::string* error) {
    jsOptions o;
    jsOptions_Init(&o);
    o.Wait = kApiWaitMs;
    o.PublishAsync.MaxPending = config_.max_pending;
    o.PublishAsync.StallWait = kRawStallWaitMs;
    o.PublishAsync.AckHandler = &RawStreamPublisher::on_ack;
    o.PublishAsync.AckHandlerClosure = this;
    return nats_ok(natsConnection_JetStream(&js_, connection, &o), "JetStream context", error);
}

bool RawStreamPublisher::ensure_stream() {
    const std::int64_t now = steady_us();
    if (now < next_ensure_us_) return false;
    next_ensure_us_ = now + kEnsureRetryUs;
    jsStreamInfo* si = nullptr;
    jsErrCode code{};
    natsStatus s = js_GetStreamInfo(&si, js_, kRawStreamName, nullptr, &code);
    std::string problem;
    if (s == NATS_NOT_FOUND || code == JSStreamNotFoundErr) {
        const char* subjects[] = {pattern_.c_str()};
        jsStreamConfig c;
        jsStreamConfig_Init(&c);
        c.Name = kRawStreamName;
        c.Description = "mocapd raw samples: durable takes";
        c.Subjects = subjects;
        c.SubjectsLen = 1;
        c.Storage = js_FileStorage;
        c.Replicas = config_.replicas;
        s = js_AddStream(&si, js_, &c, nullptr, &code);
        if (s == NATS_OK) {
            spdlog::info("cluster: created JetStream stream {} ({}, file storage, {} replica(s))", kRawStreamName,
                         pattern_, config_.replicas);
        } else {
            problem = "cannot create JetStream stream " + std::string(kRawStreamName) + ": " + js_error(s, code);
        }
    } else if (s == NATS_OK) {
        const jsStreamConfig& c = *si->Config;
        const bool covered =
            std::any_of(c.Subjects, c.Subjects + c.SubjectsLen, [&](const char* x) { return pattern_ == x; });
        if (c.Storage != js_FileStorage) {
            problem = "JetStream stream " + std::string(kRawStreamName) +
                      " exists with memory storage; durable takes need file storage (delete or fix the stream)";
        } else if (!covered) {
            // Another site's stream: add this site's subjects, keep the rest of its config.
            std::vector<const char*> subjects(c.Subjects, c.Subjects + c.SubjectsLen);
            subjects.push_back(pattern_.c_str());
            jsStreamConfig updated = c;
            updated.Subjects = subjects.data();
            updated.SubjectsLen = static_cast<int>(subjects.size());
            jsStreamInfo* after = nullptr;
            s = js_UpdateStream(&after, js_, &updated, nullptr, &code);
            jsStreamInfo_Destroy(after);
            if (s == NATS_OK) {
                spdlog::info("cluster: added {} to JetStream stream {}", pattern_, kRawStreamName);
            } else {
                problem =
                    "cannot add " + pattern_ + " to JetStream stream " + kRawStreamName + ": " + js_error(s, code);
            }
        }
        if (problem.empty() && c.Replicas != static_cast<int64_t>(config_.replicas)) {
            spdlog::warn(
                "cluster: JetStream stream {} has {} replica(s), [cluster] raw_replicas says {}; kept as it is",
                kRawStreamName, c.Replicas, config_.replicas);
        }
    } else {
        problem = "cannot look up JetStream stream " + std::string(kRawStreamName) + ": " + js_error(s, code) +
                  " (is JetStream enabled on the servers?)";
    }
    jsStreamInfo_Destroy(si);
    if (!problem.empty()) {
        stream_errors_.add();
        // Once per episode; the raw samples wait in the queue (oldest dropped, counted).
        if (!ensure_logged_) spdlog::error("cluster: {}; raw samples are dropped until it works", problem);
        ensure_logged_ = true;
        return false;
    }
    if (ensure_logged_) spdlog::info("cluster: JetStream stream {} is usable again", kRawStreamName);
    ensure_logged_ = false;
    stream_ready_ = true;
    return true;
}

void RawStreamPublisher::publish_queued() {
    if (js_ == nullptr) return;
    if (!stream_ready_ && !ensure_stream()) return;
    {
        std::lock_guard lock(queue_mutex_);
        if (queue_.empty()) return;
        batch_.assign(queue_.begin(), queue_.end());
        queue_.clear();
        queued_.store(0, std::memory_order_relaxed);
    }
    // One message per subject per drain (in arrival order within the subject), split at
    // kRawMessageBytes.
    for (const SegmentSample& s : batch_) {
        auto it = std::find_if(batches_.begin(), batches_.end(),
                               [&](const SubjectBatch& b) { return b.subject_id == s.subject_id; });
        if (it == batches_.end()) it = batches_.insert(batches_.end(), SubjectBatch{s.subject_id, {}, 0});
        serve::append_raw_sample_record(s, it->bytes);
        if (++it->samples; it->bytes.size() >= kRawMessageBytes) {
            send(raw_subject(config_.site, it->subject_id), it->bytes, it->samples);
            it->bytes.clear();
            it->samples = 0;
        }
    }
    for (SubjectBatch& b : batches_) {
        if (b.samples != 0) send(raw_subject(config_.site, b.subject_id), b.bytes, b.samples);
        b.bytes.clear();
        b.samples = 0;
    }
    batch_.clear();
}

void RawStreamPublisher::send(const std::string& subject, const std::string& payload, std::uint32_t samples) {
    natsMsg* m = nullptr;
    if (natsMsg_Create(&m, subject.c_str(), nullptr, payload.data(), static_cast<int>(payload.size())) != NATS_OK) {
        messages_failed_.add();
        samples_failed_.add(samples);
        return;
    }
    const natsMsg* key = m;
    {
        // Before the publish: the acknowledgement may arrive before js_PublishMsgAsync returns.
        std::lock_guard lock(flight_mutex_);
        in_flight_[key] = InFlight{steady_us(), samples};
    }
    jsPubOptions po;
    jsPubOptions_Init(&po);
    po.MaxWait = config_.ack_wait_ms;
    published_ = true;  // an unacknowledged message fails (is counted) after this
    const natsStatus s = js_PublishMsgAsync(js_, &m, &po);
    if (s == NATS_OK) {
        messages_sent_.add();
        bytes_sent_.add(payload.size());
        return;
    }
    // Still ours (m non-null): not sent, or sent and taken back; either way not acknowledged.
    if (m != nullptr) {
        {
            std::lock_guard lock(flight_mutex_);
            in_flight_.erase(key);
        }
        natsMsg_Destroy(m);
        messages_failed_.add();
        samples_failed_.add(samples);
    }
}

void RawStreamPublisher::on_ack(jsCtx* /*js*/, natsMsg* msg, jsPubAck* pa, jsPubAckErr* /*pae*/, void* self) {
    auto* p = static_cast<RawStreamPublisher*>(self);
    InFlight f;
    bool known = false;
    {
        std::lock_guard lock(p->flight_mutex_);
        if (auto it = p->in_flight_.find(msg); it != p->in_flight_.end()) {
            f = it->second;
            known = true;
            p->in_flight_.erase(it);
        }
    }
    if (pa != nullptr) {
        p->messages_acked_.add();
        p->samples_acked_.add(f.samples);
        if (known) p->ack_latency_.record(steady_us() - f.sent_us);
    } else {
        p->messages_failed_.add();
        p->samples_failed_.add(f.samples);
    }
    natsMsg_Destroy(msg);
}

void RawStreamPublisher::detach() {
    release_context();
    stream_ready_ = false;
}

void RawStreamPublisher::finish(bool connected, std::int64_t wait_ms) {
    if (js_ == nullptr) return;
    if (connected) {
        publish_queued();  // a clean stop leaves nothing queued
        jsPubOptions po;
        jsPubOptions_Init(&po);
        po.MaxWait = std::max<std::int64_t>(wait_ms, 1);
        if (js_PublishAsyncComplete(js_, &po) != NATS_OK)
            spdlog::warn("cluster: raw samples still unacknowledged after {} ms at stop", wait_ms);
    }
    release_context();
    std::lock_guard lock(queue_mutex_);
    samples_dropped_.add(queue_.size());  // a stop without a connection: never published
    queue_.clear();
    queued_.store(0, std::memory_order_relaxed);
}

void RawStreamPublisher::release_context() {
    if (js_ == nullptr) return;
    // What is still pending gets no callback any more: count it and free it. (The client
    // makes its table of pending messages at the first asynchronous publish and must not be
    // asked before.)
    natsMsgList pending{};
    if (published_ && js_PublishAsyncGetPendingList(&pending, js_) == NATS_OK) {
        std::lock_guard lock(flight_mutex_);
        for (int i = 0; i < pending.Count; ++i) {
            if (auto it = in_flight_.find(pending.Msgs[i]); it != in_flight_.end()) {
                samples_failed_.add(it->second.samples);
                in_flight_.erase(it);
            }
            messages_failed_.add();
        }
        natsMsgList_Destroy(&pending);
    }
    jsCtx_Destroy(js_);
    js_ = nullptr;
    published_ = false;
}

void RawStreamPublisher::register_metrics(MetricsRegistry& registry) const {
    registry.add_gauge("cluster_raw_queued_samples", "raw samples waiting for the cluster publisher thread",
                       [this] { return static_cast<double>(queued_.load(std::memory_order_relaxed)); });
    registry.add_latency("cluster_raw_ack", [this] { return ack_latency_.snapshot(); });
}

}  // namespace mocap::cluster
