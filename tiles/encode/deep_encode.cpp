// Deep shadow tile encoder: see deep_encode.hpp and tiles/core/DEEP.md.
#include "tiles/encode/deep_encode.hpp"

#include <algorithm>
#include <cmath>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/deep_format.hpp"

namespace st {
namespace {

using namespace deep;

uint16_t unorm(float t) {
  return uint16_t(std::lround(std::clamp(double(t), 0.0, 1.0) * kUnormScale));
}

}  // namespace

std::vector<uint8_t> encode_deep_tile(std::span<const VisibilityFunction> finest,
                                      uint32_t side_bits, double epsilon,
                                      DeepEncodeStats* stats, uint64_t max_bytes) {
  if (side_bits > kMaxSideBits)
    throw Error("deep tile: side_bits " + std::to_string(side_bits) + " above 8");
  const uint32_t side = 1u << side_bits;
  if (finest.size() != size_t(side) * side)
    throw Error("deep tile: " + std::to_string(finest.size()) + " functions for a " +
                std::to_string(side) + " x " + std::to_string(side) + " tile");
  if (!(epsilon >= 0) || !std::isfinite(epsilon) || !std::isfinite(float(epsilon)))
    throw Error("deep tile: epsilon must be finite and >= 0");
  max_bytes = std::min<uint64_t>(max_bytes, 0xFFFFFFFFull);
  for (size_t i = 0; i < finest.size(); ++i)
    if (const std::string why = finest[i].check(); !why.empty())
      throw Error("deep tile: texel " + std::to_string(i) + ": " + why);

  // Every mip, finest first (§5.3).
  std::vector<std::vector<VisibilityFunction>> mips(side_bits + 1);
  mips[0].assign(finest.begin(), finest.end());
  for (uint32_t m = 1; m <= side_bits; ++m) {
    const uint32_t s = side >> m;
    const double eps_m = std::ldexp(epsilon, -int(m));
    mips[m].resize(size_t(s) * s);
    const auto& below = mips[m - 1];
    const double w[4] = {1, 1, 1, 1};
    for (uint32_t y = 0; y < s; ++y)
      for (uint32_t x = 0; x < s; ++x) {
        const VisibilityFunction* in[4] = {
            &below[size_t(2 * y) * (2 * s) + 2 * x], &below[size_t(2 * y) * (2 * s) + 2 * x + 1],
            &below[size_t(2 * y + 1) * (2 * s) + 2 * x],
            &below[size_t(2 * y + 1) * (2 * s) + 2 * x + 1]};
        mips[m][size_t(y) * s + x] = compress(average(in, w), eps_m);
      }
  }

  const uint32_t texels = texel_count(side_bits);
  const uint64_t data_offset = kHeaderBytes + 8ull * texels;
  std::vector<uint8_t> out(data_offset, 0);
  std::vector<uint8_t> data;
  uint32_t index = 0;
  for (uint32_t m = 0; m <= side_bits; ++m)
    for (const VisibilityFunction& f : mips[m]) {
      const size_t n = f.vertices.size();
      if (n > kMaxVertices)
        throw Error("deep tile: a texel of mip " + std::to_string(m) + " has " +
                    std::to_string(n) + " vertices (at most 65535; raise epsilon)");
      bool mono = true;
      for (const VisVertex& v : f.vertices)
        mono = mono && unorm(v.t[1]) == unorm(v.t[0]) && unorm(v.t[2]) == unorm(v.t[0]);
      const uint32_t bytes = block_bytes(uint32_t(n), mono);
      if (data_offset + data.size() + bytes > max_bytes)
        throw Error("deep tile: over " + std::to_string(max_bytes) + " bytes (raise epsilon)");
      uint8_t* e = out.data() + kHeaderBytes + 8 * size_t(index++);
      store_le<uint32_t>(e, uint32_t(data.size()));
      store_le<uint16_t>(e + 4, uint16_t(n));
      e[6] = mono ? kFlagMonochrome : 0;
      const size_t at = data.size();
      data.resize(at + bytes, 0);
      uint8_t* p = data.data() + at;
      for (size_t k = 0; k < n; ++k) store_le<float>(p + 4 * k, f.vertices[k].depth);
      uint8_t* q = p + 4 * n;
      for (size_t k = 0; k < n; ++k)
        for (int c = 0; c < (mono ? 1 : 3); ++c, q += 2) store_le<uint16_t>(q, unorm(f.vertices[k].t[c]));
      if (stats) stats->vertices[m] += n;
    }
  uint8_t* h = out.data();
  store_le<uint32_t>(h + 0, kMagic);
  store_le<uint32_t>(h + 4, kVersion);
  store_le<uint32_t>(h + 8, kHeaderBytes);
  store_le<uint32_t>(h + 12, side_bits);
  store_le<uint32_t>(h + 16, side_bits + 1);
  store_le<uint32_t>(h + 20, texels);
  store_le<uint32_t>(h + 24, kHeaderBytes);
  store_le<uint32_t>(h + 28, uint32_t(data_offset));
  store_le<uint32_t>(h + 32, uint32_t(data.size()));
  store_le<uint32_t>(h + 36, uint32_t(data_offset + data.size()));
  store_le<float>(h + 40, float(epsilon));
  store_le<uint32_t>(h + 44, 0);
  out.insert(out.end(), data.begin(), data.end());
  if (stats) stats->bytes = out.size();
  return out;
}

}  // namespace st
