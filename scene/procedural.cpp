// make_procedural: spec parsing, the common scale/offset keys and the small test scenes
// (cube, sphere, plane, boxes). The big scenes live in procedural_{city,terrain,hairball}.cpp,
// the partial occluders (forest, smoke) in procedural_partial.cpp.
#include "scene/procedural.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>

#include "common/error.hpp"

namespace st {
namespace procedural {
namespace {

constexpr const char* kPrefix = "procedural:";
constexpr double kTiny = std::numeric_limits<double>::min();

std::string strip_prefix(const std::string& spec) {
  const std::string p = kPrefix;
  return spec.rfind(p, 0) == 0 ? spec.substr(p.size()) : spec;
}

std::vector<MeshSoup> make_cube(Params& p) {
  const double h = p.real("size", 1.0, kTiny, 1e12) / 2;
  p.finish();
  MeshSoup m{"cube", {}, {}};
  add_box(m, {-h, -h, -h}, {h, h, h});
  return {std::move(m)};
}

std::vector<MeshSoup> make_sphere(Params& p) {
  const double r = p.real("radius", 1.0, kTiny, 1e12);
  const int segments = static_cast<int>(p.integer("segments", 32, 3, 4096));
  p.finish();
  MeshSoup m{"sphere", {}, {}};
  add_uv_sphere(m, {0, 0, 0}, r, segments);
  return {std::move(m)};
}

std::vector<MeshSoup> make_plane(Params& p) {
  const double h = p.real("size", 10.0, kTiny, 1e12) / 2;
  p.finish();
  MeshSoup m{"plane", {}, {}};
  // Facing +Y (counter-clockwise seen from above).
  uint32_t a = add_vertex(m, {-h, 0, -h}), b = add_vertex(m, {-h, 0, h});
  uint32_t c = add_vertex(m, {h, 0, h}), d = add_vertex(m, {h, 0, -h});
  add_quad(m, a, b, c, d);
  return {std::move(m)};
}

// Exit-depth cases (ARCHITECTURE.md "Definitions"): overlapping solids (the counter reaches
// 2 inside both) and a solid nested inside another.
std::vector<MeshSoup> make_boxes(Params& p) {
  p.finish();
  std::vector<MeshSoup> out(4);
  out[0].name = "box_a", out[1].name = "box_b", out[2].name = "outer", out[3].name = "inner";
  add_box(out[0], {-3, 0, -1}, {-1, 2, 1});
  add_box(out[1], {-2, 1, -0.5}, {0, 3, 1.5});
  add_box(out[2], {1, 0, -2}, {5, 4, 2});
  add_box(out[3], {2, 1, -1}, {4, 3, 1});
  return out;
}

}  // namespace

Params::Params(const std::string& spec) : spec_(spec) {
  const std::string body = strip_prefix(spec);
  size_t pos = 0;
  bool first = true;
  while (pos <= body.size()) {
    size_t end = body.find(',', pos);
    if (end == std::string::npos) end = body.size();
    const std::string item = body.substr(pos, end - pos);
    pos = end + 1;
    if (first) {
      name_ = item;
      first = false;
      if (name_.empty()) fail("missing scene name (procedural:NAME[,key=value...])");
      continue;
    }
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
      fail("expected key=value, got '" + item + "'");
    const std::string key = item.substr(0, eq);
    if (!values_.emplace(key, item.substr(eq + 1)).second) fail("key '" + key + "' given twice");
  }
}

void Params::fail(const std::string& what) const {
  throw Error("procedural scene '" + spec_ + "': " + what);
}

double Params::real(const std::string& key, double fallback, double lo, double hi) {
  asked_.push_back(key);
  auto it = values_.find(key);
  if (it == values_.end()) return fallback;
  const std::string& text = it->second;
  double v = 0;
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(v) || v < lo || v > hi)
    fail("key '" + key + "' = '" + text + "' is not a number in [" + std::to_string(lo) + ", " +
         std::to_string(hi) + "]");
  return v;
}

int64_t Params::integer(const std::string& key, int64_t fallback, int64_t lo, int64_t hi) {
  asked_.push_back(key);
  auto it = values_.find(key);
  if (it == values_.end()) return fallback;
  const std::string& text = it->second;
  int64_t v = 0;
  auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || v < lo || v > hi)
    fail("key '" + key + "' = '" + text + "' is not an integer in [" + std::to_string(lo) + ", " +
         std::to_string(hi) + "]");
  return v;
}

void Params::finish() const {
  for (auto& [key, value] : values_)
    if (std::find(asked_.begin(), asked_.end(), key) == asked_.end()) {
      std::string known;
      for (auto& k : asked_) known += (known.empty() ? "" : ", ") + k;
      fail("unknown key '" + key + "' for '" + name_ + "' (known: " + known + ")");
    }
}

}  // namespace procedural

Scene make_procedural(const std::string& spec) {
  using namespace procedural;
  Params p(spec);
  const std::string& name = p.scene_name();
  // Common keys first; each generator then reads its own and calls p.finish() before
  // generating, so an unknown key fails fast and the "known:" list shows all keys.
  const double scale = p.real("scale", 1.0, kTiny, 1e30);
  const Vec3d offset{p.real("ox", 0.0, -1e30, 1e30), p.real("oy", 0.0, -1e30, 1e30),
                     p.real("oz", 0.0, -1e30, 1e30)};
  std::vector<MeshSoup> meshes;
  PartialExtras extras;
  if (name == "cube")
    meshes = make_cube(p);
  else if (name == "sphere")
    meshes = make_sphere(p);
  else if (name == "plane")
    meshes = make_plane(p);
  else if (name == "boxes")
    meshes = make_boxes(p);
  else if (name == "city")
    meshes = make_city(p);
  else if (name == "terrain")
    meshes = make_terrain(p);
  else if (name == "hairball")
    meshes = make_hairball(p);
  else if (name == "soup")
    meshes = make_soup(p);
  else if (name == "forest")
    meshes = make_forest(p, extras);
  else if (name == "smoke")
    meshes = make_smoke(p, extras);
  else
    throw Error("procedural scene '" + spec + "': unknown name '" + name +
                "' (known: cube, sphere, plane, boxes, city, terrain, hairball, soup, forest, smoke)");

  Scene scene;
  scene.name = spec;
  for (auto& m : meshes) {
    // In double, before welding and the degenerate test, so that "scale=1e-5,ox=1e7"
    // is judged on the coordinates the baker will actually see.
    if (scale != 1.0 || !(offset == Vec3d{}))
      for (auto& v : m.vertices) v = v * scale + offset;
    append_mesh(scene, std::move(m));
  }
  scene.alpha_textures = std::move(extras.textures);
  for (Volume& v : extras.volumes) {
    // Density stays per unit of world length: a scaled cloud is thicker.
    v.bounds.lo = v.bounds.lo * scale + offset;
    v.bounds.hi = v.bounds.hi * scale + offset;
    scene.volumes.push_back(std::move(v));
  }
  return scene;
}

}  // namespace st
