// origin_check.hpp — may a request of the web endpoint be answered, given the names it
// carries: its Host header (every path) and, for a WebSocket upgrade on /ws, its Origin
// (docs/security.md, "Origin of WebSocket requests" and "DNS rebinding").
//
// Host (DNS rebinding): a page on evil.example whose name the attacker's DNS later points
// at 127.0.0.1 talks to this server as "same origin"; the browser still sends
// `Host: evil.example[:port]`. So a Host that names a host must be one of `names` (the
// daemon passes localhost, this machine's names and `[http] allowed_hosts`), compared
// case-insensitively without the port and a trailing dot. An IP literal (127.0.0.1,
// 10.1.2.3, [::1]) is allowed: a rebinding page always has a name. No Host header (HTTP/1.0
// scripts; a browser always sends one) is allowed.
//
// Why: a browser lets any page open a WebSocket to any address and sends its own origin in
// the Origin header; it is the server's job to refuse foreign ones. Without the check, a
// page open in the operator's browser could read every pose from a loopback-only port.
//
// Rules: no Origin header (curl, scripts, the Python client: no browser involved) is
// allowed. Otherwise the Origin must be `http://H[:P]` or `https://H[:P]` with the same
// host and port as the Host header (default ports filled in: 80 for http, 443 for https
// and for a Host without a port), or be listed verbatim (case-insensitively, without a
// trailing '/') in `allowed` (`[http] allowed_origins`). "null" (sandboxed frames, file:
// pages) is allowed only when listed.
// Pure function, any thread.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace mocap::serve {

/// True when a request whose Host header is `host` ("" when absent) may be answered.
[[nodiscard]] bool http_host_allowed(std::string_view host, const std::vector<std::string>& names);

/// True when a WebSocket request with these headers may be upgraded; `origin` and `host`
/// are the header values ("" when absent).
[[nodiscard]] bool websocket_origin_allowed(std::string_view origin, std::string_view host,
                                            const std::vector<std::string>& allowed);

}  // namespace mocap::serve
