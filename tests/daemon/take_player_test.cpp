// TakePlayer (daemon/take_player.hpp) on hostile raw files, and PlayPacer (daemon/play_pacer.hpp).
//
// The player runs on a real io_context and the daemon's wall clock: its waits are real steady
// timers. So the tests never wait for a fixed time: they run the io_context until the event
// they expect (every sample handed on, a number of passes) or a generous deadline, and bound
// what they check by the time that actually passed (a loaded machine only makes a run slower,
// which these bounds allow).
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "daemon/play_pacer.hpp"
#include "daemon/take_player.hpp"
#include "daemon/wall_clock.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap::daemon {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr std::int64_t kHour = 3'600'000'000;
constexpr std::int64_t k31Years = 31LL * 365 * 24 * kHour;
constexpr std::int64_t kPeriod = 10'000;  // 100 Hz
constexpr int kNodes = 3;

class TempFile {
public:
    TempFile() {
        std::random_device rd;
        path_ = fs::temp_directory_path() / ("take_player_test_" + std::to_string(rd()) + ".mocapraw");
    }
    ~TempFile() {
        std::error_code ec;
        fs::remove(path_, ec);
    }
    TempFile(const TempFile&) = delete;
    TempFile& operator=(const TempFile&) = delete;
    [[nodiscard]] std::string path() const { return path_.string(); }

private:
    fs::path path_;
};

/// One instant of kNodes samples of subject 1 (received and sample instant as given).
void add_instant(std::vector<SegmentSample>& out, std::uint64_t sync, std::int64_t t_us, std::int64_t received_us) {
    for (int n = 0; n < kNodes; ++n) {
        SegmentSample s;
        s.subject_id = 1;
        s.node_id = static_cast<std::uint8_t>(n + 1);
        s.segment_index = static_cast<std::uint16_t>(n);
        s.sync = sync;
        s.imu.t_us = t_us;
        s.imu.accel_m_s2 = {0.0F, 0.0F, 9.81F};
        s.times.received_us = received_us;
        s.times.sink_send_us =
            received_us >= std::numeric_limits<std::int64_t>::min() + 1000 ? received_us - 1000 : received_us;
        out.push_back(s);
    }
}

/// `instants` instants at 100 Hz from sync 1000; from instant `step_at` on, receive time and
/// sample instant are moved by `step_us` (0 = none). with_sync false: every SYNC is 0.
std::vector<SegmentSample> take(int instants, int step_at, std::int64_t step_us, bool with_sync = true) {
    std::vector<SegmentSample> out;
    const std::int64_t t0 = 1'800'000'000'000'000;
    for (int k = 0; k < instants; ++k) {
        const std::int64_t t = t0 + k * kPeriod + (k >= step_at ? step_us : 0);
        add_instant(out, with_sync ? 1000 + static_cast<std::uint64_t>(k) : 0, t, t + 2000);
    }
    return out;
}

void write_take(const std::string& path, const std::vector<SegmentSample>& samples) {
    std::string file(serve::kRawMagic, sizeof serve::kRawMagic);
    for (const auto& s : samples)
        serve::append_raw_sample_record(s, file);
    std::ofstream(path, std::ios::binary) << file;
}

struct Played {
    std::int64_t at_us;  // wall clock when routed
    SegmentSample s;
};

class PlayerRun {
public:
    PlayerRun(const std::string& path, bool loop) {
        PlayOptions o;
        o.files = {path};
        o.loop = loop;
        player_ = std::make_unique<TakePlayer>(io_, o, clock_, [this](const SegmentSample& s) {
            played_.push_back({clock_.now_us(), s});
        });
        started_us_ = clock_.now_us();
        std::string error;
        started_ = player_->start(&error);
        EXPECT_TRUE(started_) << error;
    }
    /// Runs the player until `done()` or the deadline; true if done.
    template <class Done>
    bool run_until(Done done, std::chrono::seconds deadline) {
        const auto end = std::chrono::steady_clock::now() + deadline;
        while (started_ && !done() && std::chrono::steady_clock::now() < end)
            io_.run_one_for(50ms);
        return done();
    }
    [[nodiscard]] std::int64_t elapsed_us() const { return clock_.now_us() - started_us_; }

    asio::io_context io_;
    WallClock clock_;
    std::unique_ptr<TakePlayer> player_;
    std::vector<Played> played_;
    std::int64_t started_us_ = 0;
    bool started_ = false;
};

