// sink_listener.hpp — TCP listener for sink nodes (default port 7000).
//
// Every connection runs its own incremental mw_stream_decoder; every packet's CAN frames go
// to the FrameReassembler of the packet's sink id (1..max_subjects); its samples carry the
// subject id subject_id_base + sink id, so hosts of different zones of a site never share one.
// A sink that reconnects (or whose packets arrive on a new connection) takes its subject
// over: the old connection is closed and the reassembler starts a new counter stream, so
// nothing restarts. Malformed bytes are counted; the decoder resynchronises by itself, and
// a connection that sends only garbage (max_garbage_bytes without one valid packet) or no
// whole valid packet for idle_timeout is closed with one log line. The deadline is per
// packet, not per read: bytes that never make a packet (one every two seconds) do not
// extend it. Slots follow core/connection_slots.hpp: when max_sinks are open, a new
// connection takes the slot of one that has not delivered a valid packet yet (or has
// delivered none for longest, beyond limits.stall_evict_s), which is closed; failed
// accepts (EMFILE...) are retried after a pause (core/accept_backoff.hpp).
// Keepalive (stream version 2, docs/protocol.md §3.5): every connection is sent a 16-byte
// keepalive at once and then every keepalive_period_ms, so a sink notices a host that died
// silently. Writes are asynchronous with at most one keepalive in flight per connection; a
// tick that finds the previous one unsent (a sink that does not read: every version-1
// sink) is skipped and counted, so a sink can neither block the ingest thread nor make it
// buffer more than 16 bytes.
//
// Threading: every method and handler runs on the io_context passed in, which must be run
// by ONE thread (the ingest thread: SampleSink is called from it, in packet order).
// counters() may be read from any thread; they are SingleWriterCounter, written only on
// that thread (the destructor's stop() writes `connections_closed` after it has finished).
// Cost per packet: O(bytes) decoding plus the reassembler; buffers are allocated per
// connection at accept, never per packet.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_set>

#include "core/accept_backoff.hpp"
#include "core/asio.hpp"
#include "core/clock.hpp"
#include "core/connection_slots.hpp"
#include "core/counters.hpp"
#include "core/metrics_registry.hpp"
#include "ingest/frame_reassembler.hpp"
#include "mocap_wire/mw_packet.h"

namespace mocap::ingest {

struct SinkListenerConfig {
    std::string host = "0.0.0.0";
    std::uint16_t port = 7000;                ///< 0 = any free port (see port())
    std::uint32_t max_sinks = 64;             ///< connection slots (see above for who gets one)
    std::uint32_t max_subjects = 64;          ///< sink ids 1..max_subjects are accepted
    std::uint32_t subject_id_base = 0;        ///< a sink's subject id = subject_id_base + sink id
    double idle_timeout_s = 10.0;             ///< no whole valid packet for this long closes the connection
    PeerLimits limits{};                      ///< [limits] sink_per_address, loopback, stall_evict_s
    std::size_t max_garbage_bytes = 1 << 20;  ///< discarded bytes without a valid packet -> close
    std::uint16_t keepalive_period_ms = 250;  ///< host -> sink keepalive period; 0 = send none (stream version 1)
    /// A packet stamped further than this from the host's receive time has an implausible
    /// clock: counted (implausible_timestamps) and its samples carry sink_send_us = 0
    /// (latency unknown), so no latency figure sees it. Larger than any real latency (a
    /// sink is closed after idle_timeout) and than the clock steps a sink may take (NTP).
    std::int64_t max_clock_skew_us = 60'000'000;
    FrameReassembler::Params reassembly{};
};

class SinkConnection;

class SinkListener {
public:
    /// `clock` stamps received_us; `sink` receives every reassembled sample. Both must
    /// outlive the listener.
    SinkListener(asio::io_context& io, SinkListenerConfig config, const Clock& clock, SampleSink sink);
    ~SinkListener();

    SinkListener(const SinkListener&) = delete;
    SinkListener& operator=(const SinkListener&) = delete;

    /// Binds and starts accepting. Returns false and sets *error if the address cannot be
    /// bound. Call from the io thread or before it runs.
    bool start(std::string* error);
    /// Closes the acceptor and every connection (io thread).
    void stop();
    /// The bound port (useful with port 0).
    [[nodiscard]] std::uint16_t port() const { return port_; }
    /// Connections open now (io thread).
    [[nodiscard]] std::size_t connections() const { return connections_.size(); }

    /// Component "ingest_tcp": connections_accepted, connections_refused (every slot held by
    /// a sink delivering packets), connections_refused_per_address, connections_evicted,
    /// connections_closed, accept_errors, idle_timeouts, garbage_closes, bytes, packets,
    /// malformed_packets, crc_failures, bytes_discarded, sequence_gaps, unknown_sink_packets,
    /// sink_takeovers, implausible_timestamps, keepalives_sent, keepalives_skipped; plus the
    /// reassembly counters of every sink.
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    /// Set-up: the counters and gauge "sinks_connected" (accepted - closed, read from the
    /// counters, so any thread may read it).
    void register_metrics(MetricsRegistry& registry) const;

private:
    friend class SinkConnection;
    struct Counters {  // written on the io thread only (single writer)
        SingleWriterCounter accepted, refused, refused_per_address, evicted, closed, idle_timeouts, garbage_closes,
            bytes, packets, malformed, crc_failures, discarded, sequence_gaps, unknown_sink, takeovers,
            implausible_timestamps, keepalives_sent, keepalives_skipped;
        Counter accept_errors;  // the type AcceptBackoff takes; written on the io thread too
    };

    void do_accept();
    void on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket);
    // Called by a connection for each valid packet.
    void on_packet(SinkConnection& from, const mw_packet& packet, std::int64_t received_us);
    void on_closed(SinkConnection& c);
    // Connection events are logged at most kLogBurst per kLogWindowUs; the rest are counted
    // and summarised, so a connect/disconnect storm cannot flood the log.
    bool log_allowed();
    static constexpr std::uint32_t kLogBurst = 20;
    static constexpr std::int64_t kLogWindowUs = 10'000'000;
    std::int64_t log_window_start_us_ = 0;
    std::uint32_t log_lines_in_window_ = 0;
    std::uint64_t log_suppressed_ = 0;

    asio::io_context& io_;
    SinkListenerConfig config_;
    const Clock& clock_;
    SampleSink sink_;
    asio::ip::tcp::acceptor acceptor_;
    ConnectionSlots slots_;
    std::unique_ptr<AcceptBackoff> backoff_;  // made with c_.accept_errors, after c_
    std::uint16_t port_ = 0;
    bool stopped_ = false;
    std::unordered_set<std::shared_ptr<SinkConnection>> connections_;
    // Index = sink id; created when the sink id is first seen, kept for the daemon's life
    // so the 64-bit sync line of a subject survives reconnects.
    std::array<std::unique_ptr<FrameReassembler>, 256> reassemblers_{};
    std::array<SinkConnection*, 256> owners_{};
    Counters c_;
    ReassemblyCounters reassembly_;
    CounterGroup group_{"ingest_tcp"};
};

}  // namespace mocap::ingest
