// load_stream_client.cpp — BVH-text and WebSocket load clients on one epoll loop.
#include "load_stream_client.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/errno_text.hpp"
#include "load_tally.hpp"

namespace mocap::client {

namespace {

using Clock = std::chrono::steady_clock;
constexpr std::size_t kMaxBuffered = std::size_t{1} << 20;  // a peer that never frames a message

std::int64_t wall_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

struct StreamClient {
    int fd = -1;
    std::string buffer;
    std::string message;  // WebSocket: fragments joined so far
    bool header_done = false;
    bool open = false;
    ClientTally tally;
};

/// A connected blocking socket, or -1 with `error`.
int connect_to(const std::string& host, std::uint16_t port, std::chrono::milliseconds timeout, std::string& error) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    if (::inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1) {
        error = "not an IPv4 address: " + host;
        return -1;
    }
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) {
        error = "socket: " + errno_text(errno);
        return -1;
    }
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 && errno != EINPROGRESS) {
        error = "connect: " + errno_text(errno);
        ::close(fd);
        return -1;
    }
    pollfd p{fd, POLLOUT, 0};
    int err = 0;
    socklen_t len = sizeof err;
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1 ||
        ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) != 0 || err != 0) {
        error = "connect: " + (err != 0 ? errno_text(err) : std::string("timed out"));
        ::close(fd);
        return -1;
    }
    return fd;
}

/// Writes all of `text` (a few dozen bytes to a fresh socket) or fails.
bool send_all(int fd, std::string_view text, std::chrono::milliseconds timeout) {
    while (!text.empty()) {
        const ssize_t n = ::send(fd, text.data(), text.size(), MSG_NOSIGNAL);
        if (n > 0) {
            text.remove_prefix(static_cast<std::size_t>(n));
        } else if (n < 0 && errno == EAGAIN) {
            pollfd p{fd, POLLOUT, 0};
            if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return false;
        } else {
            return false;
        }
    }
    return true;
}

/// The unsigned number after `key` in `text` (e.g. "\"sync\":"), or nullopt.
std::optional<std::uint64_t> number_after(std::string_view text, std::string_view key) {
    const std::size_t at = text.find(key);
    if (at == std::string_view::npos) return std::nullopt;
    const char* first = text.data() + at + key.size();
    char* end = nullptr;
    const unsigned long long v = std::strtoull(first, &end, 10);
    if (end == first) return std::nullopt;
    return v;
}

class StreamLoad {
public:
    StreamLoad(const LoadOptions& o, LoadResult& r)
        : o_(o),
          r_(r),
          bvh_(o.protocol == "bvh"),
          max_latencies_(kMaxLatencySamples / std::max<std::size_t>(o.clients, 1)) {}

    void run() {
        raise_fd_limit(o_.clients);
        clients_.resize(o_.clients);
        const std::uint32_t subject = o_.subject_ids.empty() ? 0 : o_.subject_ids.front();
        const std::string request =
            bvh_ ? (subject == 0 ? std::string() : "subject " + std::to_string(subject) + "\n")
                 : "GET /ws?subject=" + std::to_string(subject) + " HTTP/1.1\r\nHost: " + o_.host + ":" +
                       std::to_string(o_.port) +
                       "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                       "Sec-WebSocket-Key: bW9jYXBkLWxvYWQtY2xpZW50\r\nSec-WebSocket-Version: 13\r\n\r\n";
        const int ep = ::epoll_create1(EPOLL_CLOEXEC);
        for (std::size_t i = 0; i < clients_.size(); ++i) {
            StreamClient& c = clients_[i];
            std::string error;
            c.fd = connect_to(o_.host, o_.port, o_.connect_timeout, error);
            if (c.fd >= 0 && !send_all(c.fd, request, o_.connect_timeout)) error = "send: request not written";
            if (!error.empty()) {
                if (r_.error.empty()) r_.error = error;
                continue;
            }
            c.open = true;
            epoll_event ev{};
            ev.events = EPOLLIN;
            ev.data.u64 = i;
            ::epoll_ctl(ep, EPOLL_CTL_ADD, c.fd, &ev);
        }
        std::vector<epoll_event> events(256);
        const auto start = Clock::now();
        const auto deadline = start + o_.duration;
        for (;;) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
            if (left <= 0) break;
            const int n = ::epoll_wait(ep, events.data(), static_cast<int>(events.size()),
                                       static_cast<int>(std::min<long long>(left, 100)));
            for (int k = 0; k < n; ++k)
                read_client(clients_[events[static_cast<std::size_t>(k)].data.u64]);
        }
        r_.duration_s = std::chrono::duration<double>(Clock::now() - start).count();
        ::close(ep);
        std::vector<ClientTally> tallies;
        std::vector<bool> counted;
        for (StreamClient& c : clients_) {
            if (c.header_done) ++r_.connected;
            counted.push_back(c.header_done);
            tallies.push_back(std::move(c.tally));
            if (c.fd >= 0) ::close(c.fd);
        }
        merge_tallies(tallies, counted, r_);
    }

