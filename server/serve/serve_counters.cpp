// serve_counters.cpp — the counter snapshot, by name, for Stats and the daemon's log.
#include "serve/serve_counters.hpp"

namespace mocap::serve {

std::vector<NamedCounter> ServeCounters::snapshot() const {
    std::vector<NamedCounter> out;
    out.reserve(24);
    auto add = [&out](const char* name, const C& c) {
        out.push_back({std::string("serve.") + name, c.load(std::memory_order_relaxed)});
    };
    add("connections_accepted", connections_accepted);
    add("connections_rejected_full", connections_rejected_full);
    add("connections_closed", connections_closed);
    add("accept_errors", accept_errors);
    add("frames_published", frames_published);
    add("frames_encoded", frames_encoded);
    add("frames_sent", frames_sent);
    add("frames_dropped", frames_dropped);
    add("backlog_dropped", backlog_dropped);
    add("bytes_sent", bytes_sent);
    add("subscriptions", subscriptions);
    add("malformed_messages", malformed_messages);
    add("oversized_messages", oversized_messages);
    add("unknown_messages", unknown_messages);
    add("idle_timeouts", idle_timeouts);
    add("rate_limited", rate_limited);
    add("write_errors", write_errors);
    add("stats_requests", stats_requests);
    control.append_to(out, "serve.");
    return out;
}

}  // namespace mocap::serve
