// A game-like consumer of the installed client: connects, lists and opens a map, asks
// for every tile of one level, waits until they are resident, then prints every texel's
// answer of that level ("x y bits", bits in hex) for the driver to compare with the pack.
// Only <shadowtile/client.hpp> and the standard library.
//   consumer HOST PORT MAP LEVEL
#include <shadowtile/client.hpp>

#include <bit>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: consumer HOST PORT MAP LEVEL\n");
    return 2;
  }
  try {
    st::client::ClientOptions options;
    options.cache_slots = 4096;
    options.request_timeout = std::chrono::milliseconds(20000);
    st::client::Client client({argv[1], uint16_t(std::stoul(argv[2]))}, options);
    bool listed = false;
    for (const st::client::MapListing& m : client.list_maps()) listed |= m.name == argv[3];
    if (!listed) throw std::runtime_error(std::string("map ") + argv[3] + " not in list_maps()");
    st::client::Map map = client.open(argv[3]);
    const st::client::MapInfo info = map.info();
    const uint32_t level = uint32_t(std::stoul(argv[4]));
    if (!map.valid() || info.name != argv[3] || level > info.finest_level)
      throw std::runtime_error("map info: name " + info.name + ", finest level " + std::to_string(info.finest_level));
    const uint64_t side = uint64_t(1) << level;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!map.region_resident(level, 0, 0, side, side)) {
      map.request_region(level, 0, 0, side, side, 1);
      if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error("tiles not resident within 60 s");
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    // An unknown map throws std::runtime_error (client.hpp), also across libshadowtile.so.
    try {
      client.open("no_such_map");
      throw std::logic_error("open('no_such_map') returned a map");
    } catch (const std::runtime_error&) {
    }
    // A default Map answers like an empty map (lit) instead of crashing.
    const st::client::Map none;
    if (none.valid() || none.depth(0, 0, 0) != 1.0f || none.visibility({0, 0, 0}) != 1.0f)
      throw std::runtime_error("a default Map does not answer lit");
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x)
        std::printf("%llu %llu %08x\n", (unsigned long long)x, (unsigned long long)y,
                    std::bit_cast<uint32_t>(map.depth(level, x, y)));
    const st::client::MapStats s = map.stats();
    std::fprintf(stderr, "consumer: %s, %llu tiles received, %llu failed\n", info.encoding.c_str(),
                 (unsigned long long)s.tiles_received, (unsigned long long)s.tiles_failed);
    return s.tiles_failed == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer: error: %s\n", e.what());
    return 1;
  }
}
