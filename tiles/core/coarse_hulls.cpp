#include "tiles/core/coarse_hulls.hpp"

#include <algorithm>
#include <cmath>

#include "common/error.hpp"

namespace st {

CellHulls::CellHulls(uint32_t levels)
    : k(levels), lo(size_t(1) << (2 * levels), INFINITY), hi(size_t(1) << (2 * levels), -INFINITY),
      known(size_t(1) << (2 * levels), 0) {}

uint64_t check_coarse_hulls(const CutGrid& grid, const CellHulls& hulls, const std::string& name) {
  if (grid.levels != hulls.k)
    throw Error(name + ": hulls of skip level " + std::to_string(hulls.k) + " for a grid of " +
                std::to_string(grid.levels) + " levels");
  const size_t side = hulls.side();
  uint64_t checked = 0;
  for (size_t y = 0; y < side; ++y)
    for (size_t x = 0; x < side; ++x) {
      const size_t i = y * side + x;
      if (!hulls.known[i]) continue;
      const float v = grid.entry(x, y).value;
      if (!(hulls.lo[i] <= v && v <= hulls.hi[i]))
        throw FormatError(name + ": skip grid entry (" + std::to_string(x) + ", " + std::to_string(y) + ") is " +
                          std::to_string(v) + ", outside [" + std::to_string(hulls.lo[i]) + ", " +
                          std::to_string(hulls.hi[i]) + "], the hull of the intervals below it");
      ++checked;
    }
  // Hulls level by level, finest first: level j from level j + 1.
  std::vector<float> lo = hulls.lo, hi = hulls.hi;
  std::vector<uint8_t> known = hulls.known;
  for (uint32_t j = hulls.k; j-- > 0;) {
    const size_t s = size_t(1) << j;
    std::vector<float> plo(s * s), phi(s * s);
    std::vector<uint8_t> pknown(s * s);
    for (size_t y = 0; y < s; ++y)
      for (size_t x = 0; x < s; ++x) {
        float a = INFINITY, b = -INFINITY;
        uint8_t all = 1;
        for (size_t dy = 0; dy < 2; ++dy)
          for (size_t dx = 0; dx < 2; ++dx) {
            const size_t i = (2 * y + dy) * (2 * s) + 2 * x + dx;
            a = std::min(a, lo[i]), b = std::max(b, hi[i]);
            all &= known[i];
          }
        plo[y * s + x] = a, phi[y * s + x] = b, pknown[y * s + x] = all;
        if (!all) continue;
        const float v = grid.coarse_at(j, x, y);
        if (!(a <= v && v <= b))
          throw FormatError(name + ": skip grid coarse value of level " + std::to_string(j) + " texel (" +
                            std::to_string(x) + ", " + std::to_string(y) + ") is " + std::to_string(v) +
                            ", outside [" + std::to_string(a) + ", " + std::to_string(b) +
                            "], the hull of the intervals below it");
        ++checked;
      }
    lo.swap(plo), hi.swap(phi), known.swap(pknown);
  }
  return checked;
}

}  // namespace st
