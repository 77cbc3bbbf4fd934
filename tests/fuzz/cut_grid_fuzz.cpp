// libFuzzer harness for CutGrid::parse (tile_cut_grid.hpp): the skip grid of a pack and
// every index tile go through it. Input: byte 0 picks max_levels (bit 0: kMaxSkipLevel,
// the skip grid; else kMaxIndexLevels, an index tile) and the texels probed; the rest is
// the serialized grid. Checks: parse either throws st::FormatError or returns a grid
// whose sizes match its levels, that re-serializes to the same bytes (one canonical
// form), answers value_at at every level without reading out of bounds, and whose
// entries respect the documented kind/index_levels rules. Tile ids round-trip.
#include <bit>
#include <cmath>
#include <span>

#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "common/error.hpp"
#include "tiles/core/tile_cut_grid.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::mt19937_64 rng(7);
  std::vector<Bytes> out;
  for (uint32_t k = 0; k <= 5; ++k) {
    for (int variant = 0; variant < 3; ++variant) {
      CutGrid g = CutGrid::constant(k, 0.25f * float(variant));
      std::uniform_real_distribution<float> unit(0.0f, 1.0f);
      for (float& v : g.coarse) v = unit(rng);
      for (GridEntry& e : g.entries) {
        e.value = unit(rng);
        const uint64_t r = rng() % 4;
        if (variant > 0 && r == 1) e.kind = EntryKind::tile;
        if (variant > 1 && r == 2) {
          e.kind = EntryKind::index;
          e.index_levels = uint8_t(1 + rng() % kMaxIndexLevels);
        }
      }
      Bytes b = g.serialize();
      // Control byte: skip grid (odd) for every k; index tile (even) for k <= 4.
      b.insert(b.begin(), uint8_t(k <= kMaxIndexLevels && variant == 1 ? 2 * k : 2 * k + 1));
      out.push_back(std::move(b));
    }
  }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::uint8_t control = data[0];
  const std::vector<std::uint8_t> bytes(data + 1, data + size);
  const uint32_t max_levels = (control & 1) ? st::kMaxSkipLevel : st::kMaxIndexLevels;
  st::CutGrid g;
  try {
    g = st::CutGrid::parse(bytes, "fuzz grid", max_levels);
  } catch (const st::FormatError&) {
    return 0;
  }
  st::fuzz::note_accepted();
  FUZZ_CHECK(g.levels <= max_levels);
  FUZZ_CHECK(bytes.size() == st::CutGrid::serialized_size(g.levels));
  FUZZ_CHECK(g.coarse.size() == st::CutGrid::coarse_count(g.levels));
  FUZZ_CHECK(g.entries.size() == (size_t(1) << (2 * g.levels)));
  FUZZ_CHECK(g.serialize() == bytes);
  for (const st::GridEntry& e : g.entries) {
    FUZZ_CHECK(!std::isnan(e.value));
    if (e.kind == st::EntryKind::index)
      FUZZ_CHECK(e.index_levels >= 1 && e.index_levels <= st::kMaxIndexLevels);
    else
      FUZZ_CHECK(e.index_levels == 0 && (e.kind == st::EntryKind::constant || e.kind == st::EntryKind::tile));
  }
  const uint64_t hash = st::fuzz::input_hash(data, size);
  for (uint32_t l = 0; l <= g.levels; ++l) {
    const uint64_t mask = (uint64_t(1) << l) - 1;
    for (uint64_t t : {uint64_t(0), mask, hash & mask, (hash >> 32) & mask}) {
      const float v = g.value_at(l, t, mask - t);
      FUZZ_CHECK(!std::isnan(v));
      // Tile ids of the nodes the grid covers round-trip (skip grid: root 0, so the
      // entry level is absolute).
      const uint64_t id = st::make_tile_id(l, uint32_t(t), uint32_t(mask - t));
      FUZZ_CHECK(st::is_valid_tile_id(id));
      const st::TileAddress a = st::tile_address(id);
      FUZZ_CHECK(a.level == l && a.x == t && a.y == mask - t);
    }
  }
  // Arbitrary 64-bit ids: valid ones decode, invalid ones throw FormatError.
  for (uint64_t id : {hash, hash >> 6, ~hash, uint64_t(control) << 58}) {
    if (st::is_valid_tile_id(id)) {
      const st::TileAddress a = st::tile_address(id);
      FUZZ_CHECK(st::make_tile_id(a.level, a.x, a.y) == id);
    } else {
      bool threw = false;
      try {
        st::tile_address(id);
      } catch (const st::FormatError&) {
        threw = true;
      }
      FUZZ_CHECK(threw);
    }
  }
  return 0;
}
