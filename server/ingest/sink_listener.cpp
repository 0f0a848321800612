#include "ingest/sink_listener.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <exception>

#include "core/peer_address.hpp"
#include "core/saturating.hpp"
#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"

namespace mocap::ingest {

using boost::system::error_code;
using tcp = asio::ip::tcp;

namespace {
// The clock of packet deadlines and connection slots: steady (the idle timer's own), so a
// wall-clock step neither closes every sink nor keeps a silent one open.
std::int64_t steady_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}
}  // namespace

// One sink's TCP connection: reads, decodes, hands packets to the listener.
class SinkConnection : public std::enable_shared_from_this<SinkConnection> {
public:
    static constexpr int kSendBufferBytes = 4096;

    SinkConnection(SinkListener& owner, tcp::socket socket, std::shared_ptr<ConnectionSlots::Slot> slot)
        : owner_(owner),
          socket_(std::move(socket)),
          slot_(std::move(slot)),
          idle_timer_(socket_.get_executor()),
          keepalive_timer_(socket_.get_executor()),
          decoder_(std::make_unique<mw_stream_decoder>()),
          packet_(std::make_unique<mw_packet>()) {
        mw_stream_decoder_init(decoder_.get());
        error_code ec;
        const auto ep = socket_.remote_endpoint(ec);
        peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
        socket_.set_option(tcp::no_delay(true), ec);
        // The host sends only keepalives (64 bytes a second): a small send buffer bounds what
        // the kernel holds for a sink that never reads them.
        socket_.set_option(asio::socket_base::send_buffer_size(kSendBufferBytes), ec);
    }

    void start() {
        last_packet_us_ = steady_us();
        arm_idle_timer(owner_.config_.idle_timeout_s);
        if (owner_.config_.keepalive_period_ms > 0) send_keepalive();
        do_read();
    }

    /// A whole valid packet arrived: it moves the packet deadline and proves the slot.
    void on_valid_packet() {
        last_packet_us_ = steady_us();
        slot_->progress(last_packet_us_);
    }

    void close() {
        if (closed_) return;
        closed_ = true;
        error_code ec;
        idle_timer_.cancel();
        keepalive_timer_.cancel();
        socket_.shutdown(tcp::socket::shutdown_both, ec);
        socket_.close(ec);
        owner_.on_closed(*this);
    }

    [[nodiscard]] const std::string& peer() const { return peer_; }
    [[nodiscard]] std::uint64_t slot_id() const { return slot_->id(); }
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

