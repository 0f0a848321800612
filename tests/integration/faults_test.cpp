// Faults, bad input, signals and limits against the real mocapd on loopback (docs/style.md,
// "Real binaries on loopback"; docs/reliability.md lists what each test tries and what it
// measured). Every test keeps a normal client subscribed to a normally streaming subject and
// requires it to receive every frame (gap-free) while the daemon is attacked or faulted. Sinks
// are either the real `mocap-sim stream` or WireSink: packets built here with the wire library,
// so a test can cut, reorder, duplicate or re-stamp them.
#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <map>
#include <random>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "http_test_client.hpp"
#include "mocap/v1/mocap.pb.h"
#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_packet.h"
#include "pose_client.hpp"
#include "serve/framing.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;

constexpr const char* kToken = "faults-t0ken-0123456789";
constexpr int kRateHz = 100;

std::int64_t realtime_us() {
    return client::wall_clock_us();
}

// ------------------------------------------------------------------ raw sockets
// (tcp_connect, send_all, closed_by_peer: harness.hpp)

Bytes random_bytes(std::mt19937& rng, std::size_t n) {
    Bytes b(n);
    for (auto& x : b)
        x = static_cast<std::uint8_t>(rng());
    return b;
}

std::string delimited(const v1::ClientMessage& m) {
    std::string out;
    serve::append_delimited(m, out);
    return out;
}

/// The sink's own 32-bit SYNC counter inside the daemon's 64-bit sync line.
std::uint32_t low32(std::uint64_t sync) {
    return static_cast<std::uint32_t>(sync & 0xFFFFFFFFu);
}

// ------------------------------------------------------------------ /proc

std::size_t open_fds(pid_t pid) {
    std::size_t n = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd")) {
        ++n;
    }
    return n;
}

std::uint64_t vm_rss_kib(pid_t pid) {
    std::istringstream in(read_file("/proc/" + std::to_string(pid) + "/status"));
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6));
    }
    return 0;
}

// ------------------------------------------------------------------ WireSink

/// A sink made of the wire library: SYNC + ACCEL/GYRO/MAG of nodes 1..15 per instant, a body
/// standing still (accelerometer +1 g up, no rotation, a fixed field). The test decides what
/// reaches the daemon: every frame list can be reordered, duplicated or split before encoding.
class WireSink {
public:
    explicit WireSink(std::uint8_t sink_id) : sink_id_(sink_id) {}
    ~WireSink() { close(); }
    WireSink(const WireSink&) = delete;
    WireSink& operator=(const WireSink&) = delete;

    bool connect(std::uint16_t port) {
        close();
        fd_ = tcp_connect(port);
        sequence_ = 0;
        return fd_ >= 0;
    }
    void close() {
        if (fd_ >= 0) ::close(fd_);
        fd_ = -1;
    }
    [[nodiscard]] int fd() const { return fd_; }

    /// SYNC + nodes first_node..first_node+nodes-1 (1..15 is the built-in body).
    static std::vector<mw_stamped_frame> instant(std::uint32_t counter, int nodes = 15, int first_node = 1) {
        std::vector<mw_stamped_frame> out;
        mw_stamped_frame f{};
        const mw_sync sync{counter};
        mw_sync_encode(&sync, &f.frame);
        out.push_back(f);
        for (int n = first_node; n < first_node + nodes; ++n) {
            const std::array<std::pair<mw_function, std::array<std::int16_t, 3>>, 3> parts{{
                {MW_FN_ACCEL, {0, 0, 2048}},  // +1 g at ±16 g
                {MW_FN_GYRO, {0, 0, 0}},
                {MW_FN_MAG, {120, 0, -250}},
            }};
            for (const auto& [kind, xyz] : parts) {
                mw_raw raw{};
                raw.kind = kind;
                raw.node_id = static_cast<std::uint8_t>(n);
                raw.xyz[0] = xyz[0];
                raw.xyz[1] = xyz[1];
                raw.xyz[2] = xyz[2];
                raw.counter_low = static_cast<std::uint16_t>(counter & 0xFFFFu);
                f.offset_us = static_cast<std::uint16_t>(100 + 20 * n);
                mw_raw_encode(&raw, &f.frame);
                out.push_back(f);
            }
        }
        return out;
    }

    Bytes encode(const std::vector<mw_stamped_frame>& frames, std::int64_t timestamp_us) {
        mw_packet_header h{};
        h.sink_id = sink_id_;
        h.sequence = sequence_++;
        h.timestamp_us = static_cast<std::uint64_t>(timestamp_us);
        Bytes out(MW_PACKET_MAX_SIZE);
        const std::int32_t n = mw_packet_encode(&h, frames.data(), frames.size(), out.data(), out.size());
        out.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
        return out;
    }

    bool send(const Bytes& b) { return send_all(fd_, b); }

private:
    std::uint8_t sink_id_;
    int fd_ = -1;
    std::uint32_t sequence_ = 0;
};

/// Calls `step(i)` for i = 0..n-1 at `kRateHz`, on the wall clock (no drift).
template <typename Step>
void paced(int n, Step step) {
    const auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
        std::this_thread::sleep_until(start + std::chrono::microseconds(i * 1'000'000 / kRateHz));
        step(i);
    }
}

// ------------------------------------------------------------------ fixture

/// A client subscribed to some subjects, read on its own thread until stop().
class Watcher {
public:
    Watcher(std::uint16_t port, std::vector<std::uint32_t> subjects) {
        std::string err;
        ok_ = client_.connect("127.0.0.1", port, 5s, err);
        client::SubscribeOptions o;
        o.subject_ids = std::move(subjects);
        ok_ = ok_ && client_.subscribe(o, 5s, err);
        error_ = err;
        thread_ = std::thread([this] {
            v1::SkeletonFrame f;
            while (!stop_.load()) {
                const auto st = client_.next_frame(f, 100ms);
                if (st == client::ReadStatus::kMessage) {
                    std::lock_guard lock(mutex_);
                    frames_.push_back(f);
                } else if (st != client::ReadStatus::kTimeout) {
                    closed_ = true;
                    return;
                }
            }
        });
    }
    ~Watcher() { stop(); }
    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    [[nodiscard]] bool ok() const { return ok_; }
    [[nodiscard]] bool closed() const { return closed_; }
    [[nodiscard]] const std::string& error() const { return error_; }
    std::vector<v1::SkeletonFrame> frames() {
        std::lock_guard lock(mutex_);
        return frames_;
    }
    /// Sync values of one subject, in arrival order.
    std::vector<std::uint64_t> syncs(std::uint32_t subject) {
        std::vector<std::uint64_t> out;
        for (const auto& f : frames()) {
            if (f.subject_id() == subject) out.push_back(f.sync());
        }
        return out;
    }

private:
    client::PoseClient client_;
    std::thread thread_;
    std::atomic<bool> stop_{false};
    std::atomic<bool> closed_{false};
    bool ok_ = false;
    std::string error_;
    std::mutex mutex_;
    std::vector<v1::SkeletonFrame> frames_;
};

