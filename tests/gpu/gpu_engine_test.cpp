// GpuMap in engine mode, driven by a tiny engine (engine_harness.hpp) that owns the
// instance, device, queue, command buffers, fences and the G-buffer images: GpuMap only
// records into the engine's command buffers. Its shadow pass over the engine's images
// equals the own-device pass and the CPU twin bit for bit, and its feedback names the
// same absent tiles as the own-device pass's (and, for one tap, exactly the tiles the
// CPU's page-table walk finds absent); frames in flight with a churning cache never stall
// and count only tile, page-table and feedback bytes; the engine's loaders and allocator
// are the ones used. The engine's validation layer must stay silent throughout.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>

#include "client/map_access.hpp"
#include "gpu/layout.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/engine_harness.hpp"
#include "tests/gpu/raster_pass.hpp"
#include "tests/gpu/gpu_test_util.hpp"
#include "tests/gpu/shadow_twins.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::gpu {
namespace gpu_engine_test {

using enginetest::RasterPass;
using enginetest::run_frame;
using enginetest::Targets;
using enginetest::TestEngine;
using looptest::wait_until;

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

struct Served {
  looptest::TestPack pack;
  looptest::TestServer server;
  std::unique_ptr<client::Client> client;
  client::Map map;
};

Served serve(const std::string& name, uint32_t slots) {
  Served s;
  s.pack = looptest::build_pack(name, looptest::small_scale() ? 5 : 6, 7, looptest::first_encoding(), 2, 512);
  s.server = looptest::start_server({s.pack.path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = slots;
  s.client = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s.server.port}, o);
  s.map = s.client->open(name);
  return s;
}

// serve() with the whole finest level resident and the server stopped: frames that see
// every tile and no arrivals (callers wrap it in ASSERT_NO_FATAL_FAILURE).
void serve_resident(const std::string& name, Served& s) {
  s = serve(name, 64);
  const uint32_t l = s.map.finest_level();
  s.map.request_region(l, 0, 0, 1u << l, 1u << l, 10);
  ASSERT_TRUE(wait_until([&] { return s.map.region_resident(l, 0, 0, 1u << l, 1u << l); }));
  s.server.stop();
  ASSERT_TRUE(wait_until([&] { return !s.client->stats().connected; }));
}

// Receiver p at light-space (u, v) of the finest level `l`, on the stored depth there (0.5
// where the map stores none), as the view's shader writes it: its float point in `rec`
// (with `footprint`) and `pos` (the G-buffer's position, w = 1). Returns the float point.
std::array<float, 3> put_receiver(const Served& s, const LightSpace& ls, uint32_t l, double u, double v,
                                  float footprint, size_t p, std::vector<float>& rec, std::vector<float>& pos) {
  const double side = std::ldexp(1.0, int(l));
  const float stored = s.map.depth(l, uint64_t(u * side), uint64_t(v * side));
  const double d = stored < 1.0f ? double(stored) : 0.5;
  const Vec3d w = ls.to_world(u, v, d);
  const std::array<float, 3> f = {float(w.x), float(w.y), float(w.z)};
  for (size_t i = 0; i < 3; ++i) rec[4 * p + i] = pos[4 * p + i] = f[i];
  rec[4 * p + 3] = footprint, pos[4 * p + 3] = 1.0f;
  return f;
}

// A tilted plane across the map's light space, a little outside the box at the edges, a
// few background pixels (w == 0): positions and normals, 4 floats a pixel.
struct Plane {
  static constexpr uint32_t width = 64, height = 48;
  std::vector<float> pos, nrm;
  explicit Plane(const PackHeader& h) : pos(size_t(width) * height * 4), nrm(pos.size()) {
    const LightSpace ls = LightSpace::from_array(h.light_kind, h.light);
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> jitter(-0.002, 0.002);
    // The plane's own normal (d rises 0.4 across u), facing the light: its receivers'
    // kernels take the receiver plane (ShadowPassSettings::receiver_plane).
    const double e = ls.extent_uv(), depth = ls.far_plane() - ls.near_plane();
    const Vec3d n = normalize(cross(ls.axis_v(), ls.axis_u() * e + ls.forward() * (0.4 * depth)));
    for (uint32_t y = 0; y < height; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        const double u = -0.05 + 1.1 * (x + 0.5) / width + jitter(rng), v = -0.05 + 1.1 * (y + 0.5) / height;
        const double d = 0.3 + 0.4 * u + jitter(rng) * 50;
        const double z = ls.near_plane() + d * depth;
        const Vec3d wp = ls.origin() + ls.axis_u() * (u * e) + ls.axis_v() * (v * e) + ls.forward() * z;
        pos[4 * p] = float(wp.x), pos[4 * p + 1] = float(wp.y), pos[4 * p + 2] = float(wp.z);
        pos[4 * p + 3] = (x * 7 + y * 3) % 29 == 0 ? 0.0f : 1.0f;
        nrm[4 * p] = float(n.x), nrm[4 * p + 1] = float(n.y), nrm[4 * p + 2] = float(n.z);
      }
  }
  ShadowPassInput input(const ShadowPassSettings& s) const {
    ShadowPassInput in;
    in.positions = pos;
    in.normals = nrm;
    in.width = width;
    in.height = height;
    in.kernel = s.kernel;
    in.normal_offset = s.normal_offset;
    in.neighbour_footprint = s.neighbour_footprint;
    in.footprint = s.footprint;
    in.time = s.time;
    in.soft = s.soft;
    in.resume_walks = s.resume_walks;
    in.receiver_plane = s.receiver_plane;
    return in;
  }
};

std::map<uint64_t, uint32_t> feedback_of(const GpuMap& g) {
  std::map<uint64_t, uint32_t> m;
  for (const auto& t : g.last_feedback()) m[t.tile] = t.pixels;
  return m;
}

// Bytes of the resident tiles as the mirror uploads them (each padded to 4 bytes).
uint64_t resident_tile_bytes(const client::Map& map) {
  uint64_t sum = 0;
  client::MapAccess::remote(map).inspect_cache([&](const TileCache& c) {
    for (uint32_t s = 0; s < c.slot_count(); ++s) {
      const TileId t = c.slot_tile(s);
      if (t == kInvalidTile) continue;
      const PageEntry pe = c.lookup(t);
      if (pe.state == PageState::resident && pe.slot == s) sum += (c.tile_bytes(s).size() + 3) & ~size_t(3);
    }
  });
  return sum;
}

bool resident(const client::Map& map, uint64_t tile) {
  bool r = false;
  client::MapAccess::remote(map).inspect_cache([&](const TileCache& c) { r = c.lookup(tile).state == PageState::resident; });
  return r;
}

// The tiles the CPU's page-table walk over the same cache finds absent for each finest
// texel, with the number of texels (pixels) that needed each.
std::map<uint64_t, uint32_t> absent_tiles(const client::Map& map, const std::vector<std::array<uint32_t, 2>>& texels) {
  const client::RemoteMap& rm = client::MapAccess::remote(map);
  const uint32_t l = map.finest_level();
  std::map<uint64_t, uint32_t> want;
  rm.inspect_cache([&](const TileCache& c) {
    std::map<uint32_t, CutGrid> grids;
    for (const auto& [x, y] : texels) {
      auto index = [&](uint64_t id, const GridEntry&) -> const CutGrid* {
        const PageEntry page = c.lookup(id);
        if (page.state != PageState::resident) return nullptr;
        auto it = grids.find(page.slot);
        if (it == grids.end())
          it = grids.emplace(page.slot, CutGrid::parse(c.tile_bytes(page.slot), "slot", kMaxIndexLevels)).first;
        return &it->second;
      };
      const PageHit hit = walk_page_table(rm.grid(), l, x, y, index);
      if (hit.kind == PageHit::Kind::absent ||
          (hit.kind == PageHit::Kind::tile && c.lookup(hit.tile).state != PageState::resident))
        ++want[hit.tile];
    }
  });
  return want;
}

// What retire() reads of a frame's feedback: the header and, per claimed key, its list
// entry, key and record (never the whole key array).
uint64_t feedback_bytes(uint32_t tiles) {
  return (uint64_t(layout::kFbHeaderWords) + uint64_t(tiles) * (2 + layout::kFbRecordWords)) * 4;
}


// An engine's fragment shader that includes shadowtile.glsl answers what the compute pass
// answers (footprint given, no neighbours), bit for bit, and feeds back the same tiles.
TEST(GpuEngine, AFragmentShaderIncludingShadowtileGlslAnswersLikeTheComputePass) {
  Served s = serve("gpu_engine_fragment", 10);
  const uint32_t l = s.map.finest_level();
  s.map.request_region(l, 0, 0, (1u << l) / 2, (1u << l) / 2, 10);
  ASSERT_TRUE(wait_until([&] { return s.map.region_resident(l, 0, 0, (1u << l) / 2, (1u << l) / 2); }));
  s.server.stop();
  ASSERT_TRUE(wait_until([&] { return !s.client->stats().connected; }));
  const PackHeader& h = client::pack_header(s.map);
  const Plane plane(h);
  TestEngine e(1);
  ASSERT_TRUE(e.fragment_stores) << "the device has no fragmentStoresAndAtomics";
  Targets t(e, plane.width, plane.height, plane.pos, plane.nrm, 1);
  enginetest::Image& colour = e.image(plane.width, plane.height, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
  GpuOptions o;
  o.frames_in_flight = 1;
  o.texel_buffers = true;  // the fragment shader reads the pool and page table as texel buffers
  GpuMap g(s.map, e.engine_device(), o);
  ShadowPassSettings set;
  set.kernel = 3;
  set.normal_offset = 0.001f;
  set.neighbour_footprint = false;
  set.footprint = 2.5f;
  // Frame 1: the compute pass.
  run_frame(e, g, t, 1, set);
  g.retire(e.finish());
  const std::vector<float> compute = t.read(1);
  const std::map<uint64_t, uint32_t> compute_feedback = feedback_of(g);
  // Frame 2: the engine's raster pass reads the same buffers at its own bindings.
  const RasterPass raster(e, colour, *t.pos, *t.nrm, g.descriptors(2));
  const RasterPass::Frame r = raster.run_frame(e, g, 2, t.readback[0], set.kernel, set.normal_offset, set.footprint);
  EXPECT_EQ(r.uploads.tile_bytes + r.uploads.page_bytes, 0u);
  ASSERT_EQ(r.retired.size(), 1u);
  const std::vector<float> fragment = t.read(2);
  std::vector<float> want(compute.size());
  shadow_pass_reference(client::evaluator(s.map), h, plane.input(set), want);
  size_t bad = 0, bad_twin = 0, shadowed = 0;
  for (size_t i = 0; i < compute.size(); ++i) {
    if (bits(fragment[i]) != bits(compute[i]) && bad++ == 0)
      ADD_FAILURE() << "pixel " << i << ": fragment " << fragment[i] << ", compute " << compute[i];
    bad_twin += bits(fragment[i]) != bits(want[i]);
    shadowed += fragment[i] < 1.0f;
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(bad_twin, 0u);
  EXPECT_GT(shadowed, 0u);
  EXPECT_FALSE(compute_feedback.empty());
  EXPECT_EQ(feedback_of(g), compute_feedback);  // the fragment shader fed back the same tiles
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

// The twin of a fragment shader's lookups (gpu::receiver_lookup_reference, what `shadowtile
// view --twin` checks a frame with) at receivers the float32 light transform puts in
// another texel than the client's double one (u on a texel's edge), or at another depth
// bit (d on the stored depth): bit for bit the shader's answer on every pixel, where the
// client's Map::visibility_filtered (the view's former twin) differs on some.
TEST(GpuEngine, TheReceiverTwinAnswersLikeAFragmentShaderWhereTheDoubleTransformDoesNot) {
  Served s;
  ASSERT_NO_FATAL_FAILURE(serve_resident("gpu_engine_twin", s));
  const uint32_t l = s.map.finest_level();
  const PackHeader& h = client::pack_header(s.map);
  const LightSpace ls = LightSpace::from_array(h.light_kind, h.light);
  const ShadowLight fl = shadow_light(h);
  constexpr uint32_t kW = 32, kH = 32, kKernel = 3;
  constexpr float kFootprint = 2.5f;  // two levels blended
  const double side = std::ldexp(1.0, int(l)), texel = ls.texel_size(ls.origin(), l);
  // Receivers 4 floats each (xyz, footprint) as the view's shader writes them; the
  // G-buffer's positions are the same points (normal offset 0: st_receiver leaves them).
  std::vector<float> rec(size_t(kW) * kH * 4), pos(rec.size()), nrm(rec.size(), 0.0f);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0), edge(-3e-7, 3e-7);
  size_t moved = 0;  // receivers whose float texel differs from the double one
  for (size_t p = 0; p < size_t(kW) * kH; ++p) {
    // u on a texel's edge (within a few float ulps), v anywhere; d the stored depth there.
    const double u = (std::floor(unit(rng) * (side - 2)) + 1) / side + edge(rng), v = unit(rng) * 0.98 + 0.01;
    const std::array<float, 3> f = put_receiver(s, ls, l, u, v, kFootprint, p, rec, pos);
    nrm[4 * p + 1] = 1.0f;
    float r[3];
    for (int i = 0; i < 3; ++i) r[i] = f[i] - fl.origin[i];
    const float fu = (r[0] * fl.axis_u[0] + r[1] * fl.axis_u[1]) + r[2] * fl.axis_u[2];
    const LightPoint dp = ls.to_light(Vec3d{f[0], f[1], f[2]});
    moved += uint64_t(std::floor(double(fu) * side)) != uint64_t(std::floor(dp.u * side));
  }
  EXPECT_GT(moved, 0u) << "no receiver whose float and double texels differ: the test tests nothing";
  TestEngine e(1);
  ASSERT_TRUE(e.fragment_stores) << "the device has no fragmentStoresAndAtomics";
  Targets t(e, kW, kH, pos, nrm, 1);
  enginetest::Image& colour = e.image(kW, kH, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
  GpuOptions o;
  o.frames_in_flight = 1;
  o.texel_buffers = true;  // the fragment shader reads the pool and page table as texel buffers
  GpuMap g(s.map, e.engine_device(), o);
  const RasterPass raster(e, colour, *t.pos, *t.nrm, g.descriptors(2));
  const RasterPass::Frame r = raster.run_frame(e, g, 1, t.readback[0], kKernel, 0.0f, kFootprint);
  ASSERT_EQ(r.retired.size(), 1u);
  EXPECT_EQ(r.retired[0].holes, 0u);
  const std::vector<float> gpu = t.read(1);
  std::vector<float> twin(gpu.size());
  ReceiverLookup q;
  q.kernel = kKernel;
  // st_visibility compares each tap with the receiver's plane: normals (0, 1, 0), the
  // light's own slope cap.
  const std::array<float, 2> up = receiver_slope_reference(fl, l, {0.0f, 1.0f, 0.0f}, receiver_slope_cap(ls, fl, l));
  std::vector<float> slopes(size_t(kW) * kH * 2);
  for (size_t p = 0; p < size_t(kW) * kH; ++p) slopes[2 * p] = up[0], slopes[2 * p + 1] = up[1];
  receiver_lookup_reference(s.map, rec, q, twin, slopes);
  size_t bad = 0, client_differs = 0, partial = 0;
  for (size_t p = 0; p < gpu.size(); ++p) {
    if (bits(gpu[p]) != bits(twin[p]) && bad++ == 0)
      ADD_FAILURE() << "pixel " << p << ": fragment shader " << gpu[p] << ", twin " << twin[p];
    const client::WorldPoint w{rec[4 * p], rec[4 * p + 1], rec[4 * p + 2]};
    client_differs += bits(s.map.visibility_filtered(w, float(double(kFootprint) * texel), kKernel)) != bits(gpu[p]);
    partial += gpu[p] > 0.0f && gpu[p] < 1.0f;
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(partial, 0u);
  EXPECT_GT(client_differs, 0u) << "the client's double transform agreed everywhere: the receivers miss the edges";
  std::printf("receiver twin: %zu pixels, %zu with another float texel, %zu partly lit, %zu where the client's "
              "double lookup differs\n",
              gpu.size(), moved, partial, client_differs);
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

// Filtered lookups with the receiver plane (shadowtile.glsl st_receiver_slope and
// st_shadow_uvd_plane; tiles/core/receiver_plane.hpp) in a fragment shader, on receivers
// tilted every way to the light (slopes of both signs, some clamped) at a footprint that
// blends two levels: bit for bit the CPU twin's (receiver_slope_reference, then
// receiver_lookup_reference with those slopes), which counts every tap; the blocks of taps
// that share a value and straddle the plane are counted tap by tap on both sides.
TEST(GpuEngine, ReceiverPlaneLookupsOnSlopesAnswerLikeTheTwin) {
  Served s;
  ASSERT_NO_FATAL_FAILURE(serve_resident("gpu_engine_slope", s));
  const uint32_t l = s.map.finest_level();
  const PackHeader& h = client::pack_header(s.map);
  const LightSpace ls = LightSpace::from_array(h.light_kind, h.light);
  const ShadowLight fl = shadow_light(h);
  constexpr uint32_t kW = 32, kH = 32, kKernel = 5;
  constexpr float kFootprint = 2.5f;
  const float texel = float(ls.texel_size(ls.origin(), l));
  const Vec3d tl = ls.forward() * -1.0;
  const std::array<float, 3> to_light = {float(tl.x), float(tl.y), float(tl.z)};
  std::vector<float> rec(size_t(kW) * kH * 4), pos(rec.size()), nrm(rec.size(), 0.0f), slopes(size_t(kW) * kH * 2);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  size_t sloped = 0;
  for (size_t p = 0; p < size_t(kW) * kH; ++p) {
    const double u = 0.02 + 0.96 * unit(rng), v = 0.02 + 0.96 * unit(rng);
    put_receiver(s, ls, l, u, v, kFootprint, p, rec, pos);
    // Tilted up to 84 degrees from facing the light (past the clamp), any azimuth.
    const double tilt = 1.47 * unit(rng), az = 6.2831853 * unit(rng);
    const Vec3d n = tl * std::cos(tilt) + (ls.axis_u() * std::cos(az) + ls.axis_v() * std::sin(az)) * std::sin(tilt);
    const std::array<float, 3> nf = {float(n.x), float(n.y), float(n.z)};
    for (int i = 0; i < 3; ++i) nrm[4 * p + size_t(i)] = nf[size_t(i)];
    const std::array<float, 2> g = receiver_slope_reference(fl, l, nf, to_light, texel);
    slopes[2 * p] = g[0], slopes[2 * p + 1] = g[1];
    sloped += g[0] != 0.0f || g[1] != 0.0f;
  }
  EXPECT_GT(sloped, size_t(kW) * kH / 2);
  TestEngine e(1);
  ASSERT_TRUE(e.fragment_stores) << "the device has no fragmentStoresAndAtomics";
  Targets t(e, kW, kH, pos, nrm, 1);
  enginetest::Image& colour = e.image(kW, kH, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
  GpuOptions o;
  o.frames_in_flight = 1;
  o.texel_buffers = true;  // the fragment shader reads the pool and page table as texel buffers
  GpuMap g(s.map, e.engine_device(), o);
  const RasterPass raster(e, colour, *t.pos, *t.nrm, g.descriptors(2));
  uint64_t completed = 0;
  VkCommandBuffer cmd = e.begin(1, completed);
  g.retire(completed);
  g.record_uploads(cmd, 1);
  raster.record(cmd, kKernel, 0.0f, kFootprint, 4, to_light, texel);
  e.record_readback(cmd, colour, VK_IMAGE_LAYOUT_GENERAL, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, t.readback[0],
                    VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT);
  g.record_end_of_frame(cmd, 1);
  e.submit(1);
  const std::span<const FrameStats> r = g.retire(e.finish());
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].holes, 0u);
  const std::vector<float> gpu = t.read(1);
  std::vector<float> twin(gpu.size()), flat(gpu.size());
  ReceiverLookup q;
  q.kernel = kKernel;
  receiver_lookup_reference(s.map, rec, q, twin, slopes);
  receiver_lookup_reference(s.map, rec, q, flat);
  size_t bad = 0, partial = 0, plane_differs = 0;
  for (size_t p = 0; p < gpu.size(); ++p) {
    if (bits(gpu[p]) != bits(twin[p]) && bad++ == 0)
      ADD_FAILURE() << "pixel " << p << ": fragment shader " << gpu[p] << ", twin " << twin[p] << " (slopes "
                    << slopes[2 * p] << ", " << slopes[2 * p + 1] << ")";
    partial += gpu[p] > 0.0f && gpu[p] < 1.0f;
    plane_differs += bits(flat[p]) != bits(twin[p]);
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(partial, 0u);
  EXPECT_GT(plane_differs, 0u) << "the plane changed no answer: the test tests nothing";
  std::printf("receiver plane twin: %zu pixels, %zu sloped, %zu partly lit, %zu answers moved by the plane\n",
              gpu.size(), sloped, partial, plane_differs);
  // The compute passes over the same G-buffer (each pixel's normal, the light's own slope
  // cap: the same slopes as the fragment shader's from to_light and texel), engine mode and
  // own device, and their CPU twin: the fragment shader's answers, bit for bit.
  ShadowPassSettings set;
  set.kernel = kKernel;
  set.normal_offset = 0.0f;
  set.neighbour_footprint = false;
  set.footprint = kFootprint;
  run_frame(e, g, t, 2, set);
  g.retire(e.finish());
  const std::vector<float> compute = t.read(2);
  ShadowPassInput in;
  in.positions = pos;
  in.normals = nrm;
  in.width = kW;
  in.height = kH;
  in.kernel = kKernel;
  in.normal_offset = 0.0f;
  in.neighbour_footprint = false;
  in.footprint = kFootprint;
  GpuMap own(s.map, gputest::options());
  std::vector<float> own_out(gpu.size()), pass_twin(gpu.size());
  own.wait(own.submit_shadow_pass(in), own_out);
  shadow_pass_reference(client::evaluator(s.map), h, in, pass_twin);
  size_t bad_compute = 0, bad_own = 0, bad_pass_twin = 0;
  for (size_t p = 0; p < gpu.size(); ++p) {
    if (bits(compute[p]) != bits(twin[p]) && bad_compute++ == 0)
      ADD_FAILURE() << "pixel " << p << ": engine pass " << compute[p] << ", twin " << twin[p];
    bad_own += bits(own_out[p]) != bits(twin[p]);
    bad_pass_twin += bits(pass_twin[p]) != bits(twin[p]);
  }
  EXPECT_EQ(bad_compute, 0u);
  EXPECT_EQ(bad_own, 0u);
  EXPECT_EQ(bad_pass_twin, 0u);
  EXPECT_EQ(own.stats().validation_messages, 0u);
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

TEST(GpuEngine, ShadowPassOverTheEnginesImagesEqualsTheOwnDevicePassAndTheCpuTwin) {
  Served s = serve("gpu_engine_pass", 10);
  const uint32_t l = s.map.finest_level();
  s.map.request_region(l, 0, 0, (1u << l) / 2, (1u << l) / 2, 10);
  ASSERT_TRUE(wait_until([&] { return s.map.region_resident(l, 0, 0, (1u << l) / 2, (1u << l) / 2); }));
  s.server.stop();
  ASSERT_TRUE(wait_until([&] { return !s.client->stats().connected; }));
  const PackHeader& h = client::pack_header(s.map);
  const Plane plane(h);
  GpuMap own(s.map, gputest::options());
  const uint64_t lookups_before = enginetest::g_instance_lookups + enginetest::g_device_lookups;
  {
    TestEngine e(2);
    Targets t(e, plane.width, plane.height, plane.pos, plane.nrm, 2);
    enginetest::CountingAllocator alloc(e.device, e.physical);
    GpuOptions o;
    o.frames_in_flight = 2;
    {
      GpuMap g(s.map, e.engine_device(&alloc), o);
      EXPECT_TRUE(g.engine_mode());
      EXPECT_GT(enginetest::g_instance_lookups + enginetest::g_device_lookups, lookups_before);  // the engine's loaders
      EXPECT_GT(alloc.live, 0);  // and its allocator
      EXPECT_THROW(g.sync(), GpuError);  // own-device calls refuse in engine mode
      uint64_t frame = 100;  // the engine's counter: any start
      std::vector<FrameStats> retired;
      uint32_t k = 0;
      size_t plane_moved = 0;
      for (const auto& [kernel, with_plane] : {std::pair{1u, true}, {3u, true}, {5u, true}, {5u, false}}) {
        SCOPED_TRACE(std::to_string(kernel) + (with_plane ? " with the receiver plane" : " one receiver depth"));
        ShadowPassSettings set;
        set.kernel = kernel;
        set.normal_offset = 0.001f;
        set.neighbour_footprint = kernel != 5;
        set.footprint = 2.5f;
        set.receiver_plane = with_plane;
        const FrameStats up = run_frame(e, g, t, ++frame, set, &retired);
        if (k++ == 0) {  // the first frame: every resident tile and the whole page table
          EXPECT_EQ(up.tile_bytes, resident_tile_bytes(s.map));
          EXPECT_EQ(up.page_bytes, g.stats().page_table_bytes);
        } else {  // nothing changed: no tile, no page-table word
          EXPECT_EQ(up.tile_bytes, 0u);
          EXPECT_EQ(up.page_bytes, 0u);
        }
        EXPECT_EQ(up.host_io_bytes, 0u);
        const uint64_t done = e.finish();
        const std::span<const FrameStats> r = g.retire(done);
        ASSERT_FALSE(r.empty());
        ASSERT_EQ(r.back().frame, frame);
        const FrameStats fs = r.back();
        const std::vector<float> got = t.read(frame);
        const std::map<uint64_t, uint32_t> engine_feedback = feedback_of(g);
        // The own-device pass over the same G-buffer (host spans) and the CPU twin.
        const ShadowPassInput in = plane.input(set);
        std::vector<float> own_out(got.size()), want(got.size());
        const FrameStats ofs = own.wait(own.submit_shadow_pass(in), own_out);
        shadow_pass_reference(client::evaluator(s.map), h, in, want);
        size_t bad = 0, bad_own = 0;
        for (size_t i = 0; i < got.size(); ++i) {
          if (bits(got[i]) != bits(want[i]) && bad++ == 0)
            ADD_FAILURE() << "pixel " << i << ": engine pass " << got[i] << ", cpu twin " << want[i];
          bad_own += bits(got[i]) != bits(own_out[i]);
        }
        EXPECT_EQ(bad, 0u);
        EXPECT_EQ(bad_own, 0u);
        if (with_plane) {  // the plane moves answers (else the twin's plane path tests nothing)
          ShadowPassInput flat_in = in;
          flat_in.receiver_plane = false;
          std::vector<float> flat(got.size());
          shadow_pass_reference(client::evaluator(s.map), h, flat_in, flat);
          for (size_t i = 0; i < got.size(); ++i) plane_moved += bits(flat[i]) != bits(want[i]);
        }
        // Feedback: the same absent tiles with the same pixel counts as the own-device pass
        // (whose feedback the own-device tests check against the CPU's walk), all absent.
        EXPECT_FALSE(engine_feedback.empty());  // half the map is absent
        EXPECT_EQ(engine_feedback, feedback_of(own));
        for (const auto& [tile, n] : engine_feedback) EXPECT_FALSE(resident(s.map, tile)) << tile;
        EXPECT_EQ(fs.holes, ofs.holes);
        EXPECT_EQ(fs.feedback_dropped, 0u);
        // Per frame: tile + page-table bytes up, the feedback read back, nothing else.
        EXPECT_EQ(fs.feedback_bytes, feedback_bytes(fs.feedback_tiles));
        EXPECT_EQ(fs.host_io_bytes, 0u);
        EXPECT_EQ(ofs.host_io_bytes, uint64_t(plane.width) * plane.height * (16 + 16 + 4));  // own mode: G-buffer in, out
      }
      EXPECT_GT(plane_moved, 0u);
      std::printf("engine pass: %zu answers moved by the receiver plane\n", plane_moved);
      // One tap at the finest level (kernel 1, footprint 1): the feedback names exactly the
      // tiles the CPU's page-table walk finds absent for the pixels' texels, each with the
      // number of pixels that needed it.
      {
        ShadowPassSettings one;
        one.kernel = 1;
        one.normal_offset = 0.001f;
        one.neighbour_footprint = false;
        one.footprint = 1.0f;
        run_frame(e, g, t, ++frame, one);
        g.retire(e.finish());
        const ShadowPassInput in = plane.input(one);
        const ShadowLight sl = shadow_light(h);
        std::vector<std::array<uint32_t, 2>> texels;
        for (size_t p = 0; p < size_t(plane.width) * plane.height; ++p) {
          uint32_t x = 0, y = 0;
          if (shadow_pass_texel(sl, in, p, s.map.finest_level(), x, y)) texels.push_back({x, y});
        }
        const std::map<uint64_t, uint32_t> want = absent_tiles(s.map, texels);
        EXPECT_FALSE(want.empty());
        EXPECT_EQ(feedback_of(g), want);
      }
      const GpuStats st = g.stats();
      EXPECT_EQ(st.host_io_bytes, 0u);
      EXPECT_EQ(st.bytes_uploaded, st.tile_bytes + st.page_bytes);
      // A frame whose ring slot still holds an unretired frame is refused, not waited for.
      uint64_t completed = 0;
      VkCommandBuffer cmd = e.begin(frame + 1, completed);
      g.record_uploads(cmd, frame + 1);
      EXPECT_THROW(g.record_uploads(cmd, frame + 3), GpuError);
      EXPECT_THROW(g.record_uploads(cmd, frame + 1), GpuError);  // not after the last
      e.submit(frame + 1);
      g.retire(e.finish());
    }
    EXPECT_EQ(alloc.live, 0);  // every buffer given back to the engine's allocator
    EXPECT_EQ(e.messages(), 0u) << e.first_message();
  }
  EXPECT_EQ(own.stats().validation_messages, 0u);
}

TEST(GpuEngine, FramesInFlightWithAChurningCacheNeverStallAndMoveOnlyTilePageAndFeedbackBytes) {
  Served s = serve("gpu_engine_churn", 6);
  const uint32_t l = s.map.finest_level();
  const uint32_t side = 1u << l;
  const Plane plane(client::pack_header(s.map));
  TestEngine e(3);
  Targets t(e, plane.width, plane.height, plane.pos, plane.nrm, 3);
  GpuOptions o;
  o.frames_in_flight = 3;
  o.upload_budget_bytes = 600;  // about one slot a frame: uploads trail the cache
  GpuMap g(s.map, e.engine_device(), o);
  std::mt19937_64 rng(5);
  std::vector<FrameStats> retired;
  ShadowPassSettings set;
  set.kernel = 3;
  uint64_t frame = 0;
  for (int i = 0; i < 30; ++i) {
    const uint32_t w = side / 4;
    s.map.request_region(l, rng() % (side - w), rng() % (side - w), w, w, uint16_t(1 + i));
    run_frame(e, g, t, ++frame, set, &retired);
  }
  const std::span<const FrameStats> last = g.retire(e.finish());
  retired.insert(retired.end(), last.begin(), last.end());
  ASSERT_EQ(retired.size(), frame);
  uint64_t tiles = 0, requested = 0;
  for (size_t i = 0; i < retired.size(); ++i) {
    const FrameStats& fs = retired[i];
    EXPECT_EQ(fs.frame, i + 1);  // oldest first, every frame once
    EXPECT_TRUE(fs.tile_bytes <= o.upload_budget_bytes || fs.slots_uploaded == 1) << fs.tile_bytes;
    EXPECT_EQ(fs.bytes_uploaded, fs.tile_bytes + fs.page_bytes);
    if (fs.feedback_dropped == 0) {
      EXPECT_EQ(fs.feedback_bytes, feedback_bytes(fs.feedback_tiles));
    }
    EXPECT_EQ(fs.host_io_bytes, 0u);
    tiles += fs.slots_uploaded;
    requested += fs.requested;
  }
  EXPECT_GT(tiles, 6u);      // slots were reused
  EXPECT_GT(requested, 0u);  // the pass's feedback reached the Map
  // The cache holds still: frames until the mirror has caught up, then one more equals
  // the CPU twin bit for bit.
  s.server.stop();
  ASSERT_TRUE(wait_until([&] { return !s.client->stats().connected; }));
  for (int i = 0; i < 64; ++i) {
    const FrameStats up = run_frame(e, g, t, ++frame, set);
    if (up.tile_bytes == 0 && up.page_bytes == 0) break;
  }
  run_frame(e, g, t, ++frame, set);
  g.retire(e.finish());
  std::vector<float> want(size_t(plane.width) * plane.height);
  shadow_pass_reference(client::evaluator(s.map), client::pack_header(s.map), plane.input(set), want);
  const std::vector<float> got = t.read(frame);
  size_t bad = 0;
  for (size_t i = 0; i < got.size(); ++i) bad += bits(got[i]) != bits(want[i]);
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

// Sizing a cache for a device: the most slots whose pool fits the device's
// maxStorageBufferRange (and maxTexelBufferElements words for texel buffers), the engine's
// device and the own-device one alike (both lavapipe here), slots rounded to words as the
// pool holds them, never past GpuMap's 2^23 slots.
TEST(GpuEngine, MaxCacheSlotsFillsTheDevicesStorageRangeAndNoMore) {
  TestEngine e(1);
  VkPhysicalDeviceProperties p{};
  vkGetPhysicalDeviceProperties(e.physical, &p);
  const uint64_t range = p.limits.maxStorageBufferRange;
  for (const uint32_t slot_bytes : {2396u, 4099u, 65536u, 1u << 20}) {
    SCOPED_TRACE(slot_bytes);
    const uint64_t words = (uint64_t(slot_bytes) + 15) / 16 * 16;  // a slot: whole 16-byte quads
    const uint32_t n = GpuMap::max_cache_slots(e.engine_device(), slot_bytes);
    EXPECT_LE(n * words, range);
    EXPECT_GT((n + 1) * words, range);
    EXPECT_EQ(GpuMap::max_cache_slots(gputest::options(), slot_bytes), n);
    EXPECT_EQ(GpuMap::max_cache_slots(range, slot_bytes), n);
    // Texel buffers (GpuOptions::texel_buffers): the pool also within maxTexelBufferElements words.
    const uint64_t texel_range = std::min<uint64_t>(range, uint64_t(p.limits.maxTexelBufferElements) * 4);
    EXPECT_EQ(GpuMap::max_cache_slots(e.engine_device(), slot_bytes, true), GpuMap::max_cache_slots(texel_range, slot_bytes));
  }
  EXPECT_EQ(GpuMap::max_cache_slots(1000, 10), 62u);  // 16-byte slots
  EXPECT_EQ(GpuMap::max_cache_slots(1000, 10, 100), 55u);  // a 100-byte dictionary takes 7 quads
  EXPECT_EQ(GpuMap::max_cache_slots(100, 10, 200), 0u);
  EXPECT_EQ(GpuMap::max_cache_slots(uint64_t(1) << 40, 4), 1u << 23);
  EXPECT_EQ(GpuMap::max_cache_slots(GpuMap::kAnyDeviceStorageRange, 4096), 32768u);
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

}  // namespace gpu_engine_test
}  // namespace st::gpu
