// Deep OpenEXR out and in: visibility functions survive the round trip (coloured and
// monochrome), and files that are not our deep EXRs are refused with a FormatError.
#include "tiles/bake/deep_exr.hpp"

#include <gtest/gtest.h>

#include "common/error.hpp"
#include "tiles/bake/exr_io.hpp"

namespace st {
namespace {

std::string test_tmp_path(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/" + name; }

TEST(DeepExr, RoundTripKeepsEveryFunction) {
  for (const char* spec : {"procedural:forest,trees=2,leaves=60,size=8,translucency=0.6",
                           "procedural:smoke,res=8"}) {
    const Scene s = make_procedural(spec);
    const LightSpace light =
        LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=55"), s.bounds());
    const DeepSampler sampler(s, light);
    DeepSampleOptions o;
    o.samples_per_side = 2;
    o.epsilon = 0.01;
    const DeepRegion in = sampler.trace({3, 1, 2, 6, 5}, o);
    const std::string path = test_tmp_path("deep_roundtrip.exr");
    write_deep_exr(path, in, o.epsilon);
    const DeepRegion back = read_deep_exr(path);
    EXPECT_EQ(back.region.level, 3u);
    EXPECT_EQ(back.region.x0, 1u);
    EXPECT_EQ(back.region.y0, 2u);
    ASSERT_EQ(back.functions.size(), in.functions.size());
    size_t non_empty = 0;
    for (size_t i = 0; i < in.functions.size(); ++i) {
      EXPECT_LE(max_difference(in.functions[i], back.functions[i]), 1e-5) << spec << " " << i;
      non_empty += !in.functions[i].vertices.empty();
    }
    EXPECT_GT(non_empty, 0u) << spec;
    // OpenEXR's own compositing of the monochrome file gives 1 - V behind everything.
    if (in.functions[0].monochrome && back.functions[0].monochrome) {
      const std::vector<float> alpha = composite_deep_exr_alpha(path);
      ASSERT_EQ(alpha.size(), in.functions.size());
      float most = 0;
      for (size_t i = 0; i < alpha.size(); ++i) {
        EXPECT_NEAR(alpha[i], 1 - in.functions[i].eval(2.0f)[0], 1e-4) << spec << " " << i;
        most = std::max(most, alpha[i]);
      }
      EXPECT_GT(most, 0.05f) << spec;
    }
  }
}

TEST(DeepExr, RefusesWhatIsNotADeepShadowExr) {
  IntervalTile t;
  t.level = 1, t.width = 2, t.height = 2;
  t.data.assign(4, Interval{0.5f, 0.5f});
  const std::string flat = test_tmp_path("not_deep.exr");
  write_interval_exr(flat, t);
  EXPECT_THROW(read_deep_exr(flat), FormatError);
  EXPECT_THROW(read_deep_exr(test_tmp_path("missing_deep.exr")), FormatError);
  DeepRegion bad;
  bad.region = {1, 0, 0, 2, 2};
  EXPECT_THROW(write_deep_exr(test_tmp_path("bad.exr"), bad), Error);  // no functions
}

}  // namespace
}  // namespace st
