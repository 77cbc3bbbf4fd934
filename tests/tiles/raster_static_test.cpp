// The rasterizer under the static-geometry interval (TraceMode::static_bounds, voxel
// paper §6.1; tiles/bake/raster_bounds.hpp): equal to the Embree tracer on every texel
// (open soups, the open and the closed hazard town, the city, a grazing sun, a grid of
// open OBJ buildings), whatever the skip; the open layers its region proofs find lie
// inside every texel's static interval; and packs built top-down over proven regions are
// lossless on every texel against the fully traced static intervals. Also the grid scene
// form (scene_grid.hpp) that tiles asset files across a ground.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>

#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene_grid.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace raster_static_test {

namespace fs = std::filesystem;

bool same_bits(const Interval& a, const Interval& b) {
  return std::memcmp(&a.lo, &b.lo, sizeof(float)) == 0 && std::memcmp(&a.hi, &b.hi, sizeof(float)) == 0;
}

// An open OBJ "building" (roofless walls with a gable roof, no floor), written once.
std::string building_obj() {
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/static_building.obj";
  std::ofstream f(path);
  f << "o building\n"
       "v 0 0 0\nv 4 0 0\nv 4 0 3\nv 0 0 3\n"   // 1-4 foot
       "v 0 5 0\nv 4 5 0\nv 4 5 3\nv 0 5 3\n"   // 5-8 eaves
       "v 0 7 1.5\nv 4 7 1.5\n"                 // 9-10 ridge
       "f 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
       "f 5 6 10\nf 5 10 9\nf 7 8 9\nf 7 9 10\nf 5 9 8\nf 6 7 10\n";
  return path;
}

struct StaticCase {
  std::string name;
  Scene scene;
  const char* sun;
};

std::vector<StaticCase> cases() {
  std::vector<StaticCase> v;
  v.push_back({"soup", make_procedural("procedural:soup,count=300,size=120"), "sun:azimuth=30,elevation=50"});
  v.push_back({"open_town", test::all_open(test::hazard_town()), "sun:azimuth=30,elevation=50"});
  v.push_back({"town", test::hazard_town(), "sun:azimuth=150,elevation=35"});
  v.push_back({"city", make_procedural("procedural:city,size=2"), "sun:azimuth=30,elevation=50"});
  v.push_back({"grazing_open_town", test::all_open(test::hazard_town()), "sun:azimuth=77,elevation=0.5"});
  v.push_back({"grid", load_scene("grid:" + building_obj() + ",n=3,gap=0.5,seed=3"), "sun:azimuth=200,elevation=60"});
  // Real tool exports (Debian's assimp-testmodels, scripts/deps), open meshes.
  const std::string teapots = "/usr/share/assimp/models/Collada/teapots.DAE";
  if (fs::exists(teapots)) v.push_back({"teapots", load_scene(teapots), "sun:azimuth=30,elevation=50"});
  return v;
}

TEST(RasterStatic, EqualsTheTracerOnEveryTexelWhateverTheSkip) {
  const uint32_t L = fields::small_test_scale() ? 6 : 8, side = 1u << L;
  uint64_t widened = 0;
  for (const StaticCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    const TraceRegion all{L, 0, 0, side, side};
    const IntervalTile truth = DepthBoundsTracer(c.scene, light).trace(all, TraceMode::static_bounds);
    const IntervalTile plain = RasterBounds(c.scene, light).trace(all);
    for (RasterSkip skip : {RasterSkip::off, RasterSkip::exact}) {
      const RasterBounds raster(c.scene, light, skip, TraceMode::static_bounds);
      EXPECT_EQ(raster.mode(), TraceMode::static_bounds);
      const IntervalTile r = raster.trace(all);
      uint64_t differ = 0;
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x)
          if (!same_bits(r.at(x, y), truth.at(x, y)) && ++differ <= 3)
            ADD_FAILURE() << c.name << " skip " << to_string(skip) << " texel " << x << "," << y << ": raster ["
                          << r.at(x, y).lo << ", " << r.at(x, y).hi << "] tracer [" << truth.at(x, y).lo << ", "
                          << truth.at(x, y).hi << "]";
      EXPECT_EQ(differ, 0u) << c.name;
    }
    // The one-texel reference agrees on a lattice of texels.
    const RasterBounds raster(c.scene, light, RasterSkip::exact, TraceMode::static_bounds);
    for (uint32_t y = 1; y < side; y += 7)
      for (uint32_t x = 2; x < side; x += 5)
        ASSERT_TRUE(same_bits(raster.brute_force_texel(L, x, y), truth.at(x, y))) << c.name << " " << x << "," << y;
    for (size_t k = 0; k < truth.data.size(); ++k) widened += truth.data[k].hi > plain.data[k].hi;
  }
  EXPECT_GT(widened, 0u) << "the static rule never widened an interval";
  EXPECT_THROW(RasterBounds(cases()[0].scene,
                            LightSpace::fit(LightSpec::parse(cases()[0].sun), cases()[0].scene.bounds()),
                            RasterSkip::exact, TraceMode::first_hit),
               Error);
}

