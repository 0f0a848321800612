// http_connection.hpp — one HTTP/1.1 connection of the web endpoint (keep-alive): reads
// requests and answers them (viewer files, /metrics, /healthz, POST /api/... control), or
// hands its socket to a WsSession after an Upgrade on /ws. Its lane's thread only.
#pragma once

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "serve/http_server.hpp"
#include "serve/ws_connection.hpp"  // HttpServer::Session

namespace mocap::serve {

class HttpServer::HttpSession : public Session, public std::enable_shared_from_this<HttpSession> {
public:
    /// The session's id is its slot's; it lives on lane `lane` of the server's ServeThread.
    HttpSession(asio::ip::tcp::socket socket, HttpServer& server, std::size_t lane, ServeThread::SlotPtr slot);

    void start() { do_read(); }
    void close() override;

private:
    using Request = boost::beast::http::request<boost::beast::http::string_body>;

    void do_read();
    void on_read(const boost::beast::error_code& ec);
    void upgrade(Request request, std::string_view query);
    void respond(const Request& request, std::string_view path, std::string_view query);
    void control(const Request& request, std::string_view path, std::string_view query);
    void send_text(const Request& request, boost::beast::http::status status, std::string body,
                   const char* content_type = "text/plain; charset=utf-8");
    template <class Body>
    void send(boost::beast::http::response<Body>&& response);
    void on_write(const boost::beast::error_code& ec);
    void fail(const boost::beast::error_code& ec, const char* what);

    boost::beast::tcp_stream stream_;
    HttpServer& server_;
    std::size_t lane_;
    ServeThread::SlotPtr slot_;  // progress: every whole request read
    std::uint64_t id_;
    boost::beast::flat_buffer buffer_;
    std::optional<boost::beast::http::request_parser<boost::beast::http::string_body>> parser_;
    std::shared_ptr<void> response_;  // the response being written
    bool keep_alive_ = false;
    bool closed_ = false;
};

}  // namespace mocap::serve
