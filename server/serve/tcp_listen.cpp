#include "serve/tcp_listen.hpp"

namespace mocap::serve {

std::unique_ptr<asio::ip::tcp::acceptor> listen_tcp(asio::io_context& io, const std::string& bind_address,
                                                    std::uint16_t port, std::string& error) {
    boost::system::error_code ec;
    const auto address = asio::ip::make_address(bind_address, ec);
    if (ec) {
        error = "bind address '" + bind_address + "': " + ec.message();
        return nullptr;
    }
    const asio::ip::tcp::endpoint endpoint(address, port);
    auto acceptor = std::make_unique<asio::ip::tcp::acceptor>(io);
    if (acceptor->open(endpoint.protocol(), ec) || acceptor->set_option(asio::socket_base::reuse_address(true), ec) ||
        acceptor->bind(endpoint, ec) || acceptor->listen(asio::socket_base::max_listen_connections, ec)) {
        error = "bind " + bind_address + ":" + std::to_string(port) + ": " + ec.message();
        return nullptr;
    }
    return acceptor;
}

}  // namespace mocap::serve