// Every aligned square of every size (down to 4 texels) whose corners prove an interval
// under the static rule: it lies inside every texel's static interval; open layers are
// proven (not only empty regions).
// Deep levels, where a texel is 2^-20 of the map: small squares around scene vertices
// (where edges meet, coverage is decided by the definition itself) at levels 14 and 20,
// binned and gathered as a 1M^2 build does, equal the tracer bit for bit.
TEST(RasterStatic, EqualsTheTracerNearVerticesAtDeepLevels) {
  uint64_t texels = 0, hit = 0;
  for (const StaticCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    const DepthBoundsTracer tracer(c.scene, light);
    const RasterBounds off(c.scene, light, RasterSkip::off, TraceMode::static_bounds);
    const RasterBounds exact(c.scene, light, RasterSkip::exact, TraceMode::static_bounds);
    const size_t nv = c.scene.vertices.size(), step = std::max<size_t>(1, nv / 6);
    for (size_t k = 0; k < nv; k += step)
      for (const uint32_t L : {14u, 20u}) {
        constexpr uint32_t kSide = 16;
        const LightPoint p = light.to_light(c.scene.vertices[k]);
        const double S = std::ldexp(1.0, int(L)), hi = S - kSide;
        const TraceRegion r{L, uint64_t(std::clamp(p.u * S - kSide / 2, 0.0, hi)),
                            uint64_t(std::clamp(p.v * S - kSide / 2, 0.0, hi)), kSide, kSide};
        const IntervalTile truth = tracer.trace(r, TraceMode::static_bounds);
        const IntervalTile a = off.trace(r), b = exact.trace(r);
        for (uint32_t y = 0; y < kSide; ++y)
          for (uint32_t x = 0; x < kSide; ++x) {
            ++texels;
            hit += truth.at(x, y).lo < kLitDepth;
            ASSERT_TRUE(same_bits(a.at(x, y), truth.at(x, y)) && same_bits(b.at(x, y), truth.at(x, y)))
                << c.name << " level " << L << " texel " << r.x0 + x << "," << r.y0 + y << ": raster off ["
                << a.at(x, y).lo << ", " << a.at(x, y).hi << "] exact [" << b.at(x, y).lo << ", " << b.at(x, y).hi
                << "] tracer [" << truth.at(x, y).lo << ", " << truth.at(x, y).hi << "]";
          }
      }
  }
  EXPECT_GT(hit, texels / 4) << "the squares around vertices should mostly hit surfaces";
}

TEST(RasterStatic, ProvenRegionsLieInsideEveryTexelsStaticInterval) {
  const uint32_t L = fields::small_test_scale() ? 6 : 8, side = 1u << L;
  uint64_t proven_open = 0;
  for (const StaticCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    const RasterBounds regions(c.scene, light, RasterSkip::regions, TraceMode::static_bounds);
    const IntervalTile truth =
        RasterBounds(c.scene, light, RasterSkip::off, TraceMode::static_bounds).trace({L, 0, 0, side, side});
    for (uint32_t s = side; s >= 4; s /= 2)
      for (uint32_t y0 = 0; y0 < side; y0 += s)
        for (uint32_t x0 = 0; x0 < side; x0 += s) {
          const std::optional<Interval> iv = regions.region_interval(L, x0, y0, s);
          if (!iv) continue;
          bool open = false;
          for (uint32_t y = y0; y < y0 + s; ++y)
            for (uint32_t x = x0; x < x0 + s; ++x) {
              const Interval t = truth.at(x, y);
              ASSERT_TRUE(t.lo <= iv->lo && iv->lo <= iv->hi && iv->hi <= t.hi)
                  << c.name << " region " << x0 << "," << y0 << " side " << s << " texel " << x << "," << y
                  << ": proven [" << iv->lo << ", " << iv->hi << "] true [" << t.lo << ", " << t.hi << "]";
              open |= t.lo < kLitDepth;
            }
          if (open && !c.scene.any_closed()) proven_open += uint64_t(s) * s;
        }
  }
  EXPECT_GT(proven_open, 0u) << "no open layer was ever proven";
}

