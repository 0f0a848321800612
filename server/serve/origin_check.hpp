// origin_check.hpp — may a WebSocket upgrade on /ws be answered, given its Origin and Host
// headers (docs/security.md, "Origin of WebSocket requests")?
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

/// True when a WebSocket request with these headers may be upgraded; `origin` and `host`
/// are the header values ("" when absent).
[[nodiscard]] bool websocket_origin_allowed(std::string_view origin, std::string_view host,
                                            const std::vector<std::string>& allowed);

}  // namespace mocap::serve
