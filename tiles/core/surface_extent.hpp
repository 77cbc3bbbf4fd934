// Where a map's surfaces lie in world space, recovered from its skip grid alone (a pack
// header carries the light, not the scene): every level-K entry's value is a depth inside
// the interval of its node (ARCHITECTURE.md "Definitions"), so the point at that depth on
// the entry's light ray lies on (or inside) geometry. Percentiles of those points give a
// ground height, a top and the footprint cameras move over; their full range is `box`.
// The client publishes it (MapInfo::surface); the load tester's camera paths and
// Map::request_view's default receiver plane use it.
#pragma once
#include "tiles/core/light.hpp"
#include "tiles/core/tile_cut_grid.hpp"
#include "tiles/core/vec.hpp"

namespace st {

struct SurfaceExtent {
  double ground = 0, top = 1;             // world heights (+Y up): 5th and 98th percentile
  double x0 = 0, x1 = 1, z0 = 0, z1 = 1;  // footprint: 1st and 99th percentiles of x, z
  Aabb box;                               // every surface point found (empty: none)
  uint64_t points = 0;                    // how many (fewer than 4: the light box's lowest face)
};

// Never throws on a map without hits: then the light box's lowest corner is the ground
// and its x, z range the footprint.
SurfaceExtent surface_extent(const LightSpace& light, const CutGrid& grid);

}  // namespace st
