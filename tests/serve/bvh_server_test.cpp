// Live BVH service on loopback: framing, subject selection, value counts, lagging clients.
#include "serve/bvh_server.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <thread>
#include <vector>

#include "bvh_outputs_fixture.hpp"
#include "skeleton/bvh.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;

class Conn {
public:
    explicit Conn(std::uint16_t port) {
        fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(port);
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        const int small = 4096;  // so that a client that does not read fills up quickly
        ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
        timeval tv{2, 0};
        ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        ok_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    }
    ~Conn() { ::close(fd_); }
    [[nodiscard]] bool ok() const { return ok_; }
    void half_close() { ::shutdown(fd_, SHUT_WR); }
    void send_text(const std::string& s) {
        ASSERT_EQ(::send(fd_, s.data(), s.size(), 0), static_cast<ssize_t>(s.size()));
    }
    /// Reads until `text` holds `lines` complete lines after the greeting (or timeout).
    std::string read_until_lines(std::size_t greeting_lines, std::size_t lines) {
        std::string text;
        char buf[4096];
        while (std::count(text.begin(), text.end(), '\n') < static_cast<long>(greeting_lines + lines)) {
            const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
            if (n <= 0) break;
            text.append(buf, static_cast<std::size_t>(n));
        }
        return text;
    }

private:
    int fd_ = -1;
    bool ok_ = false;
};

std::size_t greeting_line_count(const BvhFrameEncoder& e) {
    return static_cast<std::size_t>(std::count(e.hierarchy().begin(), e.hierarchy().end(), '\n')) + 2;
}

bool wait_clients(const BvhServer& s, std::size_t n) {
    return wait_until([&] { return s.client_count() == n; });
}

std::vector<std::string> motion_lines(const std::string& text, std::size_t skip) {
    std::vector<std::string> out;
    std::stringstream ss(text);
    std::string line;
    for (std::size_t i = 0; std::getline(ss, line); ++i) {
        if (i >= skip) out.push_back(line);
    }
    return out;
}

std::unique_ptr<BvhServer> started(const BvhFrameEncoder& encoder, std::size_t queue_frames = 64,
                                   std::size_t threads = 1) {
    BvhServerConfig c;
    c.bind_address = "127.0.0.1";
    c.port = 0;
    c.queue_frames = queue_frames;
    c.threads = threads;
    auto server = std::make_unique<BvhServer>(c, encoder);
    std::string err;
    EXPECT_TRUE(server->start(err)) << err;
    return server;
}

TEST(BvhServer, GreetingIsHierarchyMotionFrameTimeThenOneLinePerFrame) {
    const auto encoder = test::default_encoder();
    auto owned = started(encoder);
    BvhServer& server = *owned;
    Conn conn(server.port());
    ASSERT_TRUE(conn.ok());
    ASSERT_TRUE(wait_clients(server, 1));
    SubjectFrame f;
    skeleton::SkeletonPose p;
    for (std::uint64_t k = 0; k < 5; ++k) {
        test::make_pose(3, k, static_cast<std::uint16_t>(encoder.model().size()), f, p);
        server.publish(f, p);
    }
    const std::size_t g = greeting_line_count(encoder);
    const std::string text = conn.read_until_lines(g, 5);
    ASSERT_EQ(text.rfind(encoder.hierarchy() + "MOTION\nFrame Time: 0.010000\n", 0), 0u);
    // A reader turns the stream into a file by inserting "Frames: <lines received>".
    const auto lines = motion_lines(text, g);
    ASSERT_EQ(lines.size(), 5u);
    std::string file = encoder.hierarchy() + "MOTION\nFrames: 5\nFrame Time: 0.010000\n";
    for (const auto& l : lines) {
        EXPECT_EQ(bvh_value_count(l), encoder.values_per_frame());
        file += l + "\n";
    }
    const auto clip = skeleton::parse_bvh(file);
    ASSERT_TRUE(clip) << clip.error;
    EXPECT_EQ(clip.clip->frame_count, 5u);
    // The client can read the lines before the server's write completion has counted them.
    EXPECT_TRUE(wait_until([&] { return server.counters().frames_sent.value() >= 5; }));
    EXPECT_EQ(server.counters().frames_sent.value(), 5u);
}

