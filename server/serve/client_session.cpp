// client_session.cpp — read loop, bounded drop-oldest write queue, timers, requests.
#include "serve/client_session.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <optional>
#include <string>

#include "mocap/v1/mocap.pb.h"
#include "serve/serve_thread.hpp"
#include "serve/stats_reply.hpp"

namespace mocap::serve {

namespace {

constexpr std::uint32_t kMaxDecimation = 100000;

}  // namespace

SharedBytes encode_goodbye(CloseReason reason, std::string_view text) {
    v1::ServerMessage message;
    message.mutable_goodbye()->set_reason(static_cast<v1::GoodbyeReason>(reason));
    message.mutable_goodbye()->set_message(std::string(text));
    return encode_server_message(message);
}

ClientSession::ClientSession(asio::ip::tcp::socket socket, SessionContext& ctx, std::size_t lane, std::uint64_t id)
    : socket_(std::move(socket)),
      timer_(socket_.get_executor()),
      ctx_(ctx),
      lane_(lane),
      id_(id),
      reader_(ctx.config.max_client_message_bytes),
      in_(std::make_unique<v1::ClientMessage>()),
      reply_(std::make_unique<v1::ServerMessage>()),
      frames_(ctx.config.queue_frames, ctx.counters.frames_dropped),
      request_tokens_(static_cast<double>(ctx.config.client_message_burst)),
      last_refill_(std::chrono::steady_clock::now()) {
    in_flight_.reserve(kMaxBatch);
    buffers_.reserve(kMaxBatch);
}

ClientSession::~ClientSession() = default;

void ClientSession::start() {
    peer_ = remote_address(socket_);
    if (SharedBytes hello = ctx_.hello()) replies_.push_back(std::move(hello));
    do_write();
    do_read();
    arm_timer(std::chrono::milliseconds(ctx_.config.subscribe_timeout_ms));
}

// ---------------------------------------------------------------------------- read

void ClientSession::do_read() {
    if (closed_) return;
    const auto area = reader_.write_area();
    socket_.async_read_some(
        asio::buffer(area.data(), area.size()),
        [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) { self->on_read(ec, n); });
}

void ClientSession::on_read(const boost::system::error_code& ec, std::size_t n) {
    if (ec) return fail(ec, "read");
    // While closing, input is read and discarded until the client closes too (or the
    // grace timer fires): closing a socket with unread input sends RST, which can
    // destroy the Goodbye before the client reads it.
    if (!closing_) {
        reader_.commit(n);
        parse_messages(false);
        // The lane's turn is used up: no more reading (TCP pushes back on the client) until
        // the budget resumes this session, which then reads on.
        if (waiting_turn_ && !closing_) return;
    }
    do_read();
}

void ClientSession::resume_requests() {
    waiting_turn_ = false;
    if (closed_) return;
    if (!closing_) parse_messages(true);
    if (waiting_turn_ && !closing_) return;
    do_read();
}

void ClientSession::parse_messages(bool granted) {
    for (;;) {
        if (!held_) {
            if (!parse_next()) return;
            held_ = true;
        }
        if (!granted && !budget().try_take()) {
            // Frames handed to this lane meanwhile go first (request_budget.hpp).
            waiting_turn_ = true;
            ctx_.counters.requests_deferred.add();
            budget().wait([self = shared_from_this()] { self->resume_requests(); });
            return;
        }
        granted = false;
        held_ = false;
        if (slot_) slot_->progress(ServeThread::now_us());
        if (!handle(*in_)) return;
    }
}

bool ClientSession::parse_next() {
    const FrameResult r = reader_.next();
    if (r.status == FrameStatus::kNeedMore) return false;
    if (r.status == FrameStatus::kTooLarge) {
        ctx_.counters.oversized_messages.add();
        protocol_error(CloseReason::kMalformed, LogLimiter::kOversized, "message longer than max_client_message_bytes");
        return false;
    }
    if (r.status == FrameStatus::kBadPrefix ||
        !in_->ParseFromArray(r.payload.data(), static_cast<int>(r.payload.size()))) {
        ctx_.counters.malformed_messages.add();
        protocol_error(CloseReason::kMalformed, LogLimiter::kMalformed, "unparseable message");
        return false;
    }
    // The connection's budget, then its address's, which a reconnect does not refill.
    const bool connection_ok = take_request_token();
    const bool address_ok = !connection_ok || ctx_.address_budget == nullptr || !peer_ ||
                            ctx_.address_budget->take(*peer_, ServeThread::now_us());
    if (!address_ok || !connection_ok) {
        (connection_ok ? ctx_.counters.address_rate_limited : ctx_.counters.rate_limited).add();
        const std::string why =
            connection_ok ? fmt::format(
                                "too many requests from your address: more than address_message_burst ({}) at once "
                                "or max_address_messages_per_s ({}) sustained, over all its connections",
                                ctx_.config.address_message_burst, ctx_.config.max_address_messages_per_s)
                          : fmt::format(
                                "too many requests: more than client_message_burst ({}) at once or "
                                "max_client_messages_per_s ({}) sustained",
                                ctx_.config.client_message_burst, ctx_.config.max_client_messages_per_s);
        protocol_error(CloseReason::kRateLimited, LogLimiter::kRateLimited, why);
        return false;
    }
    return true;
}

bool ClientSession::take_request_token() {
    const auto now = std::chrono::steady_clock::now();
    const double dt_s = std::chrono::duration<double>(now - last_refill_).count();
    last_refill_ = now;
    request_tokens_ = std::min(static_cast<double>(ctx_.config.client_message_burst),
                               request_tokens_ + dt_s * ctx_.config.max_client_messages_per_s);
    if (request_tokens_ < 1.0) return false;
    request_tokens_ -= 1.0;
    return true;
}

void ClientSession::protocol_error(CloseReason reason, LogLimiter::Kind kind, std::string_view what) {
    std::uint64_t suppressed = 0;
    if (ctx_.log.allow(kind, suppressed)) {
        boost::system::error_code ec;
        const auto peer = socket_.remote_endpoint(ec);
        spdlog::warn("serve: client {} ({}) closed: {} ({} similar suppressed)", id_,
                     ec ? std::string("?") : peer.address().to_string(), what, suppressed);
    }
    close_with_goodbye(reason, what);
}

bool ClientSession::handle(const v1::ClientMessage& message) {
    using M = v1::ClientMessage;
    switch (message.body_case()) {
        case M::kSubscribe:
            handle_subscribe(message);
            break;
        case M::kStatsRequest:
            handle_stats(message);
            break;
        case M::kControl:
            handle_control(message);
            break;
        case M::kPing: {
            reply_->Clear();
            v1::Pong* pong = reply_->mutable_pong();
            pong->set_nonce(message.ping().nonce());
            pong->set_client_time_us(message.ping().client_time_us());
            pong->set_server_time_us(ctx_.wall_clock_us());
            send_reply(*reply_);
            break;
        }
        case M::BODY_NOT_SET:
            // A newer client's message type: tolerated (forward compatibility), counted.
            ctx_.counters.unknown_messages.add();
            break;
    }
    if (closing_) return false;
    // Any valid message keeps an unsubscribed client alive for another timeout.
    if (!subscribed_) arm_timer(std::chrono::milliseconds(ctx_.config.subscribe_timeout_ms));
    return true;
}

void ClientSession::handle_subscribe(const v1::ClientMessage& message) {
    const v1::Subscribe& sub = message.subscribe();
    const auto named = static_cast<std::uint32_t>(sub.subject_ids_size());
    if (named > ctx_.config.max_subscribe_subjects) {
        // What one request may cost the serve thread is bounded by what it may name.
        ctx_.counters.subscribe_too_many_subjects.add();
        return protocol_error(CloseReason::kMalformed, LogLimiter::kMalformed,
                              fmt::format("Subscribe names {} subjects, more than max_subscribe_subjects ({}); an "
                                          "empty list subscribes to every subject",
                                          named, ctx_.config.max_subscribe_subjects));
    }
    const std::optional<std::uint32_t> previous_fields = subscribed_ ? std::optional(fields_) : std::nullopt;
    subjects_.assign(sub.subject_ids().begin(), sub.subject_ids().end());
    std::sort(subjects_.begin(), subjects_.end());
    subjects_.erase(std::unique(subjects_.begin(), subjects_.end()), subjects_.end());
    decimation_ = std::clamp<std::uint32_t>(sub.decimation(), 1, kMaxDecimation);
    fields_ = normalize_fields(sub.fields());
    decimation_counts_.clear();
    frames_.clear();  // queued frames belong to the replaced subscription
    // Replaces the old subscription in place: only the subjects that change are touched.
    ctx_.broadcaster.subscribe(lane_, shared_from_this(), subjects_, fields_, previous_fields);
    subscribed_ = true;
    ctx_.counters.subscriptions.add();
    timer_.cancel();  // a subscribed client may stay silent

    reply_->Clear();
    v1::Subscribed* ack = reply_->mutable_subscribed();
    for (std::uint32_t s : subjects_)
        ack->add_subject_ids(s);
    ack->set_decimation(decimation_);
    ack->set_fields(fields_);
    ack->set_queue_frames(static_cast<std::uint32_t>(frames_.capacity()));
    send_reply(*reply_);
}

void ClientSession::unsubscribe() {
    if (!subscribed_) return;
    ctx_.broadcaster.unsubscribe(lane_, this, fields_);
    subscribed_ = false;
    frames_.clear();
}

void ClientSession::handle_stats(const v1::ClientMessage& message) {
    ctx_.counters.stats_requests.add();
    v1::ServerMessage reply;  // rare: a fresh message keeps reply_ small
    v1::Stats* stats = reply.mutable_stats();
    stats->set_request_id(message.stats_request().request_id());
    stats->set_server_time_us(ctx_.wall_clock_us());
    if (ctx_.handlers.stats) {
        render_stats(ctx_.handlers.stats(), *stats);
    } else {  // a server on its own (tests, tools): its own counters
        MetricsRegistry own;
        own.add(ctx_.counters.group);
        render_stats(own.snapshot(), *stats);
    }
    send_reply(reply);
}

void ClientSession::handle_control(const v1::ClientMessage& message) {
    const v1::ControlRequest& request = message.control();
    const ServeConfig& config = ctx_.config;
    ControlResult result;
    const std::string who = fmt::format("serve: control request from client {}", id_);
    if (const auto refusal =
            authorize_control({config.control_token, config.control_loopback_only, config.control_attempts.get()},
                              peer_, request.token(), ctx_.counters.control, ctx_.log, who)) {
        result = ControlResult::failure(refusal->reason);
    } else {
        const ControlHandlers& h = ctx_.handlers;
        using R = v1::ControlRequest;
        auto unsupported = [] { return ControlResult::failure("not supported by this server"); };
        switch (request.action_case()) {
            case R::kCalibrate: {
                const auto pose = request.calibrate().pose() == v1::POSE_N ? CalibrationPose::kN : CalibrationPose::kT;
                result = h.calibrate ? h.calibrate(request.calibrate().subject_id(), pose) : unsupported();
                break;
            }
            case R::kStartRecording: {
                const auto& start = request.start_recording();
                if (!start.take()) {
                    result = h.start_recording ? h.start_recording(start.path()) : unsupported();
                } else if (!start.path().empty()) {
                    result = ControlResult::failure("a take has a name, not a path");
                } else {
                    result = h.start_take ? h.start_take(start.take_name(), start.notes()) : unsupported();
                }
                break;
            }
            case R::kStopRecording:
                if (request.stop_recording().take()) {
                    result = h.stop_take ? h.stop_take() : unsupported();
                } else {
                    result = h.stop_recording ? h.stop_recording() : unsupported();
                }
                break;
            case R::kReload:
                result = h.reload ? h.reload() : unsupported();
                break;
            case R::ACTION_NOT_SET:
                result = ControlResult::failure("no action in request");
                break;
        }
        ctx_.counters.control.count_result(result);
    }
    reply_->Clear();
    v1::ControlReply* reply = reply_->mutable_control_reply();
    reply->set_request_id(request.request_id());
    reply->set_ok(result.ok);
    reply->set_error(result.error);
    reply->set_take_name(result.take);
    send_reply(*reply_);
}

void ClientSession::send_reply(const v1::ServerMessage& message) {
    if (closing_) return;
    if (replies_.size() >= max_pending_replies()) {
        // The client asks but does not read its answers: a whole burst of them waits.
        ctx_.counters.rate_limited.add();
        const std::string why =
            fmt::format("replies not read: {} answers waiting (client_message_burst)", replies_.size());
        return protocol_error(CloseReason::kRateLimited, LogLimiter::kRateLimited, why);
    }
    SharedBytes bytes = encode_server_message(message);
    if (!bytes) return;
    replies_.push_back(std::move(bytes));
    if (!writing_) do_write();
}

// --------------------------------------------------------------------------- write

void ClientSession::deliver(const EncodedFrame& frame) {
    if (!subscribed_ || closing_) return;
    if (decimation_ > 1) {
        auto it = std::find_if(decimation_counts_.begin(), decimation_counts_.end(),
                               [&](const auto& p) { return p.first == frame.subject_id; });
        if (it == decimation_counts_.end()) {
            decimation_counts_.emplace_back(frame.subject_id, 0);
            it = decimation_counts_.end() - 1;
        }
        if (it->second++ % decimation_ != 0) return;
    }
    const SharedBytes& bytes = frame.by_fields[fields_];
    if (!bytes) return;  // subscribed after this frame was encoded
    frames_.push(bytes);
    if (!writing_) do_write();
}

void ClientSession::do_write() {
    if (closed_ || writing_) return;
    in_flight_.clear();
    buffers_.clear();
    in_flight_frames_ = 0;
    if (const std::uint64_t dropped = closing_ ? 0 : frames_.take_unreported_drops(); dropped > 0) {
        reply_->Clear();
        reply_->mutable_drops()->set_dropped(dropped);
        reply_->mutable_drops()->set_dropped_total(frames_.dropped_total());
        if (SharedBytes notice = encode_server_message(*reply_)) in_flight_.push_back(notice);
    }
    while (!replies_.empty() && in_flight_.size() < kMaxBatch) {
        in_flight_.push_back(std::move(replies_.front()));
        replies_.pop_front();
    }
    in_flight_frames_ = frames_.move_into(in_flight_, kMaxBatch);
    if (in_flight_.empty()) {
        if (closing_ && !send_shut_) {
            // Goodbye written: FIN, then wait for the client's close (or the timer).
            boost::system::error_code ignored;
            socket_.shutdown(asio::ip::tcp::socket::shutdown_send, ignored);
            send_shut_ = true;
        }
        return;
    }
    for (const SharedBytes& b : in_flight_)
        buffers_.emplace_back(b->data(), b->size());
    writing_ = true;
    asio::async_write(
        socket_, buffers_,
        [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) { self->on_write(ec, n); });
}

void ClientSession::on_write(const boost::system::error_code& ec, std::size_t n) {
    writing_ = false;
    if (ec) {
        if (ec != asio::error::operation_aborted) {
            ctx_.counters.write_errors.add();
        }
        return fail(ec, "write");
    }
    ctx_.counters.bytes_sent.add(n);
    ctx_.counters.frames_sent.add(in_flight_frames_);
    if (slot_ && in_flight_frames_ > 0) slot_->progress(ServeThread::now_us());
    in_flight_.clear();  // release the shared buffers now, not at the next write
    do_write();
}

// ------------------------------------------------------------- timers and closing

void ClientSession::arm_timer(std::chrono::milliseconds after) {
    timer_.expires_after(after);
    timer_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) { self->on_timer(ec); });
}

