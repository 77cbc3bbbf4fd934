// Lookups in a shadow-map stack (tiles/core/stack_lookup.hpp): the lit test of every
// slice equals the uncompressed map's outside objects, visibility by time is exact at
// the samples and blends between them, the shared soft-shadow walk equals N independent
// lookups bit for bit and visits fewer nodes, and so does the batched (interleaved) one.
#include <gtest/gtest.h>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/stack_lookup.hpp"
#include "tiles/core/walk_interleave.hpp"

namespace st {
namespace {

struct Built {
  LightSet set;
  IntervalStack stack;
  std::vector<uint8_t> bytes;
  Aabb bounds;
};

Built build(const char* scene, const char* light, uint32_t level) {
  Built b;
  b.set = stacks::fitted_set(scene, light);
  b.stack = stacks::traced_stack(scene, b.set, level);
  b.bytes = encode_octree(build_octree(b.stack));
  b.bounds = load_scene(scene).bounds();
  return b;
}

// Nodes an independent walk to texel (x, y) of slice w visits (the root included).
uint32_t path_nodes(const MhOctree& t, uint64_t x, uint64_t y, uint32_t w) {
  const moct::Geometry& g = t.geometry();
  MhOctree::Cursor c = t.root(), next;
  uint32_t nodes = 1;
  while (c.level < g.depth()) {
    const uint32_t l = c.level;
    uint32_t slot = 0;
    if (g.splits_xy(l)) slot = uint32_t(x >> (g.n - g.xy_bits(l + 1)) & 1) | uint32_t(y >> (g.n - g.xy_bits(l + 1)) & 1) << 1;
    if (g.splits_w(l)) slot |= (w >> (g.k - g.w_bits(l + 1)) & 1) << 2;
    if (!t.child(c, slot, next)) break;
    c = next, ++nodes;
  }
  return nodes;
}

Vec3d random_point(Rng& rng, const Aabb& b) {
  return {rng.uniform(b.lo.x, b.hi.x), rng.uniform(b.lo.y, b.hi.y), rng.uniform(b.lo.z, b.hi.z)};
}

TEST(StackLookup, SlicesMatchTheUncompressedMapsAndTimeIsExactAtSamples) {
  const uint32_t level = stacks::small_scale() ? 6 : 7;
  const Built b = build("procedural:city,size=2", "sun-path:azimuth=60..150,elevation=25..55,samples=7", level);
  const MhOctree tree = MhOctree::open(b.bytes);
  const StackLookup look(tree, b.set);
  Rng rng(1);
  uint32_t compared = 0, shadowed = 0, blended = 0;
  for (int i = 0; i < 3000; ++i) {
    const Vec3d p = random_point(rng, b.bounds);
    for (uint32_t w = 0; w < b.set.size(); ++w) {
      const LightPoint lp = b.set.samples[w].to_light(p);
      const auto t = LightSpace::texel_of(level, lp.u, lp.v);
      const Interval iv = b.stack.at(t[0], t[1], w);
      const float r = float(lp.d);
      const bool got = look.lit(p, w);
      if (!(r > iv.lo && r <= iv.hi)) {  // outside every object: the exact shadow test
        ASSERT_EQ(got, r <= iv.lo) << "point " << i << " slice " << w;
        ++compared, shadowed += !got;
      }
      ASSERT_EQ(look.visibility(p, b.set.time_of(w)), got ? 1.0f : 0.0f);
    }
    const double time = rng.uniform();
    const double s = time * (b.set.size() - 1);
    const uint32_t a = uint32_t(s);
    const float v = look.visibility(p, time), la = look.lit(p, a), lb = look.lit(p, a + 1);
    ASSERT_GE(v, std::min(la, lb));
    ASSERT_LE(v, std::max(la, lb));
    blended += la != lb;
    if (la != lb) {
      EXPECT_NEAR(v, la + float(s - a) * (lb - la), 1e-6);
    }
  }
  EXPECT_GT(compared, 15000u);
  EXPECT_GT(shadowed, 500u);
  EXPECT_GT(blended, 10u);
  EXPECT_EQ(look.visibility(b.bounds.center(), -3.0), look.visibility(b.bounds.center(), 0.0));
  EXPECT_EQ(look.visibility(b.bounds.center(), 7.0), look.visibility(b.bounds.center(), 1.0));
}

TEST(StackLookup, SoftVisibilityEqualsIndependentLookupsAndSharesTheWalk) {
  const uint32_t level = stacks::small_scale() ? 6 : 7;
  const Built b = build("procedural:hairball,count=12", "area:pos=2,14,1,target=0,0,0,size=3,3,samples=16,jitter=0.5", level);
  const MhOctree tree = MhOctree::open(b.bytes);
  const StackLookup look(tree, b.set);
  const StackBounds bounds(tree);
  Rng rng(2);
  uint64_t shared_nodes = 0, separate_nodes = 0, penumbra = 0;
  for (int i = 0; i < 2000; ++i) {
    const Vec3d p = random_point(rng, b.bounds);
    const float soft = look.soft_visibility(p);
    shared_nodes += StackLookup::last_nodes_visited();
    ASSERT_EQ(soft, look.soft_visibility_independent(p)) << "point " << i;
    ASSERT_EQ(soft, look.soft_visibility_bounded(p, bounds)) << "point " << i;  // the early stop
    penumbra += soft > 0 && soft < 1;
    for (uint32_t w = 0; w < b.set.size(); ++w) {
      const LightPoint lp = b.set.samples[w].to_light(p);
      const auto t = LightSpace::texel_of(level, lp.u, lp.v);
      separate_nodes += path_nodes(tree, t[0], t[1], w);
    }
  }
  EXPECT_GT(penumbra, 100u) << "the area light casts penumbrae";
  // The batched lookup (interleaved walks) answers each point as the single one does, for
  // batches shorter and longer than the lanes in flight, and stops at the shorter span.
  std::vector<Vec3d> pts;
  for (int i = 0; i < 300; ++i) pts.push_back(random_point(rng, b.bounds));
  for (size_t count : {size_t(1), size_t(kWalkLanes - 1), pts.size()}) {
    std::vector<float> out(count + 1, -1.0f);
    look.soft_visibility(std::span<const Vec3d>(pts.data(), count), out);
    for (size_t i = 0; i < count; ++i) ASSERT_EQ(out[i], look.soft_visibility(pts[i])) << count << " " << i;
    EXPECT_EQ(out[count], -1.0f) << "written past the points";
  }
  EXPECT_LT(shared_nodes * 2, separate_nodes) << "the shared walk visits under half the nodes of 16 separate walks";
  // A light set of another size is refused.
  const LightSet other = stacks::fitted_set("procedural:hairball,count=12", "area:pos=2,14,1,target=0,0,0,size=3,3,samples=8");
  EXPECT_THROW(StackLookup(tree, other), Error);
}

}  // namespace
}  // namespace st
