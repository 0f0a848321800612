// pose_client.cpp — POSIX sockets, non-blocking, every wait bounded by poll().
#include "pose_client.hpp"
#include "core/errno_text.hpp"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <ctime>

namespace mocap::client {

namespace {

using Clock = std::chrono::steady_clock;

int remaining_ms(Clock::time_point deadline) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left, 1 << 30));
}

}  // namespace

std::int64_t wall_clock_us() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

std::optional<Endpoint> parse_endpoint(std::string_view text, std::string& error) {
    Endpoint out;
    std::string_view port_text;
    if (!text.empty() && text.front() == '[') {
        const auto close = text.find(']');
        if (close == std::string_view::npos || close + 1 >= text.size() || text[close + 1] != ':') {
            error = "expected [ADDRESS]:PORT, got '" + std::string(text) + "'";
            return std::nullopt;
        }
        out.host = std::string(text.substr(1, close - 1));
        port_text = text.substr(close + 2);
    } else {
        const auto colon = text.rfind(':');
        if (colon == std::string_view::npos || colon == 0) {
            error = "expected HOST:PORT, got '" + std::string(text) + "'";
            return std::nullopt;
        }
        out.host = std::string(text.substr(0, colon));
        port_text = text.substr(colon + 1);
    }
    unsigned port = 0;
    const auto [end, ec] = std::from_chars(port_text.data(), port_text.data() + port_text.size(), port);
    if (ec != std::errc{} || end != port_text.data() + port_text.size() || port == 0 || port > 65535) {
        error = "bad port '" + std::string(port_text) + "'";
        return std::nullopt;
    }
    out.port = static_cast<std::uint16_t>(port);
    return out;
}

PoseClient::PoseClient() = default;
PoseClient::~PoseClient() {
    close();
}

PoseClient::PoseClient(PoseClient&& other) noexcept {
    *this = std::move(other);
}

PoseClient& PoseClient::operator=(PoseClient&& other) noexcept {
    if (this != &other) {
        close();
        fd_ = std::exchange(other.fd_, -1);
        reader_ = std::move(other.reader_);
        hello_ = std::move(other.hello_);
        subscribed_ = std::move(other.subscribed_);
        goodbye_ = std::move(other.goodbye_);
        drops_announced_ = other.drops_announced_;
        last_receive_us_ = other.last_receive_us_;
        next_request_id_ = other.next_request_id_;
        error_ = std::move(other.error_);
    }
    return *this;
}

void PoseClient::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
}

bool PoseClient::connect(const std::string& host, std::uint16_t port, std::chrono::milliseconds timeout,
                         std::string& error) {
    close();
    goodbye_.reset();
    drops_announced_ = 0;
    reader_ = std::make_unique<serve::DelimitedReader>(kMaxServerMessageBytes);
    const auto deadline = Clock::now() + timeout;

    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    const std::string service = std::to_string(port);
    if (const int rc = getaddrinfo(host.c_str(), service.c_str(), &hints, &found); rc != 0) {
        error = "resolve " + host + ": " + gai_strerror(rc);
        return false;
    }
    std::string last_error = "no address";
    for (addrinfo* ai = found; ai != nullptr && fd_ < 0; ai = ai->ai_next) {
        const int fd = ::socket(ai->ai_family, ai->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, ai->ai_protocol);
        if (fd < 0) continue;
        int ok = ::connect(fd, ai->ai_addr, ai->ai_addrlen) == 0 ? 0 : errno;
        if (ok == EINPROGRESS) {
            pollfd p{fd, POLLOUT, 0};
            const int n = ::poll(&p, 1, remaining_ms(deadline));
            socklen_t len = sizeof ok;
            if (n <= 0) {
                ok = ETIMEDOUT;
            } else if (::getsockopt(fd, SOL_SOCKET, SO_ERROR, &ok, &len) != 0) {
                ok = errno;
            }
        }
        if (ok != 0) {
            last_error = errno_text(ok);
            ::close(fd);
            continue;
        }
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        fd_ = fd;
    }
    freeaddrinfo(found);
    if (fd_ < 0) {
        error = "connect " + host + ":" + service + ": " + last_error;
        return false;
    }
    v1::ServerMessage message;
    const ReadStatus s =
        wait_for(message, std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()),
                 [](const v1::ServerMessage& m) { return m.has_hello(); });
    if (s != ReadStatus::kMessage) {
        error = "no Hello from " + host + ":" + service +
                (goodbye_         ? " (" + goodbye_->message() + ")"
                 : error_.empty() ? ""
                                  : ": " + error_);
        close();
        return false;
    }
    return true;
}

