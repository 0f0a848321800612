// Sink failover between two mocapd hosts of one site (docs/cluster.md, "Failures"): one
// nats-server with JetStream, hosts A and B both publishing to it, one simulated sink given
// the ordered host list A,B, and a subscriber on mocap.<site>.*.pose. Host A dies twice over,
// in separate tests: kill -9 (the kernel resets the connection) and SIGSTOP (a silent host:
// the connection stays up and only the missing keepalives, docs/protocol.md §3.5, tell).
// Each time the sink moves to B and the subscriber's largest gap in that subject's poses must
// stay within 1.5 s (relaxed under the sanitizers, whose builds run several times slower).
// The calibration is kept: A calibrates the subject from the simulator's opening T-pose and
// shares it (docs/cluster.md, "Shared calibration"); B never calibrates by itself, and every
// pose B publishes after the failover carries A's calibration.
// The take survives too: both hosts publish the subject's raw samples to the JetStream stream
// MOCAP_RAW (docs/outputs.md, "Durable takes"). After the kill -9, the take replayed from
// the stream up to the kill holds every sample A had acknowledged, with no SYNC missing; B's
// samples follow on the same stream subject, after A's with no SYNC of both, and one hole
// between: what A received but had not yet stored, and what the sink sent while it moved.
#include <gtest/gtest.h>

#include <atomic>
#include <cinttypes>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>
#include <vector>

#include "harness.hpp"
#include "nats_harness.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr const char* kSite = "arena";
constexpr std::uint32_t kSubject = 5;
constexpr int kRateHz = 100;
constexpr std::uint64_t kNodes = 15;  // the simulated body: one raw sample per node per SYNC
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr auto kGapBound = 3000ms;  // sanitizer builds: the bound is the plain build's
#else
constexpr auto kGapBound = 1500ms;
#endif

/// Arrival times and SYNCs of one subject's pose frames, taken on a thread of its own.
class PoseTimeline {
public:
    PoseTimeline(std::uint16_t port, const std::string& subject) : sub_(port, subject), thread_([this] { run(); }) {}
    ~PoseTimeline() { stop(); }
    PoseTimeline(const PoseTimeline&) = delete;
    PoseTimeline& operator=(const PoseTimeline&) = delete;

    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    std::size_t frames_after(Clock::time_point t) {
        const std::lock_guard<std::mutex> lock(mutex_);
        std::size_t n = 0;
        for (const auto& a : arrivals_)
            n += a > t ? 1 : 0;
        return n;
    }
    std::size_t size() {
        const std::lock_guard<std::mutex> lock(mutex_);
        return arrivals_.size();
    }
    /// Frames after `t`, and how many of them had every segment calibrated.
    std::pair<std::size_t, std::size_t> calibrated_after(Clock::time_point t) {
        const std::lock_guard<std::mutex> lock(mutex_);
        std::size_t n = 0, calibrated = 0;
        for (std::size_t i = 0; i < arrivals_.size(); ++i) {
            if (arrivals_[i] <= t) continue;
            ++n;
            calibrated += calibrated_[i] ? 1 : 0;
        }
        return {n, calibrated};
    }
    /// The longest time between two consecutive frames, and the most SYNCs one step skipped.
    std::pair<std::chrono::milliseconds, std::uint64_t> largest_gap() {
        const std::lock_guard<std::mutex> lock(mutex_);
        std::chrono::milliseconds worst{0};
        std::uint64_t frames = 0;
        for (std::size_t i = 1; i < arrivals_.size(); ++i) {
            worst =
                std::max(worst, std::chrono::duration_cast<std::chrono::milliseconds>(arrivals_[i] - arrivals_[i - 1]));
            if (syncs_[i] > syncs_[i - 1]) frames = std::max(frames, syncs_[i] - syncs_[i - 1] - 1);
        }
        return {worst, frames};
    }

private:
    void run() {
        while (!stop_) {
            auto m = sub_.next(100ms);
            if (!m) continue;
            const auto now = Clock::now();
            const v1::SkeletonFrame f = decode_pose_payload(m->second);
            EXPECT_EQ(m->first, std::string("mocap.") + kSite + "." + std::to_string(f.subject_id()) + ".pose");
            if (f.subject_id() != kSubject) continue;
            const std::lock_guard<std::mutex> lock(mutex_);
            bool calibrated = f.flags_size() > 0;
            for (int i = 0; i < f.flags_size(); ++i)
                calibrated = calibrated && (f.flags(i) & v1::SEGMENT_CALIBRATED) != 0;
            arrivals_.push_back(now);
            syncs_.push_back(f.sync());
            calibrated_.push_back(calibrated);
        }
    }