/// Missing frames between consecutive syncs (0 = gap-free); a step back counts as a gap too.
std::uint64_t gaps(const std::vector<std::uint64_t>& s) {
    std::uint64_t g = 0;
    for (std::size_t i = 1; i < s.size(); ++i)
        g += s[i] > s[i - 1] ? s[i] - s[i - 1] - 1 : 1;
    return g;
}

/// SYNCs the simulated sinks skipped because mocap-sim itself ran late (a loaded machine):
/// the "syncs_skipped" total of its --sink-rate-stats line. Those instants never existed, so
/// a client's gaps are compared with this, not with zero.
std::uint64_t sim_skipped(const Process& sim) {
    const std::string log = sim.log();
    const auto skipped = sim_syncs_skipped(log);
    if (!skipped) ADD_FAILURE() << "no stats line from mocap-sim: " << log;
    return skipped.value_or(0);
}

class Faults : public ::testing::Test {
protected:
    void TearDown() override { stop_daemon_at_teardown(daemon_.get()); }

    std::string config_text(const std::string& log_level = "info") const {
        std::ostringstream cfg;
        cfg << "[log]\nlevel = \"" << log_level << "\"\nstats_interval_s = 0\n"
            << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port_ << "\"\nsink_idle_timeout_s = 1.0\n"
            << "[pipeline]\nworkers = 2\nmax_subjects = 4\nassembly_deadline_ms = 20.0\n"
            << "[skeleton]\ncalibration_dir = \"" << dir_.path().string() << "\"\n"
            << "[serve]\npose_listen = \"" << pose_host_ << ":" << pose_port_ << "\"\n"
            << "max_clients = " << max_clients_ << "\nclient_queue_frames = 16\nhandshake_timeout_s = 1.0\n"
            << "max_message_bytes = 1024\nmax_client_messages_per_s = 5.0\nclient_message_burst = 10\n"
            << "[control]\ntoken = \"" << kToken << "\"\n"
            << "[outputs]\nbvh_listen = \"127.0.0.1:" << bvh_port_ << "\"\nbvh_subject = 1\n"
            << "record_dir = \"" << dir_.path().string() << "\"\n"
            << "[http]\nlisten = \"127.0.0.1:" << http_port_ << "\"\n";
        return cfg.str();
    }

    void start_daemon() {
        sink_port_ = free_port();
        pose_port_ = free_port();
        bvh_port_ = free_port();
        http_port_ = free_port();
        config_ = dir_.file("mocapd.toml");
        write_file(config_, config_text());
        daemon_ = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", config_},
                                            dir_.file("mocapd.log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(pose_port_, 10s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(sink_port_, 10s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(bvh_port_, 10s)) << daemon_->log();
    }

    std::unique_ptr<Process> sim(std::vector<std::string> extra, const std::string& log = "sim.log") {
        std::vector<std::string> argv{MOCAP_SIM_BIN,      "stream",
                                      "--connect",        "127.0.0.1:" + std::to_string(sink_port_),
                                      "--rate",           std::to_string(kRateHz),
                                      "--nodes",          "15",
                                      "--mode",           "quat",
                                      "--sink-rate-stats"};
        argv.insert(argv.end(), extra.begin(), extra.end());
        return std::make_unique<Process>(argv, dir_.file(log));
    }

    /// Every counter of a Stats reply (a fresh connection: the caller's own may be closed).
    std::map<std::string, std::uint64_t> counters(v1::Stats* full = nullptr) {
        client::PoseClient c;
        std::string err;
        std::map<std::string, std::uint64_t> out;
        v1::Stats s;
        if (!c.connect("127.0.0.1", pose_port_, 5s, err) || !c.request_stats(s, 5s, err)) {
            ADD_FAILURE() << "stats: " << err;
            return out;
        }
        for (const auto& kv : s.counters())
            out[kv.name()] = kv.value();
        if (full) *full = s;
        return out;
    }

    TempDir dir_;
    std::uint16_t sink_port_ = 0, pose_port_ = 0, bvh_port_ = 0, http_port_ = 0;
    std::string pose_host_ = "127.0.0.1";
    int max_clients_ = 64;
    std::string config_;
    std::unique_ptr<Process> daemon_;
};

/// Waits until the watcher has at least `n` frames of `subject` (bounded).
bool wait_frames(Watcher& w, std::uint32_t subject, std::size_t n, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < end) {
        if (w.syncs(subject).size() >= n) return true;
        std::this_thread::sleep_for(20ms);
    }
    return false;
}

/// Waits until `needle` appears on at least `n` lines of the daemon's log (bounded).
bool wait_log_lines(const Process& p, const std::string& needle, std::size_t n, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < end) {
        if (count_lines(p.log(), needle) >= n) return true;
        std::this_thread::sleep_for(20ms);
    }
    return false;
}

// ================================================================== bad input