bool PoseClient::send(const v1::ClientMessage& message, std::string& error, std::chrono::milliseconds timeout) {
    if (fd_ < 0) {
        error = "not connected";
        return false;
    }
    std::string bytes;
    if (!serve::append_delimited(message, bytes)) {
        error = "cannot serialise request";
        return false;
    }
    const auto deadline = Clock::now() + timeout;
    std::size_t at = 0;
    while (at < bytes.size()) {
        const ssize_t n = ::send(fd_, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL);
        if (n > 0) {
            at += static_cast<std::size_t>(n);
            continue;
        }
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
            error = std::string("send: ") + errno_text(errno);
            return false;
        }
        pollfd p{fd_, POLLOUT, 0};
        if (::poll(&p, 1, remaining_ms(deadline)) <= 0) {
            error = "send: timed out";
            return false;
        }
    }
    return true;
}

ReadStatus PoseClient::fill(std::chrono::milliseconds timeout) {
    if (fd_ < 0) return ReadStatus::kClosed;
    const auto deadline = Clock::now() + timeout;
    for (;;) {
        const auto area = reader_->write_area();
        const ssize_t n = ::recv(fd_, area.data(), area.size(), 0);
        if (n > 0) {
            last_receive_us_ = wall_clock_us();
            reader_->commit(static_cast<std::size_t>(n));
            return ReadStatus::kMessage;
        }
        if (n == 0) {
            close();
            return ReadStatus::kClosed;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) {
            error_ = std::string("recv: ") + errno_text(errno);
            close();
            return ReadStatus::kError;
        }
        pollfd p{fd_, POLLIN, 0};
        const int r = ::poll(&p, 1, remaining_ms(deadline));
        if (r == 0) return ReadStatus::kTimeout;
        if (r < 0 && errno != EINTR) {
            error_ = std::string("poll: ") + errno_text(errno);
            return ReadStatus::kError;
        }
    }
}

ReadStatus PoseClient::pop(v1::ServerMessage& out) {
    if (!reader_) return ReadStatus::kClosed;
    const serve::FrameResult r = reader_->next();
    switch (r.status) {
        case serve::FrameStatus::kNeedMore:
            return ReadStatus::kTimeout;
        case serve::FrameStatus::kMessage:
            if (!out.ParseFromArray(r.payload.data(), static_cast<int>(r.payload.size()))) {
                error_ = "unparseable message from server";
                return ReadStatus::kError;
            }
            note(out);
            return ReadStatus::kMessage;
        case serve::FrameStatus::kTooLarge:
        case serve::FrameStatus::kBadPrefix:
            break;
    }
    error_ = "malformed stream from server";
    return ReadStatus::kError;
}

void PoseClient::note(const v1::ServerMessage& message) {
    switch (message.body_case()) {
        case v1::ServerMessage::kHello:
            hello_ = message.hello();
            break;
        case v1::ServerMessage::kDrops:
            drops_announced_ += message.drops().dropped();
            break;
        case v1::ServerMessage::kSubscribed:
            subscribed_ = message.subscribed();
            break;
        case v1::ServerMessage::kGoodbye:
            goodbye_ = message.goodbye();
            break;
        default:
            break;
    }
}

