#include "serve/vmc_sender.hpp"

#include <netdb.h>
#include <pthread.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/errno_text.hpp"
#include "serve/vmc_osc.hpp"

namespace mocap::serve {

std::string VmcDestination::str() const {
    return (host.find(':') != std::string::npos ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

std::optional<UdpAddress> resolve_udp(const VmcDestination& destination, std::string* error) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICSERV;
    addrinfo* found = nullptr;
    const std::string port = std::to_string(destination.port);
    const int rc = ::getaddrinfo(destination.host.c_str(), port.c_str(), &hints, &found);
    if (rc != 0 || found == nullptr) {
        *error = "cannot resolve host \"" + destination.host + "\": " + ::gai_strerror(rc);
        return std::nullopt;
    }
    // An IPv4 address when the name has one: VMC receivers listen on IPv4, and "localhost"
    // lists ::1 first on a stock Debian /etc/hosts.
    const addrinfo* pick = found;
    for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
        if (a->ai_family == AF_INET) {
            pick = a;
            break;
        }
    }
    UdpAddress out;
    std::memcpy(&out.address, pick->ai_addr, pick->ai_addrlen);
    out.length = pick->ai_addrlen;
    ::freeaddrinfo(found);
    return out;
}

VmcSender::VmcSender(VmcSenderConfig config, VmcRig rig, const Clock& clock)
    : config_(std::move(config)),
      rig_(std::move(rig)),
      clock_(clock),
      ring_(config_.queue_frames),
      subject_(config_.subject) {
    for (const auto& d : config_.destinations)
        targets_.push_back({d, -1});
    group_.add("frames_queued", frames_queued_);
    group_.add("frames_dropped", frames_dropped_);
    group_.add("bundles_sent", bundles_sent_);
    group_.add("bytes_sent", bytes_sent_);
    group_.add("send_errors", send_errors_);
    group_.add("sends_would_block", sends_would_block_);
    group_.add("resolve_errors", resolve_errors_);
    group_.add("encode_errors", encode_errors_);
}

VmcSender::~VmcSender() {
    stop();
}

void VmcSender::register_metrics(MetricsRegistry& registry) const {
    registry.add(group_);
    registry.add_gauge("vmc_destinations_resolved", "VMC destinations resolved and open",
                       [this] { return static_cast<double>(resolved_.load(std::memory_order_relaxed)); });
    registry.add_gauge("vmc_skipped_segments", "Body segments the VMC output does not send (no humanoid bone)",
                       [n = rig_.skipped_segments().size()] { return static_cast<double>(n); });
}

void VmcSender::start() {
    if (!rig_.skipped_segments().empty()) {
        std::string list;
        for (const auto& s : rig_.skipped_segments())
            list += (list.empty() ? "" : ", ") + s;
        spdlog::warn("vmc: segments without a humanoid bone are not sent: {} (map them in [vmc.bones])", list);
    }
    std::string where;
    for (const auto& t : targets_)
        where += (where.empty() ? "" : ", ") + t.destination.str();
    spdlog::info("vmc: sending {} bones of subject {} to {}", rig_.bone_count(),
                 subject_ == 0 ? std::string("(first with frames)") : std::to_string(subject_), where);
    thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "mocap-vmc");
        run();
    });
}

void VmcSender::stop() {
    if (thread_.joinable()) {
        stop_.store(true, std::memory_order_release);
        ready_.notify_all();
        thread_.join();
    }
    for (auto& t : targets_) {
        if (t.fd >= 0) ::close(t.fd);
        t.fd = -1;
    }
    resolved_.store(0, std::memory_order_relaxed);
}

void VmcSender::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) noexcept {
    if (subject_ == 0) subject_ = frame.subject_id;
    if (frame.subject_id != subject_) return;
    scratch_.sample_us = frame.sample_us;
    scratch_.calibrated = ((frame.segments[0].flags | pose.extra_flags[0]) & kSegmentCalibrated) != 0;
    scratch_.tracking = true;
    for (std::size_t i = 0; i < rig_.bone_count(); ++i) {
        const auto s = static_cast<std::size_t>(rig_.bone_segment(i));
        if ((frame.segments[s].flags & (kSegmentStale | kSegmentNeverSeen)) != 0) scratch_.tracking = false;
    }
    scratch_.pose = pose;
    if (ring_.try_push(scratch_)) {
        frames_queued_.add();
        ready_.notify_all();
    } else {
        frames_dropped_.add();
    }
}

