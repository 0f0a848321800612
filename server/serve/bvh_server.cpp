#include "serve/bvh_server.hpp"

#include <charconv>

#include "serve/client_send_queue.hpp"

namespace mocap::serve {

namespace {
constexpr std::size_t kMaxBatch = 32;       // lines per write (one writev)
constexpr std::size_t kMaxClientLine = 64;  // "subject <id>" fits easily
}  // namespace

BvhServerCounters::BvhServerCounters() {
    connections.register_in(group);
    group.add("frames_published", frames_published);
    group.add("frames_sent", frames_sent);
    group.add("frames_dropped", frames_dropped);
    group.add("backlog_dropped", backlog_dropped);
    group.add("bad_client_lines", bad_client_lines);
    group.add("write_errors", write_errors);
}

void BvhServer::register_metrics(MetricsRegistry& registry) const {
    registry.add(counters_.group);
    registry.add_gauge("bvh_live_clients", "Live BVH clients connected now",
                       [this] { return static_cast<double>(client_count()); });
}

// One client. Lives on its lane's thread only: no locks.
class BvhServer::Session : public std::enable_shared_from_this<Session> {
public:
    Session(asio::ip::tcp::socket socket, BvhServer& server, std::size_t lane, ServeThread::SlotPtr slot)
        : socket_(std::move(socket)),
          server_(server),
          lane_(lane),
          slot_(std::move(slot)),
          id_(slot_->id()),
          subject_(server.config_.subject),
          greeting_(server.fixed_greeting_),
          queue_(server.config_.queue_frames, server.counters_.frames_dropped) {}

    void start() {
        do_write();
        do_read();
    }

    void offer(const SubjectText& line) {
        if (closed_) return;
        if (subject_ == 0) subject_ = line.subject_id;  // first subject with a frame
        if (line.subject_id != subject_) return;
        if (!greeting_ && line.frame_time_s > 0.0) greeting_ = server_.greeting(line.frame_time_s);
        queue_.push(line.text);  // drops are not announced: BVH text has no line for them
        if (!writing_) do_write();
    }

    void close() {
        if (closed_) return;
        closed_ = true;
        boost::system::error_code ignored;
        socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        socket_.close(ignored);
        server_.on_closed(lane_, id_);
    }

private:
    void do_write() {
        if (closed_ || writing_) return;
        in_flight_.clear();
        if (!greeted_) {
            if (!greeting_) return;  // lines wait in the queue until the Frame Time is known
            in_flight_.push_back(greeting_);
            greeted_ = true;
            greeting_in_flight_ = true;
        }
        queue_.move_into(in_flight_, kMaxBatch);
        if (in_flight_.empty()) return;
        buffers_.clear();
        for (const auto& s : in_flight_)
            buffers_.emplace_back(s->data(), s->size());
        writing_ = true;
        asio::async_write(
            socket_, buffers_,
            [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) { self->on_write(ec); });
    }

    void on_write(const boost::system::error_code& ec) {
        writing_ = false;
        if (ec) return fail(ec, "write");
        // The greeting is not a frame; every other buffer is one MOTION line.
        const std::size_t lines = in_flight_.size() - (greeting_in_flight_ ? 1 : 0);
        greeting_in_flight_ = false;
        server_.counters_.frames_sent.add(lines);
        // Lines the kernel took are progress: with the bounded send buffer a client that stops
        // reading stops making it within seconds. The greeting alone is not (a dead
        // connection takes it too), so idle connections stay unproven while no frame flows.
        if (lines > 0) slot_->progress(ServeThread::now_us());
        do_write();
    }

