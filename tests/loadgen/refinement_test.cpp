// Progressive refinement: while tiles stream in, lookups answer from coarser levels; once
// every tile the view needs is resident, the client's answers equal the full pack's (the
// error against the uncompressed map is exactly zero).
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "client/map_access.hpp"
#include "load_fixture.hpp"
#include "loadgen/view_tiles.hpp"
#include "render/render.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace {

TEST(Refinement, ErrorEndsAtZeroOnceTheViewIsResident) {
  const auto& pack = loadtest::city_pack(11);
  auto srv = loadtest::start_server("city", pack.path);
  auto reader = std::shared_ptr<PackReader>(PackReader::open(pack.path));
  const PackEvaluator full(reader, 1 << 14);
  const SceneTracer tracer(pack.scene, pack.light);
  const Aabb b = pack.scene.bounds();
  Camera cam;
  cam.pos = b.center() + Vec3d{-0.45 * b.extent().x, 0.4 * b.extent().x, -0.5 * b.extent().z};
  cam.target = b.center();
  const auto rec = tracer.primary(cam, 160, 90);

  client::ClientOptions co;
  co.cache_slots = 4096;
  client::Client cl({"127.0.0.1", srv->port()}, co);
  client::Map map = cl.open("city");
  const uint32_t L = map.finest_level();
  std::vector<LightPoint> pts;
  for (const Receiver& r : rec)
    if (r.hit && r.n_dot_l > 0) pts.push_back(lookup_point(r, pack.light, L));
  ASSERT_GT(pts.size(), 1000u);
  auto differing = [&] {
    uint64_t n = 0;
    for (const Receiver& r : rec)
      n += map_visibility(client::evaluator(map), r, pack.light, 0, L) != map_visibility(full, r, pack.light, 0, L);
    return n;
  };
  const uint64_t at_cut = differing();  // nothing resident: skip-grid answers
  const auto cells = loadgen::cells_for_points(pts, L, client::skip_grid(map));
  ASSERT_GT(cells.size(), 0u);
  for (const auto& c : cells) map.request_region(c.level, c.x0(), c.y0(), c.side(), c.side(), 100);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  bool all = false;
  while (!all && std::chrono::steady_clock::now() < deadline) {
    all = true;
    for (const auto& c : cells) all = all && map.region_resident(c.level, c.x0(), c.y0(), c.side(), c.side());
    if (!all) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_TRUE(all);
  EXPECT_EQ(differing(), 0u) << "answers at full residency must equal the whole pack's";
  EXPECT_GT(at_cut, 0u) << "the coarse answers before any tile arrived should differ somewhere";
  srv->stop();
}

}  // namespace
}  // namespace st
