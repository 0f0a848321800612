// client_session.hpp — one connected client of the pose service (Boost.Asio).
//
// Thread model: a session lives on exactly one serve thread (its lane's io_context,
// run by one thread), so its handlers never run concurrently and need no strand or
// lock. Everything a session does is asynchronous; nothing here blocks.
//
// Conversation (docs/client-protocol.md): the server sends Hello at once; the client
// must send a valid message within subscribe_timeout_ms, and keep doing so until it
// has subscribed (then it may only read). Every write is a batch of whole messages
// and there is ONE write in flight per client. Frames wait in a ClientSendQueue of
// queue_frames; when it is full the OLDEST frame is dropped, counted, and announced
// to this client by a DropNotice written before its next frame. Replies (Subscribed,
// Stats, ControlReply, Pong) use a separate small queue and are never dropped; it holds
// at most client_message_burst replies, the same number the request rate limit lets a
// client send at once, so a client that pipelines its whole burst gets every answer, and
// one that keeps asking without reading is closed with Goodbye(RATE_LIMITED) saying so.
// Requests also draw on their peer address's budget (address_budget.hpp), which a
// reconnect does not refill. Garbage, an oversized length, a flood of requests or silence
// before subscribing:
// counted, logged (rate-limited), Goodbye written, FIN sent, further input discarded
// until the client closes or close_grace_ms passes, then closed.
//
// Ownership: shared_ptr (enable_shared_from_this); the server's session table, the
// broadcaster's index and pending handlers hold it. Cost per delivered frame: a
// shared_ptr copy into its send queue; per write: one writev of up to kMaxBatch messages.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "core/asio.hpp"
#include "core/connection_slots.hpp"
#include "serve/address_budget.hpp"
#include "serve/client_send_queue.hpp"
#include "serve/framing.hpp"
#include "serve/pose_broadcaster.hpp"
#include "serve/request_budget.hpp"
#include "serve/serve_config.hpp"
#include "serve/serve_counters.hpp"

namespace mocap::v1 {
class ClientMessage;
class ServerMessage;
}  // namespace mocap::v1

namespace mocap::serve {

/// Why the server closes a connection (mirrors mocap.v1.GoodbyeReason).
enum class CloseReason { kServerFull = 1, kTimeout, kMalformed, kRateLimited, kShutdown };

/// Goodbye message bytes (length-prefixed) for `reason`.
SharedBytes encode_goodbye(CloseReason reason, std::string_view text);

/// What every session of one server shares. Owned by PoseServer; outlives sessions.
struct SessionContext {
    const ServeConfig& config;
    const ControlHandlers& handlers;
    ServeCounters& counters;
    LogLimiter& log;
    PoseBroadcaster& broadcaster;
    std::function<SharedBytes()> hello;  ///< current Hello bytes (any thread)
    std::function<std::int64_t()> wall_clock_us;
    /// Called once on the lane thread when the session has closed.
    std::function<void(std::size_t lane, std::uint64_t id)> on_closed;
    /// One per lane (index = lane): how many requests a lane handles per turn.
    std::vector<RequestBudget*> request_budgets;
    /// Requests per peer address over all its connections; null = none (fuzzing).
    AddressBudget* address_budget = nullptr;
};

class ClientSession : public std::enable_shared_from_this<ClientSession> {
public:
    /// Most messages written in one batch (one writev).
    static constexpr std::size_t kMaxBatch = 32;

    /// `socket` must belong to the lane's io_context.
    ClientSession(asio::ip::tcp::socket socket, SessionContext& ctx, std::size_t lane, std::uint64_t id);
    ~ClientSession();
    ClientSession(const ClientSession&) = delete;
    ClientSession& operator=(const ClientSession&) = delete;

