// The client's public filtered lookup with the receiver's normal (Map::visibility_filtered
// with normals, receiver-plane depth bias) answers bit for bit what render's filtered path
// answers for the same receivers (map_visibility_filtered over the pack): a real open mesh
// (2CylinderEngine), the view's own receivers, PCF 3 and 5, no footprint and footprints
// of one to a few texels (two levels blended); on a map filled locally and on one served
// over loopback, single lookups and batches, and whole render views (render --server's
// filtered path). A missing package skips with the command.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <filesystem>

#include "app/public_map.hpp"
#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/core/camera.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st::client {
namespace receiver_plane_client_test {

namespace fs = std::filesystem;

// Every facing receiver's answer from `m` against render's; the number that were partly lit.
uint64_t compare_with_render(const Map& m, const PackEvaluator& pack, const LightSpace& light,
                             const std::vector<Receiver>& rec, const char* where) {
  const uint32_t L = pack.finest_level();
  uint64_t partial = 0;
  for (uint32_t side : {3u, 5u}) {
    std::vector<WorldPoint> points, normals;
    std::vector<float> footprints, want;
    for (const Receiver& r : rec) {
      if (!r.hit || r.n_dot_l <= 0) continue;
      const double texel = light.texel_size(r.pos, L);
      for (double scale : {0.0, 1.7, 4.3}) {
        const float fw = float(scale * texel);
        // render's footprint in finest texels, as the client derives it from fw.
        const float ft = fw > 0 ? float(double(fw) / texel) : 0.0f;
        const float v = map_visibility_filtered(pack, r, light, (side - 1) / 2, ft);
        const WorldPoint p{r.pos.x, r.pos.y, r.pos.z}, n{r.normal.x, r.normal.y, r.normal.z};
        EXPECT_EQ(std::bit_cast<uint32_t>(m.visibility_filtered(p, n, fw, side, r.closed)),
                  std::bit_cast<uint32_t>(v))
            << where << " side " << side << " footprint " << fw;
        if (r.closed) continue;  // the batch below is of open receivers
        points.push_back(p), normals.push_back(n), footprints.push_back(fw), want.push_back(v);
        partial += v > 0.0f && v < 1.0f;
      }
    }
    std::vector<float> got(points.size(), -1.0f);
    m.visibility_filtered(points, normals, footprints, got, side);
    for (size_t i = 0; i < got.size(); ++i)
      EXPECT_EQ(std::bit_cast<uint32_t>(got[i]), std::bit_cast<uint32_t>(want[i])) << where << " batch " << i;
  }
  return partial;
}

// `render --server`'s filtered path (RenderOptions::filtered through the public lookup,
// app/public_map.hpp) against render_view over the pack: every receiver's visibility bit
// for bit, PCF 3 and 5, with the camera's pixel angle (two levels blended) and a quarter
// of it. The count of partly lit receivers.
uint64_t compare_render_views(const Map& m, const PackEvaluator& pack, const SceneTracer& tracer,
                              const std::vector<Receiver>& rec, uint32_t width, uint32_t height, double pixel_angle,
                              const char* where) {
  uint64_t partial = 0;
  for (uint32_t radius : {1u, 2u})
    for (double angle : {pixel_angle, pixel_angle / 4}) {
      RenderOptions o;
      o.width = width, o.height = height, o.pcf_radius = radius, o.pixel_angle = angle;
      const RenderResult want = render_view(tracer, rec, pack, o);
      o.filtered = cli::filtered_lookups(m, 2 * radius + 1);
      const RenderResult got = render_view(tracer, rec, pack, o);
      for (size_t i = 0; i < rec.size(); ++i) {
        EXPECT_EQ(std::bit_cast<uint32_t>(got.visibility[i]), std::bit_cast<uint32_t>(want.visibility[i]))
            << where << " render view, radius " << radius << " pixel angle " << angle << " pixel " << i;
        partial += want.visibility[i] > 0.0f && want.visibility[i] < 1.0f;
      }
    }
  return partial;
}

TEST(ClientReceiverPlane, FilteredLookupsWithNormalsAnswerLikeRenderLocallyAndServed) {
  const std::string file = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  if (!fs::exists(file)) GTEST_SKIP() << file << " missing: run scripts/deps (Debian package assimp-testmodels)";
  const Scene scene = load_scene(file);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  MapBuildOptions o;
  o.map_level = 9;
  o.skip_level = 3;
  o.encoding = looptest::first_encoding();
  o.tile_bytes = 2048;  // many tiles: kernels cross tile borders
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/plane_client.pack";
  build_map(scene, light, o, path);
  const std::shared_ptr<const PackReader> reader = PackReader::open(path);
  const PackEvaluator pack(reader, 4096);
  const SceneTracer tracer(scene, light);
  const Camera cam = parse_camera("pos=400,300,400,target=0,0,0,fov=50");
  const std::vector<Receiver> rec = tracer.primary(cam, 40, 30);
  const double pixel_angle = 2 * std::tan(cam.fov_deg * 3.14159265358979323846 / 360) / 30;  // render --filter's
  const uint32_t L = o.map_level;

  // Locally: every tile delivered by hand.
  ClientOptions co = looptest::quick_options();
  co.cache_slots = uint32_t(reader->tiles().size()) + 8;
  co.want_capacity = co.cache_slots;
  const auto h = reader->header_bytes();
  const auto g = reader->grid_bytes();
  auto local = std::make_shared<RemoteMap>("plane_client", std::vector<uint8_t>(h.begin(), h.end()),
                                           std::vector<uint8_t>(g.begin(), g.end()), co, std::make_shared<Notifier>());
  // Every level the lookups read (footprints up to 4.3 texels: two levels up, kernels of
  // the blend one more): the tiles of levels L - 4 .. L.
  auto each_level = [&](auto&& fn) {
    bool all = true;
    for (uint32_t l = L - 4; l <= L; ++l) all = fn(l, uint64_t(1) << l) && all;
    return all;
  };
  for (uint32_t id = 1;; ++id) {
    each_level([&](uint32_t l, uint64_t s) { local->request_region(l, 0, 0, s, s, 1);
      return true;
    });
    std::vector<proto::TileRequest> want;
    local->take_wanted(1u << 20, id, want);
    if (want.empty()) break;
    for (const auto& t : want) {
      const TileIndexEntry e = *reader->find(t.tile_id);
      proto::TileMeta m;
      m.tile_id = t.tile_id, m.flags = proto::kTileFlagZlib, m.uncompressed_size = e.raw_size, m.payload_crc32 = e.crc;
      ASSERT_TRUE(local->tile_arrived(m, id, reader->read_stored(t.tile_id)));
    }
  }
  ASSERT_TRUE(each_level([&](uint32_t l, uint64_t s) { return local->region_resident(l, 0, 0, s, s); }));
  const uint64_t partial = compare_with_render(MapAccess::wrap(local), pack, light, rec, "local");
  EXPECT_GT(partial, 20u);  // kernels that straddle the plane were compared
  const uint64_t view_partial =
      compare_render_views(MapAccess::wrap(local), pack, tracer, rec, 40, 30, pixel_angle, "local");
  EXPECT_GT(view_partial, 20u);

  // Over the wire: the same pack served, every tile fetched first.
  looptest::TestServer srv = looptest::start_server({path});
  ClientOptions wo = looptest::quick_options();
  wo.cache_slots = co.cache_slots;
  Client c({"127.0.0.1", srv.port}, wo);
  Map m = c.open("plane_client");
  ASSERT_TRUE(looptest::wait_until([&] {
    return each_level([&](uint32_t l, uint64_t s) {
      m.request_region(l, 0, 0, s, s, 1);
      return m.region_resident(l, 0, 0, s, s);
    });
  }));
  EXPECT_EQ(compare_with_render(m, pack, light, rec, "served"), partial);
  EXPECT_EQ(compare_render_views(m, pack, tracer, rec, 40, 30, pixel_angle, "served"), view_partial);
  srv.stop();
}

}  // namespace receiver_plane_client_test
}  // namespace st::client
