#include "ingest/sink_listener.hpp"

#include "mocap_wire/mw_keepalive.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace mocap::ingest {
namespace {

using tcp = asio::ip::tcp;
using namespace std::chrono_literals;

class FixedClock : public Clock {
public:
    std::int64_t now_us() const noexcept override { return 777; }
};

/// stamp_us: the packet's timestamp (default: 1 s + 10 ms per counter).
std::vector<std::uint8_t> make_packet(std::uint8_t sink_id, std::uint32_t seq, std::uint32_t counter,
                                      std::uint8_t nodes, std::optional<std::uint64_t> stamp_us = std::nullopt) {
    std::vector<mw_stamped_frame> frames;
    mw_stamped_frame f{};
    mw_sync s{counter};
    mw_sync_encode(&s, &f.frame);
    frames.push_back(f);
    for (std::uint8_t n = 1; n <= nodes; ++n) {
        for (mw_function k : {MW_FN_ACCEL, MW_FN_GYRO, MW_FN_MAG}) {
            mw_raw r{};
            r.kind = k;
            r.node_id = n;
            r.xyz[2] = 100;
            r.counter_low = static_cast<std::uint16_t>(counter);
            f.offset_us = 50;
            mw_raw_encode(&r, &f.frame);
            frames.push_back(f);
        }
    }
    mw_packet_header h{sink_id, seq, stamp_us.value_or(1'000'000ull + counter * 10'000ull)};
    std::vector<std::uint8_t> out(MW_PACKET_MAX_SIZE);
    const auto n = mw_packet_encode(&h, frames.data(), frames.size(), out.data(), out.size());
    out.resize(static_cast<std::size_t>(n));
    return out;
}

/// Reads (keepalives, if any) until the server closes the connection; false if it never does.
bool closed_by_server(tcp::socket& s) {
    std::array<char, 256> b{};
    for (int i = 0; i < 10'000; ++i) {
        boost::system::error_code ec;
        s.read_some(asio::buffer(b), ec);
        if (ec) return true;
    }
    return false;
}

class SinkListenerTest : public ::testing::Test {
protected:
    void start(SinkListenerConfig cfg) {
        cfg.host = "127.0.0.1";
        cfg.port = 0;
        listener_ = std::make_unique<SinkListener>(io_, cfg, clock_, [this](const SegmentSample& s) {
            std::lock_guard lock(mu_);
            samples_.push_back(s);
        });
        std::string err;
        ASSERT_TRUE(listener_->start(&err)) << err;
        thread_ = std::thread([this] { io_.run(); });
    }
    void TearDown() override {
        asio::post(io_, [this] { listener_->stop(); });
        work_.reset();
        io_.stop();
        if (thread_.joinable()) thread_.join();
    }
    tcp::socket connect() {
        tcp::socket s(client_io_);
        s.connect({asio::ip::make_address("127.0.0.1"), listener_->port()});
        return s;
    }
    std::size_t count() {
        std::lock_guard lock(mu_);
        return samples_.size();
    }
    template <typename Pred>
    bool wait_until(Pred p, std::chrono::milliseconds limit = 3000ms) {
        const auto end = std::chrono::steady_clock::now() + limit;
        while (std::chrono::steady_clock::now() < end) {
            if (p()) return true;
            std::this_thread::sleep_for(2ms);
        }
        return p();
    }
    std::uint64_t counter(std::string_view name) { return *listener_->counters().value(name); }

    asio::io_context io_;
    asio::executor_work_guard<asio::io_context::executor_type> work_{io_.get_executor()};
    asio::io_context client_io_;
    FixedClock clock_;
    std::unique_ptr<SinkListener> listener_;
    std::thread thread_;
    std::mutex mu_;
    std::vector<SegmentSample> samples_;
};

TEST_F(SinkListenerTest, PacketsBecomeSamplesWithStamps) {
    start({});
    auto s = connect();
    for (std::uint32_t c = 0; c < 10; ++c)
        asio::write(s, asio::buffer(make_packet(3, c, c, 15)));
    ASSERT_TRUE(wait_until([&] { return count() == 150; }));
    std::lock_guard lock(mu_);
    EXPECT_EQ(samples_[0].subject_id, 3u);
    EXPECT_EQ(samples_[0].times.received_us, 777);
    EXPECT_EQ(samples_[0].times.sink_send_us, 1'000'000);
    EXPECT_EQ(samples_[0].imu.t_us, 1'000'000);  // SYNC record at offset 0
    EXPECT_EQ(samples_.back().sync, samples_[0].sync + 9);
}

TEST_F(SinkListenerTest, GarbageBetweenPacketsIsCountedAndSkipped) {
    start({});
    auto s = connect();
    std::vector<std::uint8_t> stream = make_packet(1, 0, 0, 2);
    const std::vector<std::uint8_t> junk{'M', 'C', 'A', 'x', 0xFF, 0x00, 'M', 'C', 'A', 'P', 9, 9};
    stream.insert(stream.end(), junk.begin(), junk.end());
    auto p2 = make_packet(1, 1, 1, 2);
    p2[30] ^= 0x5A;  // corrupt a payload byte: CRC failure
    stream.insert(stream.end(), p2.begin(), p2.end());
    auto p3 = make_packet(1, 2, 2, 2);
    stream.insert(stream.end(), p3.begin(), p3.end());
    // Byte by byte, the worst case for an incremental decoder.
    for (std::uint8_t b : stream)
        asio::write(s, asio::buffer(&b, 1));
    ASSERT_TRUE(wait_until([&] { return count() == 4; }));
    EXPECT_TRUE(wait_until([&] { return counter("malformed_packets") >= 2; }));
    EXPECT_GE(counter("crc_failures"), 1u);
    EXPECT_GT(counter("bytes_discarded"), 0u);
    EXPECT_EQ(counter("packets"), 2u);
}

TEST_F(SinkListenerTest, ImplausibleStampsAreCountedAndKeptOutOfLatency) {
    start({});  // the host clock reads 777 µs
    auto s = connect();
    // Above INT64_MAX (a plain cast went negative), 2^63, 31 years ahead, 61 s ahead.
    const std::vector<std::uint64_t> hostile{UINT64_MAX, 1ull << 63, 1'000'000'000'000'000'000ull, 61'000'777ull};
    std::uint32_t seq = 0;
    for (const std::uint64_t stamp : hostile) {
        asio::write(s, asio::buffer(make_packet(1, seq, seq, 1, stamp)));
        ++seq;
    }
    asio::write(s, asio::buffer(make_packet(1, seq, seq, 1, 500'000)));  // 0.5 s off: plausible
    ASSERT_TRUE(wait_until([&] { return count() == hostile.size() + 1; }));
    EXPECT_EQ(counter("implausible_timestamps"), hostile.size());
    std::lock_guard lock(mu_);
    for (std::size_t i = 0; i < hostile.size(); ++i) {
        EXPECT_EQ(samples_[i].times.sink_send_us, 0) << "latency unknown, sample " << i;
        EXPECT_GE(samples_[i].imu.t_us, 0) << "the sink's time saturates, never wraps: sample " << i;
    }
    EXPECT_EQ(samples_[0].imu.t_us, std::numeric_limits<std::int64_t>::max());
    EXPECT_EQ(samples_.back().times.sink_send_us, 500'000);
}

TEST_F(SinkListenerTest, ReconnectTakesOverTheSubject) {
    start({});
    auto a = connect();
    asio::write(a, asio::buffer(make_packet(2, 0, 100, 1)));
    ASSERT_TRUE(wait_until([&] { return count() == 1; }));
    auto b = connect();  // the sink came back; the old socket is still open
    asio::write(b, asio::buffer(make_packet(2, 0, 0, 1)));
    asio::write(b, asio::buffer(make_packet(2, 1, 1, 1)));
    ASSERT_TRUE(wait_until([&] { return count() == 3; }));
    EXPECT_EQ(counter("sink_takeovers"), 1u);
    std::lock_guard lock(mu_);
    EXPECT_GT(samples_[1].sync, samples_[0].sync);
    EXPECT_EQ(samples_[2].sync, samples_[1].sync + 1);
}

TEST_F(SinkListenerTest, SequenceGapsAndUnknownSinksCounted) {
    SinkListenerConfig cfg;
    cfg.max_subjects = 4;
    start(cfg);
    auto s = connect();
    asio::write(s, asio::buffer(make_packet(1, 0, 0, 1)));
    asio::write(s, asio::buffer(make_packet(1, 5, 1, 1)));
    asio::write(s, asio::buffer(make_packet(9, 6, 2, 1)));  // sink id beyond max_subjects
    ASSERT_TRUE(wait_until([&] { return counter("packets") == 3; }));
    EXPECT_EQ(counter("sequence_gaps"), 1u);
    EXPECT_EQ(counter("unknown_sink_packets"), 1u);
    EXPECT_EQ(count(), 2u);
}

TEST_F(SinkListenerTest, SubjectIdIsTheBasePlusTheSinkId) {
    SinkListenerConfig cfg;
    cfg.max_subjects = 4;
    cfg.subject_id_base = 4'000'000'000;
    start(cfg);
    auto s = connect();
    asio::write(s, asio::buffer(make_packet(1, 0, 0, 1)));
    asio::write(s, asio::buffer(make_packet(4, 0, 0, 1)));
    asio::write(s, asio::buffer(make_packet(5, 1, 1, 1)));  // beyond max_subjects: still refused
    ASSERT_TRUE(wait_until([&] { return counter("packets") == 3; }));
    EXPECT_EQ(counter("unknown_sink_packets"), 1u);
    ASSERT_TRUE(wait_until([&] { return count() == 2; }));
    std::lock_guard lock(mu_);
    EXPECT_EQ(samples_[0].subject_id, 4'000'000'001u);
    EXPECT_EQ(samples_[1].subject_id, 4'000'000'004u);
}

TEST_F(SinkListenerTest, IdleAndGarbageOnlyConnectionsAreClosed) {
    SinkListenerConfig cfg;
    cfg.idle_timeout_s = 0.1;
    cfg.max_garbage_bytes = 4096;
    start(cfg);
    auto idle = connect();
    auto noisy = connect();
    std::vector<std::uint8_t> junk(8192, 0xAB);
    asio::write(noisy, asio::buffer(junk));
    EXPECT_TRUE(wait_until([&] { return counter("idle_timeouts") >= 1; }));
    EXPECT_TRUE(wait_until([&] { return counter("garbage_closes") == 1; }));
    // Both sockets see the server close them (after the keepalives it sent meanwhile).
    EXPECT_TRUE(closed_by_server(idle));
}

TEST_F(SinkListenerTest, MaxSinksRefusesExtraConnections) {
    SinkListenerConfig cfg;
    cfg.max_sinks = 1;
    start(cfg);
    auto a = connect();
    asio::write(a, asio::buffer(make_packet(1, 0, 0, 1)));
    ASSERT_TRUE(wait_until([&] { return count() == 1; }));
    auto b = connect();
    EXPECT_TRUE(closed_by_server(b));
    EXPECT_EQ(counter("connections_refused"), 1u);
}

TEST_F(SinkListenerTest, EveryConnectionGetsKeepalivesAtTheirPeriod) {
    SinkListenerConfig cfg;
    cfg.keepalive_period_ms = 40;
    start(cfg);
    auto s = connect();
    // The first at once, then one per period: 5 within generous time, numbered from 0.
    std::vector<std::uint8_t> bytes(5 * MW_KEEPALIVE_SIZE);
    const auto t0 = std::chrono::steady_clock::now();
    asio::read(s, asio::buffer(bytes));
    const auto elapsed = std::chrono::steady_clock::now() - t0;
    EXPECT_GE(elapsed, 4 * 40ms - 10ms) << "one per period, not a burst";
    mw_keepalive_decoder d;
    mw_keepalive_decoder_init(&d);
    std::vector<mw_keepalive> got;
    const std::uint8_t* p = bytes.data();
    std::size_t left = bytes.size();
    for (;;) {
        std::size_t used = 0;
        mw_keepalive k{};
        const mw_stream_result r = mw_keepalive_decoder_feed(&d, p, left, &used, &k);
        p += used;
        left -= used;
        if (r == MW_STREAM_NEED_MORE) break;
        ASSERT_EQ(r, MW_STREAM_PACKET) << mw_error_name(d.last_error);
        got.push_back(k);
    }
    ASSERT_EQ(got.size(), 5u);
    for (std::uint32_t i = 0; i < 5; ++i) {
        EXPECT_EQ(got[i].sequence, i);
        EXPECT_EQ(got[i].period_ms, 40);
    }
    EXPECT_TRUE(wait_until([&] { return counter("keepalives_sent") >= 5; }));
}

TEST_F(SinkListenerTest, ASinkThatNeverReadsKeepsStreamingAndCostsNoMemory) {
    SinkListenerConfig cfg;
    cfg.keepalive_period_ms = 1;  // fills the socket buffers within a second
    start(cfg);
    tcp::socket s(client_io_);
    s.open(tcp::v4());
    s.set_option(asio::socket_base::receive_buffer_size(1024));
    s.connect({asio::ip::make_address("127.0.0.1"), listener_->port()});
    // Never read: the host's writes back up and it skips ticks instead of queueing them.
    ASSERT_TRUE(wait_until([&] { return counter("keepalives_skipped") >= 100; }, 20s))
        << "sent " << counter("keepalives_sent");
    const std::uint64_t sent = counter("keepalives_sent");
    for (std::uint32_t c = 0; c < 50; ++c)
        asio::write(s, asio::buffer(make_packet(2, c, c, 15)));
    ASSERT_TRUE(wait_until([&] { return count() == 50u * 15u; }, 10s)) << "packets still flow: " << count();
    // What went out is what the two kernels' socket buffers hold (the daemon's send buffer
    // is 4 KiB), not a queue in the daemon; the rest of the ticks were skipped.
    const std::uint64_t skipped = counter("keepalives_skipped");
    EXPECT_TRUE(wait_until([&] { return counter("keepalives_skipped") > skipped + 50; }, 10s));
    EXPECT_LE(counter("keepalives_sent") * MW_KEEPALIVE_SIZE, 64u * 1024u) << "first stall after " << sent;
    EXPECT_EQ(counter("malformed_packets"), 0u);
}

TEST_F(SinkListenerTest, KeepalivesCanBeTurnedOff) {
    SinkListenerConfig cfg;
    cfg.keepalive_period_ms = 0;
    start(cfg);
    auto s = connect();
    asio::write(s, asio::buffer(make_packet(1, 0, 0, 1)));
    ASSERT_TRUE(wait_until([&] { return count() == 1; }));
    s.non_blocking(true);
    std::array<std::uint8_t, 16> b{};
    boost::system::error_code ec;
    EXPECT_EQ(s.read_some(asio::buffer(b), ec), 0u);
    EXPECT_EQ(ec, asio::error::would_block) << "stream version 1: the host sends nothing";
    EXPECT_EQ(counter("keepalives_sent"), 0u);
}

}  // namespace
}  // namespace mocap::ingest
