#include "tiles/core/tile_cut_grid.hpp"

#include <cassert>
#include <cmath>
#include <cstdio>

#include "common/error.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/interval.hpp"
#include "common/bytes.hpp"

namespace st {


CutGrid CutGrid::constant(uint32_t k, float v) {
  CutGrid g;
  g.levels = k;
  g.coarse.assign(coarse_count(k), v);
  g.entries.assign(size_t(1) << (2 * k), GridEntry{v, EntryKind::constant, 0});
  return g;
}

std::vector<uint8_t> CutGrid::serialize() const {
  assert(coarse.size() == coarse_count(levels) && entries.size() == (size_t(1) << (2 * levels)));
  std::vector<uint8_t> out;
  out.reserve(serialized_size(levels));
  append_le<uint32_t>(out, kGridMagic);
  append_le<uint32_t>(out, levels);
  for (float v : coarse) append_le<float>(out, v);
  for (const GridEntry& e : entries) {
    append_le<float>(out, e.value);
    append_le<uint8_t>(out, uint8_t(e.kind));
    append_le<uint8_t>(out, e.index_levels);
    append_le<uint16_t>(out, 0);
  }
  return out;
}

namespace {
[[noreturn]] void grid_error(const std::string& what, size_t offset, const std::string& msg) {
  throw FormatError(what + ": " + msg + " at byte " + std::to_string(offset));
}
}  // namespace

CutGrid CutGrid::parse(std::span<const uint8_t> bytes, const std::string& what,
                       uint32_t max_levels) {
  if (bytes.size() < 8) grid_error(what, bytes.size(), "truncated grid header (" + std::to_string(bytes.size()) + " bytes)");
  if (load_le<uint32_t>(bytes, 0) != kGridMagic) grid_error(what, 0, "bad grid magic");
  uint32_t k = load_le<uint32_t>(bytes, 4);
  if (k > max_levels) grid_error(what, 4, "grid levels " + std::to_string(k) + " > " + std::to_string(max_levels));
  size_t want = serialized_size(k);
  if (bytes.size() != want)
    grid_error(what, std::min(bytes.size(), want),
               "grid of " + std::to_string(k) + " levels needs " + std::to_string(want) +
                   " bytes, has " + std::to_string(bytes.size()));
  CutGrid g;
  g.levels = k;
  g.coarse.resize(coarse_count(k));
  size_t off = 8;
  for (float& v : g.coarse) {
    v = load_le<float>(bytes, off);
    if (std::isnan(v)) grid_error(what, off, "NaN coarse value");
    off += 4;
  }
  g.entries.resize(size_t(1) << (2 * k));
  for (GridEntry& e : g.entries) {
    e.value = load_le<float>(bytes, off);
    if (std::isnan(e.value)) grid_error(what, off, "NaN entry value");
    uint8_t kind = bytes[off + 4];
    e.index_levels = bytes[off + 5];
    if (kind > uint8_t(EntryKind::index)) grid_error(what, off + 4, "bad entry kind " + std::to_string(kind));
    e.kind = EntryKind(kind);
    bool levels_ok = e.kind == EntryKind::index
                         ? e.index_levels >= 1 && e.index_levels <= kMaxIndexLevels
                         : e.index_levels == 0;
    if (!levels_ok) grid_error(what, off + 5, "bad index levels " + std::to_string(e.index_levels));
    if (load_le<uint16_t>(bytes, off + 6) != 0) grid_error(what, off + 6, "nonzero entry padding");
    off += kGridEntryBytes;
  }
  return g;
}

uint64_t make_tile_id(uint32_t level, uint32_t x, uint32_t y) {
  assert(level <= kMaxLevel && (uint64_t(x) >> level) == 0 && (uint64_t(y) >> level) == 0);
  return (uint64_t(level) << kTileIdLevelShift) | morton_encode(x, y);
}

bool is_valid_tile_id(uint64_t id) {
  const uint32_t level = tile_level(id);
  if (level > kMaxLevel) return false;
  return (tile_morton(id) >> (2 * level)) == 0;
}

TileAddress tile_address(uint64_t id) {
  if (!is_valid_tile_id(id)) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "invalid tile id 0x%016llx", (unsigned long long)id);
    throw FormatError(buf);
  }
  const uint64_t morton = tile_morton(id);
  return TileAddress{tile_level(id), morton_compact(morton), morton_compact(morton >> 1)};
}

std::string describe_tile(uint64_t id) {
  char buf[96];
  // Deep ids (pack_format.hpp, kDeepTileIdBit): bit 63 over an opaque-style id, or the
  // deep directory (level field 31).
  const uint64_t deep_bit = uint64_t(1) << 63;
  if ((id & deep_bit) && tile_level(id) == 63 && (id << 6) == 0) {
    std::snprintf(buf, sizeof buf, "deep directory 0x%016llx", (unsigned long long)id);
  } else if ((id & deep_bit) && is_valid_tile_id(id & ~deep_bit)) {
    TileAddress a = tile_address(id & ~deep_bit);
    std::snprintf(buf, sizeof buf, "deep tile 0x%016llx (level %u, x %u, y %u)", (unsigned long long)id, a.level,
                  a.x, a.y);
  } else if (!is_valid_tile_id(id)) {
    std::snprintf(buf, sizeof buf, "tile 0x%016llx (invalid id)", (unsigned long long)id);
  } else {
    TileAddress a = tile_address(id);
    std::snprintf(buf, sizeof buf, "tile 0x%016llx (level %u, x %u, y %u)", (unsigned long long)id,
                  a.level, a.x, a.y);
  }
  return buf;
}

}  // namespace st
