// Sink-node core against a fake CAN bus with simulated sensor nodes and a fake uplink; what
// reaches the uplink is decoded with the wire library's stream decoder.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <deque>
#include <memory>
#include <set>
#include <vector>

#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"
#include "sink_node/sink_node.h"

namespace mocap::test {
namespace {

struct fake_sink_hal {
    uint64_t now_us = 5'000'000;
    // CAN
    std::deque<mw_can_frame> rx;
    std::vector<std::pair<uint64_t, mw_can_frame>> tx;  // (time accepted, frame)
    bool can_busy = false;
    std::set<uint8_t> nodes;  // simulated nodes answering SYNC
    // uplink
    bool server_up = true;
    bool connect_completes = true;  // false: stays CONNECTING
    int busy_writes = 0;            // refuse this many writes as busy
    sink_uplink_state state = SINK_UPLINK_DOWN;
    std::vector<uint64_t> connect_times;
    int closes = 0;
    std::vector<std::vector<uint8_t>> connections;  // bytes written, per connection
    std::vector<uint8_t> connect_hosts;             // host index of every attempt
    std::set<uint8_t> dead_hosts;                   // attempts to these fail at once
    std::vector<uint8_t> inbox;                     // host -> sink bytes not yet read
    uint32_t keepalive_sequence = 0;
    uint16_t keepalive_period_ms = 250;  // what the host announces

    // The connected host sends one keepalive (docs/protocol.md §3.5).
    void host_keepalive() {
        const mw_keepalive k{keepalive_period_ms, keepalive_sequence++};
        uint8_t b[MW_KEEPALIVE_SIZE];
        ASSERT_EQ(mw_keepalive_encode(&k, b, sizeof b), static_cast<int32_t>(MW_KEEPALIVE_SIZE));
        inbox.insert(inbox.end(), b, b + sizeof b);
    }

    sink_node_hal hal() {
        sink_node_hal h{};
        h.user = this;
        h.can_transmit = [](void* u, const mw_can_frame* f) {
            auto* self = static_cast<fake_sink_hal*>(u);
            if (self->can_busy) {
                return 1;
            }
            self->tx.emplace_back(self->now_us, *f);
            self->answer(*f);
            return 0;
        };
        h.can_receive = [](void* u, mw_can_frame* f) {
            auto* self = static_cast<fake_sink_hal*>(u);
            if (self->rx.empty()) {
                return 0;
            }
            *f = self->rx.front();
            self->rx.pop_front();
            return 1;
        };
        h.time_us = [](void* u) { return static_cast<fake_sink_hal*>(u)->now_us; };
        h.uplink_connect = [](void* u, uint8_t host) {
            auto* self = static_cast<fake_sink_hal*>(u);
            self->connect_times.push_back(self->now_us);
            self->connect_hosts.push_back(host);
            self->inbox.clear();
            self->keepalive_sequence = 0;
            if (!self->server_up || self->dead_hosts.count(host) != 0) {
                return -1;
            }
            self->state = self->connect_completes ? SINK_UPLINK_UP : SINK_UPLINK_CONNECTING;
            if (self->state == SINK_UPLINK_UP) {
                self->connections.emplace_back();
            }
            return 0;
        };
        h.uplink_state = [](void* u) { return static_cast<fake_sink_hal*>(u)->state; };
        h.uplink_write = [](void* u, const uint8_t* d, size_t n) {
            auto* self = static_cast<fake_sink_hal*>(u);
            if (self->state != SINK_UPLINK_UP) {
                return -1;
            }
            if (self->busy_writes > 0) {
                --self->busy_writes;
                return 1;
            }
            self->connections.back().insert(self->connections.back().end(), d, d + n);
            return 0;
        };
        h.uplink_read = [](void* u, uint8_t* d, size_t cap) {
            auto* self = static_cast<fake_sink_hal*>(u);
            if (self->state != SINK_UPLINK_UP) {
                return -1;
            }
            const size_t n = std::min(cap, self->inbox.size());
            std::copy(self->inbox.begin(), self->inbox.begin() + static_cast<std::ptrdiff_t>(n), d);
            self->inbox.erase(self->inbox.begin(), self->inbox.begin() + static_cast<std::ptrdiff_t>(n));
            return static_cast<int>(n);
        };
        h.uplink_close = [](void* u) {
            auto* self = static_cast<fake_sink_hal*>(u);
            ++self->closes;
            self->state = SINK_UPLINK_DOWN;
        };
        return h;
    }

