// The takes and their exports against a hostile peer or a hostile file (issue 24, items 1, 4,
// 10, 12; docs/security.md "Takes and exports"): a FIFO planted in the store blocks nothing,
// the listing is cached and paged, a connection that leaves cancels its export so that
// abandoned requests cannot hold the queue, and what finished exports hold in memory is
// bounded per peer address and in total (507 past it).
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <condition_variable>
#include <filesystem>
#include <future>
#include <mutex>
#include <nlohmann/json.hpp>

#include "http_test_client.hpp"
#include "recorder_fixture.hpp"
#include "serve/http_server.hpp"
#include "serve/raw_recorder.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;
using mocap::testing::http_request;
namespace fs = std::filesystem;

/// A raw TCP connection that sends one GET and then does what the test says (no reading).
/// rcvbuf > 0: a small receive window, so a large reply stays in the server's hands.
int send_get(std::uint16_t port, const std::string& target, int rcvbuf = 0) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (rcvbuf > 0) ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return -1;
    }
    const std::string req = "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
    if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(req.size())) {
        ::close(fd);
        return -1;
    }
    return fd;
}

/// Reads one reply whose body holds `body_bytes`; what was read (less after `limit`).
std::string read_reply(int fd, std::size_t body_bytes, std::chrono::seconds limit) {
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(limit.count());
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    std::string out;
    char buf[65536];
    for (;;) {
        const std::size_t head = out.find("\r\n\r\n");
        if (head != std::string::npos && out.size() - head - 4 >= body_bytes) break;
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n <= 0) break;
        out.append(buf, static_cast<std::size_t>(n));
    }
    return out;
}

struct Server {
    test::TempDir dir;
    std::shared_ptr<TakeStore> store = std::make_shared<TakeStore>(dir.file("takes"));
    std::mutex mutex;
    std::condition_variable cv;
    bool open = false;  // mutex: exports may finish
    int entered = 0;    // mutex: exports that started
    int cancelled = 0;  // mutex: exports that saw their flag
    std::size_t export_bytes = 64;
    bool in_steps = false;         // write 64 KiB at a time, telling request.reserve as the daemon's does
    std::size_t written_last = 0;  // mutex: what the last export had written when it ended
    std::unique_ptr<HttpServer> server;

    explicit Server(HttpServerConfig c = {}) {
        TakeMeta m;
        m.name = "walk";
        m.start_us = 1;
        std::string error;
        EXPECT_TRUE(store->create(m, &error)) << error;
        c.bind_address = "127.0.0.1";
        c.port = 0;
        HttpHandlers h;
        h.takes = store;
        h.export_take = [this](const TakeExportRequest& request, const std::atomic<bool>& cancel) {
            std::unique_lock lock(mutex);
            ++entered;
            cv.notify_all();
            // The cancel flag is set without this condition variable: look at it often.
            while (!open && !cancel.load())
                cv.wait_for(lock, 5ms);
            if (cancel.load()) {
                ++cancelled;
                return TakeExportResult{TakeExportResult::kCancelled, "cancelled", -1};
            }
            const int fd = ::memfd_create("test-export", MFD_CLOEXEC);
            const std::size_t step = in_steps ? std::size_t{64} << 10 : export_bytes;
            std::size_t done = 0;
            while (done < export_bytes) {
                const std::string text(std::min(step, export_bytes - done), 'x');
                EXPECT_EQ(::pwrite(fd, text.data(), text.size(), static_cast<off_t>(done)),
                          static_cast<ssize_t>(text.size()));
                done += text.size();
                std::string why;
                if (in_steps && request.reserve && !request.reserve(done, &why)) {
                    ::close(fd);
                    written_last = done;
                    return TakeExportResult{TakeExportResult::kTooLarge, why, -1};
                }
            }
            written_last = done;
            return TakeExportResult{TakeExportResult::kOk, {}, fd};
        };
        server = std::make_unique<HttpServer>(c, HttpDescription{}, h);
        std::string err;
        EXPECT_TRUE(server->start(err)) << err;
    }
    void release() {
        std::lock_guard lock(mutex);
        open = true;
        cv.notify_all();
    }
    template <typename Pred>
    bool wait_for(Pred pred) {
        return wait_until([&] {
            std::lock_guard lock(mutex);
            return pred();
        });
    }
};

