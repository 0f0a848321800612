// Takes (serve/take_recorder.hpp): a take's raw file holds every sample pushed while it ran,
// its sidecar the metadata, and the rules of one take at a time hold.
#include "serve/take_recorder.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "recorder_fixture.hpp"

namespace mocap::serve {
namespace {

using test::expect_same;
using test::sample;
using test::StepClock;
using test::TempDir;
namespace fs = std::filesystem;

struct Fixture {
    TempDir dir;
    StepClock clock;
    TakeStore store{dir.file("takes")};
    TakeRecorder recorder{store, config(), clock};

    TakeRecorderConfig config() {
        fs::create_directories(dir.path / "cal");
        std::ofstream(dir.path / "cal" / "calibration-subject-2.toml") << "# calibration of subject 2\n";
        std::ofstream(dir.path / "cal" / "other.toml") << "not a calibration\n";
        TakeRecorderConfig c;
        c.raw.flush_interval_s = 0.05;
        c.raw.ring_capacity = 1024;
        c.filter = "madgwick";
        c.calibration_dir = (dir.path / "cal").string();
        return c;
    }
};

TEST(TakeRecorder, RecordsOnlyWhileATakeRunsAndWritesItsMetadata) {
    Fixture f;
    f.recorder.push(sample(0, false));  // no take: not recorded anywhere
    const ControlResult started = f.recorder.start("walk", "first try");
    ASSERT_TRUE(started.ok) << started.error;
    EXPECT_EQ(started.take, "walk");
    EXPECT_TRUE(f.recorder.running());
    EXPECT_TRUE(f.store.find("walk")->recording);
    EXPECT_EQ(f.store.find("walk")->meta.stop_us, 0) << "the start sidecar has no stop";
    std::vector<SegmentSample> pushed;
    for (std::uint64_t k = 1; k <= 300; ++k) {
        pushed.push_back(sample(k, k % 2 == 0));
        if (k % 100 == 0) pushed.back().subject_id = 9;
        f.recorder.push(pushed.back());
    }
    f.clock.now += 3'000'000;
    const ControlResult stopped = f.recorder.stop();
    ASSERT_TRUE(stopped.ok) << stopped.error;
    EXPECT_EQ(stopped.take, "walk");
    f.recorder.push(sample(301, false));  // after the stop: not recorded

    const auto take = f.store.find("walk");
    ASSERT_TRUE(take);
    EXPECT_FALSE(take->recording);
    EXPECT_EQ(take->meta.stop_us - take->meta.start_us, 3'000'000);
    EXPECT_EQ(take->meta.subjects, (std::vector<std::uint32_t>{2, 9}));
    EXPECT_EQ(take->meta.calibration, (std::vector<std::string>{"calibration-subject-2.toml"}));
    EXPECT_TRUE(fs::exists(f.store.dir("walk") + "/calibration-subject-2.toml"));
    EXPECT_EQ(take->meta.filter, "madgwick");
    EXPECT_EQ(take->meta.notes, "first try");
    EXPECT_EQ(take->meta.samples, 300u);
    EXPECT_EQ(take->meta.samples_lost, 0u);
    ASSERT_EQ(take->raw_files.size(), 1u) << "one raw file per take";

    RawRecordingReader reader;
    std::string error;
    ASSERT_TRUE(reader.open(take->raw_files[0], &error)) << error;
    SegmentSample got;
    for (const SegmentSample& want : pushed) {
        ASSERT_EQ(reader.next(got, &error), 1) << error;
        expect_same(got, want);
    }
    EXPECT_EQ(reader.next(got, &error), 0);
    EXPECT_FALSE(reader.truncated());
    EXPECT_EQ(f.recorder.counters().value("samples_recorded"), 300u);
    EXPECT_EQ(f.recorder.counters().value("takes_stopped"), 1u);
}

TEST(TakeRecorder, OneTakeAtATimeWithValidNamesAndBoundedNotes) {
    Fixture f;
    EXPECT_FALSE(f.recorder.stop().ok) << "nothing runs";
    EXPECT_FALSE(f.recorder.start("../up", "").ok);
    EXPECT_FALSE(f.recorder.start("a/b", "").ok);
    EXPECT_FALSE(f.recorder.start("n", std::string(kMaxTakeNotesBytes + 1, 'x')).ok);
    EXPECT_TRUE(f.store.list().empty()) << "a refused start leaves nothing";
    ASSERT_TRUE(f.recorder.start("n", std::string(kMaxTakeNotesBytes, 'x')).ok);
    const ControlResult second = f.recorder.start("other", "");
    EXPECT_FALSE(second.ok);
    EXPECT_EQ(second.error, "take 'n' is running; stop it first");
    ASSERT_TRUE(f.recorder.stop().ok);
    EXPECT_FALSE(f.recorder.start("n", "").ok) << "the name is taken";
    EXPECT_EQ(f.recorder.counters().value("takes_refused"), 6u);
}

TEST(TakeRecorder, AStartIsRefusedWhileTheDiskHasLessThanTheReserveFree) {
    TempDir dir;
    StepClock clock;
    TakeStore store{dir.file("takes")};
    TakeRecorderConfig c;
    c.raw.flush_interval_s = 0.05;
    c.raw.ring_capacity = 1024;
    c.min_free_bytes = std::uint64_t{1} << 60;  // more than any disk of this machine has free
    TakeRecorder short_of_space{store, c, clock};
    const ControlResult refused = short_of_space.start("big", "");
    EXPECT_FALSE(refused.ok);
    EXPECT_NE(refused.error.find("not enough free space for a take"), std::string::npos) << refused.error;
    EXPECT_NE(refused.error.find("take_start_min_free_mb"), std::string::npos) << refused.error;
    EXPECT_FALSE(short_of_space.running());
    EXPECT_TRUE(store.list().empty()) << "a refused start leaves nothing";
    EXPECT_EQ(short_of_space.counters().value("takes_refused"), 1u);
    EXPECT_EQ(short_of_space.counters().value("takes_refused_disk_full"), 1u);
    c.min_free_bytes = 0;  // no check
    TakeRecorder unchecked{store, c, clock};
    ASSERT_TRUE(unchecked.start("big", "").ok);
    ASSERT_TRUE(unchecked.stop().ok);
    EXPECT_EQ(unchecked.counters().value("takes_refused_disk_full"), 0u);
}

TEST(TakeRecorder, DefaultNamesFollowTheStartTimeAndNeverCollide) {
    Fixture f;
    f.clock.now = 1'796'227'835'000'000;  // 2026-12-02 16:10:35 UTC
    const ControlResult a = f.recorder.start("", "");
    ASSERT_TRUE(a.ok) << a.error;
    ASSERT_TRUE(f.recorder.stop().ok);
    const ControlResult b = f.recorder.start("", "");
    ASSERT_TRUE(b.ok) << b.error;
    ASSERT_TRUE(f.recorder.stop().ok);
    EXPECT_EQ(a.take, "take-20261202-161035");
    EXPECT_EQ(b.take, "take-20261202-161035-2");
}

TEST(TakeRecorder, AKilledDaemonLeavesATakeThatListsAndReads) {
    // What a SIGKILL leaves: the start sidecar, and a raw file with whatever was flushed
    // (here cut in the middle of a record).
    Fixture f;
    ASSERT_TRUE(f.recorder.start("cut", "").ok);
    for (std::uint64_t k = 0; k < 50; ++k)
        f.recorder.push(sample(k, false));
    ASSERT_TRUE(f.recorder.stop().ok);
    TakeMeta meta = f.store.find("cut")->meta;
    meta.stop_us = 0;  // the sidecar as it was before the stop
    std::string error;
    ASSERT_TRUE(f.store.save(meta, &error)) << error;
    const std::string raw = f.store.find("cut")->raw_files.at(0);
    fs::resize_file(raw, fs::file_size(raw) - 7);

    const auto take = f.store.find("cut");
    ASSERT_TRUE(take);
    EXPECT_EQ(take->meta.stop_us, 0);
    RawRecordingReader reader;
    ASSERT_TRUE(reader.open(raw, &error)) << error;
    SegmentSample got;
    int n = 0;
    while (reader.next(got, &error) == 1)
        ++n;
    EXPECT_EQ(n, 49);
    EXPECT_TRUE(reader.truncated());
}

}  // namespace
}  // namespace mocap::serve
