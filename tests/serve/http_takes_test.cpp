// The web endpoint's takes (http_takes.cpp) with a fake exporter: a BVH/CSV export waits on
// the export thread while the serve thread answers everyone else, the queue's bound answers
// 503 at once, and stopping the server cancels a running export.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>

#include "http_test_client.hpp"
#include "recorder_fixture.hpp"
#include "serve/http_server.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;
using mocap::testing::http_request;

struct Fixture {
    test::TempDir dir;
    std::shared_ptr<TakeStore> store = std::make_shared<TakeStore>(dir.file("takes"));
    std::mutex mutex;
    std::condition_variable cv;
    bool open = false;  // mutex
    int entered = 0;    // mutex: exports that started
    std::unique_ptr<HttpServer> server;

    Fixture() {
        TakeMeta m;
        m.name = "walk";
        m.start_us = 1;
        std::string error;
        EXPECT_TRUE(store->create(m, &error)) << error;
        HttpServerConfig c;
        c.bind_address = "127.0.0.1";
        c.port = 0;
        c.export_waiting = 1;
        c.control_token = "takes-test-token-0123456789";
        HttpHandlers h;
        h.takes = store;
        h.export_take = [this](const TakeExportRequest& request, const std::atomic<bool>& cancel) {
            std::unique_lock lock(mutex);
            ++entered;
            cv.notify_all();
            // The cancel flag is set without this condition variable: look at it often.
            while (!open && !cancel.load())
                cv.wait_for(lock, 5ms);
            if (cancel.load()) return TakeExportResult{TakeExportResult::kCancelled, "cancelled", -1};
            const std::string path = dir.file(("export-" + std::to_string(entered)).c_str());
            const std::string text = "export of " + request.name + " with " + request.filter + "\n";
            std::ofstream(path) << text;
            const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
            ::unlink(path.c_str());
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
    bool exports_entered(int n) {
        return wait_until([&] {
            std::lock_guard lock(mutex);
            return entered >= n;
        });
    }
};

TEST(HttpTakes, ExportsWaitOffTheServeThreadAndABusyQueueAnswers503) {
    Fixture f;
    const std::uint16_t port = f.server->port();
    const std::string target = "/api/takes/walk/download?format=bvh&filter=madgwick";
    auto running = std::async(std::launch::async, [&] { return http_request(port, target); });
    ASSERT_TRUE(f.exports_entered(1));
    // One more may wait behind the running export; of two more requests, one waits and the
    // other is refused at once, whichever arrives second.
    auto second = std::async(std::launch::async, [&] { return http_request(port, target); });
    auto third = std::async(std::launch::async, [&] { return http_request(port, target); });
    ASSERT_TRUE(wait_until([&] { return f.server->counters().take_exports_busy.value() == 1; }));
    // The serve thread is free meanwhile.
    EXPECT_EQ(http_request(port, "/healthz").status, 200u);
    EXPECT_EQ(http_request(port, "/api/takes").status, 200u);
    f.release();
    const auto a = running.get();
    const auto b = second.get();
    const auto c = third.get();
    EXPECT_EQ(a.status, 200u);
    EXPECT_EQ(a.body, "export of walk with madgwick\n");
    EXPECT_EQ(a.content_type, "text/plain; charset=utf-8");
    EXPECT_EQ(std::min(b.status, c.status), 200u);
    EXPECT_EQ(std::max(b.status, c.status), 503u);
    EXPECT_EQ(f.server->counters().take_downloads.value(), 2u);
}

TEST(HttpTakes, StoppingTheServerCancelsARunningExport) {
    Fixture f;
    const std::uint16_t port = f.server->port();
    auto waiting =
        std::async(std::launch::async, [&] { return http_request(port, "/api/takes/walk/download?format=csv"); });
    ASSERT_TRUE(f.exports_entered(1));
    f.server->stop();  // returns only once the export thread is joined
    const auto reply = waiting.get();
    EXPECT_TRUE(reply.status == 503u || reply.status == 0u) << reply.status << " " << reply.body;
    EXPECT_EQ(f.server->counters().take_downloads.value(), 0u);
}

TEST(HttpTakes, NamesAndParametersAreCheckedBeforeAnythingRuns) {
    Fixture f;
    const std::uint16_t port = f.server->port();
    for (const char* bad :
         {"/api/takes/..%2Fx/download?format=bvh", "/api/takes/.walk", "/api/takes/walk/download?format=exe",
          "/api/takes/walk/download?format=bvh&filter=a%2Fb", "/api/takes/walk/download?format=bvh&subject=-1"}) {
        EXPECT_EQ(http_request(port, bad).status, 400u) << bad;
    }
    EXPECT_EQ(http_request(port, "/api/takes/none").status, 404u);
    EXPECT_EQ(http_request(port, "/api/takes/walk/download?format=raw").status, 409u) << "a take without a raw file";
    EXPECT_EQ(http_request(port, "/api/takes/walk", boost::beast::http::verb::delete_).status, 401u);
    EXPECT_EQ(http_request(port, "/api/takes/walk", boost::beast::http::verb::delete_,
                           {{"X-Mocap-Token", "takes-test-token-0123456789"}})
                  .status,
              200u);
    EXPECT_FALSE(f.store->find("walk"));
    std::lock_guard lock(f.mutex);
    EXPECT_EQ(f.entered, 0) << "no export ran";
}

}  // namespace
}  // namespace mocap::serve