TEST(BvhServer, FirstSubjectWithFramesThenSwitchOnRequest) {
    const auto encoder = test::default_encoder();
    auto owned = started(encoder);
    BvhServer& server = *owned;
    Conn conn(server.port());
    ASSERT_TRUE(wait_clients(server, 1));
    const auto n = static_cast<std::uint16_t>(encoder.model().size());
    SubjectFrame f;
    skeleton::SkeletonPose p;
    std::string expect_7, expect_2;
    for (std::uint64_t k = 0; k < 4; ++k) {
        test::make_pose(7, k, n, f, p);
        server.publish(f, p);
        encoder.append_motion_line(p, expect_7);
        test::make_pose(2, 100 + k, n, f, p);
        server.publish(f, p);
    }
    const std::size_t g = greeting_line_count(encoder);
    std::string text = conn.read_until_lines(g, 4);
    EXPECT_EQ(text.substr(text.size() - expect_7.size()), expect_7);  // only subject 7's lines
    // Lines are handled in order on the serve thread: once the bad line after the request is
    // counted, the switch to subject 2 has happened.
    conn.send_text("subject 2\nbogus\n");
    ASSERT_TRUE(wait_until([&] { return server.counters().bad_client_lines.value() != 0; }));
    EXPECT_EQ(server.counters().bad_client_lines.value(), 1u);
    for (std::uint64_t k = 0; k < 3; ++k) {
        test::make_pose(7, 10 + k, n, f, p);
        server.publish(f, p);
        test::make_pose(2, 200 + k, n, f, p);
        server.publish(f, p);
        encoder.append_motion_line(p, expect_2);
    }
    const std::string more = conn.read_until_lines(0, 3);
    EXPECT_EQ(more, expect_2);
}

TEST(BvhServer, AClientThatHalfClosesAfterChoosingASubjectStillReceives) {
    const auto encoder = test::default_encoder();
    auto server = started(encoder);
    Conn conn(server->port());
    ASSERT_TRUE(wait_clients(*server, 1));
    conn.send_text("subject 5\nbogus\n");  // the bad line is counted after the switch
    ASSERT_TRUE(wait_until([&] { return server->counters().bad_client_lines.value() != 0; }));
    conn.half_close();
    SubjectFrame f;
    skeleton::SkeletonPose p;
    std::string expect;
    for (std::uint64_t k = 0; k < 3; ++k) {
        test::make_pose(4, k, static_cast<std::uint16_t>(encoder.model().size()), f, p);
        server->publish(f, p);
        test::make_pose(5, k, static_cast<std::uint16_t>(encoder.model().size()), f, p);
        server->publish(f, p);
        encoder.append_motion_line(p, expect);
    }
    const std::string text = conn.read_until_lines(greeting_line_count(encoder), 3);
    EXPECT_EQ(text, encoder.hierarchy() + "MOTION\nFrame Time: 0.010000\n" + expect);
}

