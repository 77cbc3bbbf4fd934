// Deep shadow map benchmark (DSM 2000 §4, §6, Figure 8): for the paper's cases (a
// semi-transparent hairball, alpha-tested leaf cards, smoke) and N = S^2 samples per
// texel at the paper's tolerance epsilon = 0.25 / sqrt(N), a 32 x 32 block of a level-7
// map is sampled and encoded as one deep tile (mips included). Per row: vertices per
// non-empty texel before and after compression, the tile's bytes, sampling time, lookup
// time (point and trilinear, ns), and the error of mip-0 lookups against a reference
// texel of 32 x 32 = 1024 samples (uncompressed) at random depths; a fit of vertices per
// texel against N (the paper finds O(N^1/4) for smooth functions); and for the leaves
// the opaque alternative of DSM 2000 Figure 6: a finer depth map with PCF.
//
//   bench_deep [--quick] [--json PATH]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "tiles/bake/deep_sampler.hpp"
#include "tiles/encode/deep_encode.hpp"
#include "tiles/core/deep_tile.hpp"

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string json_path;
  st::bench::Options opt("bench_deep", "Deep shadow maps (DSM 2000): vertices per texel, tile bytes, sampling and lookup time, error");
  opt.flag("--quick", quick, "N up to 64 samples per texel and fewer error probes").value("--json", json_path, "Write the rows as JSON to PATH");
  opt.parse(argc, argv);
  const uint32_t level = 7, bits = 5, side = 1u << bits;
  const uint64_t x0 = 48, y0 = 48;
  const std::vector<std::pair<std::string, std::string>> scenes = {
      {"hair", "procedural:hairball,transmit=0.5"},
      {"leaves", "procedural:forest,trees=9,leaves=300"},
      {"smoke", "procedural:smoke"}};
  std::vector<uint32_t> sides = {2, 4, 8, 16};
  if (quick) sides = {2, 4, 8};
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-7s %5s %8s %10s %10s %9s %8s %9s %9s %9s %9s\n", "scene", "N", "epsilon",
              "v/texel in", "v/texel out", "bytes", "trace s", "point ns", "tri ns", "max err",
              "mean err");
  for (const auto& [name, spec] : scenes) {
    const st::Scene scene = st::make_procedural(spec);
    const st::LightSpace light =
        st::LightSpace::fit(st::LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
    const st::DeepSampler sampler(scene, light);
    // The reference: 1024 samples per texel, uncompressed, for 64 random texels.
    std::mt19937_64 rng(5);
    struct Probe {
      uint32_t i, j;
      st::VisibilityFunction ref;
    };
    std::vector<Probe> probes;
    st::DeepSampleOptions ref_o;
    ref_o.samples_per_side = 32;
    ref_o.seed = 99;
    for (int k = 0; k < (quick ? 16 : 64); ++k) {
      const uint32_t i = uint32_t(rng() % side), j = uint32_t(rng() % side);
      probes.push_back({i, j, sampler.texel(level, x0 + i, y0 + j, ref_o, false)});
    }
    std::vector<double> log_n, log_v;
    for (uint32_t s : sides) {
      st::DeepSampleOptions o;
      o.samples_per_side = s;
      const double eps = o.effective_epsilon();
      st::DeepSampleStats stats;
      const double t0 = now();
      const st::DeepRegion region = sampler.trace({level, x0, y0, side, side}, o, &stats, false);
      std::vector<st::VisibilityFunction> packed(region.functions.size());
      uint64_t in_v = 0, out_v = 0, non_empty = 0;
      for (size_t k = 0; k < packed.size(); ++k) {
        packed[k] = st::compress(region.functions[k], eps);
        if (region.functions[k].vertices.empty()) continue;
        ++non_empty;
        in_v += region.functions[k].vertices.size();
        out_v += packed[k].vertices.size();
      }
      const double trace_s = now() - t0;
      st::DeepEncodeStats es;
      const std::vector<uint8_t> tile = st::encode_deep_tile(packed, bits, eps, &es);
      const st::DeepTileView view = st::DeepTileView::open(tile);
      // Lookup timing: 2^20 random point and trilinear lookups.
      std::uniform_real_distribution<double> u(0, 1);
      const int lookups = 1 << 20;
      std::vector<std::array<double, 3>> at(4096);
      for (auto& p : at) p = {u(rng), u(rng), u(rng)};
      float sink = 0;
      double t1 = now();
      for (int k = 0; k < lookups; ++k) {
        const auto& p = at[size_t(k) & 4095];
        sink += view.transmittance(uint32_t(p[0] * side), uint32_t(p[1] * side), float(p[2]), 0)[0];
      }
      const double point_ns = (now() - t1) / lookups * 1e9;
      t1 = now();
      for (int k = 0; k < lookups; ++k) {
        const auto& p = at[size_t(k) & 4095];
        sink += view.trilinear(p[0], p[1], float(p[2]), 1.5)[0];
      }
      const double tri_ns = (now() - t1) / lookups * 1e9;
      // Error of mip-0 lookups against the reference texels at random depths.
      double max_err = 0, sum_err = 0;
      uint64_t n_err = 0;
      for (const Probe& pr : probes)
        for (int k = 0; k < 64; ++k) {
          const float z = float(u(rng));
          const auto got = view.transmittance(pr.i, pr.j, z, 0);
          const auto ref = pr.ref.eval(z);
          for (int c = 0; c < 3; ++c) {
            const double e = std::fabs(double(got[c]) - ref[c]);
            max_err = std::max(max_err, e);
            sum_err += e;
            ++n_err;
          }
        }
      const double vin = non_empty ? double(in_v) / non_empty : 0, vout = non_empty ? double(out_v) / non_empty : 0;
      std::printf("%-7s %5u %8.4f %10.2f %10.2f %9zu %8.2f %9.1f %9.1f %9.4f %9.5f%s\n", name.c_str(),
                  s * s, eps, vin, vout, tile.size(), trace_s, point_ns, tri_ns, max_err,
                  sum_err / double(n_err), sink < 0 ? " " : "");
      if (vout > 0) {
        log_n.push_back(std::log(double(s * s)));
        log_v.push_back(std::log(vout));
      }
      rows.push_back({{"scene", name}, {"spec", spec}, {"samples", s * s}, {"epsilon", eps},
                      {"vertices_per_texel_in", vin}, {"vertices_per_texel_out", vout},
                      {"non_empty_texels", non_empty}, {"tile_bytes", tile.size()},
                      {"trace_seconds", trace_s}, {"point_lookup_ns", point_ns},
                      {"trilinear_lookup_ns", tri_ns}, {"max_error", max_err},
                      {"mean_error", sum_err / double(n_err)}});
    }
    // DSM 2000 Figure 6 in our setting, for the alpha-tested leaves (each sample's
    // function is one step to 0, so an opaque depth map represents it exactly): a depth
    // map s times finer than the deep map, filtered with s x s PCF per deep texel (the
    // same number of samples as a deep map of N = s^2), its bytes and lookup time, and
    // its error against the same reference texels.
    if (name == "leaves") {
      for (uint32_t s : sides) {
        const uint32_t fine = side * s;
        std::vector<float> depth(size_t(fine) * fine, 1.0f);
        const double inv = std::ldexp(1.0, -int(level)) / s;
        for (uint32_t j = 0; j < fine; ++j)
          for (uint32_t i = 0; i < fine; ++i) {
            const st::VisibilityFunction f =
                sampler.ray_function(double(x0) / (1u << level) + (i + 0.5) * inv,
                                     double(y0) / (1u << level) + (j + 0.5) * inv);
            for (const st::VisVertex& v : f.vertices)
              if (f.eval_after(v.depth)[0] < 0.5f) {
                depth[size_t(j) * fine + i] = v.depth;
                break;
              }
          }
        std::uniform_real_distribution<double> u(0, 1);
        auto pcf = [&](uint32_t ti, uint32_t tj, float z) {
          uint32_t lit = 0;
          for (uint32_t b = 0; b < s; ++b)
            for (uint32_t a = 0; a < s; ++a) lit += z <= depth[size_t(tj * s + b) * fine + ti * s + a];
          return float(lit) / float(s * s);
        };
        double max_err = 0, sum_err = 0;
        uint64_t n_err = 0;
        for (const Probe& pr : probes)
          for (int k = 0; k < 64; ++k) {
            const float z = float(u(rng));
            const double e = std::fabs(double(pcf(pr.i, pr.j, z)) - pr.ref.eval(z)[0]);
            max_err = std::max(max_err, e), sum_err += e, ++n_err;
          }
        const int lookups = 1 << 18;
        std::vector<std::array<double, 3>> at(4096);
        for (auto& p : at) p = {u(rng), u(rng), u(rng)};
        float sink = 0;
        const double t1 = now();
        for (int k = 0; k < lookups; ++k) {
          const auto& p = at[size_t(k) & 4095];
          sink += pcf(uint32_t(p[0] * side), uint32_t(p[1] * side), float(p[2]));
        }
        const double ns = (now() - t1) / lookups * 1e9;
        const size_t bytes = depth.size() * sizeof(float);
        std::printf("%-7s opaque depth map %ux finer, %ux%u PCF: %9zu bytes, %7.1f ns a lookup, "
                    "max err %.4f, mean err %.5f%s\n",
                    name.c_str(), s, s, s, bytes, ns, max_err, sum_err / double(n_err), sink < 0 ? " " : "");
        rows.push_back({{"scene", name}, {"opaque_pcf_side", s}, {"samples", s * s}, {"bytes", bytes},
                        {"lookup_ns", ns}, {"max_error", max_err}, {"mean_error", sum_err / double(n_err)}});
      }
    }
    // Least-squares slope of log(vertices) against log(N).
    if (log_n.size() >= 2) {
      double mn = 0, mv = 0;
      for (size_t k = 0; k < log_n.size(); ++k) mn += log_n[k], mv += log_v[k];
      mn /= double(log_n.size()), mv /= double(log_n.size());
      double num = 0, den = 0;
      for (size_t k = 0; k < log_n.size(); ++k) num += (log_n[k] - mn) * (log_v[k] - mv), den += (log_n[k] - mn) * (log_n[k] - mn);
      std::printf("%-7s vertices per texel grow as N^%.3f (paper: N^0.25 for smooth functions)\n",
                  name.c_str(), num / den);
      rows.push_back({{"scene", name}, {"growth_exponent", num / den}});
    }
  }
  if (!json_path.empty()) {
    std::ofstream f(json_path);
    f << nlohmann::json{{"benchmark", "deep"}, {"level", level}, {"block", side}, {"rows", rows}}.dump(2) << "\n";
    std::printf("wrote %s\n", json_path.c_str());
  }
  return 0;
}
