// Grid scenes: see scene_grid.hpp.
#include "scene/scene_grid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

constexpr const char* kGridPrefix = "grid:";
constexpr uint32_t kMaxCells = 4096;  // a side

struct GridSpec {
  std::vector<std::string> files;
  uint32_t n = 8;
  double gap = 0.25;
  uint64_t seed = 1;
  bool rotate = true, ground = true;
};

[[noreturn]] void grid_fail(const std::string& spec, const std::string& why) {
  throw Error("grid scene '" + spec + "': " + why);
}

bool parse_flag(const std::string& spec, const std::string& key, const std::string& v) {
  if (v == "yes" || v == "1" || v == "true") return true;
  if (v == "no" || v == "0" || v == "false") return false;
  grid_fail(spec, key + " expects yes or no, got '" + v + "'");
}

double parse_number(const std::string& spec, const std::string& key, const std::string& v, double lo, double hi) {
  char* end = nullptr;
  const double x = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(x) || x < lo || x > hi)
    grid_fail(spec, key + " expects a number in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" + v + "'");
  return x;
}

GridSpec parse(const std::string& spec) {
  GridSpec g;
  const std::string body = spec.substr(std::string(kGridPrefix).size());
  const size_t comma = body.find(',');
  const std::string list = body.substr(0, comma);
  if (list.empty()) grid_fail(spec, "no file (grid:FILE[|FILE...][,key=value...])");
  for (size_t p = 0;;) {
    const size_t bar = list.find('|', p);
    const std::string f = list.substr(p, bar == std::string::npos ? std::string::npos : bar - p);
    if (f.empty()) grid_fail(spec, "an empty file name in the list");
    if (is_grid_spec(f)) grid_fail(spec, "a grid cannot hold a grid ('" + f + "')");
    g.files.push_back(f);
    if (bar == std::string::npos) break;
    p = bar + 1;
  }
  std::string rest = comma == std::string::npos ? "" : body.substr(comma + 1);
  while (!rest.empty()) {
    const size_t next = rest.find(',');
    const std::string kv = rest.substr(0, next);
    rest = next == std::string::npos ? "" : rest.substr(next + 1);
    const size_t eq = kv.find('=');
    if (eq == std::string::npos) grid_fail(spec, "expected key=value, got '" + kv + "'");
    const std::string k = kv.substr(0, eq), v = kv.substr(eq + 1);
    if (k == "n") g.n = uint32_t(parse_number(spec, k, v, 1, kMaxCells));
    else if (k == "gap") g.gap = parse_number(spec, k, v, 0, 10);
    else if (k == "seed") g.seed = uint64_t(parse_number(spec, k, v, 0, 9007199254740992.0));
    else if (k == "rotate") g.rotate = parse_flag(spec, k, v);
    else if (k == "ground") g.ground = parse_flag(spec, k, v);
    else grid_fail(spec, "unknown key '" + k + "' (n, gap, seed, rotate, ground)");
    if (k == "n" && double(g.n) != std::strtod(v.c_str(), nullptr)) grid_fail(spec, "n expects a whole number, got '" + v + "'");
  }
  return g;
}

uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Appends `src` turned `quarter` quarter turns about +Y and moved by `shift` to `out`.
void append_copy(Scene& out, const Scene& src, int quarter, const Vec3d& shift, const std::string& tag) {
  const uint32_t v0 = uint32_t(out.vertices.size()), t0 = uint32_t(out.triangles.size());
  const int32_t a0 = int32_t(out.alpha_textures.size());
  for (const Vec3d& p : src.vertices) {
    Vec3d q = p;
    for (int k = 0; k < quarter; ++k) q = Vec3d{q.z, q.y, -q.x};  // exact: no rounding
    out.vertices.push_back(q + shift);
  }
  for (const auto& t : src.triangles) out.triangles.push_back({t[0] + v0, t[1] + v0, t[2] + v0});
  for (const Mesh& m : src.meshes) {
    Mesh c = m;
    c.name = m.name + "@" + tag;
    c.first_triangle = m.first_triangle + t0;
    if (m.alpha_texture >= 0) c.alpha_texture = m.alpha_texture + a0;
    out.meshes.push_back(std::move(c));
  }
  for (const AlphaTexture& a : src.alpha_textures) out.alpha_textures.push_back(a);
  if (!src.triangle_uv.empty() || !out.triangle_uv.empty()) {
    out.triangle_uv.resize(t0);
    if (src.triangle_uv.empty()) out.triangle_uv.resize(out.triangles.size());
    else out.triangle_uv.insert(out.triangle_uv.end(), src.triangle_uv.begin(), src.triangle_uv.end());
  }
  out.stats.degenerate_dropped += src.stats.degenerate_dropped;
  out.stats.meshes_flipped += src.stats.meshes_flipped;
}

}  // namespace

