// ws_connection.cpp — a WebSocket viewer: handshake, hello, frames through a drop-oldest
// queue with one write in flight, client messages read and ignored.
#include "serve/ws_connection.hpp"

#include <spdlog/spdlog.h>

#include "serve/pose_json.hpp"

namespace mocap::serve {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

namespace {
constexpr std::size_t kMaxWsMessageBytes = std::size_t{4} * 1024;
}  // namespace

HttpServer::WsSession::WsSession(asio::ip::tcp::socket socket, HttpServer& server, std::size_t lane,
                                 ServeThread::SlotPtr slot, std::uint32_t subject)
    : ws_(std::move(socket)),
      server_(server),
      lane_(lane),
      slot_(std::move(slot)),
      id_(slot_->id()),
      subject_(subject),
      frames_(server.config_.ws_queue_frames, server.counters_.ws_frames_dropped) {}

void HttpServer::WsSession::run(http::request<http::string_body> request) {
    request_ = std::move(request);
    beast::get_lowest_layer(ws_).expires_never();  // the WebSocket timeouts take over
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "mocapd"); }));
    ws_.read_message_max(kMaxWsMessageBytes);
    ws_.async_accept(request_, [self = shared_from_this()](const beast::error_code& ec) { self->on_accept(ec); });
}

void HttpServer::WsSession::offer(const SubjectText& frame) {
    if (closed_ || !open_) return;
    if (subject_ == 0) subject_ = frame.subject_id;  // first subject with a frame
    if (frame.subject_id != subject_) return;
    frames_.push(frame.text);
    if (!writing_) do_write();
}

void HttpServer::WsSession::close() {
    if (closed_) return;
    closed_ = true;
    beast::error_code ignored;
    auto& socket = beast::get_lowest_layer(ws_).socket();
    socket.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
    socket.close(ignored);
    server_.on_closed(lane_, id_);
}

void HttpServer::WsSession::on_accept(const beast::error_code& ec) {
    if (ec) return fail(ec, "accept");
    open_ = true;
    server_.on_ws_open(lane_, id_, shared_from_this());
    replies_.push_back(std::make_shared<const std::string>(server_.hello_json(subject_)));
    do_write();
    do_read();
}

void HttpServer::WsSession::do_read() {
    ws_.async_read(read_buf_,
                   [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_read(ec); });
}

void HttpServer::WsSession::on_read(const beast::error_code& ec) {
    if (ec) return fail(ec, "read");
    server_.counters_.ws_client_messages.add();
    read_buf_.consume(read_buf_.size());
    do_read();
}

void HttpServer::WsSession::do_write() {
    if (closed_ || writing_) return;
    in_flight_is_frame_ = false;
    if (const std::uint64_t dropped = frames_.take_unreported_drops(); dropped > 0) {
        in_flight_ = std::make_shared<const std::string>(encode_drops_json(dropped, frames_.dropped_total()));
    } else if (!replies_.empty()) {
        in_flight_ = std::move(replies_.front());
        replies_.pop_front();
    } else if (!frames_.empty()) {
        in_flight_ = frames_.pop();
        in_flight_is_frame_ = true;
    } else {
        return;
    }
    writing_ = true;
    ws_.text(true);
    ws_.async_write(asio::buffer(*in_flight_),
                    [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_write(ec); });
}

void HttpServer::WsSession::on_write(const beast::error_code& ec) {
    writing_ = false;
    if (ec) {
        if (ec != asio::error::operation_aborted) {
            server_.counters_.write_errors.add();
        }
        return fail(ec, "write");
    }
    if (in_flight_is_frame_) {
        server_.counters_.ws_frames_sent.add();
        // With the bounded send buffer, a browser that stops reading stops this within seconds.
        slot_->progress(ServeThread::now_us());
    }
    in_flight_.reset();
    do_write();
}

void HttpServer::WsSession::fail(const beast::error_code& ec, const char* what) {
    if (ec != asio::error::operation_aborted && ec != websocket::error::closed && ec != asio::error::eof &&
        ec != asio::error::connection_reset) {
        spdlog::debug("http: websocket {} {}: {}", id_, what, ec.message());
    }
    close();
}

}  // namespace mocap::serve