TEST_F(Faults, GarbageOnEveryPortIsCountedLoggedOnceAndDropped) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1});
    ASSERT_TRUE(ref.ok()) << ref.error();
    auto s = sim({"--subjects", "1", "--duration", "9", "--seed", "4"});
    ASSERT_TRUE(wait_frames(ref, 1, 50, 10s));
    std::mt19937 rng(7);
    constexpr int kRepeats = 1000;

    // ---- sink port (7000) ----
    // 1000 chunks of random bytes on one connection: discarded, the decoder resynchronises.
    const int junk = tcp_connect(sink_port_);
    for (int i = 0; i < kRepeats; ++i)
        ASSERT_TRUE(send_all(junk, random_bytes(rng, 100)));
    // A valid header whose payload_length claims far more than a packet can hold, 1000 times.
    WireSink liar(3);
    ASSERT_TRUE(liar.connect(sink_port_));
    Bytes huge = liar.encode(WireSink::instant(1, 1), realtime_us());
    huge[6] = 0xFF;  // frame_count
    huge[7] = 0xFF;
    huge[8] = 0xFF;  // payload_length
    huge[9] = 0xFF;
    for (int i = 0; i < kRepeats; ++i)
        ASSERT_TRUE(liar.send(huge));
    // A valid packet with a bad CRC, 1000 times.
    WireSink crc(3);
    ASSERT_TRUE(crc.connect(sink_port_));
    for (int i = 0; i < kRepeats; ++i) {
        Bytes p = crc.encode(WireSink::instant(static_cast<std::uint32_t>(i + 1), 15), realtime_us());
        p.back() ^= 0x5A;
        ASSERT_TRUE(crc.send(p));
    }
    // A truncated packet followed by a valid one: the cut packet swallows the start of the
    // next, fails its CRC, and the decoder finds the valid packet behind it.
    WireSink cut(3);
    ASSERT_TRUE(cut.connect(sink_port_));
    Bytes first = cut.encode(WireSink::instant(1), realtime_us());
    first.resize(first.size() / 2);
    ASSERT_TRUE(cut.send(first));
    ASSERT_TRUE(cut.send(cut.encode(WireSink::instant(2), realtime_us())));
    // More than max_garbage_bytes (1 MiB) without a valid packet: closed.
    const int flood = tcp_connect(sink_port_);
    for (int i = 0; i < 1100; ++i) {
        if (!send_all(flood, random_bytes(rng, 1024))) break;
    }
    EXPECT_TRUE(closed_by_peer(flood, 5s)) << "1 MiB of garbage must close the sink connection";
    // Connects and sends nothing: closed after sink_idle_timeout_s (1 s).
    const int mute_sink = tcp_connect(sink_port_);
    EXPECT_TRUE(closed_by_peer(mute_sink, 5s)) << "a silent sink must be closed";

    // ---- pose port (7001) ----
    int malformed_closed = 0;
    for (int i = 0; i < 200; ++i) {  // random bytes (a reader sees a length, then junk)
        const int fd = tcp_connect(pose_port_);
        Bytes b = random_bytes(rng, 64);
        b[0] = 40;  // a plausible length prefix, then 40 bytes that are not a ClientMessage
        b[1] = 0xFF;
        send_all(fd, b);
        malformed_closed += closed_by_peer(fd, 3s) ? 1 : 0;
        ::close(fd);
    }
    EXPECT_EQ(malformed_closed, 200);
    const int big_prefix = tcp_connect(pose_port_);  // length prefix of 2^32 - 1
    send_all(big_prefix, Bytes{0xFF, 0xFF, 0xFF, 0xFF, 0x0F});
    EXPECT_TRUE(closed_by_peer(big_prefix, 3s));
    const int too_long = tcp_connect(pose_port_);  // a real message above max_message_bytes
    v1::ClientMessage big;
    big.mutable_control()->set_token(std::string(4000, 'x'));
    send_all(too_long, delimited(big));
    EXPECT_TRUE(closed_by_peer(too_long, 3s));
    const int truncated = tcp_connect(pose_port_);  // prefix says 100, 10 bytes come, then silence
    send_all(truncated, Bytes{100, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10});
    EXPECT_TRUE(closed_by_peer(truncated, 5s)) << "a half message is closed by the handshake timeout";
    const int silent = tcp_connect(pose_port_);  // connects, sends nothing
    EXPECT_TRUE(closed_by_peer(silent, 5s));
    // Subscribes to everything, then never reads: its queue drops, nobody else notices.
    const int deaf = tcp_connect(pose_port_, "127.0.0.1", 4096);
    v1::ClientMessage subscribe;
    subscribe.mutable_subscribe()->set_fields(v1::FIELD_ORIENTATIONS | v1::FIELD_POSITIONS | v1::FIELD_JOINT_ANGLES);
    ASSERT_TRUE(send_all(deaf, delimited(subscribe)));

    // ---- live BVH port (7002) ----
    const int bvh_bad = tcp_connect(bvh_port_);
    for (int i = 0; i < kRepeats; ++i)
        send_all(bvh_bad, std::string("no such command\n"));
    const int bvh_long = tcp_connect(bvh_port_);
    send_all(bvh_long, std::string(200, 'A') + "\n");
    EXPECT_TRUE(closed_by_peer(bvh_long, 3s)) << "a line over 64 bytes closes the BVH client";
    const int bvh_deaf = tcp_connect(bvh_port_);  // never reads

    // ---- HTTP port (8080) ----
    int http_closed = 0;
    for (int i = 0; i < 20; ++i) {  // random bytes instead of a request line
        const int fd = tcp_connect(http_port_);
        send_all(fd, random_bytes(rng, 200));
        http_closed += closed_by_peer(fd, 3s) ? 1 : 0;
        ::close(fd);
    }
    EXPECT_EQ(http_closed, 20) << "an unparseable request closes the connection";
    const int http_huge = tcp_connect(http_port_);  // a header line far above any limit
    send_all(http_huge, "GET / HTTP/1.1\r\nX-Junk: " + std::string(64 * 1024, 'a') + "\r\n\r\n");
    EXPECT_TRUE(closed_by_peer(http_huge, 3s));
    ::close(http_huge);
    int http_refused = 0;
    for (int i = 0; i < 200; ++i) {  // control without the token
        const int fd = tcp_connect(http_port_);
        send_all(fd, std::string("POST /api/record/start HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n"
                                 "Connection: close\r\n\r\n"));
        std::string reply;
        std::array<char, 2048> buf{};
        for (ssize_t r; (r = ::recv(fd, buf.data(), buf.size(), 0)) > 0;)
            reply.append(buf.data(), static_cast<std::size_t>(r));
        http_refused += reply.rfind("HTTP/1.1 4", 0) == 0 ? 1 : 0;
        ::close(fd);
    }
    EXPECT_EQ(http_refused, 200);

    ASSERT_EQ(s->wait(20s).value_or(-1), 0) << s->log();
    std::this_thread::sleep_for(500ms);
    ref.stop();
    const auto c = counters();
    for (int fd :
         {junk, flood, mute_sink, big_prefix, too_long, truncated, silent, deaf, bvh_bad, bvh_long, bvh_deaf}) {
        ::close(fd);
    }

    // Everyone else kept receiving: every frame of the simulated subject, in order.
    const auto syncs = ref.syncs(1);
    const std::uint64_t skipped = sim_skipped(*s);
    EXPECT_GE(syncs.size() + skipped, 8u * kRateHz);
    EXPECT_LE(gaps(syncs), skipped) << "the normal client must see every frame the sink sent";
    EXPECT_FALSE(ref.closed());
    if (HasFailure()) {
        for (std::size_t i = 1; i < syncs.size(); ++i) {
            if (syncs[i] != syncs[i - 1] + 1)
                std::cerr << "gap after " << low32(syncs[i - 1]) << " to " << low32(syncs[i]) << "\n";
        }
        for (const auto& [k, v] : c) {
            if (v != 0) std::cerr << k << "=" << v << "\n";
        }
    }

    // Counted.
    EXPECT_GE(c.at("ingest_tcp.crc_failures"), static_cast<std::uint64_t>(kRepeats) + 1);
    EXPECT_GE(c.at("ingest_tcp.malformed_packets"), 2u * kRepeats + 1);
    EXPECT_GE(c.at("ingest_tcp.bytes_discarded"), 1u << 20);
    EXPECT_EQ(c.at("ingest_tcp.garbage_closes"), 1u);
    EXPECT_GE(c.at("ingest_tcp.idle_timeouts"), 1u);
    EXPECT_GE(c.at("serve.malformed_messages"), 200u);
    EXPECT_EQ(c.at("serve.oversized_messages"), 2u);
    EXPECT_GE(c.at("serve.idle_timeouts"), 2u);
    EXPECT_GT(c.at("serve.frames_dropped"), 0u) << "the deaf client's queue drops";
    EXPECT_GE(c.at("bvh_live.bad_client_lines"), static_cast<std::uint64_t>(kRepeats));

    // Logged once, not per packet or per client.
    const std::string log = daemon_->log();
    const std::size_t sink_malformed = count_lines(log, "malformed packet");
    const std::size_t serve_unparseable = count_lines(log, "unparseable message");
    std::cout << "[ metrics  ] log lines: sink malformed " << sink_malformed << " (3000+ bad packets on 3 "
              << "connections), pose unparseable " << serve_unparseable << " (200 clients), whole log "
              << count_lines(log, "") << " lines\n";
    EXPECT_LE(sink_malformed, 4u) << "one line per connection at most";
    EXPECT_LE(serve_unparseable, 2u) << "one line per 10 s";
    EXPECT_LE(count_lines(log, "http: control request"), 2u) << "200 refusals, one line per 10 s";
    EXPECT_LT(count_lines(log, ""), 200u) << "no log flood";
}