    NatsSubscriber sub_;
    std::mutex mutex_;
    std::vector<Clock::time_point> arrivals_;
    std::vector<std::uint64_t> syncs_;
    std::vector<bool> calibrated_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

class Failover : public ::testing::Test {
protected:
    struct Host {
        std::string id;
        std::uint16_t sink_port = 0, pose_port = 0;
        std::unique_ptr<Process> daemon;
        bool killed = false;
    };

    void SetUp() override {
        if (!have_nats_server())
            GTEST_SKIP() << "no nats-server binary at " << nats_server_bin() << " (setup.sh installs it)";
        nats_port_ = free_port();
        nats_ = start_nats(nats_port_, dir_.file("nats.log"), {"-js", "-sd", dir_.file("js")});
        start_host(a_, "host-a", "t-pose");
        start_host(b_, "host-b", "off");
        sim_ = std::make_unique<Process>(
            std::vector<std::string>{
                MOCAP_SIM_BIN, "stream", "--connect",
                "127.0.0.1:" + std::to_string(a_.sink_port) + ",127.0.0.1:" + std::to_string(b_.sink_port),
                "--subjects", "1", "--first-sink-id", std::to_string(kSubject), "--nodes", "15", "--mode", "quat",
                "--rate", std::to_string(kRateHz), "--duration", "120", "--sink-rate-stats"},
            dir_.file("sim.log"));
    }

    void TearDown() override {
        if (sim_) sim_->stop();
        for (Host* h : {&a_, &b_}) {
            if (!h->daemon) continue;
            if (HasFailure()) std::cerr << "--- " << h->id << " log ---\n" << h->daemon->log();
            if (!h->killed) {
                EXPECT_EQ(h->daemon->stop(10s), 0) << h->id << " must exit 0 on SIGTERM";
            }
        }
        if (HasFailure() && sim_) std::cerr << "--- simulator ---\n" << sim_->log();
    }

