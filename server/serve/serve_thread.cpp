// serve_thread.cpp — acceptor with connection slots and the lanes (threads) that serve.
#include "serve/serve_thread.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

#include "core/peer_address.hpp"
#include "serve/tcp_listen.hpp"

namespace mocap::serve {

namespace {
// Refusals and evictions are logged at most once per interval (a connect flood would
// otherwise flood the log); the counters have every one.
constexpr std::chrono::seconds kRefusalLogInterval{10};

template <class Lane>
std::vector<std::unique_ptr<Lane>> make_lanes(std::size_t threads) {
    std::vector<std::unique_ptr<Lane>> lanes;
    for (std::size_t i = 0; i < std::max<std::size_t>(threads, 1); ++i)
        lanes.push_back(std::make_unique<Lane>());
    return lanes;
}
}  // namespace

ServeThread::ServeThread(Names names, const Options& options, ConnectionCounters& counters, Hooks hooks)
    : names_(std::move(names)),
      options_(options),
      counters_(counters),
      hooks_(std::move(hooks)),
      slots_(options_.slots),
      lanes_(make_lanes<Lane>(options_.threads)),
      backoff_(lanes_[0]->io.get_executor(), names_.service, counters_.accept_errors) {}

ServeThread::~ServeThread() {
    stop();
}

std::int64_t ServeThread::now_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

bool ServeThread::start(const std::string& bind_address, std::uint16_t port, std::string& error) {
    acceptor_ = listen_tcp(lanes_[0]->io, bind_address, port, error);
    if (!acceptor_) {
        error = names_.service + ": " + error;
        return false;
    }
    bound_port_ = acceptor_->local_endpoint().port();
    running_ = true;
    do_accept();
    for (std::size_t i = 0; i < lanes_.size(); ++i) {
        Lane& lane = *lanes_[i];
        // One lane keeps the plain name; several get "-<lane>" (at most 15 characters in all).
        std::string name = lanes_.size() == 1 ? names_.thread_name : names_.thread_name + "-" + std::to_string(i);
        lane.thread = std::thread([&lane, name = std::move(name)] {
            pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
            auto guard = asio::make_work_guard(lane.io);
            lane.io.run();
        });
    }
    spdlog::info("{}: {} on {}:{}", names_.service, names_.serves, bind_address, bound_port_.load());
    return true;
}

void ServeThread::stop() {
    if (running_.exchange(false)) {
        for (std::size_t i = 0; i < lanes_.size(); ++i) {
            Lane& lane = *lanes_[i];
            asio::post(lane.io, [this, &lane, i] {
                if (i == 0) {
                    boost::system::error_code ignored;
                    acceptor_->close(ignored);
                    backoff_.cancel();
                }
                hooks_.close_all(i);
                lane.io.stop();  // remaining handlers are destroyed with the io_context
            });
        }
    }
    for (auto& lane : lanes_) {
        if (lane->thread.joinable()) lane->thread.join();
    }
}

void ServeThread::do_accept() {
    // The accepted socket belongs to the lane whose turn it is; the handler runs on lane 0.
    acceptor_->async_accept(lanes_[next_lane_]->io,
                            [this](const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
                                on_accept(ec, std::move(socket));
                            });
}

void ServeThread::evict(std::uint64_t id) {
    // The victim may be on any lane; only its own lane may touch it.
    hooks_.evict(0, id);
    for (std::size_t i = 1; i < lanes_.size(); ++i)
        asio::post(lanes_[i]->io, [this, i, id] { hooks_.evict(i, id); });
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
    const std::size_t lane = next_lane_;
    next_lane_ = (next_lane_ + 1) % lanes_.size();
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
            evict(a.evicted);
            [[fallthrough]];
        case ConnectionSlots::Verdict::kAdmitted:
            counters_.accepted.add();
            socket.set_option(asio::ip::tcp::no_delay(true), ignored);
            if (options_.send_buffer_bytes > 0) {
                socket.set_option(asio::socket_base::send_buffer_size(static_cast<int>(options_.send_buffer_bytes)),
                                  ignored);
            }
            if (lane == 0) {
                hooks_.admit(0, std::move(socket), std::move(a.slot));
            } else {
                asio::post(lanes_[lane]->io, [this, lane, s = std::move(socket), slot = std::move(a.slot)]() mutable {
                    hooks_.admit(lane, std::move(s), std::move(slot));
                });
            }
            break;
    }
    do_accept();
}

}  // namespace mocap::serve