private:
    void read_client(StreamClient& c) {
        if (!c.open) return;
        char chunk[65536];
        bool closed = false;
        for (;;) {
            const ssize_t n = ::recv(c.fd, chunk, sizeof chunk, 0);
            if (n > 0) {
                c.buffer.append(chunk, static_cast<std::size_t>(n));
                if (static_cast<std::size_t>(n) < sizeof chunk) break;
            } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
                break;
            } else {
                closed = true;
                break;
            }
        }
        const std::int64_t now = wall_us();
        if (bvh_) {
            parse_bvh(c, now);
        } else {
            parse_ws(c, now);
        }
        if (closed || c.buffer.size() > kMaxBuffered) {
            c.open = false;
            ++r_.closed_early;
        }
    }

    /// Counts one frame the way the pose stream's are counted (load_tally.hpp).
    void tally(StreamClient& c, std::uint32_t subject, std::uint64_t sync, std::int64_t sent_us, std::int64_t now) {
        frame_.set_subject_id(subject);
        frame_.set_sync(sync);
        frame_.mutable_times()->set_sink_send_us(sent_us);
        c.tally.add(frame_, now, 1, max_latencies_);
    }

    void parse_bvh(StreamClient& c, std::int64_t now) {
        std::size_t pos = 0;
        if (!c.header_done) {
            const std::size_t at = c.buffer.find("Frame Time:");
            if (at == std::string::npos) return;
            const std::size_t eol = c.buffer.find('\n', at);
            if (eol == std::string::npos) return;
            c.header_done = true;
            pos = eol + 1;
        }
        for (std::size_t eol; (eol = c.buffer.find('\n', pos)) != std::string::npos; pos = eol + 1) {
            const std::string_view line(c.buffer.data() + pos, eol - pos);
            auto [it, fresh] = first_seen_.try_emplace(std::hash<std::string_view>{}(line), now, next_index_);
            if (fresh) ++next_index_;
            // The line's index stands for a SYNC, its first arrival for the send time.
            tally(c, 0, it->second.second, it->second.first, now);
        }
        c.buffer.erase(0, pos);
    }

    void parse_ws(StreamClient& c, std::int64_t now) {
        std::size_t pos = 0;
        if (!c.header_done) {
            const std::size_t end = c.buffer.find("\r\n\r\n");
            if (end == std::string::npos) return;
            if (c.buffer.compare(0, 12, "HTTP/1.1 101") != 0) {
                if (r_.error.empty())
                    r_.error = "WebSocket upgrade refused: " + c.buffer.substr(0, c.buffer.find('\r'));
                c.buffer.clear();
                c.open = false;
                return;
            }
            c.header_done = true;
            pos = end + 4;
        }
        for (;;) {
            const std::size_t avail = c.buffer.size() - pos;
            if (avail < 2) break;
            const auto* b = reinterpret_cast<const unsigned char*>(c.buffer.data() + pos);
            const bool fin = (b[0] & 0x80) != 0;
            const unsigned opcode = b[0] & 0x0f;
            std::uint64_t length = b[1] & 0x7f;
            std::size_t header = 2;
            if (length == 126) {
                if (avail < 4) break;
                length = (std::uint64_t{b[2]} << 8) | b[3];
                header = 4;
            } else if (length == 127) {
                if (avail < 10) break;
                length = 0;
                for (int i = 0; i < 8; ++i)
                    length = (length << 8) | b[2 + i];
                header = 10;
            }
            if ((b[1] & 0x80) != 0) header += 4;  // a server never masks; tolerate it anyway
            if (avail < header + length) break;
            const std::string_view payload(c.buffer.data() + pos + header, static_cast<std::size_t>(length));
            pos += header + static_cast<std::size_t>(length);
            if (opcode == 8) break;                    // close: the server closes the socket next (counted then)
            if (opcode != 0 && opcode != 1) continue;  // ping, pong, binary: not ours
            c.message.append(payload);
            if (!fin) continue;
            on_ws_message(c, c.message, now);
            c.message.clear();
        }
        c.buffer.erase(0, pos);
    }

    void on_ws_message(StreamClient& c, std::string_view m, std::int64_t now) {
        if (m.find("\"type\":\"drops\"") != std::string_view::npos) {
            r_.drops += number_after(m, "\"dropped\":").value_or(0);
            return;
        }
        if (m.find("\"type\":\"frame\"") == std::string_view::npos) return;
        tally(c, static_cast<std::uint32_t>(number_after(m, "\"subject\":").value_or(0)),
              number_after(m, "\"sync\":").value_or(0),
              static_cast<std::int64_t>(number_after(m, "\"sink_send_us\":").value_or(0)), now);
    }

    const LoadOptions& o_;
    LoadResult& r_;
    bool bvh_;
    std::size_t max_latencies_;
    std::vector<StreamClient> clients_;
    v1::SkeletonFrame frame_;  // reused: what ClientTally reads of a frame
    // BVH: line hash -> (first arrival, index in arrival order)
    std::unordered_map<std::size_t, std::pair<std::int64_t, std::uint64_t>> first_seen_;
    std::uint64_t next_index_ = 0;
};

}  // namespace

LoadResult run_stream_load(const LoadOptions& options) {
    LoadResult result;
    result.clients = options.clients;
    if (options.protocol != "bvh" && options.protocol != "ws") {
        result.error = "unknown protocol: " + options.protocol;
        return result;
    }
    if (options.stalled > 0 || options.churn_clients > 0) {
        result.error = "--stalled and --churn-clients are for the pose protocol only";
        return result;
    }
    StreamLoad(options, result).run();
    return result;
}

}  // namespace mocap::client