    // Every simulated node answers a SYNC with ACCEL, GYRO, MAG tagged with the counter.
    void answer(const mw_can_frame& f) {
        mw_sync sync{};
        if (f.id != MW_CAN_ID_SYNC || mw_sync_decode(&f, &sync) != MW_OK) {
            return;
        }
        for (uint8_t node : nodes) {
            for (mw_function kind : {MW_FN_ACCEL, MW_FN_GYRO, MW_FN_MAG}) {
                mw_raw raw{kind,
                           node,
                           {static_cast<int16_t>(node), static_cast<int16_t>(kind), 7},
                           static_cast<uint16_t>(sync.counter)};
                mw_can_frame out{};
                EXPECT_EQ(mw_raw_encode(&raw, &out), MW_OK);
                rx.push_back(out);
            }
        }
    }

    std::vector<uint32_t> sync_counters() const {
        std::vector<uint32_t> out;
        for (const auto& [t, f] : tx) {
            mw_sync s{};
            if (f.id == MW_CAN_ID_SYNC && mw_sync_decode(&f, &s) == MW_OK) {
                out.push_back(s.counter);
            }
        }
        return out;
    }
};

std::vector<std::unique_ptr<mw_packet>> decode_all(const std::vector<uint8_t>& bytes) {
    auto decoder = std::make_unique<mw_stream_decoder>();
    mw_stream_decoder_init(decoder.get());
    std::vector<std::unique_ptr<mw_packet>> out;
    const uint8_t* p = bytes.data();
    size_t n = bytes.size();
    for (;;) {
        auto pkt = std::make_unique<mw_packet>();
        size_t used = 0;
        const mw_stream_result r = mw_stream_decoder_feed(decoder.get(), p, n, &used, pkt.get());
        p += used;
        n -= used;
        if (r == MW_STREAM_NEED_MORE) {
            break;
        }
        EXPECT_EQ(r, MW_STREAM_PACKET) << "malformed: " << mw_error_name(decoder->last_error);
        if (r == MW_STREAM_PACKET) {
            out.push_back(std::move(pkt));
        }
    }
    EXPECT_EQ(decoder->counters.bytes_discarded, 0u);
    EXPECT_EQ(mw_stream_decoder_buffered(decoder.get()), 0u) << "a packet was cut";
    return out;
}

class SinkNodeTest : public ::testing::Test {
protected:
    fake_sink_hal fake;
    std::unique_ptr<sink_node> sink = std::make_unique<sink_node>();
    sink_node_config config{};

    SinkNodeTest() {
        sink_node_default_config(&config);
        config.sink_id = 3;
        config.status_period_s = 0;
        config.config_period_s = 0;
        config.early_close = 0;  // the tests below that want it turn it on
    }

    void start() {
        const sink_node_hal h = fake.hal();
        ASSERT_EQ(sink_node_init(sink.get(), &h, &config), MW_OK);
    }

    // Polls every step_us for duration_us (the first poll at the current time).
    void run(uint64_t duration_us, uint64_t step_us = 1000) {
        const uint64_t end = fake.now_us + duration_us;
        while (fake.now_us < end) {
            sink_node_poll(sink.get());
            fake.now_us += step_us;
        }
    }