// Packs built top-down over proven regions under the static rule are lossless on every
// texel against the fully traced static intervals, and record both rules.
TEST(RasterStatic, RegionsPackIsLosslessOnEveryTexel) {
  const uint32_t L = fields::small_test_scale() ? 8 : 9;
  uint64_t in_regions = 0;
  int k = 0;
  for (const StaticCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    MapBuildOptions o;
    o.map_level = L;
    o.skip_level = L - 7;
    o.encoding = k % 2 ? Encoding::mh : Encoding::dagmh;
    o.intervals = IntervalRule::static_geometry;
    o.raster_skip = RasterSkip::regions;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/static_regions_" + std::to_string(k++) + ".pack";
    const MapBuildReport rep = build_map(c.scene, light, o, path);
    EXPECT_EQ(rep.builder, "raster") << "auto picks the rasterizer for a sun under the static rule";
    EXPECT_EQ(rep.texels_in_regions + rep.texels_traced, uint64_t(1) << (2 * L)) << c.name;
    in_regions += rep.texels_in_regions;
    const IntervalTile truth = DepthBoundsTracer(c.scene, light).trace({L, 0, 0, 1u << L, 1u << L},
                                                                       TraceMode::static_bounds);
    std::shared_ptr<const PackReader> reader = PackReader::open(path);
    int recorded = 0;
    for (const auto& [key, v] : reader->params())
      recorded += (key == "intervals" && v == "static") + (key == "intervals_narrowed" && v == "yes");
    EXPECT_EQ(recorded, 2) << c.name;
    PackEvaluator eval(reader);
    EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "")
        << c.name;
    fs::remove(path);
  }
  EXPECT_GT(in_regions, 0u);
}

TEST(GridScene, TilesTheFileAcrossAGround) {
  const std::string obj = building_obj();
  const Scene one = load_scene(obj);
  const Scene g = load_scene("grid:" + obj + "|" + obj + ",n=4,gap=1,seed=9");
  EXPECT_EQ(g.triangles.size(), 16 * one.triangles.size() + 2);
  EXPECT_EQ(g.meshes.size(), 16 * one.meshes.size() + 1);
  EXPECT_EQ(g.meshes.back().name, "grid/ground");
  EXPECT_FALSE(g.any_closed());
  // Cells of side 2 x 4 (the largest extent, gap 1): the ground spans 32 x 32 at y = 0.
  const Aabb b = g.bounds();
  EXPECT_EQ(b.lo.x, 0);
  EXPECT_EQ(b.hi.x, 32);
  EXPECT_EQ(b.lo.y, 0);
  EXPECT_EQ(b.hi.y, 7);
  EXPECT_EQ(b.hi.z, 32);
  EXPECT_EQ(g.content_hash(), load_scene("grid:" + obj + "|" + obj + ",n=4,gap=1,seed=9").content_hash());
  EXPECT_NE(g.content_hash(), load_scene("grid:" + obj + ",n=4,gap=1,seed=9,rotate=no").content_hash());
  EXPECT_EQ(load_scene("grid:" + obj + ",n=2,ground=no").triangles.size(), 4 * one.triangles.size());
  // A closed box keeps its flag in every copy.
  const Scene boxes = load_scene("grid:/usr/share/assimp/models/OBJ/box.obj,n=2");
  if (!boxes.triangles.empty()) {
    EXPECT_EQ(boxes.closed_triangle_count(), boxes.triangles.size() - 2);
  }
}

TEST(GridScene, BadSpecsAreOneLineErrors) {
  const std::string obj = building_obj();
 for (const std::string& spec : std::vector<std::string>{
           "grid:", "grid:" + obj + ",n=0", "grid:" + obj + ",n=5000", "grid:" + obj + ",n=2.5",
        "grid:" + obj + ",gap=-1", "grid:" + obj + ",colour=red", "grid:" + obj + ",rotate=maybe",
        "grid:" + obj + "||" + obj, "grid:grid:" + obj, "grid:" + obj + ",n", "grid:/no/such/file.obj"}) {
    try {
      load_scene(spec);
      ADD_FAILURE() << spec << " was accepted";
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
  }
  SceneLimits tight;
  tight.max_triangles = 100;
  EXPECT_THROW(load_scene("grid:" + obj + ",n=4", SceneOptions{}, tight), Error);
}

}  // namespace raster_static_test
}  // namespace st
