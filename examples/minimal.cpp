// The C++ client in a few lines: connect, open a map, prefetch, answer a batch of world
// points, print the map's stats. Only <shadowtile/client.hpp> and the standard library.
//
//   minimal HOST PORT MAP [RADIUS] < points
//
// points: "x y z" lines. Prints per point the visibility's float bits in hex, then the
// value (as examples/c_client.c). The prefetch is the finest-level texels within RADIUS
// (default 256) of the map's centre; a game asks each frame for what its camera sees.
#include <shadowtile/client.hpp>

#include <bit>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

int main(int argc, char** argv) try {
  if (argc != 4 && argc != 5) {
    std::cerr << "usage: minimal HOST PORT MAP [RADIUS] < points\n";
    return 2;
  }
  st::client::ClientOptions options;
  options.cache_slots = 1024;
  st::client::Client client({argv[1], uint16_t(std::stoul(argv[2]))}, options);
  st::client::Map map = client.open(argv[3]);  // throws: unknown map, no answer in time
  const st::client::MapInfo info = map.info();

  // Prefetch a square of the finest level around the map's centre, then wait for it
  // (lookups never block: until then they answer from coarser levels).
  const uint32_t level = info.finest_level;
  const uint64_t side = uint64_t(1) << level, radius = argc == 5 ? std::stoull(argv[4]) : 256;
  const uint64_t x0 = side / 2 > radius ? side / 2 - radius : 0, w = 2 * radius;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!map.region_resident(level, x0, x0, w, w)) {
    map.request_region(level, x0, x0, w, w, /*priority=*/1);
    if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error("not resident after 60 s");
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }

  // One batched call for all points: one lock, tile walks shared by neighbours.
  std::vector<st::client::WorldPoint> points;
  for (st::client::WorldPoint p; std::cin >> p.x >> p.y >> p.z;) points.push_back(p);
  std::vector<float> lit(points.size());
  map.visibility(points, lit, /*pcf_side=*/1);
  for (float v : lit) std::printf("%08x %g\n", std::bit_cast<uint32_t>(v), v);

  const st::client::MapStats s = map.stats();
  std::fprintf(stderr, "minimal: %s (%s, 2^%u): %zu points, %llu tiles received, %llu failed, %llu hits\n",
               info.name.c_str(), info.encoding.c_str(), level, points.size(),
               (unsigned long long)s.tiles_received, (unsigned long long)s.tiles_failed,
               (unsigned long long)s.cache.hits);
  return s.tiles_failed == 0 ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "minimal: error: %s\n", e.what());
  return 1;
}