// ================================================================== faults

TEST_F(Faults, SinkCutMidPacketReconnectsAndTheSubjectResumes) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1, 2});
    ASSERT_TRUE(ref.ok()) << ref.error();
    auto s = sim({"--subjects", "1", "--duration", "5", "--seed", "6"});
    WireSink sink(2);
    ASSERT_TRUE(sink.connect(sink_port_));
    std::uint32_t counter = 1000;
    paced(150, [&](int) { ASSERT_TRUE(sink.send(sink.encode(WireSink::instant(counter++), realtime_us()))); });
    // Half of the next packet, then the link drops.
    Bytes half = sink.encode(WireSink::instant(counter), realtime_us());
    half.resize(half.size() / 2);
    ASSERT_TRUE(sink.send(half));
    sink.close();
    std::this_thread::sleep_for(100ms);
    // The sink reconnects and goes on from the instant it could not finish.
    ASSERT_TRUE(sink.connect(sink_port_));
    paced(150, [&](int) { ASSERT_TRUE(sink.send(sink.encode(WireSink::instant(counter++), realtime_us()))); });
    ASSERT_EQ(s->wait(15s).value_or(-1), 0) << s->log();
    std::this_thread::sleep_for(300ms);
    ref.stop();

    const auto own = ref.syncs(2);
    ASSERT_GE(own.size(), 280u) << "subject 2 must stream on both connections";
    EXPECT_EQ(gaps(own), 0u) << "the instant cut mid-packet is sent again; nothing is missing";
    EXPECT_LE(low32(own.front()), 1005u);
    EXPECT_EQ(low32(own.back()), 1299u) << "the last instant sent on the new connection arrives";
    const auto other = ref.syncs(1);
    EXPECT_GE(other.size() + sim_skipped(*s), 4u * kRateHz);
    EXPECT_LE(gaps(other), sim_skipped(*s));
    const auto c = counters();
    EXPECT_EQ(c.at("ingest_tcp.malformed_packets"), 0u) << "a cut packet is not garbage";
}

TEST_F(Faults, SyncCounterWrapsWithoutAGap) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1});
    ASSERT_TRUE(ref.ok()) << ref.error();
    // 2 s before the 32-bit counter wraps, 3 s after.
    const std::uint32_t first = 0xFFFFFFFFu - 2 * kRateHz + 1;
    auto s = sim({"--subjects", "1", "--duration", "5", "--seed", "8", "--first-counter", std::to_string(first)});
    ASSERT_EQ(s->wait(15s).value_or(-1), 0) << s->log();
    std::this_thread::sleep_for(300ms);
    ref.stop();
    const auto syncs = ref.syncs(1);
    // A starved machine (TSan on a loaded host) delivers fewer of the 5 s; what matters is
    // frames on both sides of the wrap (below) and no gap the simulator did not make.
    ASSERT_GE(syncs.size(), static_cast<std::size_t>(kRateHz));
    EXPECT_GE(low32(syncs.front()), first);
    EXPECT_LT(low32(syncs.back()), 4u * kRateHz);
    EXPECT_EQ(syncs.back() >> 32, (syncs.front() >> 32) + 1) << "the 64-bit sync goes on past the wrap";
    EXPECT_LE(gaps(syncs), sim_skipped(*s));
    const auto c = counters();
    EXPECT_EQ(c.at("ingest_tcp.sync_wraps"), 1u);
}

