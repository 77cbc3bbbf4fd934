// Volume parts of scene specs ("vdb:", "+vdb:", "+fog:") and the fog layer; the OpenVDB
// reader itself is scene_vdb.cpp. scene_volumes.hpp has the grammar.
#include "scene/scene_volumes.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

// key=value pairs after the first comma-separated item of a spec part; every key must be
// one of `known`.
struct Keys {
  std::string part;
  std::map<std::string, std::string> values;

  Keys(const std::string& part_, const std::string& list, const std::vector<std::string>& known)
      : part(part_) {
    size_t pos = 0;
    while (pos < list.size()) {
      size_t end = list.find(',', pos);
      if (end == std::string::npos) end = list.size();
      const std::string item = list.substr(pos, end - pos);
      pos = end + 1;
      const size_t eq = item.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
        fail("expected key=value, got '" + item + "'");
      const std::string key = item.substr(0, eq);
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        std::string list_known;
        for (auto& k : known) list_known += (list_known.empty() ? "" : ", ") + k;
        fail("unknown key '" + key + "' (known: " + list_known + ")");
      }
      if (!values.emplace(key, item.substr(eq + 1)).second) fail("key '" + key + "' given twice");
    }
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw Error("volume spec '" + part + "': " + what);
  }
  bool has(const std::string& key) const { return values.count(key) != 0; }
  double real(const std::string& key, double fallback, double lo, double hi) const {
    auto it = values.find(key);
    if (it == values.end()) return fallback;
    double v = 0;
    const std::string& t = it->second;
    auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || ptr != t.data() + t.size() || !std::isfinite(v) || v < lo || v > hi)
      fail("key '" + key + "' = '" + t + "' is not a number in [" + std::to_string(lo) + ", " +
           std::to_string(hi) + "]");
    return v;
  }
  uint64_t integer(const std::string& key, uint64_t fallback, uint64_t lo, uint64_t hi) const {
    auto it = values.find(key);
    if (it == values.end()) return fallback;
    uint64_t v = 0;
    const std::string& t = it->second;
    auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || ptr != t.data() + t.size() || v < lo || v > hi)
      fail("key '" + key + "' = '" + t + "' is not an integer in [" + std::to_string(lo) + ", " +
           std::to_string(hi) + "]");
    return v;
  }
};

// "vdb:PATH[,k=v...]" (the "vdb:" prefix already checked) -> the volume.
Volume vdb_part(const std::string& part, UpAxis up) {
  const std::string body = part.substr(4);
  const size_t comma = body.find(',');
  const std::string path = body.substr(0, comma);
  const Keys keys(part, comma == std::string::npos ? "" : body.substr(comma + 1),
                  {"grid", "scale", "sigma", "max_voxels"});
  if (path.empty()) keys.fail("missing file (vdb:PATH[,grid=NAME,scale=S,sigma=S,max_voxels=N])");
  VdbOptions o;
  o.up = up;
  if (keys.has("grid")) o.grid = keys.values.at("grid");
  o.scale = keys.real("scale", 1.0, 0.0, 1e30);
  o.sigma = keys.real("sigma", 1.0, 0.0, 1e30);
  o.max_voxels = keys.integer("max_voxels", kVdbVoxelBudget, 1, kVdbMaxVoxels);
  return load_vdb_volume(path, o);
}

// "fog:k=v,..." over `scene`'s bounds.
Volume fog_part(const std::string& part, const Scene& scene) {
  const Keys keys(part, part.substr(4), {"density", "height", "bottom", "top", "res"});
  if (!keys.has("density")) keys.fail("missing key 'density' (extinction per unit length)");
  const Aabb b = scene.bounds();
  if (b.empty()) keys.fail("the scene it covers is empty");
  FogOptions o;
  o.density = keys.real("density", 0, 0, 1e30);
  o.height = keys.real("height", 0, 0, 1e30);
  o.bottom = keys.real("bottom", b.lo.y, -1e30, 1e30);
  o.top = keys.real("top", b.hi.y, -1e30, 1e30);
  o.cells = uint32_t(keys.integer("res", 0, 1, kFogMaxCells));
  if (!(o.top > o.bottom))
    keys.fail("the layer is empty (top " + std::to_string(o.top) + " <= bottom " +
              std::to_string(o.bottom) + "): give top=");
  return fog_layer(b, o);
}

}  // namespace

Volume fog_layer(const Aabb& footprint, const FogOptions& o) {
  if (footprint.empty() || !(o.top > o.bottom) || !(o.density >= 0) || !(o.height >= 0) ||
      !std::isfinite(o.density) || !std::isfinite(o.height))
    throw Error("fog layer: empty footprint or layer, or a negative or non-finite parameter");
  const double thick = o.top - o.bottom;
  uint32_t n = o.cells;
  if (n == 0) {
    // Cells at most H / 8 thick (height fog) and of optical depth at most 0.2 across.
    double want = std::ceil(thick * o.density / 0.2);
    if (o.height > 0) want = std::max(want, std::ceil(thick / (o.height / 8)));
    n = uint32_t(std::clamp(want, 1.0, double(kFogMaxCells)));
  }
  Volume v;
  v.name = "fog";
  v.bounds.lo = {footprint.lo.x, o.bottom, footprint.lo.z};
  v.bounds.hi = {footprint.hi.x, o.top, footprint.hi.z};
  // A flat footprint (a single quad seen edge-on in x or z) still needs a box.
  if (!(v.bounds.hi.x > v.bounds.lo.x)) v.bounds.lo.x -= 0.5, v.bounds.hi.x += 0.5;
  if (!(v.bounds.hi.z > v.bounds.lo.z)) v.bounds.lo.z -= 0.5, v.bounds.hi.z += 0.5;
  v.nx = v.nz = 1;
  v.ny = n;
  v.sigma = {1, 1, 1};
  v.density.resize(n);
  for (uint32_t j = 0; j < n; ++j) {
    const double above = (j + 0.5) / n * thick;  // the cell centre's height over the bottom
    v.density[j] = float(o.height > 0 ? o.density * std::exp(-above / o.height) : o.density);
  }
  return v;
}

size_t volume_suffix(const std::string& spec) {
  return std::min(spec.find("+vdb:"), spec.find("+fog:"));
}

void add_spec_volumes(Scene& scene, const std::string& parts, UpAxis up) {
  size_t pos = 0;
  while (pos < parts.size()) {
    if (parts[pos] != '+') throw Error("volume spec '" + parts + "': expected +vdb: or +fog:");
    size_t end = volume_suffix(parts.substr(pos + 1));
    end = end == std::string::npos ? parts.size() : pos + 1 + end;
    const std::string part = parts.substr(pos + 1, end - pos - 1);
    if (part.rfind("vdb:", 0) == 0)
      scene.volumes.push_back(vdb_part(part, up));
    else if (part.rfind("fog:", 0) == 0)
      scene.volumes.push_back(fog_part(part, scene));
    else
      throw Error("volume spec '" + part + "': expected vdb: or fog:");
    pos = end;
  }
  scene.name += parts;
}

Scene load_vdb_scene(const std::string& spec, UpAxis up) {
  Scene s;
  s.name = spec;
  s.volumes.push_back(vdb_part(spec.rfind("vdb:", 0) == 0 ? spec : "vdb:" + spec, up));
  return s;
}

}  // namespace st
