#include "tiles/encode/hierarchy.hpp"

#include <algorithm>

#include "common/error.hpp"

namespace st {

std::vector<std::vector<uint32_t>> Hierarchy::first_child_index() const {
  std::vector<std::vector<uint32_t>> out(levels.size());
  for (size_t l = 0; l + 1 < levels.size(); ++l) {
    out[l].resize(levels[l].size());
    uint32_t acc = 0;
    for (size_t j = 0; j < levels[l].size(); ++j) {
      out[l][j] = acc;
      acc += uint32_t(__builtin_popcount(levels[l][j].child_mask));
    }
  }
  if (!levels.empty()) out.back().assign(levels.back().size(), 0);
  return out;
}

size_t Hierarchy::node_count() const {
  size_t n = 0;
  for (auto& l : levels) n += l.size();
  return n;
}

size_t Hierarchy::valued_count() const {
  size_t n = 0;
  for (auto& l : levels)
    for (auto& node : l) n += node.has_value;
  return n;
}

float Hierarchy::depth_at(uint32_t level, uint64_t x, uint64_t y) const {
  ST_CHECK(!levels.empty() && !levels[0].empty() && levels[0][0].has_value);
  float value = levels[0][0].value;
  for (uint32_t l = 1; l <= level && l < levels.size(); ++l) {
    uint64_t shift = level - l;
    uint64_t code = morton_encode(uint32_t(x >> shift), uint32_t(y >> shift));
    auto& lv = levels[l];
    auto it = std::lower_bound(lv.begin(), lv.end(), code,
                               [](const HNode& n, uint64_t c) { return n.morton < c; });
    if (it == lv.end() || it->morton != code) break;
    if (it->has_value) value = it->value;
  }
  return value;
}

}  // namespace st
