// The file recorders against a disk that fills up, writes short, or loses its directory
// (serve/record_file.hpp): the files keep whole records only, the recorders say so once,
// count what they lose, stay bounded and resume. The disk is a FileWriter that fills up
// (recorder_fixture.hpp); the integration test Disk.* does the same on a real tmpfs.
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "bvh_outputs_fixture.hpp"
#include "recorder_fixture.hpp"
#include "serve/bvh_recorder.hpp"
#include "serve/raw_recorder.hpp"
#include "skeleton/bvh.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::expect_same;
using test::FillingDisk;
using test::raw_files;
using test::sample;
using test::StepClock;
using test::TempDir;

/// spdlog's lines while it lives.
class LogCapture {
public:
    LogCapture() : old_(spdlog::default_logger()) {
        spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink_));
    }
    ~LogCapture() { spdlog::set_default_logger(old_); }
    LogCapture(const LogCapture&) = delete;
    LogCapture& operator=(const LogCapture&) = delete;
    [[nodiscard]] int count(const std::string& needle) const {
        int n = 0;
        for (const auto& line : sink_->last_formatted())
            n += line.find(needle) != std::string::npos ? 1 : 0;
        return n;
    }
    [[nodiscard]] std::string all() const {
        std::string out;
        for (const auto& line : sink_->last_formatted())
            out += line;
        return out;
    }

private:
    std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink_ =
        std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(1000);
    std::shared_ptr<spdlog::logger> old_;
};

std::uint64_t counter(const CounterGroup& g, const char* name) {
    const auto v = g.value(name);
    EXPECT_TRUE(v.has_value()) << name;
    return v.value_or(0);
}

void push_all(RawRecorder& rec, std::uint64_t from, std::uint64_t count) {
    for (std::uint64_t k = from; k < from + count; ++k) {
        while (!rec.push(sample(k, false)))
            std::this_thread::sleep_for(1ms);  // test only: wait for ring room
    }
}

/// Reads a whole raw file; fails the test on a corrupt or cut record.
std::vector<SegmentSample> read_raw(const std::string& path) {
    std::vector<SegmentSample> out;
    RawRecordingReader reader;
    std::string err;
    EXPECT_TRUE(reader.open(path, &err)) << err;
    SegmentSample s;
    int r = 0;
    while ((r = reader.next(s, &err)) == 1)
        out.push_back(s);
    EXPECT_EQ(r, 0) << err;
    EXPECT_FALSE(reader.truncated()) << reader.truncation();
    return out;
}

