// http_test_client.hpp — a blocking HTTP/WebSocket client for tests of the web endpoint
// (Boost.Beast, one connection per call). Not for production use: no timeouts beyond
// the socket's, errors become an empty response with status 0.
#pragma once

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include <sys/socket.h>
#include <sys/time.h>

#include "core/asio.hpp"

namespace mocap::testing {

// Blocking Beast calls ignore tcp_stream deadlines: bound them with SO_RCVTIMEO/SO_SNDTIMEO.
inline void socket_deadline(asio::ip::tcp::socket& socket, std::chrono::milliseconds limit) {
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(limit.count() / 1000);
    tv.tv_usec = static_cast<suseconds_t>((limit.count() % 1000) * 1000);
    ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
}

struct HttpReply {
    unsigned status = 0;
    std::string body;
    std::string content_type;
};

inline HttpReply http_request(std::uint16_t port, const std::string& target,
                              boost::beast::http::verb method = boost::beast::http::verb::get,
                              const std::map<std::string, std::string>& headers = {},
                              std::chrono::milliseconds limit = std::chrono::seconds(10)) {
    namespace http = boost::beast::http;
    HttpReply out;
    try {
        asio::io_context io;
        boost::beast::tcp_stream stream(io);
        stream.connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
        socket_deadline(stream.socket(), limit);
        http::request<http::string_body> req{method, target, 11};
        req.set(http::field::host, "127.0.0.1");
        for (const auto& [k, v] : headers)
            req.set(k, v);
        req.prepare_payload();
        http::write(stream, req);
        boost::beast::flat_buffer buffer;
        http::response_parser<http::string_body> parser;
        parser.body_limit(64 * 1024 * 1024);
        http::read(stream, buffer, parser);
        const auto& res = parser.get();
        out.status = res.result_int();
        out.body = res.body();
        out.content_type = std::string(res[http::field::content_type]);
        boost::system::error_code ignored;
        stream.socket().shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
    } catch (const std::exception&) {
        out.status = 0;
    }
    return out;
}

/// A WebSocket client on /ws (blocking reads with a deadline).
class WsTestClient {
public:
    /// A fresh connection each call, so a refused attempt can be retried (a stream that
    /// failed its handshake stays failed).
    bool connect(std::uint16_t port, const std::string& target) {
        ws_.emplace(io_);
        try {
            ws_->next_layer().connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
            socket_deadline(ws_->next_layer().socket(), std::chrono::seconds(10));
            ws_->handshake("127.0.0.1", target);
            return true;
        } catch (const std::exception&) {
            return false;
        }
    }
    /// The next text message, or nullopt on error/close/deadline.
    std::optional<std::string> read(std::chrono::milliseconds limit = std::chrono::seconds(5)) {
        if (!ws_) return std::nullopt;
        try {
            socket_deadline(ws_->next_layer().socket(), limit);
            boost::beast::flat_buffer buffer;
            ws_->read(buffer);
            return boost::beast::buffers_to_string(buffer.data());
        } catch (const std::exception&) {
            return std::nullopt;
        }
    }

private:
    asio::io_context io_;
    std::optional<boost::beast::websocket::stream<boost::beast::tcp_stream>> ws_;
};

}  // namespace mocap::testing
