// The skip grid's entries and coarse levels against interval hulls: what `verify --all`
// checks of a finished pack from the re-traced texels, and PackReader::verify from the
// build journal's cell records.
#include <gtest/gtest.h>

#include "common/error.hpp"
#include "tiles/core/coarse_hulls.hpp"

namespace st {
namespace {

// A 2-level grid over 4x4 cells whose hulls are [c, c + 1] for cell value c = x + 4y, with
// every entry and coarse value at a point its hull allows.
struct Fixture {
  CutGrid grid;
  CellHulls hulls{2};
  Fixture() {
    grid.levels = 2;
    grid.coarse.assign(CutGrid::coarse_count(2), 0.f);
    grid.entries.resize(16);
    for (size_t y = 0; y < 4; ++y)
      for (size_t x = 0; x < 4; ++x) {
        const float c = float(x + 4 * y);
        hulls.set(x, y, c, c + 1);
        grid.entry(x, y).value = c + 0.5f;
      }
    // Level 1 texel (x, y) covers cells 2x..2x+1, 2y..2y+1: hull [8y + 2x, 8y + 2x + 6].
    for (size_t y = 0; y < 2; ++y)
      for (size_t x = 0; x < 2; ++x) grid.coarse_at(1, x, y) = float(8 * y + 2 * x + 6);
    grid.coarse_at(0, 0, 0) = 7.f;  // in [0, 16]
  }
};

TEST(CoarseHulls, AcceptsValuesInsideTheirHullsAndCountsThem) {
  Fixture f;
  EXPECT_EQ(check_coarse_hulls(f.grid, f.hulls, "g"), 16u + 4u + 1u);
}

TEST(CoarseHulls, RefusesAnEntryOrCoarseValueOutsideItsHull) {
  {
    Fixture f;
    f.grid.entry(3, 1).value = 6.5f;  // cell (3, 1) is [7, 8]
    try {
      check_coarse_hulls(f.grid, f.hulls, "p.pack");
      FAIL();
    } catch (const FormatError& e) {
      EXPECT_STREQ(e.what(), "p.pack: skip grid entry (3, 1) is 6.500000, outside [7.000000, 8.000000], the hull of "
                             "the intervals below it");
    }
  }
  {
    Fixture f;
    f.grid.coarse_at(1, 1, 1) = 9.f;  // cells (2..3, 2..3) are [10, 16]
    EXPECT_THROW(check_coarse_hulls(f.grid, f.hulls, "p.pack"), FormatError);
  }
  {
    Fixture f;
    f.grid.coarse_at(0, 0, 0) = 16.5f;
    EXPECT_THROW(check_coarse_hulls(f.grid, f.hulls, "p.pack"), FormatError);
  }
}

TEST(CoarseHulls, SkipsUnknownCellsAndEveryCoarseTexelAboveThem) {
  Fixture f;
  f.hulls.known[1 * 4 + 2] = 0;      // cell (2, 1), under level-1 texel (1, 0) and the root
  f.grid.entry(2, 1).value = -100;   // not checked
  f.grid.coarse_at(1, 1, 0) = -100;  // not checked
  f.grid.coarse_at(0, 0, 0) = -100;  // not checked
  EXPECT_EQ(check_coarse_hulls(f.grid, f.hulls, "g"), 15u + 3u);
  f.grid.coarse_at(1, 0, 1) = -100;  // checked: its cells are known
  EXPECT_THROW(check_coarse_hulls(f.grid, f.hulls, "g"), FormatError);
}

}  // namespace
}  // namespace st
