// load_client.cpp — many sockets, one epoll loop, exact latency percentiles.
#include "load_client.hpp"

#include <sys/epoll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <nlohmann/json.hpp>
#include <thread>

#include "load_stream_client.hpp"
#include "load_tally.hpp"
#include "pose_client.hpp"

namespace mocap::client {

namespace {

using Clock = std::chrono::steady_clock;

struct ClientState {
    PoseClient client;
    ClientTally tally;
    bool open = true;
};

/// A stalled client should stall soon: a small receive buffer fills in a fraction of a
/// second instead of holding megabytes of frames for the server.
bool shrink_receive_buffer(int fd) {
    const int bytes = 4096;
    return setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes) == 0;
}

// The churn attack: each churner sends `churn_pipelined` Subscribes at once, naming one of
// two disjoint lists of subject ids (from 1000 on, away from real subjects) in turn, so
// every Subscribe changes every subject it names; then it reads their replies and starts
// again, until `stop`.
void run_churn(const LoadOptions& o, const std::atomic<bool>& stop, std::uint64_t& subscribes,
               std::uint64_t& reconnects) {
    v1::ClientMessage lists[2];
    for (std::uint32_t i = 0; i < o.churn_subjects; ++i) {
        lists[0].mutable_subscribe()->add_subject_ids(1000 + 2 * i);
        lists[1].mutable_subscribe()->add_subject_ids(1001 + 2 * i);
    }
    std::vector<PoseClient> churners(o.churn_clients);
    std::string error;
    for (PoseClient& c : churners)
        (void)c.connect(o.host, o.port, o.connect_timeout, error);
    v1::ServerMessage reply;
    for (std::uint64_t round = 0; !stop.load(std::memory_order_relaxed); ++round) {
        for (PoseClient& c : churners) {
            if (!c.is_open()) {
                if (!c.connect(o.host, o.port, o.connect_timeout, error)) continue;
                ++reconnects;
            }
            for (std::uint32_t k = 0; k < o.churn_pipelined && c.is_open(); ++k) {
                if (!c.send(lists[round % 2], error, o.connect_timeout)) c.close();
            }
        }
        for (PoseClient& c : churners) {
            for (std::uint32_t k = 0; k < o.churn_pipelined && c.is_open();) {
                if (c.next(reply, o.connect_timeout) != ReadStatus::kMessage) {
                    c.close();  // e.g. Goodbye: more subjects than the server allows
                } else if (reply.has_subscribed()) {
                    ++k;
                    ++subscribes;
                }
            }
        }
    }
}

}  // namespace

