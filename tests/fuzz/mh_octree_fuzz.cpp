// libFuzzer harness for the MH octree reader (tiles/core/mh_octree.hpp, MHOCT.md).
// Input: an encoded octree buffer. Contract: MhOctree::open validates the whole buffer
// or throws st::FormatError; a buffer it accepts must answer depth() at every level and
// slice (in range or not) without reading out of bounds, deterministically, and the
// shared soft-shadow walk (stack_lookup.hpp) must equal independent lookups on it (also
// where blocks are shared: nodes reached through more than one parent).
#include <span>
#include <string>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/fuzz_harness.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/stack_lookup.hpp"

namespace {

// Small stacks of each shape: cubic, shallower and deeper than wide, N not a power of
// two (37: more than one run of the soft lookups' batched transforms); random intervals
// and slowly sliding ones (coherent along w).
st::IntervalStack seed_stack(uint32_t level, uint32_t slices, uint64_t seed, bool coherent) {
  st::IntervalStack s{level, slices, {}};
  s.data.resize(size_t(s.side() * s.side()) * slices);
  st::Rng rng(seed);
  for (uint32_t w = 0; w < slices; ++w)
    for (uint64_t y = 0; y < s.side(); ++y)
      for (uint64_t x = 0; x < s.side(); ++x) {
        float a = float(rng.uniform()), b = float(rng.uniform());
        if (coherent) a = (x + w / 2 < s.side() / 2 && y > s.side() / 3) ? 0.3f : 0.8f, b = a + 0.05f;
        s.at(x, y, w) = {std::min(a, b), std::max(a, b)};
      }
  return s;
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  const std::pair<uint32_t, uint32_t> shapes[] = {{0, 1}, {1, 2}, {2, 4}, {3, 3}, {3, 8}, {1, 8}, {4, 2}, {4, 5}, {2, 37}};
  uint64_t seed = 1;
  for (auto [level, slices] : shapes)
    for (bool coherent : {false, true}) out.push_back(encode_octree(build_octree(seed_stack(level, slices, seed++, coherent))));
  // A 4x4 pattern repeated over 16x16 slices: shared blocks (version 2), backward and forward.
  st::IntervalStack periodic = seed_stack(4, 3, 99, false);
  for (uint32_t w = 0; w < 3; ++w)
    for (uint64_t y = 0; y < 16; ++y)
      for (uint64_t x = 0; x < 16; ++x) periodic.at(x, y, w) = periodic.at(x % 4, y % 4, 0);
  out.push_back(encode_octree(build_octree(periodic)));
  // MHOCT.md's far-word example (version 3; the encoder uses far words only in trees of
  // more than 32767 words): quadrant 1 reaches the shared leaf through the far word 4.
  out.push_back({'S', 'T', 'O', 'C', 3, 0, 2, 0, 1, 0, 0, 0, 4, 0, 0, 0, 48, 0, 0, 0, 0, 0, 0, 0,
                 0x0A, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00, 0x3F, 0x01, 0x00, 0x03, 0x00, 0x01, 0x00, 0x00, 0x80,
                 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3E});
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);  // exact size: ASan sees overreads
  st::MhOctree tree;
  try {
    tree = st::MhOctree::open(std::span<const std::uint8_t>(bytes.data(), bytes.size()));
  } catch (const st::FormatError&) {
    return 0;
  }
  st::fuzz::note_accepted();
  const uint64_t h = st::fuzz::input_hash(data, size);
  const uint32_t n = tree.xy_level();
  for (uint32_t q = 0; q <= std::min(n + 1, 20u); ++q) {
    const uint64_t side = uint64_t(1) << q;
    for (uint32_t i = 0; i < 8; ++i) {
      const uint64_t x = (i & 1) ? side - 1 : (h >> (4 * i)) % side, y = (i & 2) ? side - 1 : (h >> (4 * i + 2)) % side;
      const uint32_t w = (i & 4) ? tree.slices() - 1 : uint32_t((h >> (3 * i)) % (tree.slices() + 1));
      const float v = tree.depth(x, y, w, q);
      FUZZ_CHECK(std::bit_cast<uint32_t>(v) == std::bit_cast<uint32_t>(tree.depth(x, y, w, q)));
      if (w >= tree.slices()) FUZZ_CHECK(v == st::kLitDepth);
    }
  }
  // The shared walk against independent ones, under a sun path and under a jittered area
  // light (windowed spots: the batched transforms of sample_texels.hpp, runs of 32 samples
  // and a shorter last one), each fitted to a unit box.
  if (tree.slices() <= 64) {
    st::Aabb box;
    box.extend({-1, -1, -1});
    box.extend({1, 1, 1});
    const std::string samples = ",samples=" + std::to_string(tree.slices());
    const st::StackBounds bounds(tree);
    for (const char* light :
         {"sun-path:azimuth=0..90,elevation=30..60", "area:pos=0.3,4,0.2,target=0,0,0,size=1,1,jitter=0.5"}) {
      const st::LightSet set = st::LightSet::fit(st::LightSetSpec::parse(light + samples), box);
      const st::StackLookup look(tree, set);
      st::Rng rng(h);
      st::Vec3d pts[20];
      for (st::Vec3d& p : pts) p = {rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
      for (int i = 0; i < 4; ++i) {
        const st::Vec3d& p = pts[i];
        FUZZ_CHECK(look.soft_visibility(p) == look.soft_visibility_independent(p));
        FUZZ_CHECK(look.soft_visibility_bounded(p, bounds) == look.soft_visibility_independent(p));
      }
      float batch[20];
      look.soft_visibility(pts, batch);  // more points than lanes: the interleaved walks
      for (int i = 0; i < 20; ++i) FUZZ_CHECK(batch[i] == look.soft_visibility(pts[i]));
    }
  }
  return 0;
}
