#include "cluster/nats_errors.hpp"

#include <nats/nats.h>
#include <spdlog/spdlog.h>

namespace mocap::cluster {
namespace {

void on_async_error(natsConnection* nc, natsSubscription* /*sub*/, natsStatus status, void* self) {
    const char* text = nullptr;
    if (status == NATS_NOT_PERMITTED) (void)natsConnection_GetLastError(nc, &text);
    static_cast<NatsErrors*>(self)->on_error(status, text);
}

}  // namespace

void NatsErrors::install(natsOptions* options) {
    (void)natsOptions_SetErrorHandler(options, &on_async_error, this);
}

void NatsErrors::on_error(int status, const char* text) {
    if (static_cast<natsStatus>(status) != NATS_NOT_PERMITTED) return;  // slow consumers: the subscriber's own counts
    permission_errors_.add();
    std::string what = text != nullptr && *text != '\0' ? text : "Permissions Violation";
    std::lock_guard lock(mutex_);
    violation_ = what;
    if (logged_.size() >= kLoggedTexts || !logged_.insert(what).second) return;
    spdlog::error(
        "cluster: {}: the NATS server refused it: {} (the [cluster] user lacks that permission on the server; "
        "config/nats/nats-server.conf lists what mocapd needs)",
        who_, what);
}

std::string NatsErrors::take_violation() {
    std::lock_guard lock(mutex_);
    return std::exchange(violation_, {});
}

}  // namespace mocap::cluster