    /// Lane thread: sends Hello, starts the read loop and the subscribe timer.
    void start();
    /// Lane thread: queue `frame` if subscribed to its subject (honouring decimation);
    /// starts a write if none is in flight. Never closes the session synchronously.
    void deliver(const EncodedFrame& frame);
    /// Lane thread: close now (no Goodbye). Idempotent.
    void close();
    /// Lane thread: write Goodbye (after pending replies), then close; frames stop.
    void close_with_goodbye(CloseReason reason, std::string_view text);

    [[nodiscard]] std::uint64_t id() const { return id_; }
    /// Before start(): the connection slot to report progress on (valid messages, frames
    /// written; core/connection_slots.hpp). Without one nothing is reported.
    void set_slot(std::shared_ptr<ConnectionSlots::Slot> slot) { slot_ = std::move(slot); }
    [[nodiscard]] std::uint64_t dropped_total() const { return frames_.dropped_total(); }

private:
    void do_read();
    void on_read(const boost::system::error_code& ec, std::size_t n);
    /// Handles the buffered requests while the lane's turn lasts; `granted`: the budget
    /// already admitted the held one. Stops (waiting_turn_) when the turn is used up.
    void parse_messages(bool granted);
    /// Parses the next buffered request into in_ and takes its rate-limit token; false when
    /// more bytes are needed or the client was closed for what it sent.
    bool parse_next();
    /// The lane's budget resumed this session with one request admitted.
    void resume_requests();
    RequestBudget& budget() { return *ctx_.request_budgets[lane_]; }
    void do_write();
    void on_write(const boost::system::error_code& ec, std::size_t n);
    void arm_timer(std::chrono::milliseconds after);
    void on_timer(const boost::system::error_code& ec);
    void fail(const boost::system::error_code& ec, const char* what);

    /// Returns false if the session is closing because of this message.
    bool handle(const v1::ClientMessage& message);
    void handle_subscribe(const v1::ClientMessage& message);
    void handle_stats(const v1::ClientMessage& message);
    void handle_control(const v1::ClientMessage& message);
    void send_reply(const v1::ServerMessage& message);
    bool take_request_token();
    /// Replies that may wait unwritten: one per request of a full burst (see above).
    [[nodiscard]] std::size_t max_pending_replies() const { return ctx_.config.client_message_burst; }
    void protocol_error(CloseReason reason, LogLimiter::Kind kind, std::string_view what);
    void unsubscribe();

    asio::ip::tcp::socket socket_;
    asio::steady_timer timer_;
    SessionContext& ctx_;
    const std::size_t lane_;
    const std::uint64_t id_;
    std::shared_ptr<ConnectionSlots::Slot> slot_;
    std::optional<asio::ip::address> peer_;  ///< for the control rules; nullopt if unknown

    DelimitedReader reader_;
    std::unique_ptr<v1::ClientMessage> in_;     ///< reused parse target
    bool held_ = false;                         ///< in_ holds a parsed request waiting for the lane's next turn
    bool waiting_turn_ = false;                 ///< reading stopped until the budget resumes this session
    std::unique_ptr<v1::ServerMessage> reply_;  ///< reused reply scratch

    bool subscribed_ = false;
    std::vector<std::uint32_t> subjects_;  ///< sorted, unique; empty = all
    std::uint32_t decimation_ = 1;
    std::uint32_t fields_ = 0;
    std::vector<std::pair<std::uint32_t, std::uint64_t>> decimation_counts_;  ///< per subject

    ClientSendQueue frames_;  ///< capacity queue_frames; drops counted in frames_dropped
    std::deque<SharedBytes> replies_;
    std::vector<SharedBytes> in_flight_;
    std::vector<asio::const_buffer> buffers_;
    std::size_t in_flight_frames_ = 0;
    bool writing_ = false;
    bool closing_ = false;
    bool closed_ = false;
    bool send_shut_ = false;  ///< Goodbye written and FIN sent

    double request_tokens_ = 0;
    std::chrono::steady_clock::time_point last_refill_{};
};

}  // namespace mocap::serve