TEST(RawRecorderDiskFull, PausesOnENOSPCKeepsWholeRecordsLogsOnceAndResumes) {
    LogCapture log;
    TempDir dir;
    StepClock clock;
    FillingDisk disk;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    c.flush_interval_s = 0;  // every pass of the writer writes
    c.rotate_s = 0;
    c.retry_min_s = 1;  // retries only when the test moves the clock
    c.retry_max_s = 2;
    c.max_buffer_bytes = 4000;
    RawRecorder rec(c, clock, disk);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    const auto& g = rec.counters();
    push_all(rec, 0, 20);
    ASSERT_TRUE(wait_until([&] { return counter(g, "samples_recorded") == 20; }));
    disk.capacity = static_cast<std::int64_t>(counter(g, "bytes_written")) + 1000;  // ~10 more samples fit
    push_all(rec, 20, 80);
    ASSERT_TRUE(wait_until([&] { return rec.paused(); }));
    EXPECT_EQ(counter(g, "disk_full"), 1u);
    EXPECT_EQ(counter(g, "write_pauses"), 1u);
    EXPECT_GE(disk.truncations.load(), 1);

    // The file ends on a whole record and holds exactly what was counted as recorded.
    const auto files = raw_files(dir.path);
    ASSERT_EQ(files.size(), 1u);
    EXPECT_EQ(fs::file_size(files[0]), counter(g, "bytes_written"));
    EXPECT_LE(fs::file_size(files[0]), static_cast<std::uint64_t>(disk.capacity.load()));
    const auto before = read_raw(files[0]);
    ASSERT_EQ(before.size(), counter(g, "samples_recorded"));
    ASSERT_GE(before.size(), 20u);
    for (std::size_t k = 0; k < before.size(); ++k)
        expect_same(sample(k, false), before[k]);

    // Still full: samples beyond the buffer bound are lost and counted; retries are counted,
    // not logged.
    push_all(rec, 100, 200);
    ASSERT_TRUE(wait_until([&] { return counter(g, "samples_lost") > 0; }));
    for (int i = 0; i < 3; ++i) {
        const auto errors = counter(g, "write_errors");
        clock.now += 2'000'000;
        ASSERT_TRUE(wait_until([&] { return counter(g, "write_errors") > errors; }));
    }
    EXPECT_TRUE(rec.paused());
    EXPECT_EQ(log.count("No space left on device"), 1) << log.all();

    // Room again: the next retry writes the buffer and recording goes on in the same file.
    disk.free_space();
    clock.now += 3'000'000;
    ASSERT_TRUE(wait_until([&] { return !rec.paused(); }));
    EXPECT_EQ(log.count("again"), 1) << log.all();
    push_all(rec, 300, 50);
    rec.stop();
    const auto after = read_raw(files[0]);
    EXPECT_EQ(after.size(), counter(g, "samples_recorded"));
    EXPECT_EQ(counter(g, "samples_recorded") + counter(g, "samples_lost") + counter(g, "samples_dropped"), 350u);
    EXPECT_EQ(fs::file_size(files[0]), counter(g, "bytes_written"));
    for (std::size_t i = 1; i < after.size(); ++i)
        EXPECT_LT(after[i - 1].imu.t_us, after[i].imu.t_us) << "in order, a gap where samples were lost";
    EXPECT_EQ(after.back().imu.t_us, sample(349, false).imu.t_us);
    EXPECT_EQ(log.count("No space left on device"), 1) << log.all();
}

// Issue 13, item 3: after a failed rotation (record directory removed) the buffer was never
// cleared and never retried, so memory grew with every sample for the daemon's lifetime.
TEST(RawRecorderDiskFull, ARemovedDirectoryBoundsTheBufferCountsTheLossAndRetries) {
    LogCapture log;
    TempDir dir;
    StepClock clock;
    RawRecorderConfig c;
    c.directory = (dir.path / "rec").string();
    fs::create_directories(c.directory);
    c.flush_interval_s = 0;
    c.rotate_bytes = 0;
    c.rotate_s = 1;  // the test moves the clock to rotate
    c.retry_min_s = 1;
    c.retry_max_s = 1;
    c.max_buffer_bytes = 3000;
    RawRecorder rec(c, clock);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    const auto& g = rec.counters();
    push_all(rec, 0, 40);
    ASSERT_TRUE(wait_until([&] { return counter(g, "samples_recorded") == 40; }));
    fs::remove_all(c.directory);
    clock.now += 1'500'000;  // rotate: the new file cannot be created
    ASSERT_TRUE(wait_until([&] { return rec.paused(); }));
    push_all(rec, 40, 1000);
    // Held while paused: at most max_buffer_bytes of records (each > 60 bytes); the rest is
    // lost and counted. Before the bound nothing was ever counted and the buffer only grew.
    constexpr std::uint64_t kMaxHeld = 3000 / 60 + 1;
    ASSERT_TRUE(wait_until([&] { return counter(g, "samples_lost") >= 1000 - kMaxHeld; }))
        << counter(g, "samples_lost");
    EXPECT_EQ(counter(g, "samples_recorded"), 40u);
    EXPECT_EQ(log.count("No such file or directory"), 1) << log.all();
    EXPECT_EQ(counter(g, "disk_full"), 0u);
    EXPECT_EQ(counter(g, "write_pauses"), 1u);

    // The directory comes back: the next retry opens a new file and writes what was held.
    fs::create_directories(c.directory);
    const auto files_before = counter(g, "files_opened");
    clock.now += 1'000'000;
    ASSERT_TRUE(wait_until([&] { return !rec.paused(); }));
    EXPECT_EQ(counter(g, "files_opened"), files_before + 1);
    push_all(rec, 1040, 20);
    rec.stop();
    EXPECT_EQ(counter(g, "samples_recorded") + counter(g, "samples_lost"), 1060u);
    const auto files = raw_files(c.directory);
    ASSERT_EQ(files.size(), 1u);
    const auto got = read_raw(files[0]);
    EXPECT_EQ(got.size(), counter(g, "samples_recorded") - 40);
    EXPECT_LE(got.size(), kMaxHeld + 20);
    EXPECT_GE(got.size(), 20u);
    expect_same(sample(1059, false), got.back());
}

