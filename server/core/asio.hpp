// asio.hpp — the one way to include Boost.Asio in this project.
//
// Boost 1.74's asio/awaitable.hpp uses std::exchange without including <utility>; under
// -std=c++20 with g++ 12 that fails to compile. Including <utility> first fixes it for
// every translation unit, so nobody includes <boost/asio...> directly.
#pragma once

// clang-format off
#include <utility>
#include <boost/asio.hpp>
// clang-format on

namespace mocap {
namespace asio = boost::asio;
}  // namespace mocap
