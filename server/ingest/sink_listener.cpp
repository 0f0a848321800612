#include "ingest/sink_listener.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <exception>

#include "core/saturating.hpp"
#include "mocap_wire/mw_packet.h"

namespace mocap::ingest {

using boost::system::error_code;
using tcp = asio::ip::tcp;

// One sink's TCP connection: reads, decodes, hands packets to the listener.
class SinkConnection : public std::enable_shared_from_this<SinkConnection> {
public:
    SinkConnection(SinkListener& owner, tcp::socket socket)
        : owner_(owner),
          socket_(std::move(socket)),
          idle_timer_(socket_.get_executor()),
          decoder_(std::make_unique<mw_stream_decoder>()),
          packet_(std::make_unique<mw_packet>()) {
        mw_stream_decoder_init(decoder_.get());
        error_code ec;
        const auto ep = socket_.remote_endpoint(ec);
        peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
        socket_.set_option(tcp::no_delay(true), ec);
    }

    void start() {
        arm_idle_timer();
        do_read();
    }

    void close() {
        if (closed_) return;
        closed_ = true;
        error_code ec;
        idle_timer_.cancel();
        socket_.shutdown(tcp::socket::shutdown_both, ec);
        socket_.close(ec);
        owner_.on_closed(*this);
    }

    [[nodiscard]] const std::string& peer() const { return peer_; }
    bool has_sequence = false;
    std::uint32_t last_sequence = 0;

private:
    void fail(const error_code& ec, const char* what) {
        if (ec != asio::error::operation_aborted && ec != asio::error::eof) {
            if (owner_.log_allowed()) spdlog::info("sink {}: {}: {}", peer_, what, ec.message());
        } else if (ec == asio::error::eof) {
            if (owner_.log_allowed()) spdlog::info("sink {}: disconnected", peer_);
        }
        close();
    }

    void arm_idle_timer() {
        idle_timer_.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
            std::chrono::duration<double>(owner_.config_.idle_timeout_s)));
        idle_timer_.async_wait([self = shared_from_this()](const error_code& ec) {
            if (ec || self->closed_) return;
            self->owner_.c_.idle_timeouts.add();
            if (self->owner_.log_allowed())
                spdlog::warn("sink {}: nothing received for {} s, closing", self->peer_,
                             self->owner_.config_.idle_timeout_s);
            self->close();
        });
    }

    void do_read() {
        socket_.async_read_some(asio::buffer(buf_), [self = shared_from_this()](const error_code& ec, std::size_t n) {
            self->on_read(ec, n);
        });
    }

    void on_read(const error_code& ec, std::size_t n) {
        if (ec) return fail(ec, "read");
        if (closed_) return;
        arm_idle_timer();
        const std::int64_t received_us = owner_.clock_.now_us();
        auto& c = owner_.c_;
        c.bytes.add(n);
        const mw_stream_counters before = decoder_->counters;
        const std::uint8_t* p = buf_.data();
        std::size_t left = n;
        for (;;) {
            std::size_t used = 0;
            const mw_stream_result r = mw_stream_decoder_feed(decoder_.get(), p, left, &used, packet_.get());
            p += used;
            left -= used;
            if (r == MW_STREAM_NEED_MORE) break;
            if (r == MW_STREAM_PACKET) {
                garbage_since_packet_ = 0;
                owner_.on_packet(*this, *packet_, received_us);
            } else if (!logged_malformed_ && owner_.log_allowed()) {
                logged_malformed_ = true;  // one line per connection: no log flood
                spdlog::warn("sink {}: malformed packet ({}); resynchronising", peer_,
                             mw_error_name(decoder_->last_error));
            }
        }
        const mw_stream_counters& after = decoder_->counters;
        c.malformed.add(after.malformed_packets - before.malformed_packets);
        c.crc_failures.add(after.crc_failures - before.crc_failures);
        const std::uint64_t discarded = after.bytes_discarded - before.bytes_discarded;
        c.discarded.add(discarded);
        garbage_since_packet_ += discarded;
        if (garbage_since_packet_ > owner_.config_.max_garbage_bytes) {
            c.garbage_closes.add();
            if (owner_.log_allowed())
                spdlog::warn("sink {}: {} bytes without a valid packet, closing", peer_, garbage_since_packet_);
            close();
            return;
        }
        do_read();
    }

    SinkListener& owner_;
    tcp::socket socket_;
    asio::steady_timer idle_timer_;
    std::unique_ptr<mw_stream_decoder> decoder_;
    std::unique_ptr<mw_packet> packet_;
    std::array<std::uint8_t, 8192> buf_{};
    std::string peer_;
    std::uint64_t garbage_since_packet_ = 0;
    bool logged_malformed_ = false;
    bool closed_ = false;
};

