// libFuzzer harness for per-slice stack cells (tiles/core/stack_slices.hpp, MHOCT.md
// "Per-slice cells"). Input: an "STSL" buffer, or its grouped stored form "STSP", which
// ungroup_slice_tiles turns back into STSL or refuses with st::FormatError (the seeds hold
// both); an STSL buffer that opens comes back byte for byte through group_slice_tiles and
// ungroup_slice_tiles. Contract: SliceTiles::open validates the
// header, every entry and every slice's 2D tile (DAG-MH, MMH, or a plane tile over either:
// seeds with plane slices, grouped with them packed) or throws
// st::FormatError; a buffer it accepts answers depth() at every level of every slice
// without reading out of bounds, deterministically, and StackTile::open accepts it too
// and answers the same.
#include <bit>
#include <span>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/fuzz_harness.hpp"
#include "tiles/encode/stack_slices_encode.hpp"
#include "tiles/core/plane_format.hpp"
#include "tiles/core/stack_slices.hpp"

namespace {

// A cell's slices: random intervals, a shadow edge sliding with w (coherent), or one
// value (a constant entry); `repeat` makes every other slice equal its predecessor (a
// buffer two entries name).
std::vector<st::IntervalTile> seed_slices(uint32_t m, uint32_t count, uint64_t seed, int pattern) {
  std::vector<st::IntervalTile> out;
  st::Rng rng(seed);
  const uint32_t side = 1u << m;
  for (uint32_t w = 0; w < count; ++w) {
    st::IntervalTile t;
    t.level = m;
    t.width = t.height = side;
    t.data.resize(size_t(side) * side);
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) {
        float a = float(rng.uniform()), b = float(rng.uniform());
        if (pattern == 1) a = (x + w / 2 < side / 2 && y > side / 3) ? 0.3f : 0.8f, b = a;
        if (pattern == 2) a = 0.5f, b = 0.5f;
        if (pattern == 4)  // a slanted plane's exact depths (plane slices), a box of wide intervals
          a = b = x < 2 && y < 2 ? 0.2f
                                 : st::planes::plane_fixed_to_float(st::planes::kOne / 2 + st::planes::kOne / 512 * int64_t(x + w) +
                                                                    st::planes::kOne / 1024 * int64_t(y));
        t.data[size_t(y) * side + x] = {std::min(a, b), std::max(a, b)};
      }
    if (pattern == 3 && w % 2 == 1) t = out.back();
    out.push_back(std::move(t));
  }
  return out;
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  const std::pair<uint32_t, uint32_t> shapes[] = {{0, 1}, {1, 2}, {2, 4}, {3, 3}, {3, 8}, {4, 2}};
  uint64_t seed = 1;
  for (auto [m, count] : shapes)
    for (int pattern = 0; pattern < 5; ++pattern) {
      uint32_t j = 0;
      while ((1u << j) < count) ++j;
      if (pattern == 4 && m < 3) continue;  // plane slices: 8x8 squares and larger
      const PlaneFitOptions fit;
      out.push_back(encode_slice_tiles(seed_slices(m, count, seed++, pattern), m, j + (pattern == 2), pattern == 4 ? &fit : nullptr));
      out.push_back(group_slice_tiles(out.back()));
    }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> bytes(data, data + size);  // exact size: ASan sees overreads
  if (st::is_grouped_slice_tiles(bytes)) {
    try {
      st::ungroup_slice_tiles(bytes);
    } catch (const st::FormatError&) {
      return 0;
    }
  }
  const std::span<const std::uint8_t> span(bytes.data(), bytes.size());
  st::SliceTiles t;
  try {
    t = st::SliceTiles::open(span);
  } catch (const st::FormatError&) {
    return 0;
  }
  st::fuzz::note_accepted();
  {
    std::vector<std::uint8_t> back = st::group_slice_tiles(span);
    FUZZ_CHECK(back.size() == bytes.size());
    if (st::is_grouped_slice_tiles(back)) st::ungroup_slice_tiles(back);
    FUZZ_CHECK(back == bytes);
  }
  const st::StackTile any = st::StackTile::open(span);
  FUZZ_CHECK(!any.is_octree() && any.xy_level() == t.xy_level() && any.w_level() == t.w_level());
  const uint64_t h = st::fuzz::input_hash(data, size);
  for (uint32_t w = 0; w < t.slices(); ++w)
    for (uint32_t q = 0; q <= t.xy_level(); ++q) {
      const uint64_t side = uint64_t(1) << q;
      for (uint32_t i = 0; i < 4; ++i) {
        const uint64_t x = (i & 1) ? side - 1 : (h >> (4 * i)) % side, y = (i & 2) ? side - 1 : (h >> (4 * i + 2)) % side;
        const float v = t.depth(x, y, w, q);
        FUZZ_CHECK(std::bit_cast<uint32_t>(v) == std::bit_cast<uint32_t>(t.depth(x, y, w, q)));
        FUZZ_CHECK(std::bit_cast<uint32_t>(v) == std::bit_cast<uint32_t>(any.ref().depth(x, y, w, q)));
      }
    }
  return 0;
}