// Before: the player waited the hour (or the 31 years) before the second half of the take.
class ForwardJump : public ::testing::TestWithParam<std::int64_t> {};

TEST_P(ForwardJump, IsPlayedAsTheSyncSaysCountedAndLoggedOnce) {
    TempFile f;
    const auto samples = take(40, 20, GetParam());
    write_take(f.path(), samples);
    PlayerRun run(f.path(), false);
    ASSERT_TRUE(run.run_until([&] { return run.played_.size() == samples.size(); }, 60s))
        << "played " << run.played_.size() << " of " << samples.size() << " within 60 s";
    EXPECT_EQ(run.player_->gaps_clamped(), 1u);
    EXPECT_EQ(run.player_->steps_back(), 0u);
    // Paced by the SYNC: the jump costs one period, so the sample instants handed on are
    // 10 ms apart across it as everywhere else.
    const std::int64_t across = run.played_[20 * kNodes].s.imu.t_us - run.played_[20 * kNodes - 1].s.imu.t_us;
    EXPECT_EQ(across, kPeriod);
}

INSTANTIATE_TEST_SUITE_P(TakePlayer, ForwardJump, ::testing::Values(kHour, k31Years));

// Without a SYNC to pace by, the gap is clamped to max_gap_s (1 s).
TEST(TakePlayer, AnHourGapWithoutSyncIsPlayedAsTheBound) {
    TempFile f;
    const auto samples = take(40, 20, kHour, /*with_sync=*/false);
    write_take(f.path(), samples);
    PlayerRun run(f.path(), false);
    ASSERT_TRUE(run.run_until([&] { return run.played_.size() == samples.size(); }, 60s))
        << "played " << run.played_.size() << " of " << samples.size() << " within 60 s";
    EXPECT_EQ(run.player_->gaps_clamped(), 1u);
    const std::int64_t across = run.played_[20 * kNodes].s.imu.t_us - run.played_[20 * kNodes - 1].s.imu.t_us;
    EXPECT_EQ(across, 1'000'000);
    // Due 19 periods and the bound after the play began, never sooner (a late host only
    // delays it; 1 ms for the wall clock against the timer's steady one).
    EXPECT_GE(run.played_[20 * kNodes].at_us - run.started_us_, 19 * kPeriod + 1'000'000 - 1000)
        << "the bound is still waited";
}

// Before: after the step every remaining sample was due at once (played unpaced).
TEST(TakePlayer, AClockStepBackwardsKeepsThePace) {
    for (const bool with_sync : {true, false}) {
        TempFile f;
        const auto samples = take(80, 20, -kHour, with_sync);
        write_take(f.path(), samples);
        PlayerRun run(f.path(), false);
        ASSERT_TRUE(run.run_until([&] { return run.played_.size() == samples.size(); }, 60s))
            << "played " << run.played_.size() << " of " << samples.size();
        EXPECT_EQ(run.player_->steps_back(), 1u) << "with_sync " << with_sync;
        // The last instant is due 79 periods after the play began, 78 without a SYNC (the step
        // back is then played as no wait; before: right after the step, 19 periods in); a late
        // host only delays it.
        EXPECT_GE(run.played_.back().at_us - run.started_us_, (with_sync ? 79 : 78) * kPeriod - 1000)
            << "with_sync " << with_sync;
        EXPECT_EQ(run.played_.back().s.imu.t_us - run.played_[20 * kNodes].s.imu.t_us, 59 * kPeriod)
            << "with_sync " << with_sync;
    }
}

/// Runs a looping take until `passes` passes began (or 60 s) and checks that they were paced:
/// a pass never begins sooner than kMinPassUs after the one before.
void expect_paced_loop(const std::vector<SegmentSample>& samples, std::uint64_t passes) {
    TempFile f;
    write_take(f.path(), samples);
    PlayerRun run(f.path(), true);
    ASSERT_TRUE(run.run_until([&] { return run.player_->passes() >= passes; }, 60s))
        << run.player_->passes() << " passes in 60 s";
    const std::uint64_t most = static_cast<std::uint64_t>(run.elapsed_us() / kMinPassUs) + 2;
    EXPECT_LE(run.player_->passes(), most) << "passes began within " << run.elapsed_us() << " us";
    for (std::size_t i = 1; i < run.played_.size(); ++i) {
        ASSERT_GE(run.played_[i].s.imu.t_us, run.played_[i - 1].s.imu.t_us) << "sample " << i;
        ASSERT_GE(run.played_[i].s.sync, run.played_[i - 1].s.sync) << "sample " << i;
    }
}