SinkListener::SinkListener(asio::io_context& io, SinkListenerConfig config, const Clock& clock, SampleSink sink)
    : io_(io), config_(std::move(config)), clock_(clock), sink_(std::move(sink)), acceptor_(io) {
    group_.add("connections_accepted", c_.accepted);
    group_.add("connections_refused", c_.refused);
    group_.add("connections_closed", c_.closed);
    group_.add("idle_timeouts", c_.idle_timeouts);
    group_.add("garbage_closes", c_.garbage_closes);
    group_.add("bytes", c_.bytes);
    group_.add("packets", c_.packets);
    group_.add("malformed_packets", c_.malformed);
    group_.add("crc_failures", c_.crc_failures);
    group_.add("bytes_discarded", c_.discarded);
    group_.add("sequence_gaps", c_.sequence_gaps);
    group_.add("unknown_sink_packets", c_.unknown_sink);
    group_.add("sink_takeovers", c_.takeovers);
    group_.add("implausible_timestamps", c_.implausible_timestamps);
    reassembly_.register_in(group_);
}

void SinkListener::register_metrics(MetricsRegistry& registry) const {
    registry.add(group_);
    registry.add_gauge("sinks_connected", "Sink TCP connections open now", [this] {
        const std::uint64_t opened = c_.accepted.value();
        const std::uint64_t closed = c_.closed.value();
        return static_cast<double>(opened - std::min(opened, closed));
    });
}

SinkListener::~SinkListener() {
    // Asio's timer cancel() reports failure by throwing; a destructor must not, and at this
    // point the only thing left to do with such a failure is to say so.
    try {
        stop();
    } catch (const std::exception& e) {
        spdlog::error("sink listener: stop: {}", e.what());
    }
}

bool SinkListener::start(std::string* error) {
    error_code ec;
    const auto addr = asio::ip::make_address(config_.host, ec);
    if (ec) {
        *error = "sink_listen: bad address '" + config_.host + "': " + ec.message();
        return false;
    }
    const tcp::endpoint ep(addr, config_.port);
    acceptor_.open(ep.protocol(), ec);
    if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
    if (!ec) acceptor_.bind(ep, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec) {
        *error = "sink_listen " + config_.host + ":" + std::to_string(config_.port) + ": " + ec.message();
        return false;
    }
    port_ = acceptor_.local_endpoint().port();
    do_accept();
    return true;
}

void SinkListener::stop() {
    if (stopped_) return;
    stopped_ = true;
    error_code ec;
    acceptor_.close(ec);
    // Moved, not copied: stop() runs in the destructor, where a copy's allocation could throw.
    // close() looks the connection up in connections_ and finds nothing to erase.
    auto conns = std::move(connections_);
    connections_.clear();
    for (const auto& c : conns)
        c->close();
}

void SinkListener::do_accept() {
    acceptor_.async_accept([this](const error_code& ec, tcp::socket s) { on_accept(ec, std::move(s)); });
}

