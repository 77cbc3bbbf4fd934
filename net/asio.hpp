// The one Boost.Asio include of the project (server and client both come through here).
// g++ 12 with Boost 1.74 needs <utility> before <boost/asio.hpp>, else "'exchange' is not
// a member of 'std'": keep the order and the blank line (include sorters must not move
// <utility> below Asio).
#pragma once
#include <utility>

#include <boost/asio.hpp>
#include <boost/asio/redirect_error.hpp>

namespace st::net {
namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using boost::system::error_code;
}  // namespace st::net
