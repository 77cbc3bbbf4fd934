// Boost.Asio include with the g++ 12 / Boost 1.74 pitfall handled (MACHINE.md: <utility>
// must come before <boost/asio.hpp>, else "'exchange' is not a member of 'std'").
#pragma once
#include <utility>
// (keep the blank line: include sorters must not move <utility> below Asio)

#include <boost/asio.hpp>
#include <boost/asio/redirect_error.hpp>

namespace st::server {
namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using boost::system::error_code;
}  // namespace st::server