bool is_grid_spec(const std::string& spec) { return spec.rfind(kGridPrefix, 0) == 0; }

Scene load_grid_scene(const std::string& spec, const SceneOptions& options, const SceneLimits& limits) {
  const GridSpec g = parse(spec);
  std::vector<Scene> assets;
  double cell = 0;
  uint64_t per_cell_max = 0;
  for (const std::string& f : g.files) {
    Scene s = load_scene(f, options, limits);
    if (!s.volumes.empty()) grid_fail(spec, "'" + f + "' has volumes; a grid copies surfaces only");
    if (s.triangles.empty()) grid_fail(spec, "'" + f + "' has no triangles");
    const Aabb b = s.bounds();
    // Centred on its footprint, standing on y = 0.
    const Vec3d c{(b.lo.x + b.hi.x) / 2, b.lo.y, (b.lo.z + b.hi.z) / 2};
    for (Vec3d& p : s.vertices) p = p - c;
    cell = std::max({cell, b.hi.x - b.lo.x, b.hi.z - b.lo.z});
    per_cell_max = std::max<uint64_t>(per_cell_max, s.triangles.size());
    assets.push_back(std::move(s));
  }
  if (!(cell > 0)) grid_fail(spec, "the files have no horizontal extent");
  cell *= 1 + g.gap;
  const uint64_t cells = uint64_t(g.n) * g.n;
  if (per_cell_max * cells + 2 > limits.max_triangles)
    grid_fail(spec, "up to " + std::to_string(per_cell_max * cells + 2) + " triangles exceed the budget of " +
                   std::to_string(limits.max_triangles) + " (raise --scene-limits triangles=N)");
  Scene out;
  out.name = spec;
  out.up = UpAxis::y;
  out.up_reason = "each file as it was read";
  for (uint32_t j = 0; j < g.n; ++j)
    for (uint32_t i = 0; i < g.n; ++i) {
      const uint64_t h = splitmix64(g.seed ^ splitmix64((uint64_t(j) << 32) | i));
      const Scene& a = assets[h % assets.size()];
      const int quarter = g.rotate ? int((h >> 32) & 3) : 0;
      append_copy(out, a, quarter, Vec3d{(i + 0.5) * cell, 0, (j + 0.5) * cell},
                  std::to_string(i) + "," + std::to_string(j));
    }
  if (g.ground) {
    const double e = g.n * cell;
    const uint32_t v0 = uint32_t(out.vertices.size());
    out.vertices.insert(out.vertices.end(), {Vec3d{0, 0, 0}, Vec3d{0, 0, e}, Vec3d{e, 0, e}, Vec3d{e, 0, 0}});
    Mesh m;
    m.name = "grid/ground";
    m.first_triangle = uint32_t(out.triangles.size());
    m.triangle_count = 2;
    out.triangles.push_back({v0, v0 + 1, v0 + 2});  // facing +Y
    out.triangles.push_back({v0, v0 + 2, v0 + 3});
    out.meshes.push_back(m);
    if (!out.triangle_uv.empty()) out.triangle_uv.resize(out.triangles.size());
  }
  return out;
}

}  // namespace st
