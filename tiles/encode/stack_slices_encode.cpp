#include "tiles/encode/stack_slices_encode.hpp"

#include <cstring>
#include <string>

#include "common/error.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st {

StackCells parse_stack_cells(const std::string& text) {
  if (text == "octree") return StackCells::octree;
  if (text == "slices") return StackCells::slices;
  if (text == "smaller") return StackCells::smaller;
  throw Error("--stack-cells: expected octree, slices or smaller, got '" + text + "'");
}

std::vector<uint8_t> encode_slice_tiles(std::span<const IntervalTile> slices, uint32_t m, uint32_t j) {
  const uint64_t count = uint64_t(1) << j;
  if (slices.size() > count) throw Error("slice tiles: " + std::to_string(slices.size()) + " slices for 2^" + std::to_string(j) + " entries");
  std::vector<uint8_t> out(kSliceTilesHeaderBytes + kSliceTilesEntryBytes * count, 0);
  auto put32 = [&](size_t at, uint32_t v) { std::memcpy(out.data() + at, &v, 4); };
  put32(0, kSliceTilesMagic);
  const uint16_t version = kSliceTilesVersion;
  std::memcpy(out.data() + 4, &version, 2);
  out[6] = uint8_t(m);
  out[7] = uint8_t(j);
  std::vector<std::pair<std::vector<uint8_t>, uint32_t>> seen;  // buffer, its offset (compared in full)
  for (uint64_t w = 0; w < count; ++w) {
    const size_t at = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w;
    if (w >= slices.size()) {
      const float lit = kLitDepth;
      uint32_t bits;
      std::memcpy(&bits, &lit, 4);
      put32(at + 4, bits);
      continue;
    }
    const IntervalTile& t = slices[w];
    if (t.width != (uint32_t(1) << m) || t.height != t.width || t.data.size() != uint64_t(t.width) * t.height)
      throw Error("slice tiles: slice " + std::to_string(w) + " is not 2^" + std::to_string(m) + " a side");
    const Hierarchy h = build_hierarchy(t);
    const HNode& root = h.levels[0][0];
    if (!root.has_value) throw Error("slice tiles: internal error: slice " + std::to_string(w) + "'s root has no value");
    if (!root.child_mask) {
      uint32_t bits;
      std::memcpy(&bits, &root.value, 4);
      put32(at + 4, bits);
      continue;
    }
    std::vector<uint8_t> dag = encode_dagmh(h), mmh = encode_mmh(h);
    const bool use_dag = zlib_compress(dag, 6).size() <= zlib_compress(mmh, 6).size();
    std::vector<uint8_t>& buf = use_dag ? dag : mmh;
    size_t s = 0;
    while (s < seen.size() && seen[s].first != buf) ++s;
    if (s == seen.size()) {
      if (out.size() + buf.size() + 3 > 0xFFFFFFF0ull) throw Error("slice tiles: cell too large for one buffer");
      seen.emplace_back(buf, uint32_t(out.size()));
      out.insert(out.end(), buf.begin(), buf.end());
      out.resize((out.size() + 3) & ~size_t(3), 0);
    }
    put32(at, seen[s].second);
    put32(at + 4, uint32_t(buf.size()));
  }
  put32(8, uint32_t(out.size()));
  return out;
}

}  // namespace st
