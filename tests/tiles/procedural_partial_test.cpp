// The procedural scenes of partial occluders (DSM 2000's cases): semi-transparent hair,
// alpha-tested leaf cards, a smoke volume. Deterministic, valid, and what the opaque map
// sees of them is only their opaque part.
#include <gtest/gtest.h>

#include "common/error.hpp"
#include "scene/scene.hpp"

namespace st {
namespace {

TEST(ProceduralPartial, HairballTransmitMakesEveryTubePartial) {
  const Scene opaque = make_procedural("procedural:hairball,count=4,segments=10");
  EXPECT_FALSE(opaque.any_partial());
  EXPECT_EQ(opaque.content_hash(),
            make_procedural("procedural:hairball,count=4,segments=10,transmit=0").content_hash());
  const Scene hair = make_procedural("procedural:hairball,count=4,segments=10,transmit=0.7");
  EXPECT_TRUE(hair.any_partial());
  EXPECT_EQ(hair.triangles, opaque.triangles);
  for (const Mesh& m : hair.meshes) EXPECT_EQ(m.transmit, (Rgb{0.7f, 0.7f, 0.7f}));
  EXPECT_NE(hair.content_hash(), opaque.content_hash());
  EXPECT_TRUE(opaque_part(hair).triangles.empty());
  EXPECT_THROW(make_procedural("procedural:hairball,transmit=1.5"), Error);
}

TEST(ProceduralPartial, ForestHasAlphaTestedCardsAndOpaqueTrunks) {
  const std::string spec = "procedural:forest,trees=3,leaves=20,size=12,translucency=0.5";
  const Scene s = make_procedural(spec);
  EXPECT_EQ(s.content_hash(), make_procedural(spec).content_hash());
  EXPECT_NE(s.content_hash(), make_procedural(spec + ",seed=2").content_hash());
  ASSERT_EQ(s.alpha_textures.size(), 1u);
  s.alpha_textures[0].validate();
  EXPECT_TRUE(s.alpha_textures[0].solid(0.5f, 0.5f));   // the leaf's middle
  EXPECT_FALSE(s.alpha_textures[0].solid(0.02f, 0.02f));  // its corner
  ASSERT_EQ(s.triangle_uv.size(), s.triangles.size());
  size_t cards = 0, trunks = 0;
  for (const Mesh& m : s.meshes) {
    if (m.alpha_texture == 0) {
      ++cards;
      EXPECT_EQ(m.triangle_count, 40u);
      EXPECT_EQ(m.transmit, (Rgb{0.15f, 0.5f, 0.1f}));
    } else {
      EXPECT_FALSE(m.partial()) << m.name;
      trunks += m.closed;
    }
  }
  EXPECT_EQ(cards, 3u);
  EXPECT_EQ(trunks, 3u);
  const Scene o = opaque_part(s);
  EXPECT_EQ(o.triangles.size(), s.triangles.size() - 3 * 40);
  EXPECT_FALSE(o.any_partial());
}

TEST(ProceduralPartial, SmokeIsAValidVolumeScaledWithTheScene) {
  const Scene s = make_procedural("procedural:smoke,res=8,size=4");
  ASSERT_EQ(s.volumes.size(), 1u);
  s.volumes[0].validate();
  EXPECT_TRUE(s.any_partial());
  EXPECT_EQ(s.volumes[0].density.size(), 512u);
  float most = 0;
  for (float d : s.volumes[0].density) most = std::max(most, d);
  EXPECT_GT(most, 0.5f);
  EXPECT_NE(s.content_hash(), make_procedural("procedural:smoke,res=8,size=4,seed=3").content_hash());
  const Scene big = make_procedural("procedural:smoke,res=8,size=4,scale=2,ox=10");
  EXPECT_DOUBLE_EQ(big.volumes[0].bounds.lo.x, s.volumes[0].bounds.lo.x * 2 + 10);
  EXPECT_DOUBLE_EQ(big.volumes[0].bounds.hi.y, s.volumes[0].bounds.hi.y * 2);
  EXPECT_TRUE(opaque_part(s).volumes.empty());
}

}  // namespace
}  // namespace st
