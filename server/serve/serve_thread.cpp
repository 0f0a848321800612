// serve_thread.cpp — acceptor with connection slots and the thread that runs it.
#include "serve/serve_thread.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <utility>

#include "core/peer_address.hpp"
#include "serve/tcp_listen.hpp"

namespace mocap::serve {

namespace {
// Refusals and evictions are logged at most once per interval (a connect flood would
// otherwise flood the log); the counters have every one.
constexpr std::chrono::seconds kRefusalLogInterval{10};
}  // namespace

ServeThread::ServeThread(Names names, const Options& options, const Counters& counters, Hooks hooks)
    : names_(std::move(names)),
      options_(options),
      counters_(counters),
      hooks_(std::move(hooks)),
      slots_(options_.slots),
      backoff_(io_.get_executor(), names_.service, counters_.accept_errors) {}

ServeThread::~ServeThread() {
    stop();
}

std::int64_t ServeThread::now_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

bool ServeThread::start(const std::string& bind_address, std::uint16_t port, std::string& error) {
    acceptor_ = listen_tcp(io_, bind_address, port, error);
    if (!acceptor_) {
        error = names_.service + ": " + error;
        return false;
    }
    bound_port_ = acceptor_->local_endpoint().port();
    running_ = true;
    do_accept();
    thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), names_.thread_name.c_str());
        auto guard = asio::make_work_guard(io_);
        io_.run();
    });
    spdlog::info("{}: {} on {}:{}", names_.service, names_.serves, bind_address, bound_port_.load());
    return true;
}

void ServeThread::stop() {
    if (!running_.exchange(false)) {
        if (thread_.joinable()) thread_.join();
        return;
    }
    asio::post(io_, [this] {
        boost::system::error_code ignored;
        acceptor_->close(ignored);
        backoff_.cancel();
        hooks_.close_all();
        io_.stop();
    });
    if (thread_.joinable()) thread_.join();
}

void ServeThread::do_accept() {
    acceptor_->async_accept([this](const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
        on_accept(ec, std::move(socket));
    });
}

void ServeThread::log_refusal(const char* what, const std::string& ip) {
    const auto now = std::chrono::steady_clock::now();
    if (refusal_logged_ && now - last_refusal_log_ < kRefusalLogInterval) {
        ++refusals_unlogged_;
        return;
    }
    spdlog::warn("{}: connection from {}: {} ({} more such events since the last line)", names_.service, ip, what,
                 refusals_unlogged_);
    refusal_logged_ = true;
    last_refusal_log_ = now;
    refusals_unlogged_ = 0;
}

void ServeThread::on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec == asio::error::operation_aborted || !running_.load()) return;
    if (ec) return backoff_.on_error(ec, [this] { do_accept(); });
    boost::system::error_code ignored;
    const PeerAddress peer = peer_address(socket);
    ConnectionSlots::Admission a = slots_.admit(peer.ip, peer.loopback, now_us());
    switch (a.verdict) {
        case ConnectionSlots::Verdict::kRefusedPerAddress:
            counters_.refused_per_address.add();
            log_refusal("refused, per-address limit reached", peer.ip);
            socket.close(ignored);
            break;
        case ConnectionSlots::Verdict::kRefusedFull:
            counters_.rejected_full.add();
            log_refusal("refused, every slot is taken by a connection making progress", peer.ip);
            socket.close(ignored);
            break;
        case ConnectionSlots::Verdict::kAdmittedEvicting:
            counters_.evicted.add();
            log_refusal("admitted in place of a connection without progress, which is closed", peer.ip);
            hooks_.evict(a.evicted);
            [[fallthrough]];
        case ConnectionSlots::Verdict::kAdmitted:
            counters_.accepted.add();
            socket.set_option(asio::ip::tcp::no_delay(true), ignored);
            if (options_.send_buffer_bytes > 0) {
                socket.set_option(asio::socket_base::send_buffer_size(static_cast<int>(options_.send_buffer_bytes)),
                                  ignored);
            }
            hooks_.admit(std::move(socket), std::move(a.slot));
            break;
    }
    do_accept();
}

}  // namespace mocap::serve
