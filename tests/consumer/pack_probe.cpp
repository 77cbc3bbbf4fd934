// The consumer test's reference: every texel of one level of a pack, read locally with
// the pack evaluator, in the consumer's output format ("x y bits").
//   pack_probe PACK LEVEL
#include <bit>
#include <cstdio>
#include <exception>
#include <memory>
#include <string>

#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: pack_probe PACK LEVEL\n");
    return 2;
  }
  try {
    std::shared_ptr<const st::PackReader> reader(st::PackReader::open(argv[1]));
    st::PackEvaluator ev(reader);
    const uint32_t level = uint32_t(std::stoul(argv[2]));
    const uint64_t side = uint64_t(1) << level;
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x)
        std::printf("%llu %llu %08x\n", (unsigned long long)x, (unsigned long long)y,
                    std::bit_cast<uint32_t>(ev.depth(level, x, y)));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pack_probe: error: %s\n", e.what());
    return 1;
  }
}