TEST_F(Faults, OutOfOrderAndDuplicatedCanFramesKeepEveryFrame) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {2});
    ASSERT_TRUE(ref.ok()) << ref.error();
    WireSink sink(2);
    ASSERT_TRUE(sink.connect(sink_port_));
    std::mt19937 rng(12);
    std::vector<mw_stamped_frame> held;  // one node's frames delivered with the next instant
    std::uint64_t duplicates = 0;
    constexpr int kInstants = 400;
    paced(kInstants, [&](int i) {
        auto frames = WireSink::instant(static_cast<std::uint32_t>(i + 1));
        const std::size_t late_node = 1 + static_cast<std::size_t>(i % 15);
        // Last instant's held-back node first (late against its own SYNC and the other
        // nodes, but before its own next instant), then this instant's frames, shuffled.
        std::shuffle(held.begin(), held.end(), rng);
        Bytes late_part = held.empty() ? Bytes{} : sink.encode(held, realtime_us());
        std::vector<mw_stamped_frame> now;
        held.clear();
        for (std::size_t k = 0; k < frames.size(); ++k) {
            const bool late = k > 0 && (k - 1) / 3 + 1 == late_node && i + 1 < kInstants;
            (late ? held : now).push_back(frames[k]);
            if (k > 0 && rng() % 10 == 0) {  // 10 % of node frames arrive twice
                now.push_back(frames[k]);
                ++duplicates;
            }
        }
        std::shuffle(now.begin(), now.end(), rng);  // the bus order is not the sample order
        if (!late_part.empty()) {
            ASSERT_TRUE(sink.send(late_part));
        }
        ASSERT_TRUE(sink.send(sink.encode(now, realtime_us())));
    });
    std::this_thread::sleep_for(300ms);
    ref.stop();
    const auto syncs = ref.syncs(2);
    EXPECT_GE(syncs.size(), static_cast<std::size_t>(kInstants - 2));
    EXPECT_EQ(gaps(syncs), 0u);
    std::size_t stale = 0, segments = 0;
    for (const auto& f : ref.frames()) {
        if (low32(f.sync()) < 100) continue;  // skip start-up
        for (int i = 0; i < f.flags_size(); ++i) {
            ++segments;
            stale += (f.flags(i) & v1::SEGMENT_STALE) != 0 ? 1 : 0;
        }
    }
    const double stale_fraction = segments ? static_cast<double>(stale) / static_cast<double>(segments) : 1.0;
    std::cout << "[ metrics  ] reordered+duplicated bus: " << syncs.size() << " frames, " << duplicates
              << " duplicate frames sent, stale segment fraction " << stale_fraction << "\n";
    EXPECT_LT(stale_fraction, 0.05) << "a node one instant late is still on time for the assembler";
    const auto c = counters();
    EXPECT_EQ(c.at("ingest_tcp.duplicate_frames") + c.at("ingest_tcp.late_frames"), duplicates)
        << "every duplicate is recognised and dropped";
    EXPECT_EQ(c.at("ingest_tcp.malformed_frames"), 0u);
}

TEST_F(Faults, SinkClockStepsOfTenSecondsDoNotStopTheSubject) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {2});
    ASSERT_TRUE(ref.ok()) << ref.error();
    WireSink sink(2);
    ASSERT_TRUE(sink.connect(sink_port_));
    // 0–2 s true time, 2–4 s the clock 10 s ahead, 4–6 s 10 s behind, 6–7 s true again.
    paced(700, [&](int i) {
        const std::int64_t step_us = i < 200 ? 0 : i < 400 ? 10'000'000 : i < 600 ? -10'000'000 : 0;
        ASSERT_TRUE(
            sink.send(sink.encode(WireSink::instant(static_cast<std::uint32_t>(i + 1)), realtime_us() + step_us)));
    });
    std::this_thread::sleep_for(300ms);
    ref.stop();
    const auto frames = ref.frames();
    const auto syncs = ref.syncs(2);
    EXPECT_GE(syncs.size(), 690u);
    EXPECT_EQ(gaps(syncs), 0u) << "the subject streams through both steps";
    // The body stands still: its orientation must not jump when the sink's clock does.
    double worst_deg = 0.0;
    std::size_t stale_after = 0, segments_after = 0;
    const v1::SkeletonFrame* before = nullptr;
    for (const auto& f : frames) {
        if (low32(f.sync()) == 190) before = &f;
    }
    ASSERT_NE(before, nullptr);
    for (const auto& f : frames) {
        if (low32(f.sync()) < 190) continue;
        for (int i = 0; i < static_cast<int>(f.segment_count()); ++i) {
            double dot = 0.0, norm = 0.0;
            for (int k = 0; k < 4; ++k) {
                dot += f.q_world_segment_wxyz(4 * i + k) * before->q_world_segment_wxyz(4 * i + k);
                norm += f.q_world_segment_wxyz(4 * i + k) * f.q_world_segment_wxyz(4 * i + k);
            }
            ASSERT_TRUE(std::isfinite(norm) && std::abs(norm - 1.0) < 1e-3) << "sync " << f.sync();
            worst_deg = std::max(worst_deg, 2.0 * std::acos(std::min(1.0, std::abs(dot))) * 180.0 / M_PI);
            if (low32(f.sync()) > 610) {
                ++segments_after;
                stale_after += (f.flags(i) & v1::SEGMENT_STALE) != 0 ? 1 : 0;
            }
        }
    }
    std::cout << "[ metrics  ] clock steps +-10 s: largest orientation change of a still body " << worst_deg
              << " deg\n";
    EXPECT_LT(worst_deg, 2.0);
    // Recovered by itself: a subject stuck by the step would be stale in every frame. A few
    // stale segments are the assembler's deadline on a starved machine (load, sanitizers),
    // as in the reordered-bus test above.
    ASSERT_GT(segments_after, 0u);
    EXPECT_LT(static_cast<double>(stale_after) / static_cast<double>(segments_after), 0.05)
        << stale_after << " of " << segments_after << " segments stale after the steps: not recovered";
    // The latency statistics survive: the step ahead is counted as negative, the step back
    // shows as a 10 s maximum, and the Stats request still answers.
    v1::Stats stats;
    const auto c = counters(&stats);
    EXPECT_GE(c.at("latency.ingest_negative"), 150u);
    bool found = false;
    for (const auto& l : stats.latencies()) {
        if (l.stage() != "ingest") continue;
        found = true;
        EXPECT_GT(l.max_us(), 9.0e6);
        EXPECT_LT(l.max_us(), 11.0e6);
        EXPECT_LT(l.p50_us(), 1.0e6) << "most packets are on time";
    }
    EXPECT_TRUE(found);
}

