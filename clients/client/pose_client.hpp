// pose_client.hpp — a small blocking client of the mocapd pose service (port 7001).
//
//   mocap::client::PoseClient c;
//   std::string err;
//   if (!c.connect("127.0.0.1", 7001, std::chrono::seconds(2), err)) ...   // waits for Hello
//   c.subscribe({.subject_ids = {1}, .decimation = 1}, std::chrono::seconds(2), err);
//   mocap::v1::SkeletonFrame f;
//   while (c.next_frame(f, std::chrono::seconds(1)) == ReadStatus::kMessage) {
//       // c.last_receive_us(): CLOCK_REALTIME µs when the bytes holding f were read
//   }
//
// Every call is bounded by the timeout it is given; nothing waits forever. DropNotices
// met while waiting for frames are summed into drops_announced(); a Goodbye ends the
// connection (goodbye() tells why). For many connections at once (the load client),
// use fd() with poll(), then fill(0ms) and pop() on the ready ones.
//
// Thread-safety: none; one PoseClient per thread at a time. Move-only.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "mocap/v1/mocap.pb.h"
#include "serve/framing.hpp"

namespace mocap::client {

struct Endpoint {
    std::string host;
    std::uint16_t port = 0;
};

/// "HOST:PORT", "[v6-address]:PORT". Returns nullopt and sets `error` when invalid.
std::optional<Endpoint> parse_endpoint(std::string_view text, std::string& error);

/// CLOCK_REALTIME in microseconds since the epoch (the clock of the frames' stamps).
std::int64_t wall_clock_us();

enum class ReadStatus {
    kMessage,  ///< a message was returned
    kTimeout,  ///< nothing complete within the timeout
    kClosed,   ///< the server closed (after a Goodbye or not)
    kError,    ///< socket error or a malformed stream; see error()
};

struct SubscribeOptions {
    std::vector<std::uint32_t> subject_ids;  ///< empty = all subjects
    std::uint32_t decimation = 1;            ///< every n-th frame per subject
    std::uint32_t fields = 0;                ///< mocap.v1.Field bits; 0 = orientations+positions
};

class PoseClient {
public:
    /// Largest server message accepted (a Hello or Stats can be tens of KiB).
    static constexpr std::size_t kMaxServerMessageBytes = 16u << 20;

    PoseClient();
    ~PoseClient();
    PoseClient(PoseClient&& other) noexcept;
    PoseClient& operator=(PoseClient&& other) noexcept;
    PoseClient(const PoseClient&) = delete;
    PoseClient& operator=(const PoseClient&) = delete;

    /// Resolves, connects (TCP_NODELAY) and waits for the server's Hello.
    bool connect(const std::string& host, std::uint16_t port, std::chrono::milliseconds timeout, std::string& error);
    /// Sends Subscribe and waits for Subscribed (frames only flow after it).
    bool subscribe(const SubscribeOptions& options, std::chrono::milliseconds timeout, std::string& error);
    /// Sends one ClientMessage (blocking until written or `timeout`).
    bool send(const v1::ClientMessage& message, std::string& error,
              std::chrono::milliseconds timeout = std::chrono::seconds(5));

    /// Next server message of any kind.
    ReadStatus next(v1::ServerMessage& out, std::chrono::milliseconds timeout);
    /// Next SkeletonFrame; other messages are consumed (DropNotice counted).
    ReadStatus next_frame(v1::SkeletonFrame& out, std::chrono::milliseconds timeout);
    /// StatsRequest -> Stats.
    bool request_stats(v1::Stats& out, std::chrono::milliseconds timeout, std::string& error);
    /// ControlRequest -> ControlReply (a refused request is a reply with ok=false).
    bool control(const v1::ControlRequest& request, v1::ControlReply& reply, std::chrono::milliseconds timeout,
                 std::string& error);

    // Low level, for poll()-driven use.
    [[nodiscard]] int fd() const { return fd_; }
    /// Waits up to `timeout` for data and reads what is there once. kMessage = bytes
    /// were read (not necessarily a whole message).
    ReadStatus fill(std::chrono::milliseconds timeout);
    /// A complete buffered message, without reading the socket: kMessage or kTimeout
    /// (= need more bytes) or kError.
    ReadStatus pop(v1::ServerMessage& out);

    void close();
    [[nodiscard]] bool is_open() const { return fd_ >= 0; }
    [[nodiscard]] const v1::Hello& hello() const { return hello_; }
    [[nodiscard]] const v1::Subscribed& subscribed() const { return subscribed_; }
    [[nodiscard]] const std::optional<v1::Goodbye>& goodbye() const { return goodbye_; }
    [[nodiscard]] std::uint64_t drops_announced() const { return drops_announced_; }
    /// CLOCK_REALTIME µs of the last successful read from the socket.
    [[nodiscard]] std::int64_t last_receive_us() const { return last_receive_us_; }
    [[nodiscard]] const std::string& error() const { return error_; }

private:
    /// Waits for a message for which `accept` returns true, consuming others.
    template <typename Accept>
    ReadStatus wait_for(v1::ServerMessage& out, std::chrono::milliseconds timeout, Accept accept);
    /// send(request), then wait_for(reply, accept); `awaited` names it in the error.
    template <typename Accept>
    bool exchange(const v1::ClientMessage& request, v1::ServerMessage& reply, std::chrono::milliseconds timeout,
                  std::string& error, const char* awaited, Accept accept);
    void note(const v1::ServerMessage& message);

    int fd_ = -1;
    std::unique_ptr<serve::DelimitedReader> reader_;
    v1::Hello hello_;
    v1::Subscribed subscribed_;
    std::optional<v1::Goodbye> goodbye_;
    std::uint64_t drops_announced_ = 0;
    std::int64_t last_receive_us_ = 0;
    std::uint64_t next_request_id_ = 1;
    std::string error_;
};

}  // namespace mocap::client