// Item 10: a FIFO named like a sidecar or a raw file blocked every reader of the store (the
// HTTP thread, and with it /healthz) for good. Now it is refused without blocking.
TEST(TakeSecurity, AFifoInTheStoreBlocksNoListingNoDownloadAndNoReader) {
    Server s;
    const fs::path takes = s.dir.path / "takes";
    fs::create_directories(takes / "trap");
    ASSERT_EQ(::mkfifo((takes / "trap" / "take.json").c_str(), 0600), 0);
    ASSERT_EQ(::mkfifo((takes / "walk" / "raw-20261207T000000Z-0.mocapraw").c_str(), 0600), 0);
    const std::string fifo_raw = (takes / "walk" / "raw-20261207T000000Z-0.mocapraw").string();
    // Each call on its own thread, with a deadline: before the fix the open never returned.
    auto listed = std::async(std::launch::async, [&] { return http_request(s.server->port(), "/api/takes"); });
    auto raw = std::async(std::launch::async,
                          [&] { return http_request(s.server->port(), "/api/takes/walk/download?format=raw"); });
    auto reader = std::async(std::launch::async, [&] {
        RawRecordingReader r;
        std::string error;
        return std::make_pair(r.open(fifo_raw, &error), error);
    });
    const bool done = listed.wait_for(60s) == std::future_status::ready &&
                      raw.wait_for(60s) == std::future_status::ready &&
                      reader.wait_for(60s) == std::future_status::ready;
    if (!done) {
        // Release the blocked opens so that the test can end, and fail.
        for (const std::string& f : {(takes / "trap" / "take.json").string(), fifo_raw}) {
            const int w = ::open(f.c_str(), O_WRONLY | O_NONBLOCK);
            if (w >= 0) ::close(w);
        }
        FAIL() << "a FIFO in the take store blocked a reader";
    }
    const auto list = nlohmann::json::parse(listed.get().body, nullptr, false);
    ASSERT_TRUE(list.is_object());
    ASSERT_EQ(list["takes"].size(), 1u) << list.dump() << ": the FIFO sidecar is skipped";
    EXPECT_EQ(list["takes"][0]["name"], "walk");
    EXPECT_EQ(list["takes"][0]["raw_bytes"], 0) << "the FIFO is no raw file";
    EXPECT_EQ(raw.get().status, 409u) << "no regular raw file: nothing opened";
    const auto [opened, error] = reader.get();
    EXPECT_FALSE(opened);
    EXPECT_NE(error.find("not a regular file"), std::string::npos) << error;
    EXPECT_EQ(http_request(s.server->port(), "/healthz").status, 200u);
    EXPECT_FALSE(read_regular_file(fifo_raw, 1024));
    EXPECT_EQ(open_regular_file(fifo_raw), -1);
}

