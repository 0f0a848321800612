// BVH file recorder and repair; raw sample recorder and its reader.
#include "serve/bvh_recorder.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>
#include <vector>

#include "bvh_outputs_fixture.hpp"
#include "recorder_fixture.hpp"
#include "serve/raw_recorder.hpp"
#include "skeleton/bvh.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::expect_same;
using test::raw_files;
using test::sample;
using test::StepClock;
using test::TempDir;

void publish_frames(BvhRecorder& r, const BvhFrameEncoder& e, std::uint32_t subject, std::uint64_t from,
                    std::uint64_t count) {
    SubjectFrame f;
    skeleton::SkeletonPose p;
    for (std::uint64_t k = from; k < from + count; ++k) {
        test::make_pose(subject, k, static_cast<std::uint16_t>(e.model().size()), f, p);
        r.publish(f, p);
    }
}

TEST(BvhRecorder, WritesACompleteFileOfOneSubject) {
    TempDir dir;
    const auto encoder = test::default_encoder();
    BvhRecorderConfig c;
    c.directory = dir.path.string();
    BvhRecorder rec(c, encoder);
    publish_frames(rec, encoder, 1, 0, 3);  // not recording: ignored
    std::string err, path;
    ASSERT_TRUE(rec.start("", &err, &path)) << err;
    EXPECT_EQ(path, dir.file("mocap-1.bvh"));
    EXPECT_FALSE(rec.start("", &err));       // one at a time
    publish_frames(rec, encoder, 4, 0, 10);  // first subject with frames: 4
    publish_frames(rec, encoder, 2, 0, 5);   // not recorded
    publish_frames(rec, encoder, 4, 10, 15);
    std::uint64_t frames = 0;
    ASSERT_TRUE(rec.stop(&err, &frames)) << err;
    EXPECT_EQ(frames, 25u);
    EXPECT_FALSE(rec.stop(&err));
    const std::string text = test::slurp(path);
    EXPECT_NE(text.find("\nFrames: 0000000025\n"), std::string::npos);
    const auto clip = skeleton::parse_bvh(text);
    ASSERT_TRUE(clip) << clip.error;
    EXPECT_EQ(clip.clip->frame_count, 25u);
    EXPECT_EQ(clip.clip->joints.size(), encoder.model().size());
    // Frame 12 of subject 4 turned 12° about ENU z: BVH Y rotation of the root is 12°.
    EXPECT_NEAR(clip.clip->frame(12)[5], 12.0, 1e-3);  // ZXY: Zrot, Xrot, Yrot
    // A second recording does not overwrite the first.
    ASSERT_TRUE(rec.start("", &err, &path)) << err;
    EXPECT_EQ(path, dir.file("mocap-2.bvh"));
    ASSERT_TRUE(rec.stop(&err));
    EXPECT_FALSE(rec.start(dir.file("mocap-1.bvh"), &err));
}

TEST(BvhRecorder, CountIsPatchedAtEveryFlushSoAKilledDaemonLeavesALoadableFile) {
    TempDir dir;
    const auto encoder = test::default_encoder();
    BvhRecorderConfig c;
    c.flush_interval_s = 0.02;
    BvhRecorder rec(c, encoder);
    std::string err;
    const std::string path = dir.file("live.bvh");
    ASSERT_TRUE(rec.start(path, &err)) << err;
    publish_frames(rec, encoder, 1, 0, 7);
    std::string text;
    for (int i = 0; i < 200; ++i) {
        std::this_thread::sleep_for(10ms);
        text = test::slurp(path);
        if (text.find("Frames: 0000000007") != std::string::npos) break;
    }
    const auto clip = skeleton::parse_bvh(text);  // while still recording
    ASSERT_TRUE(clip) << clip.error;
    EXPECT_EQ(clip.clip->frame_count, 7u);
    ASSERT_TRUE(rec.stop(&err));
}

