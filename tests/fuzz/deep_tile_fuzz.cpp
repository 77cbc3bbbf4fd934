// libFuzzer harness for the deep shadow tile reader (tiles/core/deep_tile.hpp, DEEP.md).
// Input: byte 0 steers the probes; the rest is the tile buffer. Contract: open() either
// throws st::FormatError or returns a view whose every texel is a valid visibility
// function (check() passes, as decoded), and whose lookups (point, bilinear, trilinear,
// footprint) read nothing out of bounds and answer transmittance in [0, 1] that never
// increases with depth at one texel. Seeds: encode_deep_tile on random functions.
#include <cmath>
#include <random>
#include <span>

#include "common/error.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/encode/deep_encode.hpp"
#include "tiles/core/deep_tile.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<float> u(0, 1);
  for (uint32_t bits = 0; bits <= 3; ++bits)
    for (int variant = 0; variant < 3; ++variant) {
      const uint32_t n = 1u << bits;
      std::vector<VisibilityFunction> fs(size_t(n) * n);
      for (auto& f : fs) {
        f.monochrome = variant != 2;
        std::array<float, 3> t{1, 1, 1};
        float z = 0.05f * u(rng);
        const int steps = variant == 0 ? int(rng() % 2) : int(rng() % 5);
        for (int k = 0; k < steps; ++k) {
          z += 0.2f * u(rng);
          f.vertices.push_back({z, t});
          const float keep = u(rng);
          for (int c = 0; c < 3; ++c) t[c] *= f.monochrome ? keep : u(rng);
          if (rng() % 2) z += 0.03f;
          f.vertices.push_back({z, t});
        }
      }
      Bytes b = encode_deep_tile(fs, bits, variant == 0 ? 0.0 : 0.02);
      b.insert(b.begin(), uint8_t(rng()));
      out.push_back(std::move(b));
    }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const uint8_t control = data[0];
  // An exact-size heap copy, so ASan sees a read one past the end.
  const std::vector<std::uint8_t> bytes(data + 1, data + size);
  st::DeepTileView v;
  try {
    v = st::DeepTileView::open(std::span<const std::uint8_t>(bytes.data(), bytes.size()));
  } catch (const st::FormatError&) {
    return 0;
  }
  st::fuzz::note_accepted();
  auto in_unit = [](const std::array<float, 3>& t) {
    for (float c : t)
      if (!(c >= 0 && c <= 1)) return false;
    return true;
  };
  const uint64_t hash = st::fuzz::input_hash(data, size);
  for (uint32_t m = 0; m < v.mip_count(); ++m) {
    const uint32_t s = v.side(m);
    // Every texel of small mips, a few of large ones.
    const uint32_t step = s <= 16 ? 1 : s / 7;
    for (uint32_t y = 0; y < s; y += step)
      for (uint32_t x = 0; x < s; x += step) {
        const st::VisibilityFunction f = v.function(x, y, m);
        FUZZ_CHECK(f.check().empty());
        FUZZ_CHECK(f.vertices.size() == v.vertex_count(x, y, m));
        float prev[3] = {2, 2, 2};
        for (float z : {-1.0f, 0.0f, 0.25f, 0.5f, 0.75f, 1.0f, 2.0f}) {
          const auto t = v.transmittance(x, y, z, m);
          FUZZ_CHECK(in_unit(t));
          for (int c = 0; c < 3; ++c) {
            FUZZ_CHECK(t[c] <= prev[c]);
            prev[c] = t[c];
          }
        }
      }
  }
  const double pu = double(hash & 0xFFFF) / 65536.0, pv = double((hash >> 16) & 0xFFFF) / 65536.0;
  const float z = float((hash >> 32) & 0xFFFF) / 65536.0f;
  FUZZ_CHECK(in_unit(v.bilinear(pu, pv, z, control % v.mip_count())));
  FUZZ_CHECK(in_unit(v.trilinear(pu, pv, z, double(control) / 16.0)));
  FUZZ_CHECK(in_unit(v.trilinear(pu, pv, z, NAN)));
  FUZZ_CHECK(in_unit(v.filtered(pu, pv, z, double(control) / 64.0)));
  FUZZ_CHECK(in_unit(v.filtered(-5, 7, z, 1e300)));
  return 0;
}