TEST_F(Faults, SamplesForNodesOutsideTheBodyKeepHealthzHealthy) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    ASSERT_EQ(mocap::testing::http_request(http_port_, "/healthz").status, 200u);
    // Valid instants of nodes 40..54 (the built-in body has 1..15) for 4 s: no frame can come
    // of them, so they are not "samples that arrive". They made /healthz answer 503 after 2 s.
    WireSink stranger(3);
    ASSERT_TRUE(stranger.connect(sink_port_));
    std::atomic<bool> done{false};
    std::atomic<unsigned> worst{200};
    std::string worst_body;
    std::thread poll([&] {
        while (!done.load()) {
            const auto r = mocap::testing::http_request(http_port_, "/healthz");
            if (r.status != 200) {
                worst = r.status;
                worst_body = r.body;
            }
            std::this_thread::sleep_for(100ms);
        }
    });
    paced(400, [&](int i) {
        ASSERT_TRUE(stranger.send(
            stranger.encode(WireSink::instant(static_cast<std::uint32_t>(i + 1), 15, 40), realtime_us())));
    });
    done = true;
    poll.join();
    const auto after = mocap::testing::http_request(http_port_, "/healthz");
    EXPECT_EQ(worst.load(), 200u) << worst_body;
    EXPECT_EQ(after.status, 200u) << after.body;
    EXPECT_GE(counters().at("route.samples_unknown_node"), 400u * 15u - 15u);
    // Health still means something: a served subject's samples count, and they make frames.
    Watcher ref(pose_port_, {1});
    ASSERT_TRUE(ref.ok()) << ref.error();
    WireSink real(1);
    ASSERT_TRUE(real.connect(sink_port_));
    paced(100, [&](int i) {
        ASSERT_TRUE(real.send(real.encode(WireSink::instant(static_cast<std::uint32_t>(i + 1)), realtime_us())));
    });
    ASSERT_TRUE(wait_frames(ref, 1, 90, 10s));
    const auto served = mocap::testing::http_request(http_port_, "/healthz");
    EXPECT_EQ(served.status, 200u) << served.body;
    EXPECT_EQ(served.body, "ok\n");
}

TEST_F(Faults, HostileSinkTimestampsDoNotMoveAnotherSinksLatency) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1, 2});
    ASSERT_TRUE(ref.ok()) << ref.error();
    WireSink honest(1), hostile(2);
    ASSERT_TRUE(honest.connect(sink_port_));
    ASSERT_TRUE(hostile.connect(sink_port_));
    // Stamps that overflowed "received - sent" or wrapped negative, and clocks decades or an
    // hour off (the p99 of 57 years); plus ±2 min, beyond the 60 s a real clock may be off.
    const std::int64_t now = realtime_us();
    constexpr std::int64_t kYear = 365LL * 24 * 3600 * 1'000'000;
    const std::vector<std::uint64_t> stamps{0,
                                            1,
                                            UINT64_MAX,
                                            1ull << 63,
                                            static_cast<std::uint64_t>(INT64_MAX),
                                            static_cast<std::uint64_t>(now + 57 * kYear),
                                            static_cast<std::uint64_t>(now - 3'600'000'000LL),
                                            static_cast<std::uint64_t>(now + 120'000'000LL),
                                            static_cast<std::uint64_t>(now - 120'000'000LL)};
    constexpr int kInstants = 450;
    paced(kInstants, [&](int i) {
        const auto counter = static_cast<std::uint32_t>(i + 1);
        ASSERT_TRUE(honest.send(honest.encode(WireSink::instant(counter), realtime_us())));
        // encode() takes the stamp as int64: the conversion keeps every bit of the uint64.
        const Bytes p = hostile.encode(WireSink::instant(counter),
                                       static_cast<std::int64_t>(stamps[static_cast<std::size_t>(i) % stamps.size()]));
        ASSERT_TRUE(hostile.send(p));
    });
    ASSERT_TRUE(wait_frames(ref, 1, kInstants - 5, 10s));
    // Frames can reach the client before the last packets are counted: wait (bounded) until
    // ingest has counted every packet of both sinks, then judge.
    v1::Stats stats;
    std::map<std::string, std::uint64_t> c;
    const auto ingest_count = [&] {
        for (const auto& l : stats.latencies()) {
            if (l.stage() == "ingest") return l.count();
        }
        return std::uint64_t{0};
    };
    const auto counted_by = std::chrono::steady_clock::now() + 20s;
    for (;;) {
        c = counters(&stats);
        const bool all = c.at("ingest_tcp.implausible_timestamps") >= static_cast<std::uint64_t>(kInstants) &&
                         ingest_count() >= static_cast<std::uint64_t>(kInstants) * 15u;
        if (all || std::chrono::steady_clock::now() > counted_by) break;
        std::this_thread::sleep_for(100ms);  // poll interval, under the client message rate limit
    }
    EXPECT_GE(c.at("ingest_tcp.implausible_timestamps"), static_cast<std::uint64_t>(kInstants))
        << "every hostile packet";
    EXPECT_EQ(c.at("latency.ingest_negative"), 0u) << "no hostile stamp reached a latency figure";
    bool found = false;
    for (const auto& l : stats.latencies()) {
        if (l.stage() != "ingest") continue;
        found = true;
        std::cout << "[ metrics  ] ingest latency beside a hostile sink: p99 " << l.p99_us() << " us, max "
                  << l.max_us() << " us over " << l.count() << " samples\n";
        EXPECT_EQ(l.count(), static_cast<std::uint64_t>(kInstants) * 15u) << "the honest sink's samples only";
        EXPECT_LT(l.max_us(), 2.0e6) << "was 57 years";
        EXPECT_LT(l.p99_us(), 1.0e6);
    }
    EXPECT_TRUE(found);
    // Every frame: the honest subject's stamps are its own, the hostile one's are "unknown".
    ref.stop();
    std::size_t hostile_frames = 0;
    for (const auto& f : ref.frames()) {
        const auto& t = f.times();
        if (f.subject_id() == 1) {
            ASSERT_GT(t.sink_send_us(), 0);
            EXPECT_LT(t.received_us() - t.sink_send_us(), 2'000'000) << "sync " << f.sync();
        } else {
            ++hostile_frames;
            EXPECT_EQ(t.sink_send_us(), 0) << "sync " << f.sync();
        }
    }
    EXPECT_GT(hostile_frames, 0u) << "the hostile subject is still served";
    EXPECT_EQ(gaps(ref.syncs(1)), 0u);
}

// ================================================================== signals

TEST_F(Faults, SighupAndReloadRequestUnderLoadDropNoClient) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {});
    ASSERT_TRUE(ref.ok()) << ref.error();
    auto s = sim({"--subjects", "2", "--duration", "6", "--seed", "9"});
    ASSERT_TRUE(wait_frames(ref, 1, 100, 10s));
    write_file(config_, config_text("debug"));
    daemon_->signal(SIGHUP);
    std::this_thread::sleep_for(1500ms);
    write_file(config_, config_text("info"));
    client::PoseClient ctl;
    std::string err;
    ASSERT_TRUE(ctl.connect("127.0.0.1", pose_port_, 5s, err)) << err;
    v1::ControlRequest req;
    req.set_token(kToken);
    req.mutable_reload();
    v1::ControlReply reply;
    ASSERT_TRUE(ctl.control(req, reply, 5s, err)) << err;
    EXPECT_TRUE(reply.ok()) << reply.error();
    ASSERT_EQ(s->wait(15s).value_or(-1), 0) << s->log();
    std::this_thread::sleep_for(300ms);
    ref.stop();
    EXPECT_FALSE(ref.closed());
    for (std::uint32_t subject : {1u, 2u}) {
        const auto syncs = ref.syncs(subject);
        EXPECT_GE(syncs.size(), 5u * kRateHz) << "subject " << subject;
        EXPECT_LE(gaps(syncs), sim_skipped(*s)) << "subject " << subject << ": every frame through both reloads";
    }
    const std::string log = daemon_->log();
    EXPECT_EQ(count_lines(log, "reload: log level debug"), 1u) << "SIGHUP applied [log]";
    EXPECT_EQ(count_lines(log, "reload: log level info"), 1u) << "the reload request applied [log]";
    EXPECT_EQ(count_lines(log, "need a restart"), 0u) << "only [log] changed";
}

