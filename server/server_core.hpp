// State shared by the server and its connections (internal to server/).
#pragma once
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "net/asio.hpp"

#include <boost/asio/ssl.hpp>

#include "server/catalog.hpp"
#include "server/server.hpp"
#include "server/server_stats.hpp"

namespace st::server {

namespace asio = net::asio;  // net/asio.hpp
using net::error_code;
using net::tcp;

class Connection;

struct ServerCore {
  ServerOptions options;
  Catalog catalog;
  std::unique_ptr<asio::ssl::context> tls;  // null: plain TCP
  ServerStats stats;

  std::mutex mu;  // guards connections and stopping
  std::set<std::shared_ptr<Connection>> connections;
  std::map<asio::ip::address, size_t> per_address;  // open connections by client address
  bool stopping = false;

  void log(const std::string& line) const;
};

}  // namespace st::server