void VmcSender::run() {
    resolve_pending();
    while (true) {
        if (const Item* item = ring_.front()) {
            send(*item);
            ring_.pop();
            continue;
        }
        if (stop_.load(std::memory_order_acquire)) return;
        if (resolved_.load(std::memory_order_relaxed) < targets_.size() && clock_.now_us() >= next_resolve_us_) {
            resolve_pending();
        }
        const auto key = ready_.prepare_wait();
        if (ring_.front() != nullptr || stop_.load(std::memory_order_acquire)) {
            ready_.cancel_wait();
            continue;
        }
        ready_.wait_for(key, static_cast<std::int64_t>(config_.resolve_retry_s * 1e6));
    }
}

void VmcSender::resolve_pending() {
    std::uint32_t open = 0;
    for (auto& t : targets_) {
        if (t.fd >= 0) {
            ++open;
            continue;
        }
        std::string error;
        const auto address = resolve_udp(t.destination, &error);
        int fd = -1;
        if (address) {
            fd = ::socket(address->address.ss_family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
            // Connected, so that an ICMP "port unreachable" comes back as ECONNREFUSED on a
            // later send and is counted.
            if (fd < 0 || ::connect(fd, reinterpret_cast<const sockaddr*>(&address->address), address->length) != 0) {
                const int err = errno;
                error = "cannot open a UDP socket to it: " + errno_text(err);
                if (err == EACCES) error += " (a broadcast address? VMC goes to one receiver per destination)";
                if (fd >= 0) ::close(fd);
                fd = -1;
            }
        }
        if (fd < 0) {
            resolve_errors_.add();
            // Once: a retry every few seconds must not fill the journal with the same line.
            if (t.failures++ == 0) {
                spdlog::warn("vmc: destination {}: {}; retrying every {} s, failures counted in vmc.resolve_errors",
                             t.destination.str(), error, config_.resolve_retry_s);
            }
            continue;
        }
        if (t.failures > 0) spdlog::info("vmc: destination {} open after {} failures", t.destination.str(), t.failures);
        t.failures = 0;
        t.fd = fd;
        ++open;
    }
    resolved_.store(open, std::memory_order_relaxed);
    next_resolve_us_ = clock_.now_us() + static_cast<std::int64_t>(config_.resolve_retry_s * 1e6);
}

void VmcSender::send(const Item& item) {
    if (first_sample_us_ < 0) first_sample_us_ = item.sample_us;
    rig_.convert(item.pose, vmc_pose_);
    const VmcStatus status{item.calibrated, item.tracking,
                           static_cast<float>(static_cast<double>(item.sample_us - first_sample_us_) * 1e-6)};
    if (!encode_vmc_bundle(rig_, vmc_pose_, status, bundle_)) {
        encode_errors_.add();
        return;
    }
    for (const auto& t : targets_) {
        if (t.fd < 0) continue;
        const ssize_t n = ::send(t.fd, bundle_.data(), bundle_.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
        if (n == static_cast<ssize_t>(bundle_.size())) {
            bundles_sent_.add();
            bytes_sent_.add(bundle_.size());
            continue;
        }
        const int err = n < 0 ? errno : EMSGSIZE;
        if (err == EAGAIN || err == EWOULDBLOCK) {
            sends_would_block_.add();
            continue;
        }
        send_errors_.add();
        std::uint64_t suppressed = 0;
        if (log_.allow(LogLimiter::kIoError, suppressed)) {
            spdlog::warn("vmc: send to {} failed: {}{} ({} similar lines suppressed)", t.destination.str(),
                         errno_text(err), err == ECONNREFUSED ? " (nothing listens there)" : "", suppressed);
        }
    }
}

}  // namespace mocap::serve
