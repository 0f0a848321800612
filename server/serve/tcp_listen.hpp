// tcp_listen.hpp — open, bind and listen a TCP acceptor in one call, with the error
// message every mocapd service reports ("bind 0.0.0.0:8080: Address already in use").
// Any thread, before the io_context runs; SO_REUSEADDR so a restart rebinds at once.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/asio.hpp"

namespace mocap::serve {

/// Returns the listening acceptor on `io`, or nullptr with `error` set.
std::unique_ptr<asio::ip::tcp::acceptor> listen_tcp(asio::io_context& io, const std::string& bind_address,
                                                    std::uint16_t port, std::string& error);

}  // namespace mocap::serve
