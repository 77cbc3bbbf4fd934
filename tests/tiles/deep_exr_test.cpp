// Deep OpenEXR out and in: visibility functions survive the round trip (coloured and
// monochrome), and files that are not our deep EXRs are refused with a FormatError.
#include "tiles/bake/deep_exr.hpp"

#include <gtest/gtest.h>

#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfHeader.h>
#include <ImfPartType.h>
#include <half.h>

#include <random>

#include "common/error.hpp"
#include "tiles/bake/deep_build.hpp"
#include "image/exr_io.hpp"
#include "tiles/core/deep_format.hpp"
#include "tiles/core/deep_map.hpp"

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

DeepMap map_of(const DeepMapBuild& b) {
  DeepMap m(b.level, b.side_bits);
  for (const DeepTileBytes& t : b.tiles) m.add_tile(t.tx, t.ty, t.bytes);
  return m;
}

// `build --deep-from`: a whole level exported, read back and cut into tiles answers the
// lookups the sampled build answers (the file keeps the compressed functions up to
// float rounding of the products); what does not hold a whole level in [0, 1] is refused.
TEST(DeepExr, TilesFromAnExportedFileAnswerAsSampling) {
  const Scene s = make_procedural("procedural:forest,trees=2,leaves=60,size=8,translucency=0.6");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=55"), s.bounds());
  const DeepSampler sampler(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 2;
  o.epsilon = 0.02;
  const DeepMapBuild sampled = build_deep_tiles(sampler, 4, 2, o);
  DeepExrInfo info;
  info.epsilon = o.epsilon;
  info.samples_per_side = 2;
  info.light = light.spec().to_string();
  const std::string path = test_tmp_path("deep_whole.exr");
  write_deep_exr(path, sampler.trace({4, 0, 0, 16, 16}, o), info);
  DeepExrInfo back_info;
  const DeepRegion back = read_deep_exr(path, &back_info);
  EXPECT_EQ(back_info.epsilon, 0.02);
  EXPECT_EQ(back_info.samples_per_side, 2u);
  EXPECT_EQ(back_info.light, info.light);
  EXPECT_FALSE(back_info.foreign);
  const DeepMapBuild from_file = deep_tiles_from_functions(back, 2, -1, back_info.epsilon);
  ASSERT_EQ(from_file.tiles.size(), sampled.tiles.size());
  EXPECT_GT(sampled.tiles.size(), 0u);
  const DeepMap a = map_of(sampled), b = map_of(from_file);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u01(0, 1);
  int partial = 0;
  for (int i = 0; i < 2000; ++i) {
    const double u = u01(rng), v = u01(rng);
    const auto z = float(u01(rng));
    const auto ta = a.transmittance(u, v, z), tb = b.transmittance(u, v, z);
    const auto fa = a.filtered(u, v, z, 0.1), fb = b.filtered(u, v, z, 0.1);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(ta[c], tb[c], 1e-4) << i;
      EXPECT_NEAR(fa[c], fb[c], 1e-4) << i;
    }
    partial += ta[0] < 1;
  }
  EXPECT_GT(partial, 20);
  // Recompressed with another bound: within it of the file's functions.
  const DeepMapBuild recompressed = deep_tiles_from_functions(back, 2, 0.05, 0.07);  // the map views its bytes
  const DeepMap c = map_of(recompressed);
  for (int i = 0; i < 500; ++i) {
    const double u = u01(rng), v = u01(rng);
    const auto z = float(u01(rng));
    EXPECT_NEAR(c.transmittance(u, v, z)[1], b.transmittance(u, v, z)[1], 0.05 + 2 * deep::kQuantisation) << i;
  }
  // A part of a level, or depths outside [0, 1]: one clear error.
  EXPECT_THROW(deep_tiles_from_functions(sampler.trace({4, 0, 0, 8, 16}, o), 2, -1, 0.02), Error);
  DeepRegion far = back;
  for (VisibilityFunction& f : far.functions)
    for (VisVertex& vx : f.vertices) vx.depth += 2;
  try {
    deep_tiles_from_functions(far, 2, -1, 0.02);
    ADD_FAILURE() << "depths outside [0, 1] accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("outside [0, 1]"), std::string::npos) << e.what();
  }
  EXPECT_THROW(read_deep_exr(path, nullptr, 255), FormatError);  // over max_texels
}

// Another tool's deep image: no shadowtile attributes, HALF alpha, no ZBack (point
// samples). Texel 5 holds two samples of alpha 0.5 at depths 0.3 and 0.6.
void write_foreign(const std::string& path, int w, int h) {
  Imf::Header hd(w, h);
  hd.setType(Imf::DEEPSCANLINE);
  hd.compression() = Imf::ZIPS_COMPRESSION;
  hd.channels().insert("Z", Imf::Channel(Imf::FLOAT));
  hd.channels().insert("A", Imf::Channel(Imf::HALF));
  std::vector<unsigned> counts(size_t(w) * h, 0);
  counts[5] = 2;
  float z[2] = {0.3f, 0.6f};
  Imath::half a[2] = {Imath::half(0.5f), Imath::half(0.5f)};
  std::vector<char*> zp(counts.size(), reinterpret_cast<char*>(z)), ap(counts.size(), reinterpret_cast<char*>(a));
  Imf::DeepFrameBuffer fb;
  fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), sizeof(unsigned),
                                       sizeof(unsigned) * size_t(w)));
  fb.insert("Z", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(zp.data()), sizeof(char*),
                                sizeof(char*) * size_t(w), sizeof(float)));
  fb.insert("A", Imf::DeepSlice(Imf::HALF, reinterpret_cast<char*>(ap.data()), sizeof(char*),
                                sizeof(char*) * size_t(w), sizeof(Imath::half)));
  Imf::DeepScanLineOutputFile out(path.c_str(), hd);
  out.setFrameBuffer(fb);
  out.writePixels(h);
}

TEST(DeepExr, ReadsAnotherToolsTidyDeepImageOfAWholeMap) {
  const std::string path = test_tmp_path("foreign_deep.exr");
  write_foreign(path, 4, 4);
  DeepExrInfo info;
  const DeepRegion r = read_deep_exr(path, &info);
  EXPECT_TRUE(info.foreign);
  EXPECT_LT(info.epsilon, 0);
  EXPECT_EQ(r.region.level, 2u);
  ASSERT_EQ(r.functions.size(), 16u);
  const VisibilityFunction& f = r.functions[5];
  EXPECT_EQ(f.eval(0.3f)[0], 1.0f);
  EXPECT_EQ(f.eval_after(0.3f)[0], 0.5f);
  EXPECT_EQ(f.eval(1.0f)[0], 0.25f);
  EXPECT_TRUE(r.functions[4].vertices.empty());
  write_foreign(path, 4, 2);  // not a whole map: refused
  EXPECT_THROW(read_deep_exr(path), FormatError);
}

}  // namespace
}  // namespace st