TEST(RawRecorderDiskFull, ShortWritesStillWriteEveryRecord) {
    TempDir dir;
    StepClock clock;
    FillingDisk disk;
    disk.max_chunk = 7;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    c.flush_interval_s = 0;
    RawRecorder rec(c, clock, disk);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    push_all(rec, 0, 300);
    rec.stop();
    const auto files = raw_files(dir.path);
    ASSERT_EQ(files.size(), 1u);
    const auto got = read_raw(files[0]);
    ASSERT_EQ(got.size(), 300u);
    for (std::size_t k = 0; k < got.size(); ++k)
        expect_same(sample(k, false), got[k]);
    EXPECT_EQ(disk.truncations.load(), 0);
}

TEST(RawRecordingReader, AnUnparseableLastRecordIsSkippedWithAMessageOneInTheMiddleIsAnError) {
    TempDir dir;
    StepClock clock;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    RawRecorder rec(c, clock);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    push_all(rec, 0, 10);
    rec.stop();
    const std::string path = raw_files(dir.path).at(0);
    const std::string good = test::slurp(path);
    const std::string garbage("\x05\xff\xff\xff\xff\xff", 6);  // length 5, not a message
    { std::ofstream(path, std::ios::binary | std::ios::app) << garbage; }
    RawRecordingReader reader;
    ASSERT_TRUE(reader.open(path, &err)) << err;
    SegmentSample s;
    int n = 0;
    while (reader.next(s, &err) == 1)
        ++n;
    EXPECT_EQ(n, 10);
    EXPECT_TRUE(reader.truncated());
    EXPECT_EQ(reader.truncation(), "an unparseable last record of 5 bytes after sample 10, skipped");

    // The same garbage followed by good records: corruption, not a crash's tail.
    { std::ofstream(path, std::ios::binary | std::ios::app) << good.substr(sizeof kRawMagic); }
    RawRecordingReader mid;
    ASSERT_TRUE(mid.open(path, &err)) << err;
    n = 0;
    int r = 0;
    while ((r = mid.next(s, &err)) == 1)
        ++n;
    EXPECT_EQ(r, -1);
    EXPECT_EQ(n, 10);
    EXPECT_NE(err.find("unparseable record after sample 10"), std::string::npos) << err;
}

// --- BVH ---

struct BvhFile {
    std::uint64_t count = 0;  ///< what "Frames:" says
    std::uint64_t lines = 0;  ///< whole MOTION lines with every value
    bool whole = true;        ///< no partial line
};

BvhFile read_bvh(const std::string& path, std::size_t values) {
    BvhFile out;
    const std::string text = test::slurp(path);
    const auto at = text.find("Frames: ");
    EXPECT_NE(at, std::string::npos);
    out.count = std::stoull(text.substr(at + 8));
    std::size_t pos = text.find('\n', text.find("Frame Time:")) + 1;
    std::vector<double> scratch(values);
    while (pos < text.size()) {
        const auto nl = text.find('\n', pos);
        if (nl == std::string::npos) {
            out.whole = false;
            break;
        }
        if (!skeleton::parse_bvh_motion_line(std::string_view(text).substr(pos, nl - pos), scratch).empty())
            out.whole = false;
        ++out.lines;
        pos = nl + 1;
    }
    return out;
}

void publish_frames(BvhRecorder& r, const BvhFrameEncoder& e, std::uint64_t from, std::uint64_t count) {
    SubjectFrame f;
    skeleton::SkeletonPose p;
    for (std::uint64_t k = from; k < from + count; ++k) {
        test::make_pose(1, k, static_cast<std::uint16_t>(e.model().size()), f, p);
        r.publish(f, p);
    }
}

