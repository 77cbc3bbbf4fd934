// A game-like consumer of the installed GPU component (find_package(shadowtile COMPONENTS
// gpu)): opens a map, fetches one level, mirrors the cache on the Vulkan device named by
// SHADOWTILE_VK_DEVICE and prints every texel's GPU answer of that level ("x y bits") for
// the driver to compare with the pack. Only <shadowtile/gpu.hpp> and the standard library.
//   consumer_gpu HOST PORT MAP LEVEL
#include <shadowtile/gpu.hpp>

#include <bit>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: consumer_gpu HOST PORT MAP LEVEL\n");
    return 2;
  }
  try {
    st::client::ClientOptions options;
    options.cache_slots = 4096;
    options.request_timeout = std::chrono::milliseconds(20000);
    st::client::Client client({argv[1], uint16_t(std::stoul(argv[2]))}, options);
    st::client::Map map = client.open(argv[3]);
    const uint32_t level = uint32_t(std::stoul(argv[4]));
    const uint64_t side = uint64_t(1) << level;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!map.region_resident(level, 0, 0, side, side)) {
      map.request_region(level, 0, 0, side, side, 1);
      if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error("tiles not resident within 60 s");
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    st::gpu::GpuOptions o;
    o.max_queries = uint32_t(side * side);
    st::gpu::GpuMap gpu(map, o);
    std::vector<st::gpu::GpuQuery> q;
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) q.push_back({x, y, 0, 1, 0, level});
    std::vector<float> out(q.size());
    gpu.sync();
    gpu.evaluate(q, out);
    for (size_t i = 0; i < q.size(); ++i)
      std::printf("%u %u %08x\n", q[i].x, q[i].y, std::bit_cast<uint32_t>(out[i]));
    std::fprintf(stderr, "consumer_gpu: %s, %u slots on the device\n", gpu.device_name().c_str(),
                 gpu.stats().resident_slots);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer_gpu: %s\n", e.what());
    return 1;
  }
}
