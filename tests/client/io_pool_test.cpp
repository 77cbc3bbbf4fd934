// Many Clients on a shared client::IoPool (the load tester's 1,000 connections on a
// few threads): every client fetches the whole map with exact answers, the process
// holds the pool's threads and not one per client, clients come and go while others
// keep fetching, and a pooled client survives a server restart like a threaded one.
#include <gtest/gtest.h>

#include <dirent.h>

#include <thread>

#include "client/map_access.hpp"
#include "client/io_pool.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::start_server;
using looptest::wait_until;

size_t thread_count() {
  size_t n = 0;
  if (DIR* d = ::opendir("/proc/self/task")) {
    while (dirent* e = ::readdir(d))
      if (e->d_name[0] != '.') ++n;
    ::closedir(d);
  }
  return n;
}

ClientOptions pooled(std::shared_ptr<IoPool> pool) {
  ClientOptions o = looptest::quick_options();
  o.io_pool = std::move(pool);
  return o;
}

uint64_t connections_open(Client& c) {
  for (const auto& x : c.server_stats().counters)
    if (x.name == "connections_open") return x.value;
  return ~uint64_t(0);
}

using looptest::first_encoding;

TEST(IoPool, RejectsBadThreadCounts) {
  EXPECT_THROW(IoPool(0), Error);
  EXPECT_THROW(IoPool(65), Error);
  IoPool p(3);
  EXPECT_EQ(p.threads(), 3u);
}

TEST(IoPool, ManyClientsShareTwoThreadsAndGetExactTiles) {
  auto p = build_pack("iopool", 6, 11, first_encoding(), 3, 1024);
  server::ServerOptions so;
  so.max_connections_per_address = 0;
  auto srv = start_server({p.path}, so);
  const size_t before = thread_count();
  auto pool = std::make_shared<IoPool>(2);
  const uint32_t n = looptest::small_scale() ? 24 : 64;
  std::vector<std::unique_ptr<Client>> clients;
  std::vector<Map> maps;
  for (uint32_t i = 0; i < n; ++i) {
    clients.push_back(std::make_unique<Client>(Endpoint{"127.0.0.1", srv.port}, pooled(pool)));
    maps.push_back(clients.back()->open("iopool"));
  }
  // The pool's two threads and Asio's resolver helper thread of each of its two
  // io_contexts: 4, where one thread per client would be 2 * n.
  EXPECT_LE(thread_count(), before + 2 * pool->threads());
  for (Map& m : maps) m.request_region(6, 0, 0, 64, 64, 1);
  ASSERT_TRUE(wait_until([&] {
    for (const Map& m : maps)
      if (!m.region_resident(6, 0, 0, 64, 64)) return false;
    return true;
  }));
  PackEvaluator local(p.reader);
  for (uint32_t i = 0; i < n; ++i) {
    EXPECT_EQ(maps[i].stats().tiles_received, p.reader->tiles().size());
    for (uint64_t y = 0; y < 64; y += 3)
      for (uint64_t x = 0; x < 64; x += 5) ASSERT_EQ(maps[i].depth(6, x, y), local.depth(6, x, y)) << i;
  }
  EXPECT_EQ(connections_open(*clients[0]), uint64_t(n));
  // Half the clients leave (each destructor waits for its own fetcher only); the rest
  // stay connected and answer control calls.
  const auto t0 = std::chrono::steady_clock::now();
  clients.resize(n / 2);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 5s);  // no per-client tick wait
  for (auto& c : clients) EXPECT_TRUE(c->connected());
  EXPECT_FALSE(clients.back()->list_maps().empty());
  ASSERT_TRUE(wait_until([&] { return connections_open(*clients[0]) == n / 2; }, 5s));
  clients.clear();
  // Maps outlive their clients and keep answering from the cache.
  EXPECT_EQ(maps[n - 1].depth(6, 7, 9), local.depth(6, 7, 9));
}

TEST(IoPool, PooledClientReconnectsAfterServerRestart) {
  auto p = build_pack("iopool_restart", 6, 12, first_encoding(), 3, 1024);
  server::ServerOptions so;
  so.log = [](const std::string&) {};
  uint16_t port;
  {
    auto probe = start_server({p.path});
    port = probe.port;
    probe.stop();
  }
  so.port = port;
  auto srv = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{p.path}), so);
  srv->start();
  auto pool = std::make_shared<IoPool>(1);
  Client c({"127.0.0.1", port}, pooled(pool));
  Map m = c.open("iopool_restart");
  m.request_region(6, 0, 0, 32, 64, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 32, 64); }));
  srv->stop();
  srv.reset();
  ASSERT_TRUE(wait_until([&] { return !c.connected(); }, 5s));
  srv = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{p.path}), so);
  srv->start();
  m.request_region(6, 0, 0, 64, 64, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 64, 64); }));
  EXPECT_GE(c.stats().connects, 2u);
  PackEvaluator local(p.reader);
  for (uint64_t y = 0; y < 64; ++y)
    for (uint64_t x = 0; x < 64; ++x) ASSERT_EQ(m.depth(6, x, y), local.depth(6, x, y));
}

}  // namespace
}  // namespace st::client
