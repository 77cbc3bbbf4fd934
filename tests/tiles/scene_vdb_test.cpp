// Volumes from scene specs (scene_volumes.hpp): OpenVDB density grids and the fog layer.
// Each volume's deep map is checked against the analytic transmittance exp(-sigma * rho *
// length) within the sampler's and the compression's bounds, and every hostile .vdb
// (truncated, foreign, flipped bytes, a bomb of a node count, without the grid, another
// value type, a level set, a rotated or frustum transform, a huge box, bad values) gives
// one st::Error line.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "common/error.hpp"
#include "tiles/bake/deep_build.hpp"
#include "scene/scene_volumes.hpp"
#include "tiles/core/deep_map.hpp"
#ifdef SHADOWTILE_HAVE_OPENVDB
#include "tests/tiles/vdb_fixtures.hpp"
#endif

namespace st {
namespace scene_vdb_test {

// The error of a load, which must be one line naming what it is about.
std::string load_error(const std::string& spec, const SceneOptions& so = {}) {
  try {
    load_scene(spec, so);
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    return m;
  }
  ADD_FAILURE() << spec << " loaded";
  return {};
}

// The deep map of `s` at `level` (2 x 2 samples per texel, epsilon 0.01).
struct Deep {
  LightSpace light;
  DeepMapBuild build;  // the map views its tiles' bytes
  DeepMap map;
  static constexpr double kEpsilon = 0.01;
  Deep(const Scene& s, const std::string& light_spec, uint32_t level)
      : light(LightSpace::fit(LightSpec::parse(light_spec), s.bounds())), map(level, 3) {
    DeepSampleOptions o;
    o.samples_per_side = 2;
    o.epsilon = kEpsilon;
    build = build_deep_tiles(DeepSampler(s, light), level, 3, o);
    for (const DeepTileBytes& t : build.tiles) map.add_tile(t.tx, t.ty, t.bytes);
  }
  // Transmittance behind world point p (at the far end of its light ray).
  float behind(const Vec3d& p) const {
    const LightPoint q = light.to_light(p);
    return map.transmittance(q.u, q.v, 0.9999f)[0];
  }
  float before(const Vec3d& p) const {
    const LightPoint q = light.to_light(p);
    return map.transmittance(q.u, q.v, 0.0f)[0];
  }
  // The length of the light ray per unit of height it descends.
  double per_height() const { return length(light.forward()) / std::fabs(light.forward().y); }
};

// Height fog over a plane: homogeneous and exponential, against the closed forms.
TEST(SceneFog, GroundTransmittanceMatchesTheAnalyticIntegral) {
  const char* sun = "sun:azimuth=30,elevation=50";
  {
    const Scene s = load_scene("procedural:plane,size=20+fog:density=0.1,top=5");
    ASSERT_EQ(s.volumes.size(), 1u);
    EXPECT_EQ(s.volumes[0].bounds.lo.y, 0.0);
    EXPECT_EQ(s.volumes[0].bounds.hi.y, 5.0);
    const Deep d(s, sun, 5);
    const double want = std::exp(-0.1 * 5 * d.per_height());
    for (double x : {-3.0, 0.0, 2.5}) {
      EXPECT_NEAR(d.behind({x, 0, 1}), want, Deep::kEpsilon + 2e-3) << x;
      EXPECT_NEAR(d.before({x, 0, 1}), 1.0, 1e-4);
    }
  }
  {
    const Scene s = load_scene("procedural:plane,size=20+fog:density=0.3,height=2,top=10");
    const Deep d(s, sun, 5);
    // tau = rho0 H (1 - exp(-(top - bottom) / H)) per unit of height descended.
    const double want = std::exp(-0.3 * 2 * (1 - std::exp(-5.0)) * d.per_height());
    EXPECT_NEAR(d.behind({1, 0, -1}), want, Deep::kEpsilon + 2e-3);
  }
  EXPECT_NE(load_error("procedural:plane+fog:height=2").find("missing key 'density'"), std::string::npos);
  EXPECT_NE(load_error("procedural:plane+fog:density=1").find("layer is empty"), std::string::npos);
  EXPECT_NE(load_error("procedural:plane+fog:density=1,top=2,colour=3").find("unknown key 'colour'"),
            std::string::npos);
  EXPECT_NE(load_error("procedural:plane+cloud:x=1").find("unknown name"), std::string::npos);
}

#ifdef SHADOWTILE_HAVE_OPENVDB

std::string tmp(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/" + name; }

TEST(SceneVdb, BoxAndBallTransmittanceMatchExpOfSigmaLength) {
  // A 4 x 2 x 4 box of density 0.6 (16 x 8 x 16 voxels of 0.25) with sigma 0.5 (spec key).
  const std::string box = tmp("box.vdb");
  vdbtest::write(box, {vdbtest::box_grid(16, 8, 16, 0.25, {0, 1, 0}, 0.6f)});
  const Scene s = load_scene("procedural:plane,size=8+vdb:" + box + ",sigma=0.5");
  ASSERT_EQ(s.volumes.size(), 1u);
  const Volume& v = s.volumes[0];
  EXPECT_EQ(v.bounds.lo, (Vec3d{0, 1, 0}));
  EXPECT_EQ(v.bounds.hi, (Vec3d{4, 3, 4}));
  EXPECT_EQ(v.nx * v.ny * v.nz, 16u * 8u * 16u);
  const Deep d(s, "sun:azimuth=20,elevation=60", 6);
  // Rays through the box's top and bottom faces cross 2 / sin(elevation) of it.
  const double want = std::exp(-0.5 * 0.6 * 2 * d.per_height());
  for (double x : {1.8, 2.0, 2.3})
    for (double z : {1.7, 2.1}) {
      EXPECT_NEAR(d.behind({x, 1, z}), want, Deep::kEpsilon + 1e-3) << x << "," << z;
      EXPECT_NEAR(d.before({x, 1, z}), 1.0f, 1e-4);
    }

  // A ball of radius 1.5 (voxels of 0.1, density 0.5, sigma 1) through its centre: the
  // voxelised surface (where the trilinear density crosses half) lies within half a voxel
  // diagonal of the sphere, at each end of the chord.
  const std::string ball = tmp("ball.vdb");
  vdbtest::write(ball, {vdbtest::ball_grid(1.5, {0, 2, 0}, 0.1, 0.5f)});
  const Scene b = load_scene(ball);
  const Deep db(b, "sun:azimuth=20,elevation=60", 6);
  const double texel = db.light.extent_uv() / 64;
  const double chord = 2 * std::sqrt(1.5 * 1.5 - 2.25 * texel * texel);  // a ray within 1.5 texels of the centre
  EXPECT_NEAR(db.behind({0, 2, 0}), std::exp(-0.5 * 2 * 1.5), Deep::kEpsilon + 0.5 * (std::sqrt(3.0) * 0.1 + (3 - chord)));
}

TEST(SceneVdb, TransformsGridOptionsAndUpAxis) {
  // Two grids in one file; the second one named, scaled, with a negative x voxel size.
  const std::string path = tmp("two.vdb");
  auto a = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f);
  auto c = openvdb::FloatGrid::create(0.0f);
  c->setName("smoke");
  auto xf = openvdb::math::Transform::createLinearTransform(openvdb::math::Mat4d(
      -0.5, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 10.0, 0.0, 0.0, 1.0));
  c->setTransform(xf);
  c->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);  // world x in [9.75, 10.25]
  c->tree().setValue(openvdb::Coord(3, 0, 0), 4.0f);  // world x in [8.25, 8.75]
  vdbtest::write(path, {a, c});
  const Volume v = load_scene("vdb:" + path + ",grid=smoke,scale=2").volumes.at(0);
  EXPECT_EQ(v.name, path + ":smoke");
  EXPECT_EQ(v.bounds.lo, (Vec3d{8.25, -0.25, -0.25}));
  EXPECT_EQ(v.bounds.hi, (Vec3d{10.25, 0.25, 0.25}));
  ASSERT_EQ(v.nx, 4u);
  EXPECT_EQ(v.density, (std::vector<float>{8, 0, 0, 2}));  // x increases with world x
  EXPECT_FLOAT_EQ(v.density_at({8.5, 0, 0}), 8.0f);

