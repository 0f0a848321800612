// ws_connection.hpp — one WebSocket viewer of the web endpoint (http_server.hpp has the
// messages and the lag policy). An HttpSession hands its socket over after an Upgrade on
// /ws; the server offers every published frame. Its lane's thread only: no locks.
#pragma once

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include "serve/client_send_queue.hpp"
#include "serve/http_server.hpp"

namespace mocap::serve {

/// What the server's session table holds: an HTTP connection or a WebSocket.
class HttpServer::Session {
public:
    virtual ~Session() = default;
    virtual void close() = 0;
};

class HttpServer::WsSession : public Session, public std::enable_shared_from_this<WsSession> {
public:
    /// Takes over the HTTP connection's slot (and so its id) and lane.
    WsSession(asio::ip::tcp::socket socket, HttpServer& server, std::size_t lane, ServeThread::SlotPtr slot,
              std::uint32_t subject);

    /// Completes the handshake of `request` (the Upgrade), then sends the hello.
    void run(boost::beast::http::request<boost::beast::http::string_body> request);
    /// A frame for whoever watches its subject; oldest queued frame dropped when full.
    void offer(const SubjectText& frame);
    void close() override;

private:
    void on_accept(const boost::beast::error_code& ec);
    void do_read();
    void on_read(const boost::beast::error_code& ec);
    void do_write();
    void on_write(const boost::beast::error_code& ec);
    void fail(const boost::beast::error_code& ec, const char* what);

    boost::beast::websocket::stream<boost::beast::tcp_stream> ws_;
    HttpServer& server_;
    std::size_t lane_;
    ServeThread::SlotPtr slot_;  // progress: frames the kernel took for this browser
    std::uint64_t id_;
    std::uint32_t subject_;
    boost::beast::http::request<boost::beast::http::string_body> request_;
    boost::beast::flat_buffer read_buf_;
    ClientSendQueue frames_;  // capacity ws_queue_frames; drops announced before the next frame
    std::deque<std::shared_ptr<const std::string>> replies_;  // hello only
    std::shared_ptr<const std::string> in_flight_;
    bool in_flight_is_frame_ = false;
    bool writing_ = false;
    bool open_ = false;
    bool closed_ = false;
};

}  // namespace mocap::serve
