// libFuzzer harness for MapPreview::parse (tiles/core/map_preview.hpp, tiles/PACK.md "Map
// preview"): the preview a client reads from MapInfo, values stored as varint residuals
// against a prediction. Input: byte 0 picks the skip grid (K = 1 + byte % 3, which entries
// are tiles); the rest is the preview. Checks: parse either throws st::FormatError or
// returns a preview that re-serializes to the same bytes (one canonical form: overlong
// varints refused), holds no NaN, and answers coarse_answer / value at every node of a few
// cells without reading out of bounds.
#include <cmath>
#include <span>

#include "common/error.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/core/map_preview.hpp"

namespace {

constexpr uint32_t kMapLevel = 8;  // K + p <= 3 + 4 < 8

// The grid byte 0 names: entries alternate between tiles and constants by its bits.
st::CutGrid preview_fuzz_grid(uint8_t control) {
  const uint32_t k = 1 + control % 3;
  st::CutGrid g = st::CutGrid::constant(k, 0.5f);
  for (size_t i = 0; i < g.entries.size(); ++i) {
    g.entries[i].value = 0.25f + 0.001f * float(i);
    if ((control >> 2) == 0 || ((i * 7 + (control >> 2)) % 3) != 0) g.entries[i].kind = st::EntryKind::tile;
  }
  return g;
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  for (uint8_t control : {0, 1, 2, 4, 9, 14, 30}) {
    const CutGrid g = preview_fuzz_grid(control);
    for (uint32_t p = 0; p <= kMaxPreviewLevels && g.levels + p < kMapLevel; ++p)
      for (int field = 0; field < 3; ++field) {
        // Planes (as plane tiles answer), a step between two planes, and noise.
        const MapPreview m = MapPreview::build(g, p, [&](uint32_t level, uint64_t x, uint64_t y) {
          const double s = 1.0 / double(uint64_t(1) << level);
          const double u = (double(x) + 0.5) * s, v = (double(y) + 0.5) * s;
          if (field == 0) return float(0.3 + 0.2 * u - 0.1 * v);
          if (field == 1) return float(u < 0.4 ? 0.3 + 0.2 * u : 0.7 - 0.3 * v);
          return float(std::fmod(std::sin(double(x * 131 + y * 71 + level)) * 0.5 + 0.5, 1.0));
        });
        Bytes b = m.serialize();
        b.insert(b.begin(), control);
        out.push_back(std::move(b));
      }
  }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const st::CutGrid g = preview_fuzz_grid(data[0]);
  const std::vector<std::uint8_t> bytes(data + 1, data + size);
  st::MapPreview m;
  try {
    m = st::MapPreview::parse(bytes, g, kMapLevel, "fuzz preview");
  } catch (const st::FormatError&) {
    return 0;
  }
  st::fuzz::note_accepted();
  FUZZ_CHECK(m.levels() <= st::kMaxPreviewLevels && g.levels + m.levels() <= kMapLevel);
  FUZZ_CHECK(m.serialized_size() == bytes.size());
  FUZZ_CHECK(m.serialize() == bytes);
  for (float v : m.values()) FUZZ_CHECK(!std::isnan(v));
  const uint64_t hash = st::fuzz::input_hash(data, size);
  const uint64_t side = uint64_t(1) << g.levels;
  for (uint64_t pick : {uint64_t(0), hash, hash >> 17, side * side - 1}) {
    const uint64_t ex = pick % side, ey = (pick / side) % side;
    for (uint32_t j = 0; j <= m.levels(); ++j)
      for (uint64_t ly = 0; ly < (uint64_t(1) << j); ++ly)
        for (uint64_t lx = 0; lx < (uint64_t(1) << j); ++lx)
          FUZZ_CHECK(!std::isnan(m.value(ex, ey, j, lx, ly, 0.5f)));
  }
  return 0;
}
