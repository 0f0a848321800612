// stream_uplink.cpp — why: a simulated sink must behave like the WiFi module's uplink (whole
// packets, busy when full), and a load generator must never block on one slow connection,
// so every call is non-blocking and a partial send is finished later rather than waited on.
#include "sim/stream_uplink.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <utility>

namespace mocap::sim {

PosixUplink::PosixUplink(std::vector<sockaddr_in> peers) : peers_(std::move(peers)) {
    pending_.reserve(SINK_NODE_PACKET_CAPACITY);
}

PosixUplink::~PosixUplink() {
    close();
}

int PosixUplink::connect(std::uint8_t host) {
    close();
    if (host >= peers_.size()) return -1;
    const sockaddr_in& peer = peers_[host];
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) return -1;
    const int one = 1;
    (void)::setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    if (::connect(fd_, reinterpret_cast<const sockaddr*>(&peer), sizeof peer) == 0) {
        state_ = SINK_UPLINK_UP;
        return 0;
    }
    if (errno == EINPROGRESS) {
        state_ = SINK_UPLINK_CONNECTING;
        return 0;
    }
    close();
    return -1;
}

sink_uplink_state PosixUplink::state() {
    if (state_ == SINK_UPLINK_CONNECTING) {
        pollfd p{fd_, POLLOUT, 0};
        if (::poll(&p, 1, 0) > 0) {
            int err = 0;
            socklen_t len = sizeof err;
            if (::getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0) {
                state_ = SINK_UPLINK_UP;
            } else {
                close();
            }
        }
    } else if (state_ == SINK_UPLINK_UP) {
        char byte;
        const ssize_t n = ::recv(fd_, &byte, 1, MSG_PEEK | MSG_DONTWAIT);
        // Whatever the daemon sent is read by read(); 0 here means it closed.
        if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) || !flush_pending()) {
            close();
        }
    }
    return state_;
}

bool PosixUplink::flush_pending() {
    while (pending_offset_ < pending_.size()) {
        const ssize_t n = ::send(fd_, pending_.data() + pending_offset_, pending_.size() - pending_offset_,
                                 MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
        pending_offset_ += static_cast<std::size_t>(n);
        bytes_sent_ += static_cast<std::uint64_t>(n);
    }
    pending_.clear();
    pending_offset_ = 0;
    return true;
}

int PosixUplink::write(const std::uint8_t* data, std::size_t len) {
    if (state_ != SINK_UPLINK_UP) return -1;
    if (!flush_pending()) return -1;
    if (!pending_.empty()) return 1;  // the previous packet is still going out
    const ssize_t n = ::send(fd_, data, len, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return 1;
        return -1;
    }
    bytes_sent_ += static_cast<std::uint64_t>(n);
    if (static_cast<std::size_t>(n) < len) {
        pending_.assign(data + n, data + len);  // capacity reserved: no allocation
        pending_offset_ = 0;
    }
    return 0;
}

int PosixUplink::read(std::uint8_t* data, std::size_t cap) {
    if (state_ != SINK_UPLINK_UP) return -1;
    const ssize_t n = ::recv(fd_, data, cap, MSG_DONTWAIT);
    if (n > 0) return static_cast<int>(n);
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return 0;
    close();
    return -1;
}

void PosixUplink::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    state_ = SINK_UPLINK_DOWN;
    pending_.clear();
    pending_offset_ = 0;
}

bool resolve_ipv4(const std::string& host_port, sockaddr_in* out, std::string* error) {
    const auto colon = host_port.rfind(':');
    if (colon == std::string::npos || colon == 0 || colon + 1 == host_port.size()) {
        *error = "expected HOST:PORT, got '" + host_port + "'";
        return false;
    }
    const std::string host = host_port.substr(0, colon);
    const std::string port = host_port.substr(colon + 1);
    addrinfo hints{};
    hints.ai_family = AF_INET;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* result = nullptr;
    const int rc = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &result);
    if (rc != 0 || result == nullptr) {
        *error = "cannot resolve '" + host_port + "': " + ::gai_strerror(rc);
        return false;
    }
    *out = *reinterpret_cast<const sockaddr_in*>(result->ai_addr);
    ::freeaddrinfo(result);
    return true;
}

bool resolve_host_list(const std::string& list, std::size_t max, std::vector<sockaddr_in>* out, std::string* error) {
    out->clear();
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = list.find(',', start);
        const std::string one = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        sockaddr_in addr{};
        if (!resolve_ipv4(one, &addr, error)) return false;
        out->push_back(addr);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    if (out->size() > max) {
        *error = "at most " + std::to_string(max) + " hosts in --connect, got " + std::to_string(out->size());
        return false;
    }
    return true;
}

}  // namespace mocap::sim