// The recorded subject's measured interval, patched in place with the count: a file read
// after any flush parses; a configured Frame Time is written as configured.
TEST(BvhRecorder, FrameTimeIsTheRecordedSubjectsIntervalUnlessConfigured) {
    TempDir dir;
    for (const bool fixed : {false, true}) {
        const auto encoder = fixed ? test::default_encoder() : test::measured_encoder();
        BvhRecorderConfig c;
        c.directory = dir.path.string();
        c.flush_interval_s = 0.01;
        BvhRecorder rec(c, encoder);
        std::string err, path;
        ASSERT_TRUE(rec.start("", &err, &path)) << err;
        const auto before = skeleton::parse_bvh(test::slurp(path));
        ASSERT_TRUE(before) << before.error;
        SubjectFrame f;
        skeleton::SkeletonPose p;
        for (std::uint64_t k = 0; k < 40; ++k) {
            test::make_pose(2, 100 + k, static_cast<std::uint16_t>(encoder.model().size()), f, p, 8'333);
            rec.publish(f, p);
            if (k == 20) {
                ASSERT_TRUE(wait_until([&] { return rec.counters().value("frames_recorded").value_or(0) >= 21; }));
                const auto mid = skeleton::parse_bvh(test::slurp(path));
                ASSERT_TRUE(mid) << mid.error;
                EXPECT_NEAR(mid.clip->frame_time_s, fixed ? 0.01 : 0.008333, 1e-9);
            }
        }
        ASSERT_TRUE(rec.stop(&err)) << err;
        const std::string text = test::slurp(path);
        EXPECT_NE(text.find(fixed ? "\nFrame Time: 0.010000\n" : "\nFrame Time: 0.008333\n"), std::string::npos);
        const auto clip = skeleton::parse_bvh(text);
        ASSERT_TRUE(clip) << clip.error;
        EXPECT_EQ(clip.clip->frame_count, 40u);
    }
}

TEST(BvhRepair, CountsCompleteLinesAndCutsAPartialLastLine) {
    TempDir dir;
    const auto encoder = test::default_encoder();
    BvhRecorderConfig c;
    BvhRecorder rec(c, encoder);
    std::string err;
    const std::string path = dir.file("cut.bvh");
    ASSERT_TRUE(rec.start(path, &err)) << err;
    publish_frames(rec, encoder, 1, 0, 9);
    ASSERT_TRUE(rec.stop(&err));
    // As if killed: the count is stale (0) and a line was half written.
    std::string text = test::slurp(path);
    const auto at = text.find("Frames: 0000000009");
    text.replace(at, 18, "Frames: 0000000000");
    text += "0.0 1.5 2";
    { std::ofstream(path, std::ios::binary | std::ios::trunc) << text; }
    EXPECT_FALSE(skeleton::parse_bvh(test::slurp(path)));
    const auto r = repair_bvh_file(path);
    ASSERT_TRUE(r.ok) << r.error;
    EXPECT_EQ(r.frames, 9u);
    EXPECT_EQ(r.frames_before, 0u);
    EXPECT_EQ(r.bytes_cut, 9u);
    const auto clip = skeleton::parse_bvh(test::slurp(path));
    ASSERT_TRUE(clip) << clip.error;
    EXPECT_EQ(clip.clip->frame_count, 9u);
    // A repaired file is stable under repair.
    const auto again = repair_bvh_file(path);
    ASSERT_TRUE(again.ok) << again.error;
    EXPECT_EQ(again.frames, 9u);
    EXPECT_EQ(again.bytes_cut, 0u);
}

TEST(BvhRepair, RejectsAMalformedLineInTheMiddle) {
    TempDir dir;
    const auto encoder = test::default_encoder();
    std::string text = encoder.hierarchy() + "MOTION\nFrames: 3\nFrame Time: 0.01\n";
    SubjectFrame f;
    skeleton::SkeletonPose p;
    for (std::uint64_t k = 0; k < 3; ++k) {
        test::make_pose(1, k, static_cast<std::uint16_t>(encoder.model().size()), f, p);
        encoder.append_motion_line(p, text);
        if (k == 0) text += "1 2 3\n";
    }
    const std::string path = dir.file("bad.bvh");
    { std::ofstream(path, std::ios::binary) << text; }
    const auto r = repair_bvh_file(path);
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.error.find("line 2"), std::string::npos) << r.error;
    EXPECT_EQ(test::slurp(path), text);  // untouched
}

TEST(RawRecorder, EverySampleComesBackExactly) {
    TempDir dir;
    StepClock clock;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    c.ring_capacity = 1024;
    RawRecorder rec(c, clock);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    for (std::uint64_t k = 0; k < 3000; ++k) {
        while (!rec.push(sample(k, k % 7 == 0)))
            std::this_thread::sleep_for(1ms);  // test only: wait for room
    }
    rec.stop();
    const auto files = raw_files(dir.path);
    ASSERT_EQ(files.size(), 1u);
    EXPECT_NE(files[0].find("raw-20231114-221320-0.mocapraw"), std::string::npos) << files[0];
    RawRecordingReader reader;
    ASSERT_TRUE(reader.open(files[0], &err)) << err;
    SegmentSample got;
    for (std::uint64_t k = 0; k < 3000; ++k) {
        ASSERT_EQ(reader.next(got, &err), 1) << k << " " << err;
        expect_same(sample(k, k % 7 == 0), got);
    }
    EXPECT_EQ(reader.next(got, &err), 0);
    EXPECT_FALSE(reader.truncated());
    EXPECT_EQ(rec.counters().snapshot()[0].value, 3000u);  // samples_recorded
}