// Before: the span overflowed (undefined behaviour; in practice a negative shift) and every pass was due at once.
TEST(TakePlayer, ASpanThatOverflowsInt64LoopsPaced) {
    std::vector<SegmentSample> samples;
    add_instant(samples, 1, std::numeric_limits<std::int64_t>::min() + 5, std::numeric_limits<std::int64_t>::min() + 5);
    add_instant(samples, 2, 0, 0);
    add_instant(samples, 3, std::numeric_limits<std::int64_t>::max() - 5, std::numeric_limits<std::int64_t>::max() - 5);
    expect_paced_loop(samples, 5);
}

// Before: a take of zero duration looped 1 us apart, i.e. as fast as the CPU went.
TEST(TakePlayer, ATakeAtOneInstantLoopsPaced) {
    std::vector<SegmentSample> one_sync;
    add_instant(one_sync, 7, 5'000'000, 5'000'000);
    add_instant(one_sync, 7, 5'000'000, 5'000'000);
    expect_paced_loop(one_sync, 5);
    std::vector<SegmentSample> syncs_at_one_time;
    for (std::uint64_t k = 0; k < 4; ++k)
        add_instant(syncs_at_one_time, 100 + k, 5'000'000, 5'000'000);
    expect_paced_loop(syncs_at_one_time, 5);
}

TEST(PlayPacer, ARegularTakeIsPlayedAtItsOwnPaceWithNothingClamped) {
    // The committed recording of the real daemon (50 Hz, 15 nodes; its receive times jitter).
    serve::RawRecordingReader reader;
    std::string error;
    ASSERT_TRUE(reader.open(std::string(MOCAP_SOURCE_DIR) + "/tests/regression/data/walk.mocapraw", &error)) << error;
    PlayPacer pacer(1'000'000);
    SegmentSample s;
    std::int64_t first_t = 0, last_t = 0;
    std::int64_t previous = 0;
    bool first = true;
    while (reader.next(s, &error) == 1) {
        const PlayPacer::Due due = pacer.next(s);
        EXPECT_EQ(due.clamp, PlayPacer::Clamp::kNone) << "sample " << reader.samples_read();
        EXPECT_GE(due.offset_us, previous);
        previous = due.offset_us;
        if (first) first_t = s.imu.t_us;
        first = false;
        last_t = s.imu.t_us;
    }
    ASSERT_GT(last_t - first_t, 3'000'000);
    // Its sample instants step 1 to 52 ms apart (the simulated sink ran late now and then, at
    // 50 Hz): all of them are played as recorded, so the take lasts what it spans.
    EXPECT_NEAR(static_cast<double>(pacer.end_us()), static_cast<double>(last_t - first_t), 1000.0);
    EXPECT_GT(pacer.period_us(), 15'000);
    EXPECT_LT(pacer.period_us(), 35'000);
}

TEST(PlayPacer, AMissingStretchOfSyncsIsPlayedAsTheBoundAndSubjectsKeepTheirOwnTimeline) {
    PlayPacer pacer(1'000'000);
    std::vector<SegmentSample> a, b;
    for (int k = 0; k < 5; ++k)
        add_instant(a, 10 + static_cast<std::uint64_t>(k), k * 20'000, k * 20'000);
    for (auto& s : a)
        EXPECT_EQ(pacer.next(s).clamp, PlayPacer::Clamp::kNone);
    EXPECT_EQ(pacer.end_us(), 80'000);
    // Subject 2 joins where the take is; subject 1 then skips 10 s of SYNCs (a dropout).
    add_instant(b, 5000, 0, 80'000);
    for (auto& s : b) {
        s.subject_id = 2;
        EXPECT_EQ(pacer.next(s).offset_us, 80'000);
    }
    std::vector<SegmentSample> late;
    add_instant(late, 10 + 5 + 500, 10'100'000, 10'100'000);
    const PlayPacer::Due due = pacer.next(late.front());
    EXPECT_EQ(due.clamp, PlayPacer::Clamp::kGap);
    EXPECT_EQ(due.offset_us, 80'000 + 1'000'000);
    // An out-of-order sample of an older instant is due with the current one.
    std::vector<SegmentSample> old;
    add_instant(old, 12, 40'000, 10'100'000);
    EXPECT_EQ(pacer.next(old.front()).offset_us, 80'000 + 1'000'000);
}

}  // namespace
}  // namespace mocap::daemon