  // Z-up files turn like meshes: (x, y, z) -> (x, z, -y).
  const std::string tall = tmp("tall.vdb");
  vdbtest::write(tall, {vdbtest::box_grid(1, 1, 3, 1.0, {0, 0, 0}, 1.0f)});
  SceneOptions z;
  z.up = UpAxis::z;
  const Volume t = load_scene(tall, z).volumes.at(0);
  EXPECT_EQ(t.bounds.lo, (Vec3d{0, 0, -1}));
  EXPECT_EQ(t.bounds.hi, (Vec3d{1, 3, 0}));
  EXPECT_EQ(t.ny, 3u);
  // The same scene twice hashes alike; a different scale does not.
  EXPECT_EQ(load_scene(tall).content_hash(), load_scene("vdb:" + tall).content_hash());
  EXPECT_NE(load_scene(tall).content_hash(), load_scene("vdb:" + tall + ",scale=2").content_hash());
}

TEST(SceneVdb, HostileFilesGiveOneClearLine) {
  const std::string good = tmp("good.vdb");
  vdbtest::write(good, {vdbtest::box_grid(20, 20, 20, 0.1, {0, 0, 0}, 1.0f)});
  const auto size = std::filesystem::file_size(good);
  std::ifstream in(good, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Truncated anywhere (header, descriptors, metadata, transform, topology, values).
  for (size_t keep : {size_t(0), size_t(7), size_t(40), size_t(200), size / 2, size - 9, size - 1}) {
    const std::string cut = tmp("cut_" + std::to_string(keep) + ".vdb");
    std::ofstream(cut, std::ios::binary).write(bytes.data(), std::streamsize(keep));
    EXPECT_NE(load_error(cut).find(cut), std::string::npos) << keep;
  }
  // Every byte of the header and the grid's descriptor flipped: an error or the same box,
  // never a crash (values are checked, so garbage densities cannot pass).
  for (size_t i = 0; i < std::min<size_t>(size, 300); i += 3) {
    std::string bad = bytes;
    bad[i] = char(bad[i] ^ 0x5a);
    const std::string p = tmp("flip.vdb");
    std::ofstream(p, std::ios::binary | std::ios::trunc).write(bad.data(), std::streamsize(bad.size()));
    try {
      const Scene s = load_scene(p);
      EXPECT_EQ(s.volumes.at(0).density.size(), 8000u) << i;
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << i;
    }
  }
  // A root child count past what the topology's bytes can hold (a memory bomb for a
  // reader that trusts it): after the map's name, its 144 bytes of values, the buffer
  // count and the background.
  {
    const size_t map = bytes.find("UniformScaleTranslateMap");
    ASSERT_NE(map, std::string::npos);
    std::string bad = bytes;
    const uint32_t children = 0x7fffffff;
    std::memcpy(&bad[map + 24 + 144 + 8 + 4], &children, 4);
    const std::string p = tmp("bomb.vdb");
    std::ofstream(p, std::ios::binary).write(bad.data(), std::streamsize(bad.size()));
    EXPECT_NE(load_error(p).find("corrupt topology (0 root tiles and 2147483647 root children"), std::string::npos);
  }
  const std::string text = tmp("text.vdb");
  std::ofstream(text) << "not a vdb file\n";
  EXPECT_NE(load_error(text).find("not a VDB file"), std::string::npos);
  EXPECT_NE(load_error(tmp("absent.vdb")).find("not found"), std::string::npos);

  // No such grid: the file's grids are listed.
  EXPECT_NE(load_error("vdb:" + good + ",grid=temperature").find("no such grid in the file (grids: density)"),
            std::string::npos);
  // Other value types, a level set.
  const std::string other = tmp("other.vdb");
  auto ints = openvdb::Int32Grid::create(0);
  ints->setName("density");
  ints->tree().setValue(openvdb::Coord(1, 2, 3), 7);
  auto vecs = openvdb::Vec3SGrid::create();
  vecs->setName("vel");
  vecs->tree().setValue(openvdb::Coord(0), openvdb::Vec3s(1, 0, 0));
  auto ls = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f, "surface");
  ls->setGridClass(openvdb::GRID_LEVEL_SET);
  vdbtest::write(other, {ints, vecs, ls});
  EXPECT_NE(load_error(other).find("is a grid of int32, not float"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + other + ",grid=vel").find("not float"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + other + ",grid=surface").find("level set"), std::string::npos);
  // Rotated and frustum transforms.
  const std::string turned = tmp("turned.vdb");
  auto r = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f);
  r->transform().postRotate(0.3, openvdb::math::Y_AXIS);
  auto f = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f, "frustum");
  f->setTransform(openvdb::math::Transform::createFrustumTransform(
      openvdb::BBoxd(openvdb::Vec3d(0), openvdb::Vec3d(10)), 0.5, 5.0));
  vdbtest::write(turned, {r, f});
  EXPECT_NE(load_error(turned).find("rotates or shears"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + turned + ",grid=frustum").find("non-linear"), std::string::npos);
  // Huge: two voxels 4000 apart are a dense box of 6.4e10 voxels, refused from the file's
  // statistics and, without them, from the grid read; a budget set lower refuses a box.
  for (bool stats : {true, false}) {
    const std::string huge = tmp(stats ? "huge.vdb" : "huge_nostats.vdb");
    auto h = openvdb::FloatGrid::create(0.0f);
    h->setName("density");
    h->tree().setValue(openvdb::Coord(0), 1.0f);
    h->tree().setValue(openvdb::Coord(4000), 1.0f);
    vdbtest::write(huge, {h}, stats);
    EXPECT_NE(load_error(huge).find(stats ? "(from the file's statistics) holds 64048012001 voxels, over the dense budget"
                                          : "(of the grid read) holds 64048012001 voxels"),
              std::string::npos);
  }
  EXPECT_NE(load_error("vdb:" + good + ",max_voxels=7999").find("over the dense budget of 7999"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + good + ",max_voxels=0").find("not an integer in [1, 1073741824]"), std::string::npos);
  // Bad values.
  const std::string neg = tmp("neg.vdb");
  auto n = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f);
  n->tree().setValue(openvdb::Coord(1, 0, 1), -0.5f);
  auto nan = vdbtest::box_grid(2, 2, 2, 1.0, {0, 0, 0}, 1.0f, "nan");
  nan->tree().setValue(openvdb::Coord(0, 1, 0), NAN);
  auto none = openvdb::FloatGrid::create(0.0f);
  none->setName("empty");
  vdbtest::write(neg, {n, nan, none});
  EXPECT_NE(load_error(neg).find("voxel (1, 0, 1) has density -0.5"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + neg + ",grid=nan").find("not finite"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + neg + ",grid=empty").find("no active voxels"), std::string::npos);
  EXPECT_NE(load_error("vdb:" + neg + ",colour=1").find("unknown key 'colour'"), std::string::npos);
  EXPECT_NE(load_error("vdb:,grid=x").find("missing file"), std::string::npos);
}

#else

TEST(SceneVdb, BuiltWithoutOpenVdbSaysSo) {
  EXPECT_FALSE(vdb_supported());
  EXPECT_NE(load_error("vdb:x.vdb").find("without OpenVDB"), std::string::npos);
}

#endif

}  // namespace scene_vdb_test
}  // namespace st
