// session_table.hpp — the open sessions of one serve thread, by id (the id of the
// connection slot, serve_thread.hpp): what the live BVH server and the HTTP server keep
// for each lane of their ServeThread (the pose server has one table per lane in
// pose_server.cpp).
//
// `Session` must have close(), which ends (at once or later) in remove(id). Each
// remove() of a listed session counts one closed connection in the counter given at
// construction; open() mirrors size() for other threads.
// Thread-safety: the serve thread only, except open() (any thread).
// Ownership: the table holds the sessions; a session's own handlers may hold it longer.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/counters.hpp"

namespace mocap::serve {

template <class Session>
class SessionTable {
public:
    /// `closed_counter` (e.g. ConnectionCounters::closed) must outlive the table.
    explicit SessionTable(Counter& closed_counter) : closed_counter_(closed_counter) {}

    /// Lists `session` under `id`, or replaces the one listed there (an HTTP connection
    /// that became a WebSocket keeps its id and its slot).
    void put(std::uint64_t id, std::shared_ptr<Session> session) {
        sessions_[id] = std::move(session);
        open_.store(sessions_.size(), std::memory_order_relaxed);
    }
    /// Unlists `id`; counts a closed connection if it was listed.
    void remove(std::uint64_t id) {
        if (sessions_.erase(id) != 0) closed_counter_.add();
        open_.store(sessions_.size(), std::memory_order_relaxed);
    }
    /// Closes session `id` if it is listed (its close() removes it).
    void close(std::uint64_t id) {
        const auto it = sessions_.find(id);
        if (it == sessions_.end()) return;
        const std::shared_ptr<Session> session = it->second;
        session->close();
    }
    /// Closes every session (each close() removes it).
    void close_all() {
        std::vector<std::shared_ptr<Session>> all;
        all.reserve(sessions_.size());
        for (auto& [id, session] : sessions_)
            all.push_back(session);
        for (auto& session : all)
            session->close();
    }
    /// Calls `f(Session&)` for each listed session; `f` may close (and so remove) it.
    template <class F>
    void for_each(F&& f) {
        for (auto it = sessions_.begin(); it != sessions_.end();) {
            const std::shared_ptr<Session> session = (it++)->second;
            f(*session);
        }
    }

    [[nodiscard]] std::size_t size() const { return sessions_.size(); }
    /// Sessions listed now; any thread (relaxed: a gauge, and a "skip work" hint).
    [[nodiscard]] std::size_t open() const { return open_.load(std::memory_order_relaxed); }

private:
    std::unordered_map<std::uint64_t, std::shared_ptr<Session>> sessions_;
    Counter& closed_counter_;
    std::atomic<std::size_t> open_{0};
};

/// One table per lane of a ServeThread, each counting closes in `closed_counter`.
template <class Session>
std::vector<std::unique_ptr<SessionTable<Session>>> make_session_tables(std::size_t lanes, Counter& closed_counter) {
    std::vector<std::unique_ptr<SessionTable<Session>>> tables;
    for (std::size_t i = 0; i < lanes; ++i)
        tables.push_back(std::make_unique<SessionTable<Session>>(closed_counter));
    return tables;
}

/// Sessions open on all lanes now; any thread.
template <class Session>
std::size_t open_sessions(const std::vector<std::unique_ptr<SessionTable<Session>>>& tables) {
    std::size_t n = 0;
    for (const auto& table : tables)
        n += table->open();
    return n;
}

}  // namespace mocap::serve
