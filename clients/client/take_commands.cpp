// take_commands.cpp — mocap-client's HTTP client for /api/takes.
#include "take_commands.hpp"

#include <sys/socket.h>
#include <sys/time.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>

namespace mocap::client {

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;

constexpr int kExitFailed = 1;
constexpr int kExitConnection = 2;

class Connection {
public:
    bool open(const TakeCommand& c, std::string& error) {
        try {
            asio::ip::tcp::resolver resolver(io_);
            asio::connect(socket_, resolver.resolve(c.host, std::to_string(c.port)));
        } catch (const std::exception& e) {
            error = "cannot connect to " + c.host + ":" + std::to_string(c.port) + ": " + e.what();
            return false;
        }
        // Blocking Beast calls ignore deadlines of their own: bound every socket call.
        timeval tv{};
        tv.tv_sec = static_cast<time_t>(c.timeout.count() / 1000);
        tv.tv_usec = static_cast<suseconds_t>((c.timeout.count() % 1000) * 1000);
        ::setsockopt(socket_.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        ::setsockopt(socket_.native_handle(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
        return true;
    }
    void send(http::verb method, const std::string& target, const TakeCommand& c) {
        http::request<http::empty_body> req{method, target, 11};
        req.set(http::field::host, c.host);
        req.set(http::field::user_agent, "mocap-client");
        if (!c.token.empty()) req.set("X-Mocap-Token", c.token);
        req.prepare_payload();
        http::write(socket_, req);
    }
    asio::ip::tcp::socket& socket() { return socket_; }
    beast::flat_buffer& buffer() { return buffer_; }

private:
    asio::io_context io_;
    asio::ip::tcp::socket socket_{io_};
    beast::flat_buffer buffer_;
};

std::string start_text(const nlohmann::json& t) {
    std::string s = t.value("start", std::string{});
    return s.size() >= 19 ? s.substr(0, 10) + " " + s.substr(11, 8) : s;
}

int print_list(const std::string& body, bool json) {
    if (json) {
        std::cout << body;
        return 0;
    }
    const auto j = nlohmann::json::parse(body, nullptr, false);
    if (!j.is_object() || !j.contains("takes") || !j["takes"].is_array()) {
        std::cerr << "mocap-client: not a take list\n";
        return kExitFailed;
    }
    std::printf("%-32s %-19s %9s %-10s %10s %12s  %s\n", "NAME", "START (UTC)", "LENGTH_S", "SUBJECTS", "SAMPLES",
                "BYTES", "NOTES");
    for (const auto& t : j["takes"]) {
        const auto start = t.value("start_us", std::int64_t{0});
        const auto stop = t.value("stop_us", std::int64_t{0});
        std::string subjects;
        for (const auto& s : t.value("subjects", nlohmann::json::array()))
            subjects += (subjects.empty() ? "" : ",") + std::to_string(s.get<std::uint32_t>());
        char seconds[32];
        std::snprintf(seconds, sizeof seconds, "%.3f", static_cast<double>(stop - start) * 1e-6);
        const std::string length = t.value("recording", false) ? "recording" : stop == 0 ? "cut" : seconds;
        std::printf("%-32s %-19s %9.9s %-10s %10llu %12llu  %s\n", t.value("name", std::string{}).c_str(),
                    start_text(t).c_str(), length.c_str(), subjects.c_str(),
                    static_cast<unsigned long long>(t.value("samples", std::uint64_t{0})),
                    static_cast<unsigned long long>(t.value("raw_bytes", std::uint64_t{0})),
                    t.value("notes", std::string{}).c_str());
    }
    return 0;
}

int download(Connection& conn, const TakeCommand& c, const std::string& target) {
    const char* ext = c.format == "bvh" ? ".bvh" : c.format == "csv" ? ".csv" : ".mocapraw";
    const std::string out = c.out.empty() ? c.name + ext : c.out;
    std::error_code ec;
    if (std::filesystem::exists(out, ec)) {
        std::cerr << "mocap-client: " << out << " exists\n";
        return kExitFailed;
    }
    const std::string part = out + ".part";
    http::response_parser<http::file_body> parser;
    parser.body_limit(std::numeric_limits<std::uint64_t>::max());
    beast::error_code bec;
    conn.send(http::verb::get, target, c);
    http::read_header(conn.socket(), conn.buffer(), parser, bec);
    if (bec) {
        std::cerr << "mocap-client: " << bec.message() << "\n";
        return kExitConnection;
    }
    if (parser.get().result() != http::status::ok) {
        http::response_parser<http::string_body> error_parser(std::move(parser));
        http::read(conn.socket(), conn.buffer(), error_parser, bec);
        std::cerr << "mocap-client: " << error_parser.get().result_int() << " " << error_parser.get().body();
        return kExitFailed;
    }
    parser.get().body().open(part.c_str(), beast::file_mode::write_new, bec);
    if (bec) {
        std::cerr << "mocap-client: cannot create " << part << ": " << bec.message() << "\n";
        return kExitFailed;
    }
    http::read(conn.socket(), conn.buffer(), parser, bec);
    parser.get().body().close();
    if (bec) {
        std::filesystem::remove(part, ec);
        std::cerr << "mocap-client: download cut: " << bec.message() << "\n";
        return kExitConnection;
    }
    std::filesystem::rename(part, out, ec);
    if (ec) {
        std::cerr << "mocap-client: cannot rename " << part << ": " << ec.message() << "\n";
        return kExitFailed;
    }
    std::cout << out << "\n";
    return 0;
}

}  // namespace

std::string url_encode(const std::string& text) {
    static const char* hex = "0123456789ABCDEF";
    std::string out;
    for (const char ch : text) {
        const auto c = static_cast<unsigned char>(ch);
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '.' ||
            c == '_' || c == '~') {
            out += ch;
        } else {
            out += '%';
            out += hex[c >> 4];
            out += hex[c & 15];
        }
    }
    return out;
}

int run_takes(const TakeCommand& c) {
    Connection conn;
    std::string error;
    if (!conn.open(c, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    const std::string base = "/api/takes";
    http::verb method = http::verb::get;
    std::string target = base;
    if (c.action == "download") {
        target = base + "/" + url_encode(c.name) + "/download?format=" + url_encode(c.format);
        if (!c.filter.empty()) target += "&filter=" + url_encode(c.filter);
        if (c.offline) target += "&offline=1";
        if (c.subject != 0) target += "&subject=" + std::to_string(c.subject);
        return download(conn, c, target);
    }
    if (c.action == "delete") {
        method = http::verb::delete_;
        target = base + "/" + url_encode(c.name);
    } else if (c.action == "start") {
        method = http::verb::post;
        target = base + "/start?name=" + url_encode(c.name) + "&notes=" + url_encode(c.notes);
    } else if (c.action == "stop") {
        method = http::verb::post;
        target = base + "/stop";
    }
    http::response<http::string_body> res;
    const auto exchange = [&](const std::string& t) {
        try {
            conn.send(method, t, c);
            http::response_parser<http::string_body> parser;
            parser.body_limit(std::uint64_t{64} << 20);
            http::read(conn.socket(), conn.buffer(), parser);
            res = parser.release();
        } catch (const std::exception& e) {
            std::cerr << "mocap-client: " << e.what() << "\n";
            return kExitConnection;
        }
        if (res.result() != http::status::ok) {
            std::cerr << "mocap-client: " << res.result_int() << " " << res.body();
            return kExitFailed;
        }
        return 0;
    };
    if (c.action == "list") {
        // The list comes in pages; `total` says how many takes there are in all.
        auto all = nlohmann::json::array();
        for (;;) {
            if (const int status = exchange(base + "?offset=" + std::to_string(all.size())); status != 0) return status;
            const auto page = nlohmann::json::parse(res.body(), nullptr, false);
            if (!page.is_object() || !page.contains("takes") || !page["takes"].is_array()) break;
            for (const auto& t : page["takes"])
                all.push_back(t);
            if (page["takes"].empty() || all.size() >= page.value("total", std::size_t{0})) break;
        }
        const std::size_t total = all.size();
        return print_list(nlohmann::json{{"takes", std::move(all)}, {"total", total}}.dump() + "\n", c.json);
    }
    if (const int status = exchange(target); status != 0) return status;
    const auto j = nlohmann::json::parse(res.body(), nullptr, false);
    std::cout << "ok" << (j.is_object() && j.contains("take") ? " " + j["take"].get<std::string>() : "") << "\n";
    return 0;
}

}  // namespace mocap::client