    /// auto_calibrate: A calibrates from the opening T-pose, B only ever gets A's calibration.
    void start_host(Host& h, const std::string& id, const std::string& auto_calibrate) {
        h.id = id;
        h.sink_port = free_port();
        h.pose_port = free_port();
        const std::string cal_dir = dir_.file(id + "-cal");
        std::filesystem::create_directories(cal_dir);
        std::ostringstream cfg;
        cfg << "[log]\nlevel = \"info\"\nstats_interval_s = 0\n"
            << "[ingest]\nsink_listen = \"127.0.0.1:" << h.sink_port << "\"\n"
            << "[pipeline]\nworkers = 1\nmax_subjects = 8\n"
            << "[skeleton]\ncalibration_dir = \"" << cal_dir << "\"\nauto_calibrate = \"" << auto_calibrate << "\"\n"
            << "[serve]\npose_listen = \"127.0.0.1:" << h.pose_port << "\"\n"
            << "[outputs]\nbvh_live = false\n[http]\nenabled = false\n"
            << cluster_section(nats_port_, kSite, id, cluster_credentials());
        const std::string path = dir_.file(id + ".toml");
        write_file(path, cfg.str());
        h.daemon = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", path},
                                             dir_.file(id + ".log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(h.sink_port, 10s)) << h.daemon->log();
    }

    /// Streams through A until B holds A's calibration of the subject, stops A with `sig`,
    /// and returns the subscriber's largest gap once B has served two more seconds of it.
    std::pair<std::chrono::milliseconds, std::uint64_t> fail_over(int sig) {
        PoseTimeline poses(nats_port_, std::string("mocap.") + kSite + ".*.pose");
        EXPECT_TRUE(wait_until([&] { return poses.size() >= 2u * kRateHz; }, 60s)) << "2 s of poses through A";
        EXPECT_GE(wait_stats_counter(
                      a_.pose_port, "skeleton.calibrations_ok", [](auto v) { return v >= 1; }, 30s),
                  1u)
            << "A calibrates the subject from the simulator's opening T-pose";
        EXPECT_GE(wait_stats_counter(
                      b_.pose_port, "calibration_kv.received", [](auto v) { return v >= 1; }, 30s),
                  1u)
            << "B receives A's calibration through the bucket";
        EXPECT_GT(stats_counter(a_.pose_port, "ingest_tcp.packets"), 0u);
        EXPECT_EQ(stats_counter(b_.pose_port, "ingest_tcp.packets"), 0u) << "the sink starts on the first host";

        // What A's raw stream publisher had acknowledged (stored by JetStream), read just
        // before the fault: the take must hold at least this much of A's part.
        EXPECT_GE(wait_stats_counter(
                      a_.pose_port, "cluster.raw_samples_acked", [](auto v) { return v >= 2 * kNodes * kRateHz; }, 30s),
                  2 * kNodes * kRateHz)
            << "A acknowledges the raw samples of the take while it runs";
        a_acked_ = stats_counter(a_.pose_port, "cluster.raw_samples_acked");
        const auto t_acked = Clock::now();
        a_.daemon->signal(sig);
        const auto t_fault = Clock::now();
        acked_before_fault_ = std::chrono::duration_cast<std::chrono::microseconds>(t_fault - t_acked);
        if (sig == SIGKILL) {
            a_.killed = true;
            EXPECT_TRUE(a_.daemon->wait(10s).has_value()) << "host A did not die";
        }
        // A receives nothing after this (it is dead or frozen), B nothing before it: the sink
        // comes to B only after its reconnect back-off of 100 ms.
        dead_wall_us_ =
            std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
                .count();
        EXPECT_TRUE(wait_until([&] { return poses.frames_after(t_fault) >= 2u * kRateHz; }, 60s))
            << "B serves the subject: 2 s of poses after the fault";
        poses.stop();  // before a frozen A could be woken
        EXPECT_GT(stats_counter(b_.pose_port, "ingest_tcp.packets"), 0u) << "the sink moved to B";
        const auto [after, calibrated] = poses.calibrated_after(t_fault);
        EXPECT_EQ(calibrated, after) << "every pose B publishes carries A's calibration";
        EXPECT_EQ(stats_counter(b_.pose_port, "skeleton.calibrations_ok"), 0u) << "B never calibrated by itself";
        EXPECT_GE(stats_counter(b_.pose_port, "skeleton.calibrations_shared"), 1u);
        return poses.largest_gap();
    }

    /// What `mocapd --jetstream` replays of the subject's take: its sample count and the SYNC
    /// of every frame it solved. `range` selects by received time (--from/--to).
    struct Replayed {
        std::uint64_t samples = 0;
        std::vector<std::uint64_t> syncs;
        std::uint64_t reordered = 0;  // put back in SYNC order (daemon/sync_order.hpp)
        std::uint64_t too_late = 0;
    };
    Replayed replay_take(const std::string& name, const std::vector<std::string>& range) {
        std::vector<std::string> argv{MOCAPD_BIN, "--config", dir_.file("host-b.toml")};
        for (const auto& a : jetstream_replay_args(nats_port_, kSubject))
            argv.push_back(a);
        argv.insert(argv.end(), range.begin(), range.end());
        argv.insert(argv.end(), {"--angles-out", dir_.file(name + ".csv")});
        Process p(argv, dir_.file(name + ".log"));
        const int rc = p.wait(120s).value_or(-1);
        EXPECT_EQ(rc, 0) << p.log();
        const auto samples = replayed_samples(p.log());
        EXPECT_TRUE(samples) << p.log();
        if (rc != 0 || !samples) return {};
        std::smatch m;
        const std::string log = p.log();
        static const std::regex order_re("([0-9]+) reordered, ([0-9]+) too late");
        EXPECT_TRUE(std::regex_search(log, m, order_re)) << log;
        return {*samples, csv_syncs(read_file(dir_.file(name + ".csv"))), m.size() == 3 ? std::stoull(m[1]) : 0,
                m.size() == 3 ? std::stoull(m[2]) : 0};
    }

    /// Epoch seconds with six decimals, as --from/--to take them.
    static std::string epoch_text(std::int64_t us) {
        char text[32];
        std::snprintf(text, sizeof text, "%" PRId64 ".%06" PRId64, us / 1'000'000, us % 1'000'000);
        return text;
    }

    TempDir dir_;
    std::uint16_t nats_port_ = 0;
    std::unique_ptr<Process> nats_, sim_;
    Host a_, b_;
    std::uint64_t a_acked_ = 0;                       // A's cluster.raw_samples_acked just before the fault
    std::chrono::microseconds acked_before_fault_{};  // from that reply to the signal
    std::int64_t dead_wall_us_ = 0;                   // wall clock once A stopped receiving
};

/// Frames missing between consecutive SYNCs (the SYNCs are strictly increasing: a test failure
/// otherwise).
std::uint64_t missing_syncs(const std::vector<std::uint64_t>& syncs) {
    std::uint64_t missing = 0;
    for (std::size_t i = 1; i < syncs.size(); ++i) {
        EXPECT_GT(syncs[i], syncs[i - 1]) << "row " << i << ": each SYNC once, in order";
        if (syncs[i] > syncs[i - 1]) missing += syncs[i] - syncs[i - 1] - 1;
    }
    return missing;
}

TEST_F(Failover, KilledHostTheSinkMovesToTheNextWithinTheBound) {
    const auto [gap, frames] = fail_over(SIGKILL);
    std::cout << "[ metrics  ] kill -9 host A: largest pose gap " << gap.count() << " ms, " << frames
              << " SYNCs skipped in one step, at " << kRateHz << " Hz\n";
    EXPECT_LE(gap, kGapBound) << "the subscriber's largest gap when the sink's host is killed";

    // The take: the sink stops, B settles what it still owes the stream.
    sim_->stop();
    const std::uint64_t b_queued = stats_counter(b_.pose_port, "cluster.raw_samples_queued");
    const std::uint64_t b_acked = wait_stats_counter(
        b_.pose_port, "cluster.raw_samples_acked", [&](auto v) { return v >= b_queued; }, 30s);
    EXPECT_EQ(b_acked, b_queued) << "B stores every raw sample it received";
    EXPECT_EQ(stats_counter(b_.pose_port, "cluster.raw_samples_dropped"), 0u);
    EXPECT_EQ(stats_counter(b_.pose_port, "cluster.raw_samples_failed"), 0u);

    // A's part, up to the kill: every acknowledged sample, every SYNC from the first, each
    // frame whole but possibly the last (A's last message may end mid-SYNC).
    const Replayed a_part = replay_take("a-part", {"--to", epoch_text(dead_wall_us_)});
    EXPECT_GE(a_part.samples, a_acked_) << "every sample A had acknowledged is in the take";
    ASSERT_GE(a_part.syncs.size(), a_acked_ / kNodes);
    // The simulator counts the SYNCs it skipped itself (a late timer on a loaded host).
    const std::uint64_t sim_skipped = sim_syncs_skipped(sim_->log()).value_or(0);
    const std::uint64_t a_missing = missing_syncs(a_part.syncs);
    EXPECT_LE(a_missing, sim_skipped) << "A's part of the take has no hole but what the sink never sent";
    EXPECT_GE(a_part.samples, (a_part.syncs.size() - 1) * kNodes) << "every frame but the last is complete";

    // B's part, after the kill: exactly what B acknowledged, no hole either.
    const Replayed b_part = replay_take("b-part", {"--from", epoch_text(dead_wall_us_)});
    EXPECT_EQ(b_part.samples, b_acked) << "B's part of the take is what B stored";
    ASSERT_FALSE(b_part.syncs.empty());
    const std::uint64_t b_missing = missing_syncs(b_part.syncs);
    EXPECT_LE(b_missing, sim_skipped) << "B's part of the take has no hole but what the sink never sent";

    // The whole take, by subject alone, reads both parts in order: A's, then B's, no SYNC in
    // both (the sink sends each packet to one host), one hole at the switch.
    const Replayed whole = replay_take("whole", {});
    EXPECT_EQ(whole.samples, a_part.samples + b_part.samples);
    ASSERT_FALSE(a_part.syncs.empty());
    EXPECT_LT(a_part.syncs.back(), b_part.syncs.front()) << "no overlap: B's samples begin after A's end";
    const std::uint64_t hole = b_part.syncs.front() - a_part.syncs.back() - 1;
    EXPECT_EQ(missing_syncs(whole.syncs), a_missing + hole + b_missing) << "the switch is the take's only hole";
    EXPECT_LE(hole * 1000 / kRateHz, static_cast<std::uint64_t>(kGapBound.count()))
        << "the take's hole at the switch stays within the subscriber's bound";
    std::cout << "[ metrics  ] kill -9 host A: take: A acknowledged " << a_acked_ << " samples ("
              << acked_before_fault_.count() << " us before the kill), the stream holds " << a_part.samples << " of A ("
              << a_part.syncs.size() << " SYNCs, " << a_part.samples - a_acked_ << " beyond the last ack read) and "
              << b_part.samples << " of B (" << b_part.syncs.size() << " SYNCs); hole at the switch " << hole
              << " SYNCs\n";
}

TEST_F(Failover, FrozenHostIsNoticedByItsSilenceAndTheSinkMovesOn) {
    const auto [gap, frames] = fail_over(SIGSTOP);
    a_.daemon->signal(SIGCONT);
    std::cout << "[ metrics  ] SIGSTOP host A: largest pose gap " << gap.count() << " ms, " << frames
              << " SYNCs skipped in one step, at " << kRateHz << " Hz\n";
    EXPECT_LE(gap, kGapBound) << "the subscriber's largest gap when the sink's host freezes";

    // The take. A wakes, reads what the sink wrote to it before moving on (its socket kept
    // it), sees the connection closed, and publishes those samples after B's first ones.
    EXPECT_GE(wait_stats_counter(
                  a_.pose_port, "ingest_tcp.connections_closed", [](auto v) { return v >= 1; }, 60s),
              1u)
        << "A, awake, finds the sink gone";
    const std::uint64_t a_queued = stats_counter(a_.pose_port, "cluster.raw_samples_queued");
    const std::uint64_t a_acked = wait_stats_counter(
        a_.pose_port, "cluster.raw_samples_acked", [&](auto v) { return v >= a_queued; }, 60s);
    EXPECT_GE(a_acked, a_queued) << "A stores what it received, late";
    sim_->stop();
    const std::uint64_t b_queued = stats_counter(b_.pose_port, "cluster.raw_samples_queued");
    const std::uint64_t b_acked = wait_stats_counter(
        b_.pose_port, "cluster.raw_samples_acked", [&](auto v) { return v >= b_queued; }, 60s);
    EXPECT_GE(b_acked, b_queued);

    // Replayed by subject alone, the take has every SYNC once and in order: A's late samples
    // go back into the hole at the switch instead of handing the filters a time that runs
    // backwards.
    const Replayed whole = replay_take("whole", {});
    ASSERT_FALSE(whole.syncs.empty());
    const std::uint64_t sim_skipped = sim_syncs_skipped(sim_->log()).value_or(0);
    const std::uint64_t missing = missing_syncs(whole.syncs);  // fails on a SYNC out of order
    EXPECT_GT(whole.reordered, 0u) << "A's late samples were stored after B's: the case this test is for";
    EXPECT_EQ(whole.too_late, 0u);
    EXPECT_GE(whole.samples, a_acked + b_acked) << "every sample either host acknowledged is in the take";
    EXPECT_LE(missing * 1000 / kRateHz, static_cast<std::uint64_t>(kGapBound.count()) + sim_skipped * 1000 / kRateHz)
        << "the take's holes stay within the subscriber's bound";
    std::cout << "[ metrics  ] SIGSTOP host A: take: " << whole.samples << " samples, " << whole.reordered
              << " of A's stored after B's put back in SYNC order, " << missing << " SYNCs missing\n";
}

}  // namespace
}  // namespace mocap::itest