// Item 12: 3,000 takes cost 0.22 s of the HTTP thread per GET. The listing is cached (no
// sidecar read again until a take is created, saved or removed) and paged.
TEST(TakeSecurity, TheListingIsCachedInvalidatedByChangesAndPaged) {
    Server s;
    std::string error;
    for (int i = 0; i < 30; ++i) {
        TakeMeta m;
        m.name = "t" + std::to_string(100 + i);
        m.start_us = 100 + i;
        ASSERT_TRUE(s.store->create(m, &error)) << error;
    }
    const std::uint16_t port = s.server->port();
    const auto first = nlohmann::json::parse(http_request(port, "/api/takes").body, nullptr, false);
    ASSERT_TRUE(first.is_object());
    EXPECT_EQ(first["total"], 31);
    EXPECT_EQ(first["takes"].size(), 31u);
    const std::uint64_t read = s.store->sidecars_read();
    EXPECT_EQ(read, 31u);
    for (int i = 0; i < 5; ++i)
        EXPECT_EQ(http_request(port, "/api/takes").status, 200u);
    EXPECT_EQ(s.store->sidecars_read(), read) << "a listing without a change reads no sidecar";

    const auto page = nlohmann::json::parse(http_request(port, "/api/takes?offset=10&limit=5").body, nullptr, false);
    ASSERT_TRUE(page.is_object());
    EXPECT_EQ(page["total"], 31);
    EXPECT_EQ(page["offset"], 10);
    ASSERT_EQ(page["takes"].size(), 5u);
    EXPECT_EQ(page["takes"][0]["name"], first["takes"][10]["name"]);
    const auto past = nlohmann::json::parse(http_request(port, "/api/takes?offset=40").body, nullptr, false);
    EXPECT_EQ(past["takes"].size(), 0u);
    EXPECT_EQ(past["total"], 31);
    for (const char* bad :
         {"/api/takes?limit=0", "/api/takes?limit=501", "/api/takes?offset=-1", "/api/takes?limit=x"}) {
        EXPECT_EQ(http_request(port, bad).status, 400u) << bad;
    }

    // A change through the store, and one behind its back, both show.
    ASSERT_EQ(s.store->remove("t100", &error), TakeStore::Removal::kRemoved);
    EXPECT_EQ(nlohmann::json::parse(http_request(port, "/api/takes").body, nullptr, false)["total"], 30);
    fs::remove_all(s.dir.path / "takes" / "t101");
    EXPECT_EQ(nlohmann::json::parse(http_request(port, "/api/takes").body, nullptr, false)["total"], 29);
}

// Item 4: 23 exports queued and abandoned held the export thread; every real download got 503
// for 40 s. A connection that closes now cancels its export, running or waiting.
TEST(TakeSecurity, ClientsThatQueueExportsAndLeaveDoNotHoldTheQueue) {
    HttpServerConfig c;
    c.export_waiting = 4;
    Server s(c);
    const std::uint16_t port = s.server->port();
    const std::string target = "/api/takes/walk/download?format=bvh";
    // The first holds the export thread, four more wait; all leave.
    std::vector<int> gone;
    for (int i = 0; i < 5; ++i) {
        const int fd = send_get(port, target);
        ASSERT_GE(fd, 0);
        gone.push_back(fd);
        if (i == 0) {
            ASSERT_TRUE(s.wait_for([&] { return s.entered == 1; }));
        }
    }
    // Queued (not refused): five requests read by the server, none answered 503.
    ASSERT_TRUE(wait_until([&] { return s.server->counters().requests.value() >= 5; }));
    EXPECT_EQ(s.server->counters().take_exports_busy.value(), 0u);
    for (const int fd : gone)
        ::close(fd);
    // The running export is cancelled, the waiting ones dropped without running.
    ASSERT_TRUE(s.wait_for([&] { return s.cancelled == 1; })) << "the running export was not cancelled";
    ASSERT_TRUE(wait_until([&] { return s.server->counters().take_exports_abandoned.value() == 5; }));
    // A real download now runs at once and gets its file.
    s.release();
    const auto reply = http_request(port, target);
    EXPECT_EQ(reply.status, 200u) << reply.body;
    EXPECT_EQ(reply.body, std::string(s.export_bytes, 'x'));
    std::lock_guard lock(s.mutex);
    EXPECT_EQ(s.entered, 2) << "the abandoned waiting exports never ran";
}

