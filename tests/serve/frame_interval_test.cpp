// FrameInterval: the measured sample interval behind BVH "Frame Time:".
#include "serve/frame_interval.hpp"

#include <gtest/gtest.h>

namespace mocap::serve {
namespace {

TEST(FrameInterval, MeanOverTheRunOnceItSpansEnoughSyncs) {
    FrameInterval fi(10);
    EXPECT_FALSE(fi.seconds());
    // 120 Hz with ±200 µs of jitter on the sample instants: the mean over the run is exact
    // to the jitter over its length.
    for (std::uint64_t k = 0; k <= 10; ++k) {
        const std::int64_t jitter = (k % 2 == 0) ? 200 : -200;
        fi.add(1000 + k, static_cast<std::int64_t>(k) * 8'333 + (k == 0 || k == 10 ? 0 : jitter));
        if (k < 10) {
            EXPECT_FALSE(fi.seconds()) << k;
        }
    }
    ASSERT_TRUE(fi.seconds());
    EXPECT_NEAR(*fi.seconds(), 0.008333, 1e-9);
}

TEST(FrameInterval, SkippedSyncsCountAsIntervals) {
    FrameInterval fi;
    fi.add(0, 0);
    fi.add(5, 50'000);  // a gap of four frames (stale, or dropped)
    ASSERT_TRUE(fi.seconds());
    EXPECT_DOUBLE_EQ(*fi.seconds(), 0.01);
}

TEST(FrameInterval, ARestartedCounterOrAJumpingClockStartsANewRun) {
    FrameInterval fi;
    fi.add(500, 5'000'000);
    fi.add(501, 5'010'000);
    EXPECT_DOUBLE_EQ(*fi.seconds(), 0.01);
    fi.add(0, 9'000'000);  // the sink reconnected and counts from 0 at 50 Hz now
    EXPECT_FALSE(fi.seconds());
    fi.add(1, 9'020'000);
    EXPECT_DOUBLE_EQ(*fi.seconds(), 0.02);
    fi.add(2, 20'000'000);  // its clock stepped 11 s in one SYNC: not an interval
    EXPECT_FALSE(fi.seconds());
    fi.add(3, 20'020'000);
    EXPECT_DOUBLE_EQ(*fi.seconds(), 0.02);
    fi.add(4, 20'010'000);  // backwards
    EXPECT_FALSE(fi.seconds());
}

}  // namespace
}  // namespace mocap::serve
