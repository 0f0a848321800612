// http_takes.cpp — the web endpoint's /api/takes: list, show, download, start/stop, delete
// (http_server.hpp has the routes, docs/client-protocol.md "Takes" the replies).
//
// A name from the URL is checked by valid_take_name before anything touches the disk, so
// no request reaches outside the store's root. Reading needs no token (the pose stream
// needs none either); every change goes through the control rules. A raw download opens
// the file on the serve thread (one open(), refused unless a regular file) and streams it;
// BVH and CSV are charged to the export budget as they grow (take_export_budget.hpp), wait
// for the export queue, and the session reads no further request meanwhile but watches for
// its peer to leave, which cancels the export.
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "serve/http_connection.hpp"
#include "serve/http_query.hpp"
#include "serve/pose_json.hpp"
#include "serve/record_file.hpp"

namespace mocap::serve {

namespace beast = boost::beast;
namespace http = beast::http;

namespace {

constexpr std::string_view kPrefix = "/api/takes";
/// What a BVH/CSV export is charged when asked for, and the step its charge grows by as the
/// export is written (take_export_budget.hpp).
constexpr std::uint64_t kExportChunkBytes = std::uint64_t{256} << 10;
/// Most takes one GET /api/takes answers (and its default): ~1 KiB each.
constexpr std::uint32_t kMaxListLimit = 500;

nlohmann::ordered_json take_json(const TakeEntry& e) {
    auto j = nlohmann::ordered_json::parse(encode_take_json(e.meta));
    j["recording"] = e.recording;
    j["raw_bytes"] = e.raw_bytes;
    return j;
}

std::string dump(const nlohmann::ordered_json& j) {
    return j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

/// A filter name as the factory spells them: [a-z0-9_-]{1,32}.
bool valid_filter_name(std::string_view f) {
    if (f.empty() || f.size() > 32) return false;
    for (const char c : f) {
        if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-')) return false;
    }
    return true;
}

}  // namespace

void HttpServer::HttpSession::takes(const Request& request, std::string_view path, std::string_view query) {
    const TakeStore* store = server_.handlers_.takes.get();
    if (store == nullptr) return send_text(request, http::status::not_found, "takes are off\n");
    const http::verb method = request.method();
    std::string_view rest = path.substr(kPrefix.size());
    if (rest.empty() || rest == "/") {
        if (method != http::verb::get) return send_text(request, http::status::method_not_allowed, "GET only\n");
        const auto offset_text = query_value(query, "offset");
        const auto limit_text = query_value(query, "limit");
        const auto offset = offset_text ? parse_u32(*offset_text) : std::optional<std::uint32_t>(0);
        const auto limit = limit_text ? parse_u32(*limit_text) : std::optional<std::uint32_t>(kMaxListLimit);
        if (!offset || !limit || *limit == 0 || *limit > kMaxListLimit) {
            return send_text(request, http::status::bad_request,
                             "expected ?offset=N&limit=1.." + std::to_string(kMaxListLimit) + "\n");
        }
        const TakeStore::Page page = store->list_page(*offset, *limit);
        auto list = nlohmann::ordered_json::array();
        for (const TakeEntry& e : page.takes)
            list.push_back(take_json(e));
        server_.counters_.takes_listed.add();
        return send_text(request, http::status::ok,
                         dump({{"takes", std::move(list)}, {"total", page.total}, {"offset", *offset}}),
                         "application/json");
    }
    if (method == http::verb::post && (rest == "/start" || rest == "/stop")) {
        return start_or_stop_take(request, path, query);
    }
    rest.remove_prefix(1);
    const std::size_t slash = rest.find('/');
    const std::string name(rest.substr(0, slash));
    const std::string_view action = slash == std::string_view::npos ? "" : rest.substr(slash);
    if (!valid_take_name(name)) return send_text(request, http::status::bad_request, "invalid take name\n");
    if (action == "/download") {
        if (method != http::verb::get) return send_text(request, http::status::method_not_allowed, "GET only\n");
        return download(request, name, query);
    }
    if (!action.empty()) return send_text(request, http::status::not_found, "not found\n");
    if (method == http::verb::get) {
        const auto entry = store->find(name);
        if (!entry) return send_text(request, http::status::not_found, "no take '" + name + "'\n");
        server_.counters_.takes_listed.add();
        return send_text(request, http::status::ok, dump(take_json(*entry)), "application/json");
    }
    if (method != http::verb::delete_) return send_text(request, http::status::method_not_allowed, "GET or DELETE\n");
    if (!authorized(request, path)) return;
    std::string error;
    ControlResult result = ControlResult::success();
    result.take = name;
    http::status status = http::status::ok;
    switch (server_.handlers_.takes->remove(name, &error)) {
        case TakeStore::Removal::kRemoved:
            server_.counters_.takes_deleted.add();
            break;
        case TakeStore::Removal::kNotFound:
            status = http::status::not_found;
            result.ok = false;
            result.error = "no take '" + name + "'";
            break;
        case TakeStore::Removal::kRecording:
            status = http::status::conflict;
            result.ok = false;
            result.error = error;
            break;
        case TakeStore::Removal::kFailed:
            status = http::status::internal_server_error;
            result.ok = false;
            result.error = error;
            break;
    }
    server_.counters_.control.count_result(result);
    send_text(request, status, encode_control_reply_json(result), "application/json");
}

void HttpServer::HttpSession::start_or_stop_take(const Request& request, std::string_view path,
                                                 std::string_view query) {
    if (!authorized(request, path)) return;
    auto reply = [&](http::status status, const ControlResult& r) {
        send_text(request, status, encode_control_reply_json(r), "application/json");
    };
    const ControlHandlers& h = server_.handlers_.control;
    const bool start = path.ends_with("/start");
    if (!(start ? static_cast<bool>(h.start_take) : static_cast<bool>(h.stop_take))) {
        return reply(http::status::not_implemented, ControlResult::failure("not supported by this server"));
    }
    ControlResult result;
    if (start) {
        const auto name = percent_decode(query_value(query, "name").value_or(""));
        const auto notes = percent_decode(query_value(query, "notes").value_or(""));
        if (!name || !notes || (!name->empty() && !valid_take_name(*name))) {
            return reply(http::status::bad_request,
                         ControlResult::failure("expected ?name=[A-Za-z0-9][A-Za-z0-9._-]{0,63}&notes=TEXT"));
        }
        result = h.start_take(*name, *notes);
    } else {
        result = h.stop_take();
    }
    server_.counters_.control.count_result(result);
    // A stop that stopped a take answers 200 even when not ok: the take did stop, and the
    // reply says what it lost.
    const bool stopped = !start && !result.take.empty();
    reply(result.ok || stopped ? http::status::ok : http::status::conflict, result);
}

void HttpServer::HttpSession::download(const Request& request, const std::string& name, std::string_view query) {
    const std::string_view format = query_value(query, "format").value_or("raw");
    const auto filter = percent_decode(query_value(query, "filter").value_or(""));
    const auto subject_text = query_value(query, "subject");
    const auto subject = subject_text ? parse_u32(*subject_text) : std::optional<std::uint32_t>(0);
    const std::string_view offline = query_value(query, "offline").value_or("0");
    if ((format != "raw" && format != "bvh" && format != "csv") || !filter ||
        (!filter->empty() && !valid_filter_name(*filter)) || !subject || (offline != "0" && offline != "1") ||
        (format == "raw" && offline == "1")) {
        return send_text(request, http::status::bad_request,
                         "expected ?format=raw|bvh|csv[&filter=NAME][&subject=ID][&offline=1] (offline: bvh or csv)\n");
    }
    const ReplyTo to{request.version(), request.keep_alive(), false};
    if (format == "raw") {
        const auto entry = server_.handlers_.takes->find(name);
        if (!entry) return send_text(request, http::status::not_found, "no take '" + name + "'\n");
        if (entry->raw_files.size() != 1) {
            return send_text(request, http::status::conflict,
                             "take '" + name + "' holds " + std::to_string(entry->raw_files.size()) + " raw files\n");
        }
        // Opened now: a delete from here on unlinks a file this download keeps reading.
        const int fd = open_regular_file(entry->raw_files.front());
        if (fd < 0) return send_text(request, http::status::not_found, "no take '" + name + "'\n");
        return send_file(to, fd, "application/octet-stream", name + ".mocapraw");
    }
    const TakeExporter& exporter = server_.handlers_.export_take;
    if (!exporter) return send_text(request, http::status::not_implemented, "no exporter in this server\n");
    const auto entry = server_.handlers_.takes->find(name);
    if (!entry) return send_text(request, http::status::not_found, "no take '" + name + "'\n");
    // Charged one chunk before it is queued (an address whose exports hold its share is
    // refused before any work), then its memfd's growth as it is written, in chunks, and its
    // real size at the end: a take is refused for what its export really holds, never for its
    // raw file's size (docs/security.md "Takes and exports").
    beast::error_code peer_ec;
    const auto peer = stream_.socket().remote_endpoint(peer_ec);
    const std::string address = peer_ec ? std::string("?") : peer.address().to_string();
    std::string why;
    auto charge = server_.export_budget_.try_charge(address, kExportChunkBytes, &why);
    if (!charge) {
        server_.counters_.take_exports_over_budget.add();
        return send_text(request, http::status::insufficient_storage, why + "\n");
    }
    TakeExportRequest job{name,
                          format == "bvh" ? TakeFormat::kBvh : TakeFormat::kCsv,
                          *filter,
                          *subject,
                          offline == "1",
                          [&budget = server_.export_budget_, charge](std::uint64_t held, std::string* reason) {
                              return budget.grow(*charge, held, kExportChunkBytes, reason);
                          }};
    const std::string file_name = name + (format == "bvh" ? ".bvh" : ".csv");
    const auto executor = stream_.get_executor();
    auto cancel = std::make_shared<std::atomic<bool>>(false);
    TakeExportBudget& budget = server_.export_budget_;
    const bool queued = server_.exports_.submit(
        [self = shared_from_this(), job = std::move(job), to, file_name, executor, &exporter, &budget,
         charge](const std::atomic<bool>& cancelled) {
            // Abandoned while it waited, or the server stops: answer without running it.
            auto result = std::make_shared<TakeExportResult>(
                cancelled.load() ? TakeExportResult{TakeExportResult::kCancelled, "export cancelled", -1}
                                 : exporter(job, cancelled));
            struct stat st {};
            std::string over;
            if (result->status == TakeExportResult::kOk &&
                (::fstat(result->fd, &st) != 0 ||
                 !budget.grow(*charge, static_cast<std::uint64_t>(st.st_size), 0, &over) ||
                 !budget.resize(*charge, static_cast<std::uint64_t>(st.st_size), &over))) {
                ::close(result->fd);
                *result =
                    TakeExportResult{TakeExportResult::kTooLarge, over.empty() ? "cannot size the export" : over, -1};
            }
            asio::post(executor,
                       [self, to, file_name, result, charge] { self->on_export(to, file_name, *result, charge); });
        },
        cancel);
    if (!queued) {
        server_.counters_.take_exports_busy.add();
        return send_text(request, http::status::service_unavailable, "busy: other exports are waiting, retry later\n");
    }
    export_cancel_ = std::move(cancel);
    watch_for_close();
}

void HttpServer::HttpSession::watch_for_close() {
    // The session reads no request while its export is pending, so nothing else would notice
    // the peer leave: wait for the socket to become readable and look without consuming.
    stream_.socket().async_wait(
        asio::ip::tcp::socket::wait_read, [self = shared_from_this()](const beast::error_code& ec) {
            if (ec || self->closed_ || !self->export_cancel_) return;  // closed, or the export answered
            char byte = 0;
            const ssize_t n = ::recv(self->stream_.socket().native_handle(), &byte, 1, MSG_PEEK | MSG_DONTWAIT);
            if (n > 0) return;  // a pipelined request: read after the reply
            if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return self->watch_for_close();
            self->server_.counters_.take_exports_abandoned.add();
            self->close();  // sets the export's cancel flag
        });
}

void HttpServer::HttpSession::on_export(const ReplyTo& to, const std::string& file_name, const TakeExportResult& result,
                                        std::shared_ptr<TakeExportBudget::Charge> charge) {
    export_cancel_.reset();
    if (closed_) {
        if (result.fd >= 0) ::close(result.fd);
        return;
    }
    // The read's deadline ran on while the export did: the reply gets a fresh one.
    stream_.expires_after(std::chrono::seconds(server_.config_.idle_timeout_s));
    if (result.status == TakeExportResult::kOk) {
        const bool csv = file_name.ends_with(".csv");
        export_charge_ = std::move(charge);  // held until the file is sent or the session ends
        return send_file(to, result.fd, csv ? "text/csv; charset=utf-8" : "text/plain; charset=utf-8", file_name);
    }
    server_.counters_.take_exports_failed.add();
    http::status status = http::status::internal_server_error;
    if (result.status == TakeExportResult::kNotFound) status = http::status::not_found;
    if (result.status == TakeExportResult::kBadRequest) status = http::status::bad_request;
    if (result.status == TakeExportResult::kCancelled) status = http::status::service_unavailable;
    if (result.status == TakeExportResult::kTooLarge) {
        server_.counters_.take_exports_over_budget.add();
        status = http::status::insufficient_storage;
    }
    send_text(to, status, result.error + "\n");
}

void HttpServer::HttpSession::send_file(const ReplyTo& to, int fd, const char* content_type,
                                        const std::string& file_name) {
    beast::file body_file;
    body_file.native_handle(fd);
    auto res = std::make_shared<FileResponse>(http::status::ok, to.version);
    beast::error_code ec;
    res->body().reset(std::move(body_file), ec);
    if (ec) return send_text(to, http::status::internal_server_error, "cannot read the file\n");
    res->set(http::field::server, "mocapd");
    res->set(http::field::content_type, content_type);
    res->set(http::field::cache_control, "no-store");
    res->set(http::field::content_disposition, "attachment; filename=\"" + file_name + "\"");
    res->keep_alive(to.keep_alive);
    res->prepare_payload();
    server_.counters_.take_downloads.add();
    keep_alive_ = res->keep_alive();
    response_ = res;
    write_file_some(res, std::make_shared<http::response_serializer<http::file_body>>(*res));
}

void HttpServer::HttpSession::write_file_some(const std::shared_ptr<FileResponse>& res,
                                              const std::shared_ptr<http::response_serializer<http::file_body>>& sr) {
    stream_.expires_after(std::chrono::seconds(server_.config_.idle_timeout_s));
    http::async_write_some(stream_, *sr,
                           [self = shared_from_this(), res, sr](const beast::error_code& ec, std::size_t) {
                               if (ec || sr->is_done()) {
                                   self->export_charge_.reset();  // sent: its memory is given back
                                   return self->on_write(ec);
                               }
                               self->slot_->progress(ServeThread::now_us());
                               self->write_file_some(res, sr);
                           });
}

}  // namespace mocap::serve
