// The consumer and C API tests' reference, read locally with the pack evaluator:
//   pack_probe PACK LEVEL             every texel of one level ("x y bits", bits in hex)
//   pack_probe PACK points N SEED     N world points ("x y z") for the lookups to answer:
//                                     on texel rays of the finest level just above, at
//                                     and below the stored depth (lit and shadowed both
//                                     occur), anywhere along the ray, and a few outside
//                                     the light's box
//   pack_probe PACK visibility        reads "x y z" lines on stdin, prints each point's
//                                     single-tap visibility (pcf_side 1) as hex bits:
//                                     lit outside the light's box, else d <= depth of the
//                                     finest texel under it (client.hpp's contract)
#include <bit>
#include <cstdio>
#include <exception>
#include <memory>
#include <random>
#include <string>

#include "tiles/core/light.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace {

int print_level(const st::PackEvaluator& ev, uint32_t level) {
  const uint64_t side = uint64_t(1) << level;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x)
      std::printf("%llu %llu %08x\n", (unsigned long long)x, (unsigned long long)y,
                  std::bit_cast<uint32_t>(ev.depth(level, x, y)));
  return 0;
}

int print_points(const st::PackReader& reader, const st::PackEvaluator& ev, unsigned n, unsigned seed) {
  const st::LightSpace light = reader.light();
  const uint32_t L = reader.map_level();
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<uint64_t> texel(0, (uint64_t(1) << L) - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (unsigned i = 0; i < n; ++i) {
    const uint64_t x = texel(rng), y = texel(rng);
    const st::LightRay ray = light.texel_ray(L, x, y);
    const double depth = ev.depth(L, x, y);
    double t;
    switch (i % 8) {
      case 0: t = depth - 1e-3; break;
      case 1: t = depth + 1e-3; break;
      case 2: t = depth; break;
      case 7: t = i % 16 == 7 ? -0.5 : 1.5; break;  // before near / past far: outside the box
      default: t = unit(rng); break;
    }
    const st::Vec3d p = ray.origin + ray.dir * t;
    std::printf("%.17g %.17g %.17g\n", p.x, p.y, p.z);
  }
  return 0;
}

int print_visibility(const st::PackReader& reader, const st::PackEvaluator& ev) {
  const st::LightSpace light = reader.light();
  const uint32_t L = reader.map_level();
  double x, y, z;
  while (std::scanf("%lf %lf %lf", &x, &y, &z) == 3) {
    const st::LightPoint p = light.to_light({x, y, z});
    float v = 1.0f;
    if (p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1 && p.d >= 0 && p.d <= 1) {
      const auto t = st::LightSpace::texel_of(L, p.u, p.v);
      v = float(p.d) <= ev.depth(L, t[0], t[1]) ? 1.0f : 0.0f;
    }
    std::printf("%08x\n", std::bit_cast<uint32_t>(v));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc >= 3 ? argv[2] : "";
  if (!(argc == 3 || (argc == 5 && mode == "points"))) {
    std::fprintf(stderr, "usage: pack_probe PACK LEVEL | PACK points N SEED | PACK visibility\n");
    return 2;
  }
  try {
    std::shared_ptr<const st::PackReader> reader(st::PackReader::open(argv[1]));
    st::PackEvaluator ev(reader);
    if (mode == "points") return print_points(*reader, ev, unsigned(std::stoul(argv[3])), unsigned(std::stoul(argv[4])));
    if (mode == "visibility") return print_visibility(*reader, ev);
    return print_level(ev, uint32_t(std::stoul(mode)));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pack_probe: error: %s\n", e.what());
    return 1;
  }
}
