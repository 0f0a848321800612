#include "serve/bvh_server.hpp"

#include <spdlog/spdlog.h>

#include <charconv>
#include <deque>

namespace mocap::serve {

namespace {
constexpr std::size_t kMaxBatch = 32;       // lines per write (one writev)
constexpr std::size_t kMaxClientLine = 64;  // "subject <id>" fits easily
}  // namespace

std::vector<NamedCounter> BvhServerCounters::snapshot() const {
    auto v = [](const C& c) { return c.load(std::memory_order_relaxed); };
    return {{"bvh_live.connections_accepted", v(connections_accepted)},
            {"bvh_live.connections_rejected_full", v(connections_rejected_full)},
            {"bvh_live.connections_closed", v(connections_closed)},
            {"bvh_live.frames_published", v(frames_published)},
            {"bvh_live.frames_sent", v(frames_sent)},
            {"bvh_live.frames_dropped", v(frames_dropped)},
            {"bvh_live.backlog_dropped", v(backlog_dropped)},
            {"bvh_live.bad_client_lines", v(bad_client_lines)},
            {"bvh_live.write_errors", v(write_errors)}};
}

// One client. Lives on the serve thread only: no locks.
class BvhServer::Session : public std::enable_shared_from_this<Session> {
public:
    Session(asio::ip::tcp::socket socket, BvhServer& server, std::uint64_t id)
        : socket_(std::move(socket)), server_(server), id_(id), subject_(server.config_.subject) {}

    void start() {
        boost::system::error_code ignored;
        socket_.set_option(asio::ip::tcp::no_delay(true), ignored);
        do_write();
        do_read();
    }

    void offer(const Line& line) {
        if (closed_) return;
        if (subject_ == 0) subject_ = line.subject_id;  // first subject with a frame
        if (line.subject_id != subject_) return;
        if (queue_.size() >= server_.config_.queue_frames) {
            queue_.pop_front();
            server_.counters_.frames_dropped.fetch_add(1, std::memory_order_relaxed);
        }
        queue_.push_back(line.text);
        if (!writing_) do_write();
    }

    void close() {
        if (closed_) return;
        closed_ = true;
        boost::system::error_code ignored;
        socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        socket_.close(ignored);
        server_.on_closed(id_);
    }

private:
    void do_write() {
        if (closed_ || writing_) return;
        in_flight_.clear();
        if (!greeted_) {
            in_flight_.push_back(server_.greeting_);
            greeted_ = true;
        }
        while (!queue_.empty() && in_flight_.size() < kMaxBatch) {
            in_flight_.push_back(std::move(queue_.front()));
            queue_.pop_front();
        }
        if (in_flight_.empty()) return;
        buffers_.clear();
        for (const auto& s : in_flight_) buffers_.emplace_back(s->data(), s->size());
        writing_ = true;
        asio::async_write(socket_, buffers_,
                          [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                              self->on_write(ec);
                          });
    }

    void on_write(const boost::system::error_code& ec) {
        writing_ = false;
        if (ec) return fail(ec, "write");
        // The greeting is not a frame; every other buffer is one MOTION line.
        const std::size_t lines = in_flight_.size() - (in_flight_.front() == server_.greeting_ ? 1 : 0);
        server_.counters_.frames_sent.fetch_add(lines, std::memory_order_relaxed);
        do_write();
    }

    void do_read() {
        socket_.async_read_some(asio::buffer(read_buf_),
                                [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) {
                                    self->on_read(ec, n);
                                });
    }

    void on_read(const boost::system::error_code& ec, std::size_t n) {
        // A client that half-closes (e.g. `echo subject 2 | nc`) still reads: keep writing.
        if (ec == asio::error::eof) return;
        if (ec) return fail(ec, "read");
        for (std::size_t i = 0; i < n; ++i) {
            const char c = read_buf_[i];
            if (c == '\n') {
                handle_line(partial_);
                partial_.clear();
            } else if (partial_.size() >= kMaxClientLine) {
                server_.counters_.bad_client_lines.fetch_add(1, std::memory_order_relaxed);
                return close();
            } else {
                partial_ += c;
            }
        }
        do_read();
    }

    // "subject <id>" (an optional '\r' is tolerated); anything else is counted and ignored.
    void handle_line(std::string_view line) {
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        constexpr std::string_view kCommand = "subject ";
        std::uint32_t id = 0;
        if (line.substr(0, kCommand.size()) == kCommand) {
            const char* first = line.data() + kCommand.size();
            const char* last = line.data() + line.size();
            const auto [ptr, err] = std::from_chars(first, last, id);
            if (err == std::errc() && ptr == last) {
                if (id != subject_) queue_.clear();  // lines of the old subject are not wanted
                subject_ = id;
                return;
            }
        }
        server_.counters_.bad_client_lines.fetch_add(1, std::memory_order_relaxed);
    }

