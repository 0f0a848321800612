#include "nats_load_client.hpp"

#include <nats/nats.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "load_tally.hpp"

namespace mocap::client {

namespace {

struct NatsClientState {
    std::mutex mutex;  // the delivery pool thread vs. the final merge
    ClientTally tally;
    std::map<std::uint32_t, std::uint64_t> seen_per_subject;  // decimation, as NatsPoseClient
    v1::ServerMessage scratch;
    std::uint32_t decimation = 1;
    std::size_t max_latencies = 0;
    std::vector<std::uint32_t> subject_ids;  // empty = all
    std::uint64_t undecodable = 0;
    const std::atomic<bool>* counting = nullptr;  // true during the measured window only
    natsConnection* connection = nullptr;
    std::vector<natsSubscription*> subscriptions;
};

void on_message(natsConnection* /*nc*/, natsSubscription* /*sub*/, natsMsg* msg, void* closure) {
    auto* s = static_cast<NatsClientState*>(closure);
    const std::int64_t receive_us = wall_clock_us();
    if (s->counting->load(std::memory_order_relaxed)) {
        const std::lock_guard<std::mutex> lock(s->mutex);
        if (!s->scratch.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg)) || !s->scratch.has_frame()) {
            ++s->undecodable;
        } else {
            const v1::SkeletonFrame& f = s->scratch.frame();
            const auto& ids = s->subject_ids;
            const bool wanted = ids.empty() || std::find(ids.begin(), ids.end(), f.subject_id()) != ids.end();
            if (wanted && s->seen_per_subject[f.subject_id()]++ % s->decimation == 0)
                s->tally.add(f, receive_us, s->decimation, s->max_latencies);
        }
    }
    natsMsg_Destroy(msg);
}

natsStatus connect_one(const NatsOptions& nats, const LoadOptions& options, NatsClientState& s) {
    natsOptions* o = nullptr;
    natsStatus st = natsOptions_Create(&o);
    if (st == NATS_OK) st = natsOptions_SetURL(o, nats.url.c_str());
    if (st == NATS_OK) st = natsOptions_SetTimeout(o, std::max<std::int64_t>(1, options.connect_timeout.count()));
    if (st == NATS_OK && !nats.user.empty()) st = natsOptions_SetUserInfo(o, nats.user.c_str(), nats.password.c_str());
    if (st == NATS_OK && !nats.creds_file.empty())
        st = natsOptions_SetUserCredentialsFromFiles(o, nats.creds_file.c_str(), nullptr);
    // Callbacks on the library's shared pool instead of one more thread per connection.
    if (st == NATS_OK) st = natsOptions_UseGlobalMessageDelivery(o, true);
    if (st == NATS_OK) st = natsConnection_Connect(&s.connection, o);
    natsOptions_Destroy(o);
    if (st != NATS_OK) {
        s.connection = nullptr;
        return st;
    }
    const std::string prefix = "mocap." + nats.site + ".";
    std::vector<std::string> subjects;
    for (std::uint32_t id : options.subject_ids)
        subjects.push_back(prefix + std::to_string(id) + ".pose");
    if (subjects.empty()) subjects.push_back(prefix + "*.pose");
    for (const std::string& subject : subjects) {
        natsSubscription* sub = nullptr;
        st = natsConnection_Subscribe(&sub, s.connection, subject.c_str(), on_message, &s);
        if (st != NATS_OK) return st;
        s.subscriptions.push_back(sub);
        // As NatsPoseClient: ~10 s of 100 Hz frames of 64 subjects before the library drops.
        st = natsSubscription_SetPendingLimits(sub, 65536, 256 << 20);
        if (st != NATS_OK) return st;
    }
    return natsConnection_FlushTimeout(s.connection, std::max<std::int64_t>(1, options.connect_timeout.count()));
}

}  // namespace

LoadResult run_nats_load(const NatsOptions& nats, const LoadOptions& options) {
    LoadResult result;
    result.clients = options.clients;
    (void)nats_SetMessageDeliveryPoolSize(2);
    std::vector<std::unique_ptr<NatsClientState>> states;
    std::vector<bool> subscribed;
    // Frames count from the moment every client is subscribed, as the window is measured.
    std::atomic<bool> counting{false};
    for (std::size_t i = 0; i < options.clients; ++i) {
        auto s = std::make_unique<NatsClientState>();
        s->decimation = std::max<std::uint32_t>(options.decimation, 1);
        s->max_latencies = kMaxLatencySamples / std::max<std::size_t>(options.clients, 1);
        s->subject_ids = options.subject_ids;
        s->counting = &counting;
        const natsStatus st = connect_one(nats, options, *s);
        subscribed.push_back(st == NATS_OK);
        if (st == NATS_OK) {
            ++result.connected;
        } else if (result.error.empty()) {
            result.error = "cannot subscribe at " + nats.url + ": " + natsStatus_GetText(st);
        }
        states.push_back(std::move(s));
    }
    counting.store(true);
    const auto start = std::chrono::steady_clock::now();
    std::this_thread::sleep_for(options.duration);  // the measurement window: callbacks count meanwhile
    result.duration_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    // Close the window, then drain every subscription: once a drain completed, no callback of
    // it runs again, so the tallies can be merged.
    counting.store(false);
    for (auto& s : states) {
        for (natsSubscription* sub : s->subscriptions) {
            int64_t dropped = 0;
            if (natsSubscription_GetDropped(sub, &dropped) == NATS_OK)
                result.drops += static_cast<std::uint64_t>(std::max<int64_t>(0, dropped));
            (void)natsSubscription_Drain(sub);
        }
        if (s->connection && natsConnection_IsClosed(s->connection)) ++result.closed_early;
    }
    for (auto& s : states)
        for (natsSubscription* sub : s->subscriptions)
            (void)natsSubscription_WaitForDrainCompletion(sub, 5000);
    std::vector<ClientTally> tallies;
    std::uint64_t undecodable = 0;
    for (auto& s : states) {
        const std::lock_guard<std::mutex> lock(s->mutex);
        tallies.push_back(std::move(s->tally));
        undecodable += s->undecodable;
    }
    for (auto& s : states) {
        for (natsSubscription* sub : s->subscriptions)
            natsSubscription_Destroy(sub);
        if (s->connection) {
            natsConnection_Close(s->connection);
            natsConnection_Destroy(s->connection);
        }
    }
    merge_tallies(tallies, subscribed, result);
    if (undecodable > 0 && result.error.empty())
        result.error =
            std::to_string(undecodable) + " messages on pose subjects were not mocap.v1.ServerMessage frames";
    return result;
}

}  // namespace mocap::client