    // The same, while the connected host sends a keepalive every period it announces.
    void run_with_keepalives(uint64_t duration_us) {
        const uint64_t end = fake.now_us + duration_us;
        uint64_t next = fake.now_us;
        while (fake.now_us < end) {
            if (fake.now_us >= next && fake.state == SINK_UPLINK_UP) {
                fake.host_keepalive();
                next = fake.now_us + uint64_t{fake.keepalive_period_ms} * 1000u;
            }
            sink_node_poll(sink.get());
            fake.now_us += 1000;
        }
    }
};

TEST_F(SinkNodeTest, SyncScheduleFollowsRateWithoutDrift) {
    config.rate_hz = 120;  // 8333.3 us: rounding a period would drift
    config.first_counter = 1000;
    start();
    const uint64_t t0 = fake.now_us;
    run(1'000'000, 100);
    const auto counters = fake.sync_counters();
    ASSERT_EQ(counters.size(), 120u);
    std::size_t k = 0;
    for (const auto& [t, f] : fake.tx) {
        if (f.id != MW_CAN_ID_SYNC) {
            continue;
        }
        const uint64_t due = t0 + k * 1'000'000 / 120;
        EXPECT_GE(t, due) << k;
        EXPECT_LT(t, due + 100) << k;
        EXPECT_EQ(counters[k], 1000u + k);
        ++k;
    }
    EXPECT_EQ(sink->counters.syncs_sent, 120u);
    EXPECT_EQ(sink->counters.syncs_skipped, 0u);
}

TEST_F(SinkNodeTest, StalledLoopSkipsInstantsInsteadOfBursting) {
    start();
    sink_node_poll(sink.get());  // SYNC 0
    fake.now_us += 35'000;       // instants 1, 2, 3 are due; 1 and 2 are lost
    sink_node_poll(sink.get());
    EXPECT_EQ(fake.sync_counters(), (std::vector<uint32_t>{0, 1}));
    EXPECT_EQ(sink->counters.syncs_skipped, 2u);
    fake.now_us += 5'000;  // 40 ms: instant 4
    sink_node_poll(sink.get());
    EXPECT_EQ(fake.sync_counters().size(), 3u);
}

TEST_F(SinkNodeTest, OnePacketPerSyncInstantWithItsFrames) {
    fake.nodes = {1, 2};
    start();
    const uint64_t t0 = fake.now_us;
    run(50'000);  // SYNC 0..4; batches 0..3 closed
    ASSERT_EQ(fake.connections.size(), 1u);
    const auto packets = decode_all(fake.connections[0]);
    ASSERT_EQ(packets.size(), 4u);
    for (std::size_t n = 0; n < packets.size(); ++n) {
        const mw_packet& p = *packets[n];
        EXPECT_EQ(p.header.sink_id, 3);
        EXPECT_EQ(p.header.sequence, n);
        EXPECT_EQ(p.header.timestamp_us, t0 + n * 10'000);
        ASSERT_EQ(p.frame_count, 7u) << "SYNC + 2 nodes x 3 frames";
        mw_sync sync{};
        ASSERT_EQ(mw_sync_decode(&p.frames[0].frame, &sync), MW_OK);
        EXPECT_EQ(sync.counter, n);
        EXPECT_EQ(p.frames[0].offset_us, 0u);
        for (std::size_t i = 1; i < 7; ++i) {
            mw_raw raw{};
            ASSERT_EQ(mw_raw_decode(&p.frames[i].frame, &raw), MW_OK);
            EXPECT_EQ(raw.counter_low, n);
            EXPECT_EQ(raw.node_id, i <= 3 ? 1 : 2);
            EXPECT_EQ(p.frames[i].offset_us, 1000u) << "received at the next poll, 1 ms later";
        }
    }
    // The bytes are exactly what the wire encoder makes of the same content.
    std::vector<uint8_t> expected(MW_PACKET_MAX_SIZE);
    const int32_t len = mw_packet_encode(&packets[1]->header, packets[1]->frames, packets[1]->frame_count,
                                         expected.data(), expected.size());
    ASSERT_GT(len, 0);
    const std::size_t first_len = mw_packet_size(packets[0]->frames, packets[0]->frame_count);
    ASSERT_GE(fake.connections[0].size(), first_len + static_cast<std::size_t>(len));
    EXPECT_EQ(0, std::memcmp(fake.connections[0].data() + first_len, expected.data(), static_cast<std::size_t>(len)));
    EXPECT_EQ(sink->counters.frames_in, 5u * 6u);
    EXPECT_EQ(sink->counters.packets_out, 4u);
}

TEST_F(SinkNodeTest, NodeLossLeavesItsFramesOutButPacketsContinue) {
    fake.nodes = {1, 2, 3};
    start();
    run(20'000);  // instants 0, 1 with all nodes
    fake.nodes = {1, 3};
    run(30'000);  // instants 2..4 without node 2
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 4u);
    EXPECT_EQ(packets[0]->frame_count, 10u);
    EXPECT_EQ(packets[1]->frame_count, 10u);
    for (std::size_t n = 2; n < packets.size(); ++n) {
        ASSERT_EQ(packets[n]->frame_count, 7u) << n;
        for (std::size_t i = 1; i < packets[n]->frame_count; ++i) {
            EXPECT_NE(mw_can_id_node(packets[n]->frames[i].frame.id), 2u);
        }
    }
}

TEST_F(SinkNodeTest, EarlyCloseSendsThePacketAsSoonAsEveryNodeDelivered) {
    fake.nodes = {1, 2};
    config.early_close = 1;
    start();
    const uint64_t t0 = fake.now_us;
    run(11'000);  // polls at 0..10 ms: SYNC 0, its frames at 1 ms, SYNC 1 at 10 ms closes instant 0
    EXPECT_EQ(decode_all(fake.connections.at(0)).size(), 1u) << "nothing learnt yet: closed by SYNC 1";
    run(1'000);  // 11 ms: instant 1's six frames arrive; the count of instant 0 says it is complete
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 2u) << "instant 1 left 1 ms after its SYNC, not at SYNC 2";
    EXPECT_EQ(packets[1]->header.timestamp_us, t0 + 10'000);
    EXPECT_EQ(packets[1]->frame_count, 7u);
    EXPECT_EQ(mw_can_id_function(packets[1]->frames[0].frame.id), MW_FN_SYNC);
    EXPECT_EQ(sink->counters.early_closes, 1u);
    run(8'000);  // up to 19 ms: no SYNC yet, no further packet (no empty continuation)
    EXPECT_EQ(decode_all(fake.connections.at(0)).size(), 2u);
    run(2'000);  // SYNC 2 at 20 ms, its frames at 21 ms
    EXPECT_EQ(decode_all(fake.connections.at(0)).size(), 3u);
    EXPECT_EQ(sink->counters.early_closes, 2u);
}

TEST_F(SinkNodeTest, EarlyCloseWithNodeLossDeliversAtTheNextSyncThenLearns) {
    fake.nodes = {1, 2, 3};
    config.early_close = 1;
    start();
    run(20'000);          // instants 0 (closed by SYNC 1) and 1 (early, 9 frames)
    fake.nodes = {1, 3};  // node 2 falls silent from instant 2 on
    run(10'000);          // SYNC 2 at 20 ms, 6 frames at 21 ms: short of 9, so it waits
    EXPECT_EQ(decode_all(fake.connections.at(0)).size(), 2u);
    run(2'000);  // 31 ms: SYNC 3 at 30 ms closed instant 2; instant 3 learnt 6
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 4u);
    EXPECT_EQ(packets[2]->frame_count, 7u);
    mw_sync sync{};
    ASSERT_EQ(mw_sync_decode(&packets[2]->frames[0].frame, &sync), MW_OK);
    EXPECT_EQ(sync.counter, 2u);
    ASSERT_EQ(mw_sync_decode(&packets[3]->frames[0].frame, &sync), MW_OK);
    EXPECT_EQ(sync.counter, 3u) << "instant 3 closed early with the learnt count";
    EXPECT_EQ(sink->counters.early_closes, 2u);
}

TEST_F(SinkNodeTest, EarlyCloseReturningNodeGoesIntoAContinuation) {
    fake.nodes = {1, 3};
    config.early_close = 1;
    start();
    run(20'000);  // instant 0 (SYNC close), instant 1 early with 6 frames
    fake.nodes = {1, 2, 3};
    run(20'000);  // instant 2: closes after 6 frames, node 3's three follow in a
                  // continuation closed by SYNC 3; instant 3 learnt 9 and closes early
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 5u);
    EXPECT_EQ(packets[2]->frame_count, 7u);
    EXPECT_EQ(packets[3]->frame_count, 3u);
    EXPECT_EQ(packets[3]->header.timestamp_us, packets[2]->header.timestamp_us);
    EXPECT_EQ(packets[3]->frames[0].frame.id, MW_CAN_ID(MW_FN_ACCEL, 3)) << "no SYNC record";
    EXPECT_EQ(packets[4]->frame_count, 10u);
    EXPECT_EQ(sink->counters.early_closes, 3u);
    EXPECT_EQ(sink->counters.frames_in, 6u + 6u + 9u + 9u);
}

TEST_F(SinkNodeTest, EarlyCloseIgnoresStatusFrames) {
    fake.nodes = {1};
    config.early_close = 1;
    start();
    run(20'000);  // instants 0 and 1 (early, 3 frames)
    mw_status status{};
    status.node_id = 1;
    status.state = MW_NODE_RUNNING;
    status.accel_range = MW_ACCEL_16G;
    status.gyro_range = MW_GYRO_2000DPS;
    status.protocol_version = MW_CAN_PROTOCOL_VERSION;
    mw_can_frame f{};
    ASSERT_EQ(mw_status_encode(&status, &f), MW_OK);
    fake.rx.push_back(f);  // a node STATUS during instant 1's remainder
    run(12'000);           // instants 2 and 3 still close early: STATUS is not a sample
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 5u) << "0, 1, STATUS continuation of 1, 2, 3";
    EXPECT_EQ(packets[2]->frame_count, 1u);
    EXPECT_EQ(mw_can_id_function(packets[2]->frames[0].frame.id), MW_FN_STATUS);
    EXPECT_EQ(sink->counters.early_closes, 3u);
}

TEST_F(SinkNodeTest, SyncCounterWrapsAt32Bits) {
    fake.nodes = {4};
    config.first_counter = 0xFFFFFFFEu;
    start();
    run(50'000);
    EXPECT_EQ(fake.sync_counters(), (std::vector<uint32_t>{0xFFFFFFFEu, 0xFFFFFFFFu, 0u, 1u, 2u}));
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 4u);
    const uint32_t expected[4] = {0xFFFFFFFEu, 0xFFFFFFFFu, 0u, 1u};
    for (std::size_t n = 0; n < 4; ++n) {
        mw_sync sync{};
        ASSERT_EQ(mw_sync_decode(&packets[n]->frames[0].frame, &sync), MW_OK);
        EXPECT_EQ(sync.counter, expected[n]);
        mw_raw raw{};
        ASSERT_EQ(mw_raw_decode(&packets[n]->frames[1].frame, &raw), MW_OK);
        EXPECT_EQ(raw.counter_low, static_cast<uint16_t>(expected[n]));
        EXPECT_EQ(mw_counter_extend(sync.counter, raw.counter_low, MW_RAW_COUNTER_BITS), expected[n]);
    }
}

TEST_F(SinkNodeTest, UplinkDropBacksOffExponentiallyThenReconnects) {
    fake.nodes = {1};
    config.backoff_min_us = 100'000;
    config.backoff_max_us = 800'000;
    start();
    run(100'000);
    ASSERT_EQ(fake.connect_times.size(), 1u);
    // The peer drops the connection and the server stays away for a while.
    fake.state = SINK_UPLINK_DOWN;
    fake.server_up = false;
    const uint64_t t_drop = fake.now_us;
    run(3'000'000);
    // Attempts at +100, +300, +700, +1500, +2300 ms (delay doubles, capped at 800 ms).
    const std::vector<uint64_t> expected{t_drop + 100'000, t_drop + 300'000, t_drop + 700'000, t_drop + 1'500'000,
                                         t_drop + 2'300'000};
    ASSERT_EQ(fake.connect_times.size(), 1u + expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
        EXPECT_EQ(fake.connect_times[i + 1], expected[i]) << "attempt " << i;
    }
    EXPECT_EQ(sink->counters.disconnects, 1u);
    EXPECT_EQ(sink->counters.connect_failures, 5u);
    EXPECT_EQ(sink->counters.packets_dropped, 300u) << "one per instant while down";
    EXPECT_EQ(sink->counters.frames_dropped, 900u);

    fake.server_up = true;  // next attempt at +3100 ms succeeds
    run(300'000);
    ASSERT_EQ(fake.connect_times.size(), 7u);
    EXPECT_EQ(fake.connect_times.back(), t_drop + 3'100'000);
    EXPECT_EQ(sink->counters.reconnects, 1u);
    EXPECT_EQ(sink->counters.connects, 2u);
    ASSERT_EQ(fake.connections.size(), 2u);
    const auto packets = decode_all(fake.connections[1]);
    ASSERT_FALSE(packets.empty());
    EXPECT_EQ(packets.front()->header.sequence, 0u) << "the sequence is per connection";
    EXPECT_EQ(packets.back()->header.sequence, packets.size() - 1);

    // After a good connection the back-off starts again from the minimum.
    fake.state = SINK_UPLINK_DOWN;
    const uint64_t t_drop2 = fake.now_us;
    run(150'000);
    EXPECT_EQ(fake.connect_times.back(), t_drop2 + 100'000);
}

TEST_F(SinkNodeTest, ALostConnectionMovesToTheNextHostOfTheList) {
    config.host_count = 3;
    start();
    run(50'000);
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0}));
    fake.state = SINK_UPLINK_DOWN;  // host 0 resets the connection
    const uint64_t t_drop = fake.now_us;
    run(200'000);
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0, 1}));
    EXPECT_EQ(fake.connect_times[1], t_drop + 100'000) << "the next host after the minimum back-off";
    EXPECT_EQ(sink->counters.host_switches, 1u);
    fake.state = SINK_UPLINK_DOWN;
    run(200'000);
    fake.state = SINK_UPLINK_DOWN;
    run(1'200'000);
    EXPECT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0, 1, 2, 0})) << "wraps to the first";
    EXPECT_EQ(sink->counters.connects, 4u);
    EXPECT_EQ(fake.connections.size(), 4u);
    EXPECT_FALSE(decode_all(fake.connections.back()).empty()) << "packets flow to the new host";
}

TEST_F(SinkNodeTest, DeadHostsAreTriedInTurnAtMostOncePerSecondEach) {
    config.host_count = 3;
    config.backoff_min_us = 100'000;
    config.backoff_max_us = 400'000;
    fake.dead_hosts = {0, 1, 2};
    start();
    run(10'000'000);
    ASSERT_GE(fake.connect_hosts.size(), 9u);
    std::vector<uint64_t> last(3, 0);
    std::vector<bool> seen(3, false);
    for (std::size_t i = 0; i < fake.connect_hosts.size(); ++i) {
        const uint8_t h = fake.connect_hosts[i];
        EXPECT_EQ(h, i % 3) << "in list order, wrapping";
        if (seen[h]) {
            EXPECT_GE(fake.connect_times[i] - last[h], 1'000'000u) << "host " << int(h) << " attempt " << i;
        }
        seen[h] = true;
        last[h] = fake.connect_times[i];
    }
    // Host 1 is tried 100 ms after host 0 failed: one dead host does not delay the next.
    EXPECT_EQ(fake.connect_times[1] - fake.connect_times[0], 100'000u);
    fake.dead_hosts = {0, 2};
    run(2'000'000);
    EXPECT_EQ(sink->link, SINK_UPLINK_UP);
    EXPECT_EQ(fake.connect_hosts.back(), 1);
}

TEST_F(SinkNodeTest, ASilentHostIsLeftWithinItsKeepaliveTimeout) {
    config.host_count = 2;
    start();
    run_with_keepalives(1'000'000);
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0}));
    EXPECT_GE(sink->counters.keepalives_in, 4u);
    // Host 0 freezes: the connection stays up, nothing more arrives.
    const uint64_t last_keepalive = sink->last_keepalive_us;
    run(1'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 1u);
    EXPECT_EQ(fake.closes, 1);
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0, 1}));
    // Time-out after 750 ms of silence (+1 poll), then the next host after 100 ms.
    EXPECT_LE(fake.connect_times[1] - last_keepalive, 750'000u + 1'000u + 100'000u);
    EXPECT_GT(fake.connect_times[1] - last_keepalive, 750'000u);
    run_with_keepalives(2'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 1u) << "host 1 is alive";
    EXPECT_FALSE(decode_all(fake.connections.back()).empty());
}

TEST_F(SinkNodeTest, AHostWithASlowerKeepaliveIsGivenThreeOfItsPeriods) {
    // A host configured for a 1 s keepalive ([ingest] keepalive_period_s) says so in every
    // keepalive: the sink's 750 ms time-out stretches to three announced periods.
    config.host_count = 2;
    fake.keepalive_period_ms = 1000;
    start();
    run_with_keepalives(5'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 0u) << "1 s between keepalives is not silence";
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0}));
    const uint64_t last_keepalive = sink->last_keepalive_us;
    for (int ms = 0; ms < 5000 && fake.connect_hosts.size() < 2; ++ms)
        run(1'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 1u);
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0, 1}));
    EXPECT_GT(fake.connect_times[1] - last_keepalive, 3'000'000u);
    EXPECT_LE(fake.connect_times[1] - last_keepalive, 3'000'000u + 1'000u + 100'000u);
    // Host 1 accepts and stays silent: its connection gets the sink's own 750 ms, not host
    // 0's three seconds.
    for (int ms = 0; ms < 5000 && fake.connect_hosts.size() < 3; ++ms)
        run(1'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 2u);
    ASSERT_EQ(fake.connect_hosts.size(), 3u);
    EXPECT_LE(fake.connect_times[2] - fake.connect_times[1], 750'000u + 2'000u + 100'000u);
}

TEST_F(SinkNodeTest, AnAnnouncedPeriodStretchesTheTimeoutToOneMinuteAtMost) {
    config.host_count = 2;
    fake.keepalive_period_ms = 65535;  // the most the field holds: 196 s if taken as is
    start();
    run_with_keepalives(1'000'000);
    const uint64_t last_keepalive = sink->last_keepalive_us;
    run(181'000'000);
    ASSERT_GE(sink->counters.keepalive_timeouts, 1u);
    ASSERT_GE(fake.connect_times.size(), 2u);
    EXPECT_GT(fake.connect_times[1] - last_keepalive, 180'000'000u) << "three periods of 60 s";
    EXPECT_LE(fake.connect_times[1] - last_keepalive, 180'000'000u + 1'000u + 100'000u);
}

TEST_F(SinkNodeTest, AHostThatNeverSentAKeepaliveIsNeverTimedOut) {
    // Stream version 1 hosts send nothing: the sink must not take them for dead.
    config.host_count = 2;
    start();
    run(5'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 0u);
    EXPECT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0}));
    // Bytes that are no keepalive do not arm it either.
    fake.inbox.assign(64, 0x55);
    run(2'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 0u);
    EXPECT_EQ(sink->counters.keepalives_in, 0u);
}

TEST_F(SinkNodeTest, OnceKeepalivesWereHeardANewSilentConnectionIsAbandoned) {
    // A frozen host's kernel still completes the TCP handshake: the new connection is up
    // but silent, and must not hold the sink.
    config.host_count = 2;
    start();
    run_with_keepalives(600'000);
    fake.state = SINK_UPLINK_DOWN;  // host 0 goes away
    run(300'000);                   // host 1 accepts but never sends a keepalive
    ASSERT_EQ(fake.connect_hosts, (std::vector<uint8_t>{0, 1}));
    const uint64_t t_connect = fake.connect_times[1];
    run(1'000'000);
    EXPECT_EQ(sink->counters.keepalive_timeouts, 1u);
    ASSERT_EQ(fake.connect_hosts.size(), 3u);
    EXPECT_EQ(fake.connect_hosts[2], 0);
    // 750 ms of silence, then host 0 again (its last attempt was over a second ago).
    EXPECT_EQ(fake.connect_times[2] - t_connect, 751'000u + 100'000u);
}

TEST_F(SinkNodeTest, WriteErrorClosesAndRetries) {
    start();
    run(30'000);
    fake.connections.back().clear();
    // The write fails (the link died between polls without the state showing it yet).
    sink_node_hal h = fake.hal();
    h.uplink_write = [](void*, const uint8_t*, size_t) { return -1; };
    sink->hal = h;
    run(10'000);
    EXPECT_EQ(fake.closes, 1);
    EXPECT_EQ(sink->counters.disconnects, 1u);
    EXPECT_EQ(fake.connect_times.size(), 1u);
    sink->hal = fake.hal();
    run(100'000);
    EXPECT_EQ(fake.connect_times.size(), 2u);
    EXPECT_EQ(sink->counters.reconnects, 1u);
}

TEST_F(SinkNodeTest, ConnectAttemptTimesOut) {
    config.connect_timeout_us = 2'000'000;
    config.backoff_min_us = 500'000;
    fake.connect_completes = false;
    const uint64_t t0 = fake.now_us;
    start();
    run(2'600'000);
    ASSERT_EQ(fake.connect_times.size(), 2u);
    EXPECT_EQ(fake.connect_times[0], t0);
    EXPECT_EQ(fake.closes, 1);
    // Closed 1 ms after the 2 s time-out, retried 500 ms later.
    EXPECT_EQ(fake.connect_times[1], t0 + 2'001'000 + 500'000);
    EXPECT_EQ(sink->counters.connect_failures, 1u);
}

TEST_F(SinkNodeTest, BusyUplinkDropsPacketAndLeavesSequenceGap) {
    fake.nodes = {1};
    start();
    run(20'000);
    fake.busy_writes = 1;
    run(30'000);
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 3u);
    EXPECT_EQ(packets[0]->header.sequence, 0u);
    EXPECT_EQ(packets[1]->header.sequence, 2u);
    EXPECT_EQ(packets[2]->header.sequence, 3u);
    EXPECT_EQ(sink->counters.packets_busy, 1u);
    EXPECT_EQ(sink->counters.frames_dropped, 3u);
}

TEST_F(SinkNodeTest, FullBatchIsSplitWithTheSameTimestamp) {
    fake.nodes = {1, 2};
    config.max_batch_frames = 4;
    start();
    run(20'000);
    const auto packets = decode_all(fake.connections.at(0));
    // Instant 0 (SYNC + 6 frames) closes as 4 + 3 at SYNC 1; instant 1's first 4 follow.
    ASSERT_EQ(packets.size(), 3u);
    EXPECT_EQ(mw_can_id_function(packets[2]->frames[0].frame.id), MW_FN_SYNC);
    EXPECT_EQ(packets[2]->header.timestamp_us, packets[0]->header.timestamp_us + 10'000);
    EXPECT_EQ(packets[0]->frame_count, 4u);
    EXPECT_EQ(packets[1]->frame_count, 3u);
    EXPECT_EQ(packets[0]->header.timestamp_us, packets[1]->header.timestamp_us);
    EXPECT_EQ(packets[1]->header.sequence, 1u);
    // SYNC + node 1's three frames, then node 2's from its ACCEL on, without a SYNC record.
    EXPECT_EQ(packets[1]->frames[0].frame.id, MW_CAN_ID(MW_FN_ACCEL, 2));
    EXPECT_EQ(sink->counters.batch_splits, 2u);
}

TEST_F(SinkNodeTest, ConfigBroadcastAndSinkStatus) {
    config.config_period_s = 2;
    config.status_period_s = 1;
    config.node_config.accel_range = MW_ACCEL_8G;
    config.node_config.rate_hz = 200;
    config.rate_hz = 200;
    start();
    run(4'500'000);
    std::vector<mw_config> configs;
    for (const auto& [t, f] : fake.tx) {
        if (mw_can_id_function(f.id) == MW_FN_CONFIG) {
            mw_config c{};
            ASSERT_EQ(mw_config_decode(&f, &c), MW_OK);
            configs.push_back(c);
        }
    }
    ASSERT_EQ(configs.size(), 3u) << "at 0, 2 and 4 s";
    EXPECT_EQ(configs[0].node_id, MW_NODE_ID_BROADCAST);
    EXPECT_EQ(configs[0].accel_range, MW_ACCEL_8G);
    EXPECT_EQ(configs[0].rate_hz, 200);

    std::vector<mw_status> statuses;
    for (const auto& p : decode_all(fake.connections.at(0))) {
        for (std::size_t i = 0; i < p->frame_count; ++i) {
            if (mw_can_id_function(p->frames[i].frame.id) == MW_FN_STATUS) {
                mw_status s{};
                ASSERT_EQ(mw_status_decode(&p->frames[i].frame, &s), MW_OK);
                statuses.push_back(s);
            }
        }
    }
    ASSERT_EQ(statuses.size(), 5u) << "at 0..4 s";
    EXPECT_EQ(statuses[0].node_id, MW_NODE_ID_SINK);
    EXPECT_TRUE(statuses[0].error_flags & MW_ERRF_RESET);
    EXPECT_EQ(statuses[3].uptime_s, 3);
    EXPECT_EQ(statuses[3].state, MW_NODE_RUNNING);
}

TEST_F(SinkNodeTest, LateFrameAtLowRateStartsAPacketWithinOffsetRange) {
    config.rate_hz = 5;  // 200 ms between SYNCs
    start();
    sink_node_poll(sink.get());  // SYNC 0 at t0
    const uint64_t t0 = fake.now_us;
    mw_raw raw{MW_FN_ACCEL, 1, {1, 2, 3}, 0};
    mw_can_frame f{};
    ASSERT_EQ(mw_raw_encode(&raw, &f), MW_OK);
    fake.now_us = t0 + 40'000;
    fake.rx.push_back(f);
    sink_node_poll(sink.get());
    fake.now_us = t0 + 120'000;  // offset 120 ms does not fit 16 bits of microseconds
    fake.rx.push_back(f);
    sink_node_poll(sink.get());
    fake.now_us = t0 + 200'000;  // SYNC 1 closes the continuation
    sink_node_poll(sink.get());
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_EQ(packets.size(), 2u);
    EXPECT_EQ(packets[0]->header.timestamp_us, t0);
    ASSERT_EQ(packets[0]->frame_count, 2u);
    EXPECT_EQ(packets[0]->frames[1].offset_us, 40'000u);
    EXPECT_EQ(packets[1]->header.timestamp_us, t0 + 120'000);
    ASSERT_EQ(packets[1]->frame_count, 1u);
    EXPECT_EQ(packets[1]->frames[0].offset_us, 0u);
    EXPECT_EQ(sink->counters.batch_splits, 1u);
}

TEST_F(SinkNodeTest, SinkStatusReportsCanFramesLostOnReception) {
    config.status_period_s = 1;
    static uint32_t lost = 0;
    lost = 258;
    start();
    sink_node_hal h = fake.hal();
    h.can_rx_lost = [](void*) { return lost; };
    sink->hal = h;
    run(20'000);
    const auto packets = decode_all(fake.connections.at(0));
    ASSERT_FALSE(packets.empty());
    mw_status status{};
    ASSERT_EQ(mw_status_decode(&packets[0]->frames[1].frame, &status), MW_OK);
    EXPECT_EQ(status.node_id, MW_NODE_ID_SINK);
    EXPECT_EQ(status.tx_overflows, 2u) << "258 wraps to 2 in the 8-bit field";
}

TEST_F(SinkNodeTest, BusyCanControllerQueuesSyncAndCountsOverflow) {
    start();
    fake.can_busy = true;
    run(100'000);  // the start-up CONFIG + 10 SYNCs for a queue of 8
    EXPECT_EQ(sink->counters.can_tx_overflows, 3u);
    fake.can_busy = false;
    sink_node_poll(sink.get());
    ASSERT_EQ(fake.tx.size(), 8u);
    EXPECT_EQ(fake.tx[1].second.id, MW_CAN_ID(MW_FN_CONFIG, 0)) << "queued right after SYNC 0";
    EXPECT_EQ(fake.sync_counters(), (std::vector<uint32_t>{0, 1, 2, 3, 4, 5, 6}));
}

TEST(SinkNodeInit, RejectsBadConfig) {
    fake_sink_hal fake;
    auto sink = std::make_unique<sink_node>();
    sink_node_config c{};
    sink_node_default_config(&c);
    sink_node_hal h = fake.hal();
    c.rate_hz = 0;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_RANGE);
    sink_node_default_config(&c);
    c.max_batch_frames = SINK_NODE_MAX_BATCH_FRAMES + 1;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_RANGE);
    sink_node_default_config(&c);
    c.backoff_max_us = c.backoff_min_us - 1;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_RANGE);
    sink_node_default_config(&c);
    c.host_count = 0;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_RANGE);
    c.host_count = SINK_NODE_MAX_HOSTS + 1;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_RANGE);
    sink_node_default_config(&c);
    h.uplink_close = nullptr;
    EXPECT_EQ(sink_node_init(sink.get(), &h, &c), MW_ERR_ARGUMENT);
}

}  // namespace
}  // namespace mocap::test
