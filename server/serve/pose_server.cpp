// pose_server.cpp — acceptor, lanes (one io_context + thread each), session table.
#include "serve/pose_server.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>

#include <chrono>

#include "core/peer_address.hpp"
#include "mocap/v1/mocap.pb.h"
#include "serve/tcp_listen.hpp"

namespace mocap::serve {

void PoseServer::register_metrics(MetricsRegistry& registry) const {
    registry.add(counters_.group);
    registry.add_gauge(
        "pose_clients", "Protobuf pose clients connected now", [this] { return static_cast<double>(client_count()); },
        "clients");
}

PoseServer::PoseServer(ServeConfig config, ControlHandlers handlers)
    : config_(std::move(config)), handlers_(std::move(handlers)) {
    if (!config_.wall_clock_us) {
        config_.wall_clock_us = [] {
            return std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                .count();
        };
    }
    if (!config_.control_attempts) config_.control_attempts = std::make_shared<ControlAttemptLimiter>();
    const std::size_t lane_count = std::max<std::size_t>(config_.io_threads, 1);
    std::vector<asio::io_context*> ios;
    std::vector<RequestBudget*> budgets;
    for (std::size_t i = 0; i < lane_count; ++i) {
        lanes_.push_back(std::make_unique<Lane>(config_.requests_per_turn));
        ios.push_back(&lanes_.back()->io);
        budgets.push_back(&lanes_.back()->requests);
    }
    broadcaster_ = std::make_unique<PoseBroadcaster>(std::move(ios), config_.publish_backlog_frames,
                                                     config_.wall_clock_us, counters_);
    session_context_ = std::make_unique<SessionContext>(SessionContext{
        config_, handlers_, counters_, log_, *broadcaster_, [this] { return hello(); }, config_.wall_clock_us,
        [this](std::size_t lane, std::uint64_t id) { on_session_closed(lane, id); }, std::move(budgets),
        &address_budget_});
    goodbye_full_ = encode_goodbye(CloseReason::kServerFull, "client limit reached");
    goodbye_per_address_ = encode_goodbye(CloseReason::kServerFull, "connection limit of your address reached");
    goodbye_address_budget_ = encode_goodbye(
        CloseReason::kRateLimited, "too many requests from your address (address_message_burst): try again later");
    set_description({});
}

PoseServer::~PoseServer() {
    stop();
}

void PoseServer::set_description(const ServeDescription& description) {
    v1::ServerMessage message;
    v1::Hello* hello = message.mutable_hello();
    hello->set_server_version(config_.server_version);
    hello->set_protocol_version(1);
    hello->set_max_client_message_bytes(config_.max_client_message_bytes);
    hello->set_subscribe_timeout_ms(config_.subscribe_timeout_ms);
    hello->set_frame_rate_hz(config_.frame_rate_hz);
    hello->set_world_frame(config_.world_frame);
    v1::SkeletonDefinition* skeleton = hello->mutable_skeleton();
    for (const SegmentInfo& s : description.segments) {
        v1::Segment* out = skeleton->add_segments();
        out->set_name(s.name);
        out->set_parent(s.parent);
        out->set_offset_x_m(s.offset_m[0]);
        out->set_offset_y_m(s.offset_m[1]);
        out->set_offset_z_m(s.offset_m[2]);
        out->set_node_id(s.node_id);
    }
    for (const std::string& name : description.joint_angle_names) {
        skeleton->add_joint_angle_names(name);
    }
    for (const SubjectInfo& s : description.subjects) {
        v1::Subject* out = hello->add_subjects();
        out->set_id(s.id);
        out->set_name(s.name);
    }
    SharedBytes bytes = encode_server_message(message);
    std::lock_guard lock(hello_mutex_);
    hello_ = std::move(bytes);
}

SharedBytes PoseServer::hello() const {
    std::lock_guard lock(hello_mutex_);
    return hello_;
}

bool PoseServer::start(std::string& error) {
    if (running_.load()) {
        error = "pose server already started";
        return false;
    }
    acceptor_ = listen_tcp(lanes_[0]->io, config_.bind_address, config_.port, error);
    if (!acceptor_) return false;
    boost::system::error_code ec;
    bound_port_ = acceptor_->local_endpoint(ec).port();
    accept_backoff_ =
        std::make_unique<AcceptBackoff>(lanes_[0]->io.get_executor(), "serve", counters_.connections.accept_errors);
    running_ = true;
    do_accept();
    for (std::size_t i = 0; i < lanes_.size(); ++i) {
        Lane& lane = *lanes_[i];
        beat(lane);
        lane.thread = std::thread([&lane, i] {
            const std::string name = "mocap-serve-" + std::to_string(i);
            pthread_setname_np(pthread_self(), name.c_str());
            auto guard = asio::make_work_guard(lane.io);
            lane.io.run();
        });
    }
    spdlog::info("serve: listening on {}:{} ({} thread(s), max {} clients)", config_.bind_address, bound_port_.load(),
                 lanes_.size(), config_.max_clients);
    return true;
}

void PoseServer::stop() {
    if (!running_.exchange(false)) return;
    broadcaster_->stop();
    for (std::size_t i = 0; i < lanes_.size(); ++i) {
        Lane& lane = *lanes_[i];
        asio::post(lane.io, [this, &lane, i] {
            boost::system::error_code ignored;
            if (i == 0) {
                acceptor_->close(ignored);
                accept_backoff_->cancel();
            }
            // Copy: close() erases from the table through on_session_closed().
            std::vector<std::shared_ptr<ClientSession>> sessions;
            sessions.reserve(lane.sessions.size());
            for (auto& [id, session] : lane.sessions)
                sessions.push_back(session);
            for (auto& session : sessions)
                session->close();
            lane.io.stop();  // remaining handlers are destroyed with the io_context
        });
    }
    for (auto& lane : lanes_) {
        if (lane->thread.joinable()) lane->thread.join();
    }
    spdlog::info("serve: stopped");
}

void PoseServer::beat(Lane& lane) {
    lane.beats.fetch_add(1, std::memory_order_relaxed);
    lane.beat_timer.expires_after(std::chrono::milliseconds(250));
    lane.beat_timer.async_wait([this, &lane](const boost::system::error_code& ec) {
        if (!ec && running_.load()) beat(lane);
    });
}

std::vector<Heartbeat> PoseServer::heartbeats() const {
    std::vector<Heartbeat> out;
    for (std::size_t i = 0; i < lanes_.size(); ++i)
        out.push_back({"pose serve thread " + std::to_string(i), &lanes_[i]->beats});
    return out;
}

void PoseServer::do_accept() {
    asio::io_context& target = lanes_[next_lane_]->io;
    acceptor_->async_accept(target, [this](const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
        on_accept(ec, std::move(socket));
    });
}

void PoseServer::on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec == asio::error::operation_aborted || !running_.load()) return;
    if (ec) return accept_backoff_->on_error(ec, [this] { do_accept(); });
    const std::size_t lane = next_lane_;
    next_lane_ = (next_lane_ + 1) % lanes_.size();
    const PeerAddress peer = peer_address(socket);
    // An address that has used up its requests reconnects for nothing: refused before it
    // costs a session, so a reconnect storm cannot queue work ahead of other clients.
    boost::system::error_code peer_ec;
    const auto endpoint = socket.remote_endpoint(peer_ec);
    if (!peer_ec && !address_budget_.in_hand(endpoint.address(), ServeThread::now_us())) {
        counters_.address_rate_limited.add();
        std::uint64_t suppressed = 0;
        if (log_.allow(LogLimiter::kRateLimited, suppressed)) {
            spdlog::warn("serve: connection from {} refused: its address used up address_message_burst ({} suppressed)",
                         peer.ip, suppressed);
        }
        reject(socket, *goodbye_address_budget_);
        return do_accept();
    }
    ConnectionSlots::Admission a = slots_.admit(peer.ip, peer.loopback, ServeThread::now_us());
    std::uint64_t suppressed = 0;
    switch (a.verdict) {
        case ConnectionSlots::Verdict::kRefusedPerAddress:
            counters_.connections.refused_per_address.add();
            if (log_.allow(LogLimiter::kClientFull, suppressed)) {
                spdlog::warn("serve: connection from {} refused: {} connections from that address ({} suppressed)",
                             peer.ip, config_.limits.max_per_address, suppressed);
            }
            reject(socket, *goodbye_per_address_);
            break;
        case ConnectionSlots::Verdict::kRefusedFull:
            counters_.connections.rejected_full.add();
            if (log_.allow(LogLimiter::kClientFull, suppressed)) {
                spdlog::warn(
                    "serve: client limit {} reached, every client making progress, connection refused ({} "
                    "suppressed)",
                    config_.max_clients, suppressed);
            }
            reject(socket, *goodbye_full_);
            break;
        case ConnectionSlots::Verdict::kAdmittedEvicting:
            counters_.connections.evicted.add();
            if (log_.allow(LogLimiter::kClientFull, suppressed)) {
                spdlog::warn("serve: client limit {} reached, closing a client without progress for {} ({} suppressed)",
                             config_.max_clients, peer.ip, suppressed);
            }
            evict(a.evicted);
            [[fallthrough]];
        case ConnectionSlots::Verdict::kAdmitted:
            active_clients_.fetch_add(1);
            counters_.connections.accepted.add();
            asio::post(lanes_[lane]->io, [this, lane, s = std::move(socket), slot = std::move(a.slot)]() mutable {
                start_session(lane, std::move(s), std::move(slot));
            });
            break;
    }
    do_accept();
}