// Item 1: exports live in memory, charged to a budget per peer address and in total; past
// it a download is refused with 507 and the reason, and reading the download gives it back.
TEST(TakeSecurity, HeldExportsAreBoundedPerAddressAndInTotalWith507) {
    HttpServerConfig c;
    c.export_memory_bytes = 5u << 20;
    c.export_memory_per_address_bytes = 3u << 20;
    Server s(c);
    s.export_bytes = 2u << 20;  // far beyond what the socket buffers take
    s.release();
    const std::uint16_t port = s.server->port();
    const std::string target = "/api/takes/walk/download?format=csv";
    // A reader that reads nothing: its 2 MiB stay charged.
    const int slow = send_get(port, target, 4096);
    ASSERT_GE(slow, 0);
    ASSERT_TRUE(wait_until([&] { return s.server->counters().take_downloads.value() == 1; }));
    // The second of the same address would hold 4 MiB, over its 3.
    const auto refused = http_request(port, target);
    EXPECT_EQ(refused.status, 507u) << refused.body;
    EXPECT_NE(refused.body.find("insufficient storage"), std::string::npos) << refused.body;
    EXPECT_EQ(s.server->counters().take_exports_over_budget.value(), 1u);
    // Reading it to the end gives its memory back: the next one is served.
    const std::string got = read_reply(slow, s.export_bytes, 60s);
    ::close(slow);
    ASSERT_TRUE(got.starts_with("HTTP/1.1 200")) << got.substr(0, 200);
    EXPECT_TRUE(got.ends_with(std::string(1000, 'x')));
    // The server gives the charge back when its last write completes, just before or after
    // the reader has it all: poll.
    ASSERT_TRUE(wait_until([&] {
        const auto r = http_request(port, target);
        return r.status == 200u && r.body.size() == s.export_bytes;
    }));
}

// An export was charged half its take's raw file up front, so a big take was refused however
// small its export. Now it is charged what it holds as it is written: one bigger than what
// its address may hold is stopped as soon as it outgrows it (507, counted), one that fits is
// served whole, and what the budget holds is back to zero after either.
TEST(TakeSecurity, AnExportIsChargedAsItGrowsAndStoppedWith507OnceItOutgrowsTheBudget) {
    HttpServerConfig c;
    c.export_memory_bytes = 8u << 20;
    c.export_memory_per_address_bytes = 3u << 20;
    Server s(c);
    s.in_steps = true;
    s.export_bytes = 5u << 20;
    s.release();
    const std::uint16_t port = s.server->port();
    const std::string target = "/api/takes/walk/download?format=csv";
    const auto held = [&] {
        const std::string text = http_request(port, "/metrics").body;
        const std::string key = "\nmocapd_http_take_export_bytes ";
        const std::size_t at = text.find(key);
        return at == std::string::npos ? ~std::uint64_t{0} : std::stoull(text.substr(at + key.size()));
    };
    const auto refused = http_request(port, target);
    EXPECT_EQ(refused.status, 507u) << refused.body;
    EXPECT_NE(refused.body.find("this export has grown to 3.1 MiB"), std::string::npos) << refused.body;
    EXPECT_NE(refused.body.find("export the take on the host"), std::string::npos) << refused.body;
    EXPECT_EQ(s.server->counters().take_exports_over_budget.value(), 1u);
    {
        std::lock_guard lock(s.mutex);
        EXPECT_EQ(s.written_last, (3u << 20) + (64u << 10)) << "stopped at the first step past the budget";
    }
    ASSERT_TRUE(wait_until([&] { return held() == 0u; })) << held();
    // Just the budget: served whole.
    s.export_bytes = 3u << 20;
    const auto served = http_request(port, target);
    EXPECT_EQ(served.status, 200u) << served.body.substr(0, 200);
    EXPECT_EQ(served.body, std::string(s.export_bytes, 'x'));
    ASSERT_TRUE(wait_until([&] { return held() == 0u; })) << held();
    EXPECT_EQ(s.server->counters().take_exports_over_budget.value(), 1u);
}

}  // namespace
}  // namespace mocap::serve