TEST(RawRecorder, RotatesBySizeAndACutFileReadsUpToItsLastRecord) {
    TempDir dir;
    StepClock clock;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    c.rotate_bytes = 20'000;
    c.flush_interval_s = 0;
    RawRecorder rec(c, clock);
    std::string err;
    ASSERT_TRUE(rec.start(&err)) << err;
    for (std::uint64_t k = 0; k < 2000; ++k) {
        while (!rec.push(sample(k, false)))
            std::this_thread::sleep_for(1ms);
        if (k % 100 == 0) std::this_thread::sleep_for(10ms);  // let the writer see the size
    }
    rec.stop();
    const auto files = raw_files(dir.path);
    ASSERT_GE(files.size(), 3u);
    std::uint64_t k = 0;
    SegmentSample got;
    std::vector<int> records;  // per file
    for (const auto& f : files) {
        RawRecordingReader reader;
        ASSERT_TRUE(reader.open(f, &err)) << err;
        records.push_back(0);
        while (reader.next(got, &err) == 1) {
            expect_same(sample(k++, false), got);
            ++records.back();
        }
    }
    EXPECT_EQ(k, 2000u);
    // Cut a file in the middle of its last record, as a crash mid-write would: every record
    // before it still reads. (The fullest file: where the writer rotated is timing, and the
    // last file may hold a single record.)
    const auto fullest = std::max_element(records.begin(), records.end());
    ASSERT_GE(*fullest, 2);
    const auto& cut = files[static_cast<std::size_t>(fullest - records.begin())];
    fs::resize_file(cut, fs::file_size(cut) - 5);
    RawRecordingReader reader;
    ASSERT_TRUE(reader.open(cut, &err));
    int n = 0;
    while (reader.next(got, &err) == 1)
        ++n;
    EXPECT_TRUE(reader.truncated());
    EXPECT_EQ(n, *fullest - 1);
    // Not a recording at all.
    { std::ofstream(dir.file("junk")) << "HIERARCHY\n"; }
    RawRecordingReader junk;
    EXPECT_FALSE(junk.open(dir.file("junk"), &err));
}

TEST(RawRecorder, TheReaderReadsRecordsFromMemoryAsAJetStreamMessageCarriesThem) {
    std::string records;
    for (std::uint64_t k = 0; k < 50; ++k)
        append_raw_sample_record(sample(k, k % 5 == 0), records);
    RawRecordingReader reader;
    std::string err;
    ASSERT_TRUE(reader.open_records(records, &err)) << err;
    SegmentSample got;
    for (std::uint64_t k = 0; k < 50; ++k) {
        ASSERT_EQ(reader.next(got, &err), 1) << k << " " << err;
        expect_same(sample(k, k % 5 == 0), got);
    }
    EXPECT_EQ(reader.next(got, &err), 0);
    EXPECT_FALSE(reader.truncated());
    // The next message continues the count; a cut one says what was cut.
    ASSERT_TRUE(reader.open_records(records.substr(0, records.size() - 3), &err)) << err;
    int n = 0;
    while (reader.next(got, &err) == 1)
        ++n;
    EXPECT_EQ(n, 49);
    EXPECT_TRUE(reader.truncated());
    EXPECT_EQ(reader.samples_read(), 99u);
    EXPECT_FALSE(reader.open_records("", &err));
}

TEST(RawRecorder, AFullRingDropsAndCountsInsteadOfBlocking) {
    TempDir dir;
    StepClock clock;
    RawRecorderConfig c;
    c.directory = dir.path.string();
    c.ring_capacity = 16;
    RawRecorder rec(c, clock);  // not started: nothing drains the ring
    std::uint64_t accepted = 0;
    for (std::uint64_t k = 0; k < 100; ++k)
        accepted += rec.push(sample(k, false)) ? 1 : 0;
    EXPECT_EQ(accepted, 16u);
    EXPECT_EQ(rec.counters().snapshot()[1].value, 84u);  // samples_dropped
}

}  // namespace
}  // namespace mocap::serve
