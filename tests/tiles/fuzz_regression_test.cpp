// Regressions found by the fuzz harnesses (tests/fuzz/), as plain tests on the tiles
// libraries. Each test names the harness, the root cause and the fix. The failing inputs
// themselves lie in tests/fuzz/regressions/<harness>/ and are replayed by ctest
// (fuzz_regress.<harness>) through the harness; these tests pin the cause directly.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "tests/tiles/pack_test_support.hpp"
#include "tiles/core/light.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"

namespace st {
namespace {

std::vector<uint8_t> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// pack_reader_fuzz, first seed: a map whose every cell is constant has no tiles, so its
// tile index is 0 bytes; PackReader::read_at then called memcpy(nullptr, p, 0) on the
// empty vector's data(), undefined behaviour (UBSan: "null pointer passed as argument
// 1"). Fix: read_at returns before copying when the span is empty. Under the asan
// preset this test fails without the fix.
TEST(FuzzRegression, PackWithoutTilesOpensFromMemoryAndFile) {
  IntervalTile t;
  t.level = 3;
  t.width = t.height = 8;
  t.data.assign(64, Interval{0.25f, 0.25f});
  const Hierarchy h = build_hierarchy(t);
  for (Encoding e : packtest::available_encodings()) {
    CutParams cut;
    cut.map_level = 3;
    cut.skip_level = 1;
    cut.codec = TileCodec::of(e);
    const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"),
                                             Aabb{{-10, 0, -10}, {10, 5, 10}});
    PackParams pp = PackParams::from(light, cut);
    pp.build_params = {};  // an empty params blob: the other 0-byte section
    const std::string path = packtest::temp_path("fuzz_regression_no_tiles_" + to_string(e) + ".pack");
    write_pack(path, h, cut, pp);
    std::shared_ptr<PackReader> from_memory = PackReader::open_memory(read_file(path), "no_tiles.pack");
    std::shared_ptr<PackReader> from_file = PackReader::open(path);
    for (const auto& r : {from_memory, from_file}) {
      EXPECT_TRUE(r->tiles().empty()) << to_string(e);
      ASSERT_NO_THROW(r->verify(cut.codec.open)) << to_string(e);
      PackEvaluator ev(r);
      EXPECT_EQ(packtest::first_difference(ev, h), "") << to_string(e);
    }
    std::filesystem::remove(path);
  }
}

}  // namespace
}  // namespace st
