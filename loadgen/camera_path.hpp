// Synthetic cameras for the load tester: where the map's receivers lie in
// world space, and deterministic seeded camera paths over them.
//
// A pack header carries only the light space, not the scene. The world region the map
// covers is recovered from the skip grid: every level-K entry's value is a depth inside
// the interval of its node (ARCHITECTURE.md "Definitions"), so the point at that depth on
// the entry's light ray lies on (or inside) geometry. Percentiles of those points' heights
// give a ground height and a top; their x/z range the footprint cameras move over.
//
// Paths (all deterministic functions of (kind, seed, camera index, time)):
//   flyover   smooth Lissajous sweep above the roofs, looking ahead and down
//   orbit     circles a point of the footprint, looking at it
//   walk      slow Lissajous at eye height, looking nearly level
//   teleport  every kTeleportSeconds a cut to a new random place and heading (worst case:
//             nothing of the new view is resident), slow flyover motion in between
// Every path has a cut at t = 0; only teleport has more.
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>

#include "common/hash.hpp"
#include "tiles/core/camera.hpp"  // header-only: links nothing
#include "tiles/core/light.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/surface_extent.hpp"
#include "tiles/core/tile_cut_grid.hpp"
#include "tiles/core/vec.hpp"

namespace st::loadgen {

struct WorldFrame {
  LightSpace light;
  double ground = 0, top = 1;            // world heights (+Y up)
  double x0 = 0, x1 = 1, z0 = 0, z1 = 1;  // footprint
  double span() const { return std::max(x1 - x0, z1 - z0); }
  Vec3d centre() const { return {(x0 + x1) / 2, ground, (z0 + z1) / 2}; }
};

// From a pack header and its skip grid. Never throws on a map without hits (falls back
// to the light box's extent at its lowest corner).
WorldFrame world_frame(const PackHeader& header, const CutGrid& grid);
// From a light and where its surfaces lie (what client::MapInfo publishes).
WorldFrame world_frame(const LightSpace& light, const SurfaceExtent& surface);

enum class PathKind { flyover, orbit, walk, teleport };
PathKind parse_path(const std::string& name);  // throws st::Error
std::string to_string(PathKind k);

inline constexpr double kTeleportSeconds = 1.0;

class CameraPath {
 public:
  CameraPath(PathKind kind, const WorldFrame& world, uint64_t seed, uint32_t camera_index);
  Camera at(double t) const;
  // Index of the path segment containing t: a new segment starts at every cut.
  uint64_t segment(double t) const;
  PathKind kind() const { return kind_; }

 private:
  PathKind kind_;
  WorldFrame w_;
  uint64_t seed_;
  double phase_[4];
};

using st::splitmix64;  // common/hash.hpp
using st::unit_random;

}  // namespace st::loadgen