void raise_fd_limit(std::size_t needed) {
    rlimit lim{};
    if (getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
    if (lim.rlim_cur >= needed + 64) return;
    lim.rlim_cur = lim.rlim_max;
    setrlimit(RLIMIT_NOFILE, &lim);
}

LoadResult run_load(const LoadOptions& options) {
    if (options.protocol != "pose") return run_stream_load(options);
    LoadResult result;
    result.clients = options.clients;
    raise_fd_limit(options.clients + options.stalled);
    const std::uint32_t decimation = std::max<std::uint32_t>(options.decimation, 1);

    std::vector<ClientState> states(options.clients);
    for (auto& s : states) {
        std::string error;
        if (!s.client.connect(options.host, options.port, options.connect_timeout, error)) {
            if (result.error.empty()) result.error = error;
            s.open = false;
        }
    }
    // Subscribe everyone first, then wait for the acknowledgements in the read loop's
    // way (frames for early clients queue in the server meanwhile, within its bound).
    v1::ClientMessage subscribe;
    for (std::uint32_t id : options.subject_ids)
        subscribe.mutable_subscribe()->add_subject_ids(id);
    subscribe.mutable_subscribe()->set_decimation(decimation);
    subscribe.mutable_subscribe()->set_fields(options.fields);
    for (auto& s : states) {
        std::string error;
        if (s.open && !s.client.send(subscribe, error, options.connect_timeout)) {
            if (result.error.empty()) result.error = error;
            s.client.close();
            s.open = false;
        }
    }

    // The stalled connections: subscribed, then never read until the end of the run.
    std::vector<PoseClient> stalled(options.stalled);
    for (PoseClient& c : stalled) {
        std::string error;
        if (c.connect(options.host, options.port, options.connect_timeout, error) && shrink_receive_buffer(c.fd()) &&
            c.subscribe({options.subject_ids, decimation, options.fields}, options.connect_timeout, error)) {
            ++result.stalled;
        } else if (result.error.empty()) {
            result.error = "stalled client: " + error;
        }
    }

    std::atomic<bool> stop_churn{false};
    std::thread churn;
    if (options.churn_clients > 0) {
        churn = std::thread([&] { run_churn(options, stop_churn, result.churn_subscribes, result.churn_reconnects); });
    }

    const int ep = epoll_create1(EPOLL_CLOEXEC);
    for (std::size_t i = 0; i < states.size(); ++i) {
        if (!states[i].open) continue;
        epoll_event ev{};
        ev.events = EPOLLIN;
        ev.data.u64 = i;
        epoll_ctl(ep, EPOLL_CTL_ADD, states[i].client.fd(), &ev);
    }

    const std::size_t max_latencies = kMaxLatencySamples / std::max<std::size_t>(options.clients, 1);
    std::vector<epoll_event> events(256);
    v1::ServerMessage message;
    const auto start = Clock::now();
    const auto deadline = start + options.duration;
    for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
        if (left <= 0) break;
        const int n = epoll_wait(ep, events.data(), static_cast<int>(events.size()),
                                 static_cast<int>(std::min<long long>(left, 100)));
        for (int k = 0; k < n; ++k) {
            ClientState& s = states[events[static_cast<std::size_t>(k)].data.u64];
            if (!s.open) continue;
            const ReadStatus f = s.client.fill(std::chrono::milliseconds(0));
            for (;;) {
                const ReadStatus st = s.client.pop(message);
                if (st != ReadStatus::kMessage) {
                    if (st == ReadStatus::kError) s.client.close();
                    break;
                }
                if (!message.has_frame()) continue;
                s.tally.add(message.frame(), s.client.last_receive_us(), decimation, max_latencies);
            }
            if (f == ReadStatus::kClosed || f == ReadStatus::kError || !s.client.is_open()) {
                s.open = false;
                ++result.closed_early;
            }
        }
    }
    result.duration_s = std::chrono::duration<double>(Clock::now() - start).count();
    ::close(ep);
    stop_churn = true;
    if (churn.joinable()) churn.join();

    std::vector<ClientTally> tallies;
    std::vector<bool> counted;
    for (auto& s : states) {
        result.drops += s.client.drops_announced();
        if (!s.client.hello().server_version().empty() && s.client.subscribed().decimation() != 0) {
            ++result.connected;
        }
        counted.push_back(!s.client.hello().server_version().empty());
        tallies.push_back(std::move(s.tally));
    }
    merge_tallies(tallies, counted, result);
    return result;
}

std::string load_result_json(const LoadResult& r) {
    auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
    nlohmann::ordered_json j{{"clients", r.clients},
                             {"connected", r.connected},
                             {"stalled", r.stalled},
                             {"closed_early", r.closed_early},
                             {"duration_s", r.duration_s},
                             {"frames", r.frames},
                             {"frames_per_client_min", r.frames_per_client_min},
                             {"frames_per_client_max", r.frames_per_client_max},
                             {"gaps", r.gaps},
                             {"missing_frames", r.missing_frames},
                             {"drops", r.drops},
                             {"latency_samples", r.latency_samples},
                             {"negative_latencies", r.negative_latencies},
                             {"p50_ms", opt(r.p50_ms)},
                             {"p90_ms", opt(r.p90_ms)},
                             {"p99_ms", opt(r.p99_ms)},
                             {"max_ms", opt(r.max_ms)},
                             {"churn_subscribes", r.churn_subscribes},
                             {"churn_reconnects", r.churn_reconnects}};
    if (!r.error.empty()) j["error"] = r.error;
    // An error text is not ours to trust as UTF-8: invalid bytes become U+FFFD, not an exception.
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace mocap::client
