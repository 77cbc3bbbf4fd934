// The pack header's reserved deep_shadow feature (PACK.md): no pack carries deep tiles
// yet, so the writer refuses the bit and a reader refuses a pack that claims it (CRC
// fixed), in one line, instead of serving it without its partial occluders.
#include <gtest/gtest.h>

#include <fstream>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/build/mh_build.hpp"
#include "tiles/build/pack_writer.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace {

TEST(DeepPackFeature, WriterRefusesAndReaderRefusesTheReservedBit) {
  const IntervalTile field = fields::city_field(16, 2);
  CutParams cut;
  cut.map_level = 4;
  cut.skip_level = 2;
  cut.tile_bytes = 256;
  cut.codec = TileCodec::of(packtest::available_encodings().at(0));
  const LightSpace light =
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{0, 0, 0}, {1, 1, 1}});
  PackParams pp = PackParams::from(light, cut);
  pp.build_params = {{"scene", "deep-feature"}};
  const std::string path = packtest::temp_path("deep_feature.pack");
  pp.features = kFeatureDeepShadow;
  EXPECT_THROW(write_pack(path, build_hierarchy(field), cut, pp), Error);
  pp.features = 0;
  write_pack(path, build_hierarchy(field), cut, pp);
  std::ifstream f(path, std::ios::binary);
  std::vector<uint8_t> bytes(std::istreambuf_iterator<char>(f), {});
  PackReader::open_memory(bytes, "deep_feature.pack");
  store_le<uint32_t>(bytes.data() + 20, load_le<uint32_t>(bytes, 20) | kFeatureDeepShadow);
  store_le<uint32_t>(bytes.data() + 252, crc32_of({bytes.data(), 252}));
  try {
    PackReader::open_memory(bytes, "deep_feature.pack");
    ADD_FAILURE() << "a pack claiming deep_shadow was opened";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("deep_shadow"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace st
