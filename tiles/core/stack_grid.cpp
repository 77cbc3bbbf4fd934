#include "tiles/core/stack_grid.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/tile_cut_grid.hpp"  // the id fields (level, code) a cell id reuses

namespace st {

namespace {

// The id level of a grid's tiles (stack_grid.hpp): ceil(B / 2).
uint32_t stack_id_level(const StackGrid& g) {
  uint32_t b = 2 * g.geo.xy_bits(g.skip_level) + g.geo.w_bits(g.skip_level);
  if (g.split()) b = uint32_t(std::bit_width(g.entries.size() - 1));
  return (b + 1) / 2;
}

}  // namespace

uint64_t StackGrid::tile_id(uint64_t cell) const {
  return (uint64_t(stack_id_level(*this)) << kTileIdLevelShift) | cell;
}

void StackGrid::link() {
  const uint64_t E = cells(skip_level);
  if (entries.size() < E) throw Error("stack grid: fewer entries than cells at the skip level");
  uint64_t next = E;
  for (uint64_t i = 0; i < E; ++i) entries[i].level = uint8_t(skip_level);
  for (uint64_t i = 0; i < entries.size(); ++i) {
    StackEntry& e = entries[i];
    e.first = 0;
    if (e.kind != kStackSplit) continue;
    if (e.level >= geo.depth()) throw Error("stack grid: a split cell at the finest level");
    const uint32_t c = children(e.level);
    if (next + c > entries.size()) throw Error("stack grid: split cells name more children than the entries hold");
    e.first = uint32_t(next);
    for (uint32_t j = 0; j < c; ++j) entries[next + j].level = uint8_t(e.level + 1);
    next += c;
  }
  if (next != entries.size()) throw Error("stack grid: entries no split cell names");
}

bool StackGrid::cell_of(uint64_t id, uint64_t& cell) const {
  if (tile_level(id) != stack_id_level(*this)) return false;
  cell = tile_morton(id);
  return cell < entries.size();
}

uint64_t StackGrid::serialized_size(const moct::Geometry& geo, uint32_t slices, uint32_t skip_level,
                                    size_t spec_size, uint64_t split_entries) {
  StackGrid g;
  g.geo = geo;
  uint64_t coarse = 0;
  for (uint32_t l = 0; l < skip_level; ++l) coarse += g.cells(l);
  return kStackGridFixedBytes + 144ull * slices + ((spec_size + 3) & ~size_t(3)) + 4 * coarse +
         8 * (g.cells(skip_level) + split_entries);
}

std::vector<uint8_t> StackGrid::serialize() const {
  std::vector<uint8_t> out;
  const uint64_t extra = entries.size() - std::min<uint64_t>(entries.size(), cells(skip_level));
  out.reserve(serialized_size(geo, slices, skip_level, spec.size(), extra));
  append_le<uint32_t>(out, kStackGridMagic);
  append_le<uint32_t>(out, extra ? kStackGridSplitVersion : kStackGridVersion);
  out.push_back(uint8_t(geo.n));
  out.push_back(uint8_t(geo.k));
  out.push_back(uint8_t(skip_level));
  out.push_back(uint8_t(light_kind));
  append_le<uint32_t>(out, slices);
  append_le<uint32_t>(out, uint32_t(spec.size()));
  append_le<uint32_t>(out, uint32_t(extra));
  for (const auto& l : lights)
    for (double d : l) append_le<uint64_t>(out, std::bit_cast<uint64_t>(d));
  out.insert(out.end(), spec.begin(), spec.end());
  while (out.size() % 4) out.push_back(0);
  for (const auto& lv : coarse)
    for (float v : lv) append_le<uint32_t>(out, std::bit_cast<uint32_t>(v));
  for (const StackEntry& e : entries) {
    append_le<uint32_t>(out, std::bit_cast<uint32_t>(e.value));
    out.push_back(e.kind);
    out.push_back(0);
    append_le<uint16_t>(out, 0);
  }
  return out;
}

StackGrid StackGrid::parse(std::span<const uint8_t> b, const std::string& what) {
  auto fail = [&](size_t off, const std::string& msg) {
    throw FormatError(what + ": stack grid " + msg + " at byte " + std::to_string(off));
  };
  if (b.size() < kStackGridFixedBytes) fail(0, "truncated (" + std::to_string(b.size()) + " bytes)");
  if (load_le<uint32_t>(b, 0) != kStackGridMagic) fail(0, "bad magic");
  const uint32_t version = load_le<uint32_t>(b, 4);
  if (version != kStackGridVersion && version != kStackGridSplitVersion) fail(4, "unsupported version");
  StackGrid g;
  g.geo.n = b[8];
  g.geo.k = b[9];
  g.skip_level = b[10];
  if (g.geo.n > moct::kMaxXyLevel) fail(8, "xy_level above 20");
  if (g.geo.k > moct::kMaxWLevel) fail(9, "w_level above 12");
  if (g.skip_level > g.geo.depth()) fail(10, "skip level below the finest octree level");
  if (!light_kind_known(b[11])) fail(11, "unknown light kind " + std::to_string(b[11]));
  g.light_kind = LightKind(b[11]);
  g.slices = load_le<uint32_t>(b, 12);
  const uint32_t k = g.geo.k;
  if (g.slices == 0 || g.slices > (1u << k) || (k > 0 && g.slices <= (1u << (k - 1))))
    fail(12, "slice count does not pad to 2^w_level");
  const uint32_t spec_size = load_le<uint32_t>(b, 16);
  if (spec_size > kStackMaxSpecBytes) fail(16, "spec longer than 4096 bytes");
  const uint64_t extra = load_le<uint32_t>(b, 20);
  if (version == kStackGridVersion && extra != 0) fail(20, "nonzero reserved field");
  if (version == kStackGridSplitVersion && extra == 0) fail(20, "version 2 without split entries");
  if (g.cells(g.skip_level) > kStackMaxCells) fail(10, "more than 2^22 cells at the skip level");
  if (g.cells(g.skip_level) + extra > kStackMaxCells) fail(20, "more than 2^22 entries with the split cells'");
  const uint64_t size = serialized_size(g.geo, g.slices, g.skip_level, spec_size, extra);
  if (b.size() != size) fail(0, "size " + std::to_string(b.size()) + " != " + std::to_string(size));
  size_t o = kStackGridFixedBytes;
  g.lights.resize(g.slices);
  for (uint32_t w = 0; w < g.slices; ++w) {
    for (int i = 0; i < 18; ++i, o += 8) g.lights[w][i] = std::bit_cast<double>(load_le<uint64_t>(b, o));
    const std::string bad = LightSpace::check_array(g.light_kind, g.lights[w]);
    if (!bad.empty()) fail(o - 144, "light of slice " + std::to_string(w) + ": " + bad);
  }
  g.spec.assign(reinterpret_cast<const char*>(b.data() + o), spec_size);
  if (g.spec.find('\0') != std::string::npos) fail(o, "NUL in the spec");
  o += spec_size;
  for (; o % 4; ++o)
    if (b[o]) fail(o, "nonzero padding");
  g.coarse.resize(g.skip_level);
  for (uint32_t l = 0; l < g.skip_level; ++l) {
    g.coarse[l].resize(g.cells(l));
    for (float& v : g.coarse[l]) {
      v = std::bit_cast<float>(load_le<uint32_t>(b, o));
      if (std::isnan(v)) fail(o, "NaN value");
      o += 4;
    }
  }
  const uint64_t E = g.cells(g.skip_level);
  g.entries.resize(E + extra);
  uint64_t next = E;  // the first child of the next split entry
  for (uint64_t i = 0; i < g.entries.size(); ++i) {
    StackEntry& e = g.entries[i];
    if (i < E) e.level = uint8_t(g.skip_level);
    if (i >= next) fail(o, "split entry " + std::to_string(i) + " no split cell names");
    e.value = std::bit_cast<float>(load_le<uint32_t>(b, o));
    if (std::isnan(e.value)) fail(o, "NaN value");
    e.kind = b[o + 4];
    if (e.kind > (extra ? kStackSplit : 1)) fail(o + 4, "bad entry kind");
    if (b[o + 5] || load_le<uint16_t>(b, o + 6)) fail(o + 5, "nonzero entry padding");
    if (e.kind == kStackSplit) {
      if (e.level >= g.geo.depth()) fail(o + 4, "split cell at the finest level");
      const uint32_t c = g.children(e.level);
      if (next + c > g.entries.size()) fail(o + 4, "split cell's children past the last entry");
      e.first = uint32_t(next);
      for (uint32_t j = 0; j < c; ++j) g.entries[next + j].level = uint8_t(e.level + 1);
      next += c;
    }
    o += 8;
  }
  if (next != g.entries.size()) fail(20, "split entries no split cell names");
  return g;
}

}  // namespace st