    // The timer is not re-armed per packet (100 a second per sink): when it fires it checks
    // the time of the last valid packet and sleeps for what is left of its deadline.
    void arm_idle_timer(double after_s) {
        idle_timer_.expires_after(
            std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(after_s)));
        idle_timer_.async_wait([self = shared_from_this()](const error_code& ec) {
            if (ec || self->closed_) return;
            const double timeout_s = self->owner_.config_.idle_timeout_s;
            const double since_s = static_cast<double>(steady_us() - self->last_packet_us_) * 1e-6;
            if (since_s < timeout_s) return self->arm_idle_timer(timeout_s - since_s);
            self->owner_.c_.idle_timeouts.add();
            if (self->owner_.log_allowed())
                spdlog::warn("sink {}: no valid packet for {} s, closing", self->peer_,
                             self->owner_.config_.idle_timeout_s);
            self->close();
        });
    }

    // One keepalive in flight at most: the buffer is not touched while a write holds it, and a
    // sink that does not read costs a skipped tick, not memory.
    void send_keepalive() {
        if (closed_) return;
        if (keepalive_in_flight_) {
            owner_.c_.keepalives_skipped.add();
        } else {
            const mw_keepalive k{owner_.config_.keepalive_period_ms, keepalive_sequence_++};
            if (mw_keepalive_encode(&k, keepalive_buf_.data(), keepalive_buf_.size()) > 0) {
                keepalive_in_flight_ = true;
                asio::async_write(socket_, asio::buffer(keepalive_buf_),
                                  [self = shared_from_this()](const error_code& ec, std::size_t) {
                                      self->keepalive_in_flight_ = false;
                                      if (ec) return self->fail(ec, "write");
                                      self->owner_.c_.keepalives_sent.add();
                                  });
            }
        }
        keepalive_timer_.expires_after(std::chrono::milliseconds(owner_.config_.keepalive_period_ms));
        keepalive_timer_.async_wait([self = shared_from_this()](const error_code& ec) {
            if (!ec) self->send_keepalive();
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
                on_valid_packet();
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
    std::shared_ptr<ConnectionSlots::Slot> slot_;
    std::int64_t last_packet_us_ = 0;  // connection start until the first valid packet
    asio::steady_timer idle_timer_;
    asio::steady_timer keepalive_timer_;
    std::array<std::uint8_t, MW_KEEPALIVE_SIZE> keepalive_buf_{};
    std::uint32_t keepalive_sequence_ = 0;
    bool keepalive_in_flight_ = false;
    std::unique_ptr<mw_stream_decoder> decoder_;
    std::unique_ptr<mw_packet> packet_;
    std::array<std::uint8_t, 8192> buf_{};
    std::string peer_;
    std::uint64_t garbage_since_packet_ = 0;
    bool logged_malformed_ = false;
    bool closed_ = false;
};

SinkListener::SinkListener(asio::io_context& io, SinkListenerConfig config, const Clock& clock, SampleSink sink)
    : io_(io),
      config_(std::move(config)),
      clock_(clock),
      sink_(std::move(sink)),
      acceptor_(io),
      slots_(SlotPolicy{config_.max_sinks, config_.limits}),
      backoff_(std::make_unique<AcceptBackoff>(io.get_executor(), "sink listener", c_.accept_errors)) {
    group_.add("connections_accepted", c_.accepted);
    group_.add("connections_refused", c_.refused);
    group_.add("connections_refused_per_address", c_.refused_per_address);
    group_.add("connections_evicted", c_.evicted);
    group_.add("connections_closed", c_.closed);
    group_.add("accept_errors", c_.accept_errors);
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
    group_.add("keepalives_sent", c_.keepalives_sent);
    group_.add("keepalives_skipped", c_.keepalives_skipped);
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
    backoff_->cancel();
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
    if (ec) return backoff_->on_error(ec, [this] { do_accept(); });
    const PeerAddress peer = peer_address(socket);
    ConnectionSlots::Admission a = slots_.admit(peer.ip, peer.loopback, steady_us());
    if (!a.admitted()) {
        const bool per_address = a.verdict == ConnectionSlots::Verdict::kRefusedPerAddress;
        (per_address ? c_.refused_per_address : c_.refused).add();
        if (log_allowed()) {
            if (per_address) {
                spdlog::warn("sink listener: refusing a connection from {}: {} connections from that address", peer.ip,
                             config_.limits.max_per_address);
            } else {
                spdlog::warn(
                    "sink listener: refusing a connection from {}: max_sinks ({}) reached, every one "
                    "delivering packets",
                    peer.ip, config_.max_sinks);
            }
        }
        error_code ignored;
        socket.close(ignored);
        return do_accept();
    }
    if (a.verdict == ConnectionSlots::Verdict::kAdmittedEvicting) {
        c_.evicted.add();
        const auto victim = std::find_if(connections_.begin(), connections_.end(),
                                         [&](const auto& c) { return c->slot_id() == a.evicted; });
        if (victim != connections_.end()) {
            if (log_allowed())
                spdlog::warn(
                    "sink {}: closed to make room for {}: max_sinks reached and it delivered no valid "
                    "packet yet, or none for longest",
                    (*victim)->peer(), peer.ip);
            // Keep it alive through close(), which erases it from connections_.
            // NOLINTNEXTLINE(performance-unnecessary-copy-initialization): a reference would dangle
            const std::shared_ptr<SinkConnection> closing = *victim;
            closing->close();
        }
    }
    c_.accepted.add();
    auto conn = std::make_shared<SinkConnection>(*this, std::move(socket), std::move(a.slot));
    if (log_allowed()) spdlog::info("sink {}: connected", conn->peer());
    connections_.insert(conn);
    conn->start();
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
        r = std::make_unique<FrameReassembler>(config_.subject_id_base + sink_id, config_.reassembly, reassembly_,
                                               sink_);
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
    slots_.release(c.slot_id());
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