TEST_F(Faults, SighupWithARefusedConfigKeepsTheRunningOne) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1});
    ASSERT_TRUE(ref.ok()) << ref.error();
    auto s = sim({"--subjects", "1", "--duration", "8", "--seed", "5"});
    ASSERT_TRUE(wait_frames(ref, 1, 50, 10s));
    // Each of these used to "reload": the [log] part applied, the rest logged as needing a
    // restart, and a restart would then have refused the file (or run on defaults).
    const std::string good = config_text("info");
    const std::vector<std::pair<std::string, std::string>> bad{
        {config_text("debug") + "[filter]\nname = \"kalman\"\n", "filter.name: unknown filter"},
        {config_text("debug") + "[filter]\nname = \"madgwick\"\nparams = { beta = \"abc\" }\n", "filter.params.beta"},
        {"", "the file has no settings"},
        {"# a comment only\n", "the file has no settings"},
    };
    std::size_t refusals = 0;
    for (const auto& [text, reason] : bad) {
        write_file(config_, text);
        daemon_->signal(SIGHUP);
        ASSERT_TRUE(wait_log_lines(*daemon_, "reload: keeping the running config", ++refusals, 10s))
            << "refusal " << refusals << ": " << daemon_->log();
        EXPECT_GE(count_lines(daemon_->log(), reason), 1u) << reason;
    }
    // The config path replaced by a directory.
    std::filesystem::remove(config_);
    std::filesystem::create_directory(config_);
    daemon_->signal(SIGHUP);
    ASSERT_TRUE(wait_log_lines(*daemon_, "reload: keeping the running config", ++refusals, 10s)) << daemon_->log();
    EXPECT_EQ(count_lines(daemon_->log(), "not a regular file (a directory)"), 1u);
    std::filesystem::remove(config_);
    // Nothing applied: the level is still info (no debug lines), and a valid file applies.
    EXPECT_EQ(count_lines(daemon_->log(), "reload: log level"), 0u);
    EXPECT_EQ(count_lines(daemon_->log(), "need a restart"), 0u);
    write_file(config_, good);
    daemon_->signal(SIGHUP);
    ASSERT_TRUE(wait_log_lines(*daemon_, "reload: log level info", 1, 10s)) << daemon_->log();
    ASSERT_EQ(s->wait(15s).value_or(-1), 0) << s->log();
    ref.stop();
    EXPECT_FALSE(ref.closed());
    EXPECT_LE(gaps(ref.syncs(1)), sim_skipped(*s)) << "every frame through the refused reloads";
}

TEST_F(Faults, SigtermUnderLoadDrainsWithinFiveSeconds) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {});
    ASSERT_TRUE(ref.ok()) << ref.error();
    client::PoseClient deaf;  // a stalled client must not hold the exit up
    std::string err;
    ASSERT_TRUE(deaf.connect("127.0.0.1", pose_port_, 5s, err)) << err;
    ASSERT_TRUE(deaf.subscribe({}, 5s, err)) << err;
    const int bvh = tcp_connect(bvh_port_);
    auto s = sim({"--subjects", "4", "--duration", "30", "--seed", "10"});
    ASSERT_TRUE(wait_frames(ref, 4, 200, 15s));
    const auto t0 = std::chrono::steady_clock::now();
    daemon_->signal(SIGTERM);
    const auto rc = daemon_->wait(10s);
    const double drain_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "[ metrics  ] SIGTERM under load (4 subjects x 15 nodes, 3 clients): exit after " << drain_s << " s\n";
    ASSERT_TRUE(rc.has_value()) << "mocapd did not exit within 10 s (systemd TimeoutStopSec)";
    EXPECT_EQ(*rc, 0);
    EXPECT_LT(drain_s, 5.0);
    s->stop(5s);
    ::close(bvh);
    ref.stop();
    std::uint64_t all_gaps = 0;
    for (std::uint32_t subject = 1; subject <= 4; ++subject)
        all_gaps += gaps(ref.syncs(subject));
    EXPECT_LE(all_gaps, sim_skipped(*s)) << "the drain delivers every frame up to the end";
    EXPECT_NE(daemon_->log().find("mocapd stopped"), std::string::npos);
}

// ================================================================== resources