void SinkListener::on_accept(const error_code& ec, tcp::socket socket) {
    if (ec == asio::error::operation_aborted || stopped_) return;
    if (ec) {
        if (log_allowed()) spdlog::warn("sink listener: accept: {}", ec.message());
    } else if (connections_.size() >= config_.max_sinks) {
        c_.refused.add();
        if (log_allowed())
            spdlog::warn("sink listener: refusing a connection: max_sinks ({}) reached", config_.max_sinks);
        error_code ignored;
        socket.close(ignored);
    } else {
        c_.accepted.add();
        auto conn = std::make_shared<SinkConnection>(*this, std::move(socket));
        if (log_allowed()) spdlog::info("sink {}: connected", conn->peer());
        connections_.insert(conn);
        conn->start();
    }
    do_accept();
}

void SinkListener::on_packet(SinkConnection& from, const mw_packet& packet, std::int64_t received_us) {
    c_.packets.add();
    const std::uint8_t sink_id = packet.header.sink_id;
    if (sink_id == 0 || sink_id > config_.max_subjects) {
        c_.unknown_sink.add();
        return;
    }
    if (from.has_sequence && packet.header.sequence != from.last_sequence + 1) c_.sequence_gaps.add();
    from.has_sequence = true;
    from.last_sequence = packet.header.sequence;

    auto& r = reassemblers_[sink_id];
    if (!r) {
        r = std::make_unique<FrameReassembler>(sink_id, config_.reassembly, reassembly_, sink_);
    }
    SinkConnection*& owner = owners_[sink_id];
    if (owner != &from) {
        if (owner != nullptr) {
            // The sink came back on a new connection before the old one timed out.
            c_.takeovers.add();
            if (log_allowed())
                spdlog::info("sink id {}: now on {}, closing the old connection {}", sink_id, from.peer(),
                             owner->peer());
            SinkConnection* old = owner;
            owner = &from;
            old->close();
        }
        owner = &from;
        r->reset_stream();
    }
    // The stamp is the sink's word: a plain cast of a stamp above 2^63 went negative and
    // "ts + offset" or "received - ts" could overflow, which gave latencies of decades for
    // the daemon's lifetime. Clamp the arithmetic, and keep a stamp that is implausibly far
    // from the host clock out of every latency figure (sink_send_us = 0 means unknown); the
    // sample times stay on the sink's own clock, which only its own subject's filters use.
    const std::int64_t ts = saturating_int64(packet.header.timestamp_us);
    const std::int64_t skew = saturating_sub(received_us, ts);
    const bool plausible = skew >= -config_.max_clock_skew_us && skew <= config_.max_clock_skew_us;
    if (!plausible) c_.implausible_timestamps.add();
    const std::int64_t send_us = plausible ? ts : 0;
    for (std::uint16_t i = 0; i < packet.frame_count; ++i) {
        const mw_stamped_frame& f = packet.frames[i];
        r->on_frame(f.frame, saturating_add(ts, f.offset_us), send_us, received_us);
    }
}

bool SinkListener::log_allowed() {
    const std::int64_t now = clock_.now_us();
    if (now - log_window_start_us_ >= kLogWindowUs || now < log_window_start_us_) {
        if (log_suppressed_ > 0) {
            spdlog::warn("sink listener: {} more connection events in the last {} s were not logged", log_suppressed_,
                         kLogWindowUs / 1'000'000);
        }
        log_window_start_us_ = now;
        log_lines_in_window_ = 0;
        log_suppressed_ = 0;
    }
    if (log_lines_in_window_ < kLogBurst) {
        ++log_lines_in_window_;
        return true;
    }
    ++log_suppressed_;
    return false;
}

void SinkListener::on_closed(SinkConnection& c) {
    c_.closed.add();
    for (auto& o : owners_) {
        if (o == &c) o = nullptr;
    }
    for (auto it = connections_.begin(); it != connections_.end(); ++it) {
        if (it->get() == &c) {
            // Keep the object alive until its pending handlers run (they hold a shared_ptr).
            connections_.erase(it);
            break;
        }
    }
}

}  // namespace mocap::ingest
