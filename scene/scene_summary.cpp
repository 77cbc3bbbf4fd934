// summary(): the one paragraph a CLI prints after loading a scene.
#include <cstdio>
#include <optional>

#include "common/error.hpp"
#include "scene/scene.hpp"

namespace st {

std::string summary(const Scene& scene) {
  size_t closed = 0;
  for (auto& m : scene.meshes) closed += m.closed ? 1 : 0;
  const Aabb b = scene.bounds();
  char box[256];
  if (b.empty())
    std::snprintf(box, sizeof box, "empty bounds");
  else
    std::snprintf(box, sizeof box, "bounds [%.9g, %.9g, %.9g] - [%.9g, %.9g, %.9g]", b.lo.x, b.lo.y, b.lo.z,
                  b.hi.x, b.hi.y, b.hi.z);
  char text[768];
  std::snprintf(text, sizeof text,
                "%zu triangles, %zu vertices, %zu meshes (%zu closed, %zu closed triangles), "
                "%llu degenerate triangles dropped, %llu meshes flipped outwards, %s",
                scene.triangles.size(), scene.vertices.size(), scene.meshes.size(), closed,
                scene.closed_triangle_count(),
                static_cast<unsigned long long>(scene.stats.degenerate_dropped),
                static_cast<unsigned long long>(scene.stats.meshes_flipped), box);
  std::string volumes;
  for (const Volume& v : scene.volumes)
    volumes += ", volume '" + v.name + "' " + std::to_string(v.nx) + "x" + std::to_string(v.ny) + "x" +
               std::to_string(v.nz) + " voxels";
  const std::string up = scene.up_reason.empty() ? "" : ", up axis " + up_axis_text(scene);
  const std::string unit = scene.unit_reason.empty() ? "" : ", unit scale " + scene.unit_reason;
  return "scene '" + scene.name + "': " + text + volumes + up + unit;
}

std::optional<UpAxis> parse_up_axis(const std::string& text) {
  if (text.empty()) return std::nullopt;
  if (text == "y") return UpAxis::y;
  if (text == "z") return UpAxis::z;
  throw Error("--up: expected y or z, got '" + text + "'");
}

std::string up_axis_text(const Scene& scene) {
  const std::string axis = scene.up == UpAxis::z ? "z" : "y";
  return scene.up_reason.empty() ? axis : axis + " (" + scene.up_reason + ")";
}

}  // namespace st
