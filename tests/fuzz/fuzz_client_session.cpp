// Fuzz target: the pose service's client request path, through the real ClientSession.
//
// Each input is what one client sends: a loopback TCP connection is made to an acceptor
// of this process, the input is written and the client half-closes; the server side
// socket is handed to a ClientSession (as PoseServer does) and its io_context runs until
// the session has closed. That drives the real code: DelimitedReader framing, ClientMessage
// parsing, the request rate limit, Subscribe validation and the broadcaster index, Stats,
// Ping, and control requests (token check, loopback rule, handlers). Control is enabled
// with a known token (the seeds carry it) so the accepted branch is reached too.
// Checks: the session always closes after the client's EOF (exactly once, counted).
// Before that, the framing alone is checked differentially: DelimitedReader must return
// the same messages (and the same final error) whether the bytes arrive at once or in
// chunks of 1..16 bytes (the first input byte picks the size), and write_area() must never
// be empty while no error was returned.
#include <spdlog/spdlog.h>

#include <signal.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_target.hpp"
#include "mocap/v1/mocap.pb.h"
#include "serve/client_session.hpp"
#include "serve/pose_encoder.hpp"

namespace {

namespace asio = mocap::asio;
namespace serve = mocap::serve;

struct Harness {
    asio::io_context io{1};
    asio::ip::tcp::acceptor acceptor{io, {asio::ip::make_address("127.0.0.1"), 0}};
    serve::ServeConfig config;
    serve::ControlHandlers handlers;
    serve::ServeCounters counters;
    serve::LogLimiter log;
    serve::PoseBroadcaster broadcaster{{&io}, 64, [] { return std::int64_t{1}; }, counters};
    serve::RequestBudget requests{io, 4};  // small, so the fuzzer reaches the waiting path
    serve::SharedBytes hello;
    std::unique_ptr<serve::SessionContext> context;
    std::uint64_t closed = 0;
    std::uint64_t next_id = 1;

    Harness() {
        spdlog::set_level(spdlog::level::off);
        config.control_token = "fuzz-token";
        config.subscribe_timeout_ms = 60'000;  // the client's EOF closes every session
        config.close_grace_ms = 60'000;
        handlers.calibrate = [](std::uint32_t, serve::CalibrationPose) { return serve::ControlResult::success(); };
        handlers.start_recording = [](const std::string& path) {
            return path.size() < 64 ? serve::ControlResult::success() : serve::ControlResult::failure("path too long");
        };
        handlers.stop_recording = [] { return serve::ControlResult::success(); };
        handlers.reload = [] { return serve::ControlResult::failure("no config file"); };
        handlers.stats = [] {
            mocap::MetricsSnapshot s;
            s.counters.push_back({"samples", 42});
            s.latencies.push_back({"filter", {}});
            return s;
        };
        mocap::v1::ServerMessage m;
        m.mutable_hello()->set_max_client_message_bytes(config.max_client_message_bytes);
        hello = serve::encode_server_message(m);
        context.reset(new serve::SessionContext{config,
                                                handlers,
                                                counters,
                                                log,
                                                broadcaster,
                                                [this] { return hello; },
                                                [] { return std::int64_t{1'700'000'000'000'000}; },
                                                [this](std::size_t, std::uint64_t) { ++closed; },
                                                {&requests}});
    }
};

// libFuzzer's -timeout watchdog is a SIGALRM timer; a blocking connect() it interrupts
// fails with EINTR (and Asio throws). The signal is held while the loopback pair is made
// and delivered as soon as it is released, so a real hang is still caught.
class AlarmHeld {
public:
    AlarmHeld() {
        sigset_t alarm;
        sigemptyset(&alarm);
        sigaddset(&alarm, SIGALRM);
        pthread_sigmask(SIG_BLOCK, &alarm, &old_);
    }
    ~AlarmHeld() { pthread_sigmask(SIG_SETMASK, &old_, nullptr); }
    AlarmHeld(const AlarmHeld&) = delete;
    AlarmHeld& operator=(const AlarmHeld&) = delete;

private:
    sigset_t old_{};
};

// Every message (and a final error marker) the reader yields when fed `chunk` bytes at a time.
std::vector<std::string> deframe(const std::uint8_t* data, std::size_t size, std::size_t chunk) {
    serve::DelimitedReader reader(serve::ServeConfig{}.max_client_message_bytes);
    std::vector<std::string> out;
    std::size_t pos = 0;
    for (;;) {
        const serve::FrameResult r = reader.next();
        if (r.status == serve::FrameStatus::kMessage) {
            out.emplace_back(reinterpret_cast<const char*>(r.payload.data()), r.payload.size());
            continue;
        }
        if (r.status != serve::FrameStatus::kNeedMore) {
            out.push_back(r.status == serve::FrameStatus::kTooLarge ? "<too large>" : "<bad prefix>");
            return out;
        }
        if (pos == size) return out;
        const auto area = reader.write_area();
        MOCAP_FUZZ_CHECK(!area.empty(), "write_area() empty without an error");
        const std::size_t n = std::min({chunk, area.size(), size - pos});
        std::memcpy(area.data(), data + pos, n);
        reader.commit(n);
        pos += n;
    }
}

}  // namespace

MOCAP_FUZZ_ENTRY(client_session) {
    if (size > 0) {
        const auto whole = deframe(data, size, size);
        MOCAP_FUZZ_CHECK(whole == deframe(data, size, 1 + data[0] % 16), "framing depends on how the bytes were split");
    }

    static Harness* h = new Harness;
    asio::ip::tcp::socket client(h->io);
    asio::ip::tcp::socket server(h->io);
    {
        const AlarmHeld held;
        client.connect(h->acceptor.local_endpoint());
        h->acceptor.accept(server);
        // The input fits the loopback socket buffers (run_fuzzers.sh caps it at 8 KiB).
        asio::write(client, asio::buffer(data, size));
        client.shutdown(asio::ip::tcp::socket::shutdown_send);
    }

    const std::uint64_t closed_before = h->closed;
    const std::uint64_t id = h->next_id++;
    {
        auto session = std::make_shared<serve::ClientSession>(std::move(server), *h->context, 0, id);
        session->start();
    }
    h->io.restart();
    h->io.run();
    MOCAP_FUZZ_CHECK(h->closed == closed_before + 1, "session did not close exactly once");

    const serve::ServeCounters& c = h->counters;
    MOCAP_FUZZ_CHECK(c.connections.closed.value() == h->closed, "connections_closed");
    return 0;
}
