// http_connection.hpp — one HTTP/1.1 connection of the web endpoint (keep-alive): reads
// requests and answers them (viewer files, /metrics, /healthz, POST /api/... control, the
// takes under /api/takes: http_takes.cpp), or
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
#include "serve/take_export_queue.hpp"
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
    using FileResponse = boost::beast::http::response<boost::beast::http::file_body>;
    /// What a reply needs of its request, kept while the request waits for a take export.
    struct ReplyTo {
        unsigned version = 11;
        bool keep_alive = false;
        bool head = false;
    };

    void do_read();
    void on_read(const boost::beast::error_code& ec);
    /// The Host header against the allowed names (origin_check.hpp); false = refused, and
    /// the refusal was sent.
    bool host_allowed(const Request& request);
    void upgrade(Request request, std::string_view query);
    void respond(const Request& request, std::string_view path, std::string_view query);
    void control(const Request& request, std::string_view path, std::string_view query);
    /// The control rules (control_access.hpp); false = refused, and the refusal was sent.
    bool authorized(const Request& request, std::string_view path);
    void send_text(const Request& request, boost::beast::http::status status, std::string body,
                   const char* content_type = "text/plain; charset=utf-8");
    void send_text(const ReplyTo& to, boost::beast::http::status status, std::string body,
                   const char* content_type = "text/plain; charset=utf-8");
    // /api/takes... (http_takes.cpp)
    void takes(const Request& request, std::string_view path, std::string_view query);
    void start_or_stop_take(const Request& request, std::string_view path, std::string_view query);
    void download(const Request& request, const std::string& name, std::string_view query);
    void on_export(const ReplyTo& to, const std::string& file_name, const TakeExportResult& result,
                   std::shared_ptr<TakeExportBudget::Charge> charge);
    /// While an export is pending: a peer that closes its side cancels it (http_takes.cpp).
    void watch_for_close();
    /// Streams an open file (taken over: closed when sent), one chunk per write, each with
    /// the idle timeout, so a stalled client is dropped and a slow one is not.
    void send_file(const ReplyTo& to, int fd, const char* content_type, const std::string& file_name);
    void write_file_some(
        const std::shared_ptr<FileResponse>& res,
        const std::shared_ptr<boost::beast::http::response_serializer<boost::beast::http::file_body>>& sr);
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
    std::shared_ptr<std::atomic<bool>> export_cancel_;         // the pending export's; set by close()
    std::shared_ptr<TakeExportBudget::Charge> export_charge_;  // the export being sent
};

}  // namespace mocap::serve
