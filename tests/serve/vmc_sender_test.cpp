// Tests of serve/vmc_sender.hpp on loopback: the chosen subject's frames arrive as one
// bundle each, in order; a destination nobody listens on and one that does not resolve are
// counted and do not stop the others, and logged once however often they are retried; a
// full ring drops and counts.
#include "serve/vmc_sender.hpp"

#include <gtest/gtest.h>
#include <netinet/in.h>
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>

#include "skeleton/body_model.hpp"
#include "vmc_receiver.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

struct FixedClock final : Clock {
    [[nodiscard]] std::int64_t now_us() const noexcept override { return 0; }
};

VmcRig default_rig() {
    std::string error;
    auto rig = VmcRig::build(skeleton::default_body_model(), {}, &error);
    EXPECT_TRUE(rig) << error;
    return std::move(*rig);
}

SubjectFrame frame_of(std::uint32_t subject, std::int64_t sample_us) {
    SubjectFrame f;
    f.subject_id = subject;
    f.sample_us = sample_us;
    f.segment_count = 15;
    for (std::size_t i = 0; i < 15; ++i)
        f.segments[i].flags = kSegmentCalibrated;
    return f;
}

skeleton::SkeletonPose pose_of() {
    skeleton::SkeletonPose p;
    p.segment_count = 15;
    p.position_m[0] = {0.0, 0.0, 0.9};
    return p;
}

std::uint64_t counter(const VmcSender& s, const char* name) {
    return s.counters().value(name).value_or(0);
}

// A UDP port on loopback that nothing listens on any more.
std::uint16_t closed_udp_port() {
    const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    ::close(fd);
    return ntohs(a.sin_port);
}

std::vector<float> times(const VmcReceiver& rx) {
    std::vector<float> t;
    for (const auto& m : rx.messages) {
        if (m.path == "/VMC/Ext/T") t.push_back(m.floats.at(0));
    }
    return t;
}

TEST(VmcSender, SendsTheFirstSubjectOneBundlePerFrame) {
    VmcReceiver rx;
    ASSERT_TRUE(rx.ok());
    const FixedClock clock;
    VmcSenderConfig config;
    config.destinations = {{"127.0.0.1", static_cast<std::uint16_t>(rx.port())}};
    VmcSender sender(config, default_rig(), clock);
    sender.start();
    const auto pose = pose_of();
    for (int i = 0; i < 20; ++i) {
        sender.publish(frame_of(3, 1'000'000 + i * 10'000), pose);
        sender.publish(frame_of(4, 1'000'000 + i * 10'000), pose);  // not the chosen subject
    }
    ASSERT_TRUE(wait_until([&] {
        rx.poll();
        return times(rx).size() >= 20;
    }));
    sender.stop();
    const auto t = times(rx);
    ASSERT_EQ(t.size(), 20u);
    for (std::size_t i = 0; i < t.size(); ++i)
        EXPECT_NEAR(t[i], 0.01 * static_cast<double>(i), 1e-6);
    EXPECT_EQ(rx.messages.size(), 20u * (3 + 15));
    EXPECT_EQ(counter(sender, "frames_queued"), 20u);
    EXPECT_EQ(counter(sender, "bundles_sent"), 20u);
    EXPECT_GT(counter(sender, "bytes_sent"), 20u * 1000);
    EXPECT_EQ(counter(sender, "send_errors"), 0u);
}

TEST(VmcSender, CountsUnreachableAndUnresolvableDestinationsAndServesTheRest) {
    VmcReceiver rx;
    ASSERT_TRUE(rx.ok());
    const FixedClock clock;
    VmcSenderConfig config;
    config.subject = 7;
    config.destinations = {{"127.0.0.1", closed_udp_port()},
                           {"no-such-host.invalid", 39539},
                           {"127.0.0.1", static_cast<std::uint16_t>(rx.port())}};
    VmcSender sender(config, default_rig(), clock);
    sender.start();
    const auto pose = pose_of();
    std::int64_t t_us = 0;
    // The refusal of the closed port (ICMP port unreachable) shows on the send after it.
    ASSERT_TRUE(wait_until([&] {
        sender.publish(frame_of(7, t_us += 10'000), pose);
        rx.poll();
        return counter(sender, "send_errors") > 0 && times(rx).size() >= 5;
    }));
    sender.stop();
    EXPECT_EQ(counter(sender, "resolve_errors"), 1u);
}

// Every call is a second later, so each wake-up of the sender may retry.
struct SecondPerCallClock final : Clock {
    [[nodiscard]] std::int64_t now_us() const noexcept override { return t_us += 1'000'000; }
    mutable std::atomic<std::int64_t> t_us{0};
};

// A broadcast address cannot be opened (connect() without SO_BROADCAST: EACCES); it used to
// log its warning on every retry, every 5 s for the daemon's lifetime.
TEST(VmcSender, ADestinationThatCannotBeOpenedIsLoggedOnceAndCounted) {
    const auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(1000);
    const auto old_logger = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink));
    const SecondPerCallClock clock;
    VmcSenderConfig config;
    config.destinations = {{"255.255.255.255", 39539}};
    config.resolve_retry_s = 2.0;
    VmcSender sender(config, default_rig(), clock);
    sender.start();
    const auto pose = pose_of();
    std::int64_t t_us = 0;
    // Each frame wakes the sender, and the clock moves on a second per look.
    const bool retried = wait_until([&] {
        sender.publish(frame_of(1, t_us += 10'000), pose);
        return counter(sender, "resolve_errors") >= 5;
    });
    sender.stop();
    spdlog::set_default_logger(old_logger);
    ASSERT_TRUE(retried) << "resolve_errors " << counter(sender, "resolve_errors");
    int lines = 0;
    for (const auto& line : sink->last_formatted())
        lines += line.find("vmc: destination 255.255.255.255:39539") != std::string::npos ? 1 : 0;
    EXPECT_EQ(lines, 1) << "logged once, then only counted";
}

TEST(VmcSender, AFullRingDropsAndCounts) {
    const FixedClock clock;
    VmcSenderConfig config;
    config.destinations = {{"127.0.0.1", 39539}};
    config.queue_frames = 4;
    VmcSender sender(config, default_rig(), clock);  // not started: nothing drains the ring
    const auto pose = pose_of();
    for (int i = 0; i < 6; ++i)
        sender.publish(frame_of(1, i), pose);
    EXPECT_EQ(counter(sender, "frames_queued"), 4u);
    EXPECT_EQ(counter(sender, "frames_dropped"), 2u);
}

}  // namespace
}  // namespace mocap::serve