void PoseServer::evict(std::uint64_t id) {
    // The victim may be on any lane; only its own lane may touch it.
    for (auto& lane : lanes_) {
        asio::post(lane->io, [l = lane.get(), id] {
            const auto it = l->sessions.find(id);
            if (it == l->sessions.end()) return;
            const std::shared_ptr<ClientSession> session = it->second;
            session->close_with_goodbye(CloseReason::kServerFull, "client limit reached: slot given to a new client");
        });
    }
}

void PoseServer::reject(asio::ip::tcp::socket& socket, const std::string& goodbye) {
    // A fresh socket's send buffer always has room for a few dozen bytes: one
    // non-blocking write, no session, no state.
    boost::system::error_code ignored;
    socket.non_blocking(true, ignored);
    socket.write_some(asio::buffer(goodbye), ignored);
    socket.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
    socket.close(ignored);
}

void PoseServer::start_session(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot) {
    boost::system::error_code ignored;
    socket.set_option(asio::ip::tcp::no_delay(true), ignored);  // frames are small and urgent
    if (config_.send_buffer_bytes > 0) {
        socket.set_option(asio::socket_base::send_buffer_size(static_cast<int>(config_.send_buffer_bytes)), ignored);
    }
    const std::uint64_t id = slot->id();
    auto session = std::make_shared<ClientSession>(std::move(socket), *session_context_, lane, id);
    session->set_slot(std::move(slot));
    lanes_[lane]->sessions.emplace(id, session);
    session->start();
}

void PoseServer::on_session_closed(std::size_t lane, std::uint64_t id) {
    if (lanes_[lane]->sessions.erase(id) > 0) active_clients_.fetch_sub(1);
    slots_.release(id);
}

}  // namespace mocap::serve