TEST_F(Faults, ConnectStormLeavesDescriptorsAndMemoryBounded) {
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    Watcher ref(pose_port_, {1});
    ASSERT_TRUE(ref.ok()) << ref.error();
    auto s = sim({"--subjects", "1", "--duration", "60", "--seed", "13"});
    ASSERT_TRUE(wait_frames(ref, 1, 100, 10s));
    // Warm-up round so that lazily grown buffers exist before the baseline.
    for (int i = 0; i < 50; ++i) {
        client::PoseClient c;
        std::string err;
        if (c.connect("127.0.0.1", pose_port_, 5s, err)) c.subscribe({}, 5s, err);
    }
    std::this_thread::sleep_for(1500ms);
    const pid_t pid = daemon_->pid();
    const std::size_t fd0 = open_fds(pid);
    const std::uint64_t rss0 = vm_rss_kib(pid);

    constexpr int kClients = 2000, kSinks = 500;
    int subscribed = 0;
    for (int i = 0; i < kClients; ++i) {
        if (i % 2 == 0) {  // half subscribe and leave, half connect and drop at once
            client::PoseClient c;
            std::string err;
            subscribed += c.connect("127.0.0.1", pose_port_, 5s, err) && c.subscribe({}, 5s, err) ? 1 : 0;
        } else {
            const int fd = tcp_connect(pose_port_);
            ::close(fd);
        }
    }
    WireSink sink(3);
    for (int i = 0; i < kSinks; ++i) {  // each a new connection of sink 3 with one instant
        ASSERT_TRUE(sink.connect(sink_port_));
        sink.send(sink.encode(WireSink::instant(static_cast<std::uint32_t>(i + 1)), realtime_us()));
        sink.close();
    }
    // Closing sessions get close_grace; wait (bounded) for the count to settle.
    std::size_t fd1 = open_fds(pid);
    for (int i = 0; i < 100 && fd1 > fd0; ++i) {
        std::this_thread::sleep_for(100ms);
        fd1 = open_fds(pid);
    }
    const std::uint64_t rss1 = vm_rss_kib(pid);
    s->stop(5s);
    ref.stop();
    std::cout << "[ metrics  ] storm " << kClients << " clients (" << subscribed << " subscribed) + " << kSinks
              << " sinks: fds " << fd0 << " -> " << fd1 << ", VmRSS " << rss0 << " -> " << rss1 << " KiB ("
              << static_cast<std::int64_t>(rss1) - static_cast<std::int64_t>(rss0) << "), log lines "
              << count_lines(daemon_->log(), "") << "\n";
    EXPECT_EQ(subscribed, kClients / 2);
    EXPECT_LE(fd1, fd0) << "every descriptor of the storm is closed";
#if defined(__SANITIZE_ADDRESS__)
    // ASan's quarantine keeps freed blocks (up to 256 MiB) out of reuse, so RSS says nothing
    // about leaks here; LeakSanitizer does, at mocapd's exit (TearDown requires status 0).
    std::cout << "[ metrics  ] RSS bound not judged under AddressSanitizer\n";
#else
    EXPECT_LT(rss1, rss0 + 16 * 1024) << "RSS grows by less than 16 MiB";
#endif
    EXPECT_LE(gaps(ref.syncs(1)), sim_skipped(*s)) << "the normal client saw every frame during the storm";
    const auto c = counters();
    EXPECT_GE(c.at("serve.connections_accepted"), static_cast<std::uint64_t>(kClients));
    EXPECT_GE(c.at("ingest_tcp.connections_accepted"), static_cast<std::uint64_t>(kSinks));
}

// ================================================================== security

std::string non_loopback_ipv4() {
    ifaddrs* list = nullptr;
    if (::getifaddrs(&list) != 0) return {};
    std::string out;
    for (ifaddrs* i = list; i && out.empty(); i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET) continue;
        const auto* a = reinterpret_cast<const sockaddr_in*>(i->ifa_addr);
        if ((ntohl(a->sin_addr.s_addr) >> 24) == 127) continue;
        char text[INET_ADDRSTRLEN] = {};
        ::inet_ntop(AF_INET, &a->sin_addr, text, sizeof text);
        out = text;
    }
    ::freeifaddrs(list);
    return out;
}

TEST_F(Faults, ClientLimitRateLimitAndLoopbackOnlyControl) {
    const std::string lan = non_loopback_ipv4();
    if (!lan.empty()) pose_host_ = "0.0.0.0";  // reachable through a non-loopback address too
    max_clients_ = 4;
    ASSERT_NO_FATAL_FAILURE(start_daemon());
    std::string err;

    // Rate limit: burst 10, then 5 requests/s. 30 pings at once close the client.
    {
        client::PoseClient greedy;
        ASSERT_TRUE(greedy.connect("127.0.0.1", pose_port_, 5s, err)) << err;
        v1::ClientMessage ping;
        ping.mutable_ping()->set_nonce(1);
        for (int i = 0; i < 30; ++i)
            greedy.send(ping, err);
        v1::ServerMessage m;
        for (int i = 0; i < 60 && greedy.next(m, 200ms) != client::ReadStatus::kClosed; ++i) {
        }
        ASSERT_TRUE(greedy.goodbye().has_value());
        EXPECT_EQ(greedy.goodbye()->reason(), v1::GOODBYE_RATE_LIMITED);
    }
    // A client within the rate is never limited: 20 pings at 4/s after its burst allowance.
    {
        client::PoseClient polite;
        ASSERT_TRUE(polite.connect("127.0.0.1", pose_port_, 5s, err)) << err;
        v1::ClientMessage ping;
        ping.mutable_ping()->set_nonce(2);
        v1::ServerMessage m;
        for (int i = 0; i < 20; ++i) {
            ASSERT_TRUE(polite.send(ping, err)) << err;
            std::this_thread::sleep_for(250ms);
            while (polite.next(m, 1ms) == client::ReadStatus::kMessage) {
            }
        }
        EXPECT_FALSE(polite.goodbye().has_value());
    }

    // Control from a non-loopback address is refused even with the right token.
    if (!lan.empty()) {
        client::PoseClient remote;
        ASSERT_TRUE(remote.connect(lan, pose_port_, 5s, err)) << err;
        v1::ControlRequest req;
        req.set_token(kToken);
        req.mutable_reload();
        v1::ControlReply reply;
        ASSERT_TRUE(remote.control(req, reply, 5s, err)) << err;
        EXPECT_FALSE(reply.ok());
        EXPECT_NE(reply.error().find("loopback"), std::string::npos) << reply.error();
    } else {
        std::cout << "[ note     ] no non-loopback IPv4 address: the loopback-only refusal is not exercised\n";
    }

    // Client limit: max_clients = 4, every one subscribed (so none is evictable: see
    // docs/security.md, "Connection slots"); the fifth gets Goodbye(SERVER_FULL).
    std::this_thread::sleep_for(300ms);  // the clients above are gone
    std::vector<client::PoseClient> held(4);
    for (auto& c : held) {
        ASSERT_TRUE(c.connect("127.0.0.1", pose_port_, 5s, err)) << err;
        ASSERT_TRUE(c.subscribe({}, 5s, err)) << err;
    }
    {
        client::PoseClient fifth;
        EXPECT_FALSE(fifth.connect("127.0.0.1", pose_port_, 5s, err));
        ASSERT_TRUE(fifth.goodbye().has_value()) << err;
        EXPECT_EQ(fifth.goodbye()->reason(), v1::GOODBYE_SERVER_FULL);
    }
    held.pop_back();
    std::this_thread::sleep_for(200ms);
    const auto c = counters();
    EXPECT_EQ(c.at("serve.rate_limited"), 1u);
    EXPECT_GE(c.at("serve.connections_rejected_full"), 1u);
    EXPECT_EQ(c.at("serve.control_refused_not_loopback"), lan.empty() ? 0u : 1u);
    const std::string log = daemon_->log();
    EXPECT_LE(count_lines(log, "too many requests"), 1u);
}

}  // namespace
}  // namespace mocap::itest
