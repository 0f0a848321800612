// serve_thread.cpp — acceptor with a client limit and the thread that runs it.
#include "serve/serve_thread.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>

#include <utility>

#include "serve/tcp_listen.hpp"

namespace mocap::serve {

ServeThread::ServeThread(Names names, std::size_t max_clients, Counters counters, Hooks hooks)
    : names_(std::move(names)), max_clients_(max_clients), counters_(counters), hooks_(std::move(hooks)) {}

ServeThread::~ServeThread() {
    stop();
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

void ServeThread::on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec == asio::error::operation_aborted || !running_.load()) return;
    if (!ec) {
        boost::system::error_code ignored;
        if (hooks_.open_clients() >= max_clients_) {
            counters_.rejected_full.add();
            socket.close(ignored);
        } else {
            counters_.accepted.add();
            socket.set_option(asio::ip::tcp::no_delay(true), ignored);
            hooks_.admit(std::move(socket));
        }
    }
    do_accept();
}

}  // namespace mocap::serve
