// serve_counters.cpp — the pose service's counter group: the names Stats, /metrics and the
// log line show (through the metrics registry).
#include "serve/serve_counters.hpp"

namespace mocap::serve {

ServeCounters::ServeCounters() {
    connections.register_in(group);
    group.add("frames_published", frames_published);
    group.add("frames_encoded", frames_encoded);
    group.add("frames_sent", frames_sent);
    group.add("frames_dropped", frames_dropped);
    group.add("backlog_dropped", backlog_dropped);
    group.add("bytes_sent", bytes_sent);
    group.add("subscriptions", subscriptions);
    group.add("malformed_messages", malformed_messages);
    group.add("oversized_messages", oversized_messages);
    group.add("unknown_messages", unknown_messages);
    group.add("idle_timeouts", idle_timeouts);
    group.add("rate_limited", rate_limited);
    group.add("address_rate_limited", address_rate_limited);
    group.add("write_errors", write_errors);
    group.add("stats_requests", stats_requests);
    group.add("subscribe_too_many_subjects", subscribe_too_many_subjects);
    group.add("requests_deferred", requests_deferred);
    control.register_in(group);
}

}  // namespace mocap::serve
