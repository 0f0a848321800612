// viewer_assets.hpp — the live viewer's static files, embedded in the binary at build time
// (server/serve/CMakeLists.txt: clients/viewer/*.html|*.js and three.js from
// clients/viewer/node_modules), so an installed daemon needs no web directory.
#pragma once

#include <span>
#include <string_view>

namespace mocap::serve {

struct StaticAsset {
    std::string_view path;          ///< URL path, e.g. "/viewer.js"
    std::string_view content_type;  ///< e.g. "text/javascript; charset=utf-8"
    std::string_view body;          ///< file contents (static storage)
};

/// Every embedded file; "/" is served as "/index.html". Static storage, any thread.
std::span<const StaticAsset> viewer_assets();

}  // namespace mocap::serve
