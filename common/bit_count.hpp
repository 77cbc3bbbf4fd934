// Population count for the lookup and build paths.
#pragma once
#include <bit>
#include <cstdint>

namespace st {

// Without a POPCNT target (the baseline x86-64 this project builds for) std::popcount
// becomes a libgcc call; this inline SWAR form is several times cheaper.
inline uint32_t bit_count(uint64_t x) {
#if defined(__POPCNT__) || !(defined(__x86_64__) || defined(__i386__))
  return uint32_t(std::popcount(x));
#else
  x = x - ((x >> 1) & 0x5555555555555555ull);
  x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
  x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0Full;
  return uint32_t((x * 0x0101010101010101ull) >> 56);
#endif
}

}  // namespace st