    void do_read() {
        socket_.async_read_some(
            asio::buffer(read_buf_),
            [self = shared_from_this()](const boost::system::error_code& ec, std::size_t n) { self->on_read(ec, n); });
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
                server_.counters_.bad_client_lines.add();
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
                slot_->progress(ServeThread::now_us());
                if (id != subject_) queue_.clear();  // lines of the old subject are not wanted
                subject_ = id;
                return;
            }
        }
        server_.counters_.bad_client_lines.add();
    }

    void fail(const boost::system::error_code& ec, const char* what) {
        if (ec != asio::error::operation_aborted && ec != asio::error::eof && std::string_view(what) == "write") {
            server_.counters_.write_errors.add();
        }
        close();
    }

    asio::ip::tcp::socket socket_;
    BvhServer& server_;
    std::size_t lane_;
    ServeThread::SlotPtr slot_;
    std::uint64_t id_;
    std::uint32_t subject_;
    std::shared_ptr<const std::string> greeting_;  // null until the Frame Time is known
    bool greeted_ = false;
    bool greeting_in_flight_ = false;
    bool writing_ = false;
    bool closed_ = false;
    ClientSendQueue queue_;  // MOTION lines only; the greeting is written apart
    std::vector<std::shared_ptr<const std::string>> in_flight_;
    std::vector<asio::const_buffer> buffers_;
    std::array<char, 256> read_buf_{};
    std::string partial_;
};

BvhServer::BvhServer(BvhServerConfig config, const BvhFrameEncoder& encoder)
    : config_(std::move(config)),
      encoder_(encoder),
      serve_({"bvh", "mocap-bvh", "live BVH"},
             {{config_.max_clients, config_.limits}, config_.send_buffer_bytes, config_.threads}, counters_.connections,
             {[this](std::size_t lane, asio::ip::tcp::socket s, ServeThread::SlotPtr slot) {
                  admit(lane, std::move(s), std::move(slot));
              },
              [this](std::size_t lane, std::uint64_t id) { sessions_[lane]->close(id); },
              [this](std::size_t lane) { sessions_[lane]->close_all(); }}),
      sessions_(make_session_tables<Session>(serve_.lanes(), counters_.connections.closed)),
      backlog_(serve_.ios(), config_.publish_backlog_frames,
               [this](std::size_t lane, const SubjectText& line) { deliver(lane, line); }) {
    if (encoder_.fixed_frame_time()) fixed_greeting_ = greeting(0.0);
}

std::shared_ptr<const std::string> BvhServer::greeting(double measured_s) const {
    return std::make_shared<const std::string>(encoder_.hierarchy() + "MOTION\n" +
                                               encoder_.frame_time_line(measured_s));
}

double BvhServer::measure(const SubjectFrame& frame) {
    if (encoder_.fixed_frame_time()) return 0.0;
    std::lock_guard lock(intervals_mutex_);
    FrameInterval& interval = intervals_.try_emplace(frame.subject_id, kMeasuredIntervals).first->second;
    interval.add(frame.sync, frame.sample_us);
    return interval.seconds().value_or(0.0);
}

BvhServer::~BvhServer() {
    stop();
}

bool BvhServer::start(std::string& error) {
    return serve_.start(config_.bind_address, config_.port, error);
}

void BvhServer::stop() {
    serve_.stop();
}

std::size_t BvhServer::client_count() const {
    return open_sessions(sessions_);
}

void BvhServer::admit(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot) {
    const std::uint64_t id = slot->id();
    auto s = std::make_shared<Session>(std::move(socket), *this, lane, std::move(slot));
    sessions_[lane]->put(id, s);
    s->start();
}

void BvhServer::on_closed(std::size_t lane, std::uint64_t id) {
    sessions_[lane]->remove(id);
    serve_.release(id);
}

void BvhServer::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    // Measured with or without clients, so a client that connects later is greeted at once.
    const double frame_time_s = measure(frame);
    if (client_count() == 0 || !serve_.running()) return;
    auto text = std::make_shared<std::string>();
    text->reserve(16 * encoder_.values_per_frame());
    encoder_.append_motion_line(pose, *text);
    counters_.frames_published.add();
    // One encoding, shared by every lane and client.
    if (const std::size_t refused = backlog_.push({frame.subject_id, std::move(text), frame_time_s}); refused > 0) {
        counters_.backlog_dropped.add(refused);
    }
}

void BvhServer::deliver(std::size_t lane, const SubjectText& line) {
    sessions_[lane]->for_each([&](Session& s) { s.offer(line); });
}

}  // namespace mocap::serve