template <typename Accept>
ReadStatus PoseClient::wait_for(v1::ServerMessage& out, std::chrono::milliseconds timeout, Accept accept) {
    const auto deadline = Clock::now() + timeout;
    for (;;) {
        const ReadStatus s = pop(out);
        if (s == ReadStatus::kError) return s;
        if (s == ReadStatus::kMessage) {
            if (accept(out)) return s;
            continue;
        }
        if (fd_ < 0) return ReadStatus::kClosed;  // drained what arrived before the close
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
        const ReadStatus f = fill(std::max(left, std::chrono::milliseconds(0)));
        if (f == ReadStatus::kTimeout || f == ReadStatus::kError) return f;
        if (f == ReadStatus::kClosed) continue;  // parse what is still buffered first
        // Bytes keep arriving but not the awaited message: still bounded by the deadline.
        if (Clock::now() > deadline) {
            while (pop(out) == ReadStatus::kMessage) {
                if (accept(out)) return ReadStatus::kMessage;
            }
            return ReadStatus::kTimeout;
        }
    }
}

ReadStatus PoseClient::next(v1::ServerMessage& out, std::chrono::milliseconds timeout) {
    return wait_for(out, timeout, [](const v1::ServerMessage&) { return true; });
}

ReadStatus PoseClient::next_frame(v1::SkeletonFrame& out, std::chrono::milliseconds timeout) {
    v1::ServerMessage message;
    const ReadStatus s = wait_for(message, timeout, [](const v1::ServerMessage& m) { return m.has_frame(); });
    if (s == ReadStatus::kMessage) out.Swap(message.mutable_frame());
    return s;
}

template <typename Accept>
bool PoseClient::exchange(const v1::ClientMessage& request, v1::ServerMessage& reply, std::chrono::milliseconds timeout,
                          std::string& error, const char* awaited, Accept accept) {
    if (!send(request, error, timeout)) return false;
    if (wait_for(reply, timeout, accept) == ReadStatus::kMessage) return true;
    error = std::string("no ") + awaited + " reply" +
            (goodbye_         ? " (" + goodbye_->message() + ")"
             : error_.empty() ? ""
                              : ": " + error_);
    return false;
}

bool PoseClient::subscribe(const SubscribeOptions& options, std::chrono::milliseconds timeout, std::string& error) {
    v1::ClientMessage request;
    v1::Subscribe* sub = request.mutable_subscribe();
    for (std::uint32_t s : options.subject_ids)
        sub->add_subject_ids(s);
    sub->set_decimation(options.decimation);
    sub->set_fields(options.fields);
    v1::ServerMessage reply;
    return exchange(request, reply, timeout, error, "Subscribed",
                    [](const v1::ServerMessage& m) { return m.has_subscribed(); });
}

bool PoseClient::request_stats(v1::Stats& out, std::chrono::milliseconds timeout, std::string& error) {
    v1::ClientMessage request;
    const std::uint64_t id = next_request_id_++;
    request.mutable_stats_request()->set_request_id(id);
    v1::ServerMessage reply;
    if (!exchange(request, reply, timeout, error, "Stats",
                  [id](const v1::ServerMessage& m) { return m.has_stats() && m.stats().request_id() == id; })) {
        return false;
    }
    out.Swap(reply.mutable_stats());
    return true;
}

bool PoseClient::control(const v1::ControlRequest& request, v1::ControlReply& reply, std::chrono::milliseconds timeout,
                         std::string& error) {
    v1::ClientMessage message;
    *message.mutable_control() = request;
    const std::uint64_t id = request.request_id() != 0 ? request.request_id() : next_request_id_++;
    message.mutable_control()->set_request_id(id);
    v1::ServerMessage answer;
    if (!exchange(message, answer, timeout, error, "ControlReply", [id](const v1::ServerMessage& m) {
            return m.has_control_reply() && m.control_reply().request_id() == id;
        })) {
        return false;
    }
    reply.Swap(answer.mutable_control_reply());
    return true;
}

}  // namespace mocap::client