    void fail(const boost::system::error_code& ec, const char* what) {
        if (ec != asio::error::operation_aborted && ec != asio::error::eof && std::string_view(what) == "write") {
            server_.counters_.write_errors.fetch_add(1, std::memory_order_relaxed);
        }
        close();
    }

    asio::ip::tcp::socket socket_;
    BvhServer& server_;
    std::uint64_t id_;
    std::uint32_t subject_;
    bool greeted_ = false;
    bool writing_ = false;
    bool closed_ = false;
    std::deque<std::shared_ptr<const std::string>> queue_;
    std::vector<std::shared_ptr<const std::string>> in_flight_;
    std::vector<asio::const_buffer> buffers_;
    std::array<char, 256> read_buf_{};
    std::string partial_;
};

BvhServer::BvhServer(BvhServerConfig config, const BvhFrameEncoder& encoder)
    : config_(std::move(config)), encoder_(encoder) {
    greeting_ = std::make_shared<const std::string>(encoder_.hierarchy() + "MOTION\n" + encoder_.frame_time_line());
    backlog_.reserve(config_.publish_backlog_frames);
    draining_.reserve(config_.publish_backlog_frames);
}

BvhServer::~BvhServer() { stop(); }

bool BvhServer::start(std::string& error) {
    boost::system::error_code ec;
    const auto address = asio::ip::make_address(config_.bind_address, ec);
    if (ec) {
        error = "bvh: bind address " + config_.bind_address + ": " + ec.message();
        return false;
    }
    const asio::ip::tcp::endpoint ep(address, config_.port);
    acceptor_ = std::make_unique<asio::ip::tcp::acceptor>(io_);
    acceptor_->open(ep.protocol(), ec);
    if (!ec) acceptor_->set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor_->bind(ep, ec);
    if (!ec) acceptor_->listen(asio::socket_base::max_listen_connections, ec);
    if (ec) {
        error = "bvh: bind " + config_.bind_address + ":" + std::to_string(config_.port) + ": " + ec.message();
        return false;
    }
    bound_port_ = acceptor_->local_endpoint().port();
    running_ = true;
    do_accept();
    thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "mocap-bvh");
        auto guard = asio::make_work_guard(io_);
        io_.run();
    });
    spdlog::info("bvh: live BVH on {}:{}", config_.bind_address, bound_port_.load());
    return true;
}

void BvhServer::stop() {
    if (!running_.exchange(false)) {
        if (thread_.joinable()) thread_.join();
        return;
    }
    asio::post(io_, [this] {
        boost::system::error_code ignored;
        acceptor_->close(ignored);
        auto sessions = sessions_;  // close() erases from sessions_
        for (auto& [id, s] : sessions) s->close();
        io_.stop();
    });
    if (thread_.joinable()) thread_.join();
}

void BvhServer::do_accept() {
    acceptor_->async_accept([this](const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
        if (ec == asio::error::operation_aborted || !running_.load()) return;
        if (!ec) {
            if (sessions_.size() >= config_.max_clients) {
                counters_.connections_rejected_full.fetch_add(1, std::memory_order_relaxed);
                boost::system::error_code ignored;
                socket.close(ignored);
            } else {
                counters_.connections_accepted.fetch_add(1, std::memory_order_relaxed);
                const std::uint64_t id = next_id_++;
                auto s = std::make_shared<Session>(std::move(socket), *this, id);
                sessions_.emplace(id, s);
                clients_.store(sessions_.size());
                s->start();
            }
        }
        do_accept();
    });
}

void BvhServer::on_closed(std::uint64_t id) {
    if (sessions_.erase(id) != 0) counters_.connections_closed.fetch_add(1, std::memory_order_relaxed);
    clients_.store(sessions_.size());
}

void BvhServer::publish(const SubjectFrame& frame, const SkeletonPose& pose) {
    if (clients_.load(std::memory_order_relaxed) == 0 || !running_.load(std::memory_order_relaxed)) return;
    auto text = std::make_shared<std::string>();
    text->reserve(16 * encoder_.values_per_frame());
    encoder_.append_motion_line(pose, *text);
    counters_.frames_published.fetch_add(1, std::memory_order_relaxed);
    bool wake = false;
    {
        std::lock_guard lock(backlog_mutex_);
        if (backlog_.size() >= config_.publish_backlog_frames) {
            counters_.backlog_dropped.fetch_add(1, std::memory_order_relaxed);
            return;
        }
        wake = backlog_.empty();
        backlog_.push_back({frame.subject_id, std::move(text)});
    }
    if (wake) asio::post(io_, [this] { drain(); });
}

void BvhServer::drain() {
    {
        std::lock_guard lock(backlog_mutex_);
        draining_.swap(backlog_);
    }
    for (const Line& line : draining_) {
        for (auto it = sessions_.begin(); it != sessions_.end();) {
            auto s = (it++)->second;  // offer() may close and erase the session
            s->offer(line);
        }
    }
    draining_.clear();
}

}  // namespace mocap::serve