TEST(BvhRecorderDiskFull, AFullDiskStopsTheRecordingWithWholeLinesAndTheStopReplySaysWhy) {
    LogCapture log;
    TempDir dir;
    FillingDisk disk;
    const auto encoder = test::default_encoder();
    BvhRecorderConfig c;
    c.directory = dir.path.string();
    c.flush_interval_s = 0.01;
    BvhRecorder rec(c, encoder, disk);
    const auto& g = rec.counters();
    std::string err, path;
    ASSERT_TRUE(rec.start("", &err, &path)) << err;
    publish_frames(rec, encoder, 0, 5);
    ASSERT_TRUE(wait_until([&] { return counter(g, "frames_recorded") == 5; }));
    const auto size = fs::file_size(path);
    disk.capacity = static_cast<std::int64_t>(size + 600);  // a line is ~400 bytes: 1.5 lines fit
    disk.hold = true;  // all 10 frames are published while the recording still runs
    publish_frames(rec, encoder, 5, 10);
    disk.hold = false;
    ASSERT_TRUE(wait_until([&] { return !rec.recording(); })) << "the recording stops on ENOSPC";
    publish_frames(rec, encoder, 15, 5);  // not recording any more: ignored
    std::uint64_t frames = 0;
    EXPECT_FALSE(rec.stop(&err, &frames));
    EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
    EXPECT_NE(err.find("holds " + std::to_string(frames) + " whole frames"), std::string::npos) << err;
    const BvhFile f = read_bvh(path, encoder.values_per_frame());
    EXPECT_TRUE(f.whole);
    EXPECT_EQ(f.count, f.lines);
    EXPECT_EQ(f.lines, frames);
    EXPECT_GE(frames, 5u);
    EXPECT_LE(frames, 6u);
    EXPECT_EQ(counter(g, "frames_recorded"), frames);
    EXPECT_EQ(counter(g, "frames_recorded") + counter(g, "frames_lost"), 15u);
    EXPECT_EQ(counter(g, "disk_full"), 1u);
    EXPECT_EQ(counter(g, "recordings_failed"), 1u);
    EXPECT_EQ(log.count("No space left on device"), 1) << log.all();
    EXPECT_FALSE(rec.stop(&err));  // reported once

    // Still full: a new recording is refused with the reason and leaves no file behind.
    disk.capacity = 100;
    std::string second;
    EXPECT_FALSE(rec.start("", &err, &second));
    EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
    EXPECT_FALSE(fs::exists(dir.file("mocap-2.bvh")));

    // Room again: a new recording works.
    disk.free_space();
    ASSERT_TRUE(rec.start("", &err, &second)) << err;
    publish_frames(rec, encoder, 0, 3);
    ASSERT_TRUE(rec.stop(&err, &frames)) << err;
    EXPECT_EQ(frames, 3u);
    const BvhFile f2 = read_bvh(second, encoder.values_per_frame());
    EXPECT_TRUE(f2.whole);
    EXPECT_EQ(f2.count, 3u);
    EXPECT_EQ(f2.lines, 3u);
}

TEST(BvhRecorderDiskFull, ShortWritesStillWriteEveryLine) {
    TempDir dir;
    FillingDisk disk;
    disk.max_chunk = 7;
    const auto encoder = test::default_encoder();
    BvhRecorderConfig c;
    c.directory = dir.path.string();
    c.flush_interval_s = 0.01;
    BvhRecorder rec(c, encoder, disk);
    std::string err, path;
    ASSERT_TRUE(rec.start("", &err, &path)) << err;
    publish_frames(rec, encoder, 0, 20);
    std::uint64_t frames = 0;
    ASSERT_TRUE(rec.stop(&err, &frames)) << err;
    EXPECT_EQ(frames, 20u);
    const BvhFile f = read_bvh(path, encoder.values_per_frame());
    EXPECT_TRUE(f.whole);
    EXPECT_EQ(f.count, 20u);
    EXPECT_EQ(f.lines, 20u);
}

}  // namespace
}  // namespace mocap::serve