// Frame Time measured: a client that connects before the frames flow is greeted once its
// subject's interval spans kMeasuredIntervals SYNCs; its lines wait in its queue meanwhile,
// so it still gets every line. A client that connects later is greeted with its first line.
TEST(BvhServer, FrameTimeIsTheSubjectsMeasuredIntervalAndNoLineIsLostWaitingForIt) {
    const auto encoder = test::measured_encoder();
    auto owned = started(encoder);
    BvhServer& server = *owned;
    Conn early(server.port());
    ASSERT_TRUE(early.ok());
    ASSERT_TRUE(wait_clients(server, 1));
    const auto segments = static_cast<std::uint16_t>(encoder.model().size());
    SubjectFrame f;
    skeleton::SkeletonPose p;
    const std::uint64_t frames = kMeasuredIntervals + 2;
    for (std::uint64_t k = 0; k < frames; ++k) {
        test::make_pose(3, k, segments, f, p, 4'000);  // 250 Hz
        server.publish(f, p);
    }
    const std::size_t g = greeting_line_count(encoder);
    const std::string text = early.read_until_lines(g, frames);
    ASSERT_EQ(text.rfind(encoder.hierarchy() + "MOTION\nFrame Time: 0.004000\n", 0), 0u) << text.substr(0, 400);
    EXPECT_EQ(motion_lines(text, g).size(), frames);

    Conn late(server.port());
    ASSERT_TRUE(late.ok());
    ASSERT_TRUE(wait_clients(server, 2));
    test::make_pose(3, frames, segments, f, p, 4'000);
    server.publish(f, p);
    const std::string late_text = late.read_until_lines(g, 1);
    ASSERT_EQ(late_text.rfind(encoder.hierarchy() + "MOTION\nFrame Time: 0.004000\n", 0), 0u);
    EXPECT_EQ(motion_lines(late_text, g).size(), 1u);
}

TEST(BvhServer, NoClientNoEncodingAndStopClosesClients) {
    const auto encoder = test::default_encoder();
    auto server = started(encoder);
    SubjectFrame f;
    skeleton::SkeletonPose p;
    test::make_pose(1, 1, static_cast<std::uint16_t>(encoder.model().size()), f, p);
    server->publish(f, p);
    EXPECT_EQ(server->counters().frames_published.value(), 0u);
    Conn conn(server->port());
    ASSERT_TRUE(wait_clients(*server, 1));
    server->stop();
    const std::string text = conn.read_until_lines(greeting_line_count(encoder), 1000);
    EXPECT_EQ(text, encoder.hierarchy() + "MOTION\nFrame Time: 0.010000\n");  // then EOF
}

TEST(BvhServer, LaggingClientLosesOldestLinesNotThePipeline) {
    const auto encoder = test::default_encoder();
    auto owned = started(encoder, 8);
    BvhServer& server = *owned;
    Conn conn(server.port());  // never reads until the end
    ASSERT_TRUE(wait_clients(server, 1));
    SubjectFrame f;
    skeleton::SkeletonPose p;
    // If publish() waited for the client, this loop would never end (the client never reads).
    for (std::uint64_t k = 0; k < 20000; ++k) {
        test::make_pose(1, k, static_cast<std::uint16_t>(encoder.model().size()), f, p);
        server.publish(f, p);
    }
    for (int i = 0;
         i < 400 && server.counters().frames_dropped.value() + server.counters().backlog_dropped.value() == 0; ++i) {
        std::this_thread::sleep_for(5ms);
    }
    EXPECT_GT(server.counters().frames_dropped.value() + server.counters().backlog_dropped.value(), 0u);
}

TEST(BvhServer, ClientsOnSeveralServeThreadsEachGetEveryLineInOrder) {
    const auto encoder = test::default_encoder();
    constexpr std::size_t kThreads = 3;
    constexpr std::size_t kClients = 6;
    constexpr std::uint64_t kFrames = 200;
    // Queues hold every line: a client that reads late must still see them all.
    auto owned = started(encoder, kFrames + 16, kThreads);
    BvhServer& server = *owned;
    std::vector<std::unique_ptr<Conn>> conns;
    for (std::size_t i = 0; i < kClients; ++i) {
        conns.push_back(std::make_unique<Conn>(server.port()));
        ASSERT_TRUE(conns.back()->ok());
    }
    ASSERT_TRUE(wait_clients(server, kClients));
    for (std::size_t lane = 0; lane < kThreads; ++lane)
        EXPECT_EQ(server.lane_client_count(lane), kClients / kThreads) << "round-robin over the lanes";

    const auto segments = static_cast<std::uint16_t>(encoder.model().size());
    std::vector<std::string> expected;
    SubjectFrame f;
    skeleton::SkeletonPose p;
    for (std::uint64_t k = 0; k < kFrames; ++k) {
        test::make_pose(1, k, segments, f, p);
        server.publish(f, p);
        std::string line;
        encoder.append_motion_line(p, line);
        line.pop_back();  // getline strips the '\n'
        expected.push_back(std::move(line));
    }
    const std::size_t greeting = greeting_line_count(encoder);
    for (auto& conn : conns) {
        const auto lines = motion_lines(conn->read_until_lines(greeting, kFrames), greeting);
        EXPECT_EQ(lines, expected) << "every line, in order, no gaps";
    }
    // Encoded once per frame, however many threads and clients.
    EXPECT_EQ(server.counters().frames_published.value(), kFrames);
    EXPECT_TRUE(wait_until([&] { return server.counters().frames_sent.value() == kFrames * kClients; }));
    EXPECT_EQ(server.counters().frames_dropped.value(), 0u);
    EXPECT_EQ(server.counters().backlog_dropped.value(), 0u);

    // stop() with every client connected: each lane closes its own, the threads join.
    server.stop();
    EXPECT_EQ(server.client_count(), 0u);
    EXPECT_EQ(server.counters().connections.closed.value(), kClients);
    for (auto& conn : conns)
        EXPECT_EQ(conn->read_until_lines(0, 1), "") << "closed: EOF";
}

}  // namespace
}  // namespace mocap::serve