void ClientSession::on_timer(const boost::system::error_code& ec) {
    if (ec) return fail(ec, "timer");
    // Re-armed after this expiry was already queued: not a timeout.
    if (timer_.expiry() > asio::steady_timer::clock_type::now()) return;
    if (closed_) return;
    if (closing_) return close();  // the client did not take its Goodbye in time
    if (!subscribed_) {
        ctx_.counters.idle_timeouts.add();
        protocol_error(CloseReason::kTimeout, LogLimiter::kIdle, "nothing received within subscribe_timeout_ms");
    }
}

void ClientSession::fail(const boost::system::error_code& ec, const char* what) {
    if (ec == asio::error::operation_aborted) return;  // our own cancel/close
    if (ec != asio::error::eof && ec != asio::error::connection_reset && ec != asio::error::broken_pipe) {
        std::uint64_t suppressed = 0;
        if (ctx_.log.allow(LogLimiter::kIoError, suppressed)) {
            spdlog::info("serve: client {} {}: {} ({} similar suppressed)", id_, what, ec.message(), suppressed);
        }
    }
    close();
}

void ClientSession::close_with_goodbye(CloseReason reason, std::string_view text) {
    if (closing_ || closed_) return;
    closing_ = true;
    frames_.clear();
    if (SharedBytes bye = encode_goodbye(reason, text)) replies_.push_back(std::move(bye));
    arm_timer(std::chrono::milliseconds(ctx_.config.close_grace_ms));
    if (!writing_) do_write();
}

void ClientSession::close() {
    if (closed_) return;
    closed_ = true;
    closing_ = true;
    boost::system::error_code ignored;
    timer_.cancel();
    socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
    socket_.close(ignored);
    unsubscribe();
    replies_.clear();
    ctx_.counters.connections.closed.add();
    ctx_.on_closed(lane_, id_);
}

}  // namespace mocap::serve
