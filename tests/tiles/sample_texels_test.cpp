// The batched light-space transforms of the soft lookups (tiles/core/sample_texels.hpp):
// every run of 1..32 samples gives, lane for lane, LightSpace::to_light's texel and depth
// bit for bit, in every frame a light set makes (ground and ortho sun paths, windowed and
// translated area lights, jittered) and in a set mixing kinds.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>

#include "common/hash.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/sample_texels.hpp"

namespace st {
namespace {

Aabb town_box() {
  Aabb b;
  b.extend({-10, 0, -8});
  b.extend({12, 6, 9});
  return b;
}

std::vector<LightSpace> samples_of(const std::string& spec) {
  return LightSet::fit(LightSetSpec::parse(spec), town_box()).samples;
}

// "" when run [w0, w0 + n) equals the scalar path, else the first difference.
std::string run_mismatch(const SampleTexels& st, const std::vector<LightSpace>& samples, const Vec3d& p, uint32_t w0,
                         uint32_t n) {
  SampleTexels::Run run;
  st.run(p, w0, n, run);
  for (uint32_t i = 0; i < n; ++i) {
    const LightPoint lp = samples[w0 + i].to_light(p);
    const auto t = LightSpace::texel_of(st.level(), lp.u, lp.v);
    const float d = float(lp.d);
    if (run.x[i] != t[0] || run.y[i] != t[1] || std::bit_cast<uint32_t>(run.d[i]) != std::bit_cast<uint32_t>(d))
      return "sample " + std::to_string(w0 + i) + " (run " + std::to_string(w0) + "+" + std::to_string(n) + "): (" +
             std::to_string(run.x[i]) + ", " + std::to_string(run.y[i]) + ", " + std::to_string(run.d[i]) +
             ") against (" + std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " + std::to_string(d) + ")";
  }
  return "";
}

TEST(SampleTexels, RunsEqualToLightAndTexelOfBitForBit) {
  std::vector<std::pair<std::string, std::vector<LightSpace>>> sets;
  for (const char* spec : {"sun-path:azimuth=100..260,elevation=25..65,samples=37",
                           "sun-path:azimuth=30..200,elevation=12..80,samples=64,frame=ortho",
                           "area:pos=2,14,1,target=0,0,0,size=3,3,samples=64",
                           "area:pos=-3,20,4,target=1,0,-1,size=5,2,samples=33,jitter=0.8,seed=7",
                           "area:pos=2,14,1,target=0,0,0,size=3,3,samples=20,frame=translate,jitter=0.5"})
    sets.emplace_back(spec, samples_of(spec));
  {  // a hand-made set mixing kinds: the scalar path
    std::vector<LightSpace> mixed = samples_of("sun-path:azimuth=100..160,elevation=30..50,samples=9");
    for (const LightSpace& l : samples_of("area:pos=2,14,1,target=0,0,0,size=3,3,samples=9")) mixed.push_back(l);
    sets.emplace_back("mixed", mixed);
  }
  const Aabb b = town_box();
  Rng rng(11);
  for (const auto& [name, samples] : sets) {
    const uint32_t N = uint32_t(samples.size());
    for (uint32_t level : {0u, 5u, 11u, 20u, SampleTexels::kMaxLevel}) {
      const SampleTexels st(samples, level);
      ASSERT_EQ(st.size(), N);
      std::vector<Vec3d> points;
      for (int i = 0; i < 120; ++i)  // inside the box and well beyond it (clamped texels)
        points.push_back({rng.uniform(b.lo.x - 20, b.hi.x + 20), rng.uniform(b.lo.y - 5, b.hi.y + 30),
                          rng.uniform(b.lo.z - 20, b.hi.z + 20)});
      points.push_back({0, 0, 0});
      points.push_back(samples[0].origin());  // a spot's eye: z = 0
      points.push_back({std::numeric_limits<double>::quiet_NaN(), 1, 1});
      points.push_back({1e30, -1e30, 3});
      for (size_t i = 0; i < points.size(); ++i)
        for (uint32_t n = 1; n <= std::min(SampleTexels::kRun, N); ++n) {
          const uint32_t starts[3] = {0, N - n, uint32_t(rng.next() % (N - n + 1))};
          for (uint32_t w0 : starts)
            ASSERT_EQ(run_mismatch(st, samples, points[i], w0, n), "") << name << " level " << level << " point " << i;
        }
    }
  }
}

}  // namespace
}  // namespace st
