// Grid scenes: real asset files tiled across a ground, the shape of an open world built
// from a kit of models (a town of building assets, a level repeated into a region), so
// that maps of any size can be covered by real, open geometry.
//
// Spec: "grid:FILE[|FILE...][,n=N][,gap=F][,seed=S][,rotate=yes|no][,ground=yes|no]"
//   FILE    a scene file load_scene() reads (any format, "ARCHIVE.pk3:maps/NAME.bsp"), one
//           or more separated by '|'; read once each (under the caller's SceneLimits) and
//           copied into the cells, so the triangle budget counts every copy
//   n=N     N x N cells (1..4096, default 8)
//   gap=F   space between neighbours as a fraction of the cell (0..10, default 0.25)
//   seed=S  which file and which quarter turn each cell gets (splitmix64; default 1)
//   rotate  yes (default): each copy turned by a multiple of 90 degrees about +Y
//   ground  yes (default): one open quad at y = 0 under every cell (mesh "grid/ground")
// Cells are squares of side (1 + gap) times the largest horizontal extent of any file,
// row-major in x then z from the origin; a copy stands in its cell's centre with its
// lowest point on y = 0. Meshes keep their closed and partial flags (a rotation and a
// translation keep orientation) and are named "NAME@I,J". Files with volumes are refused.
// Deterministic: the same spec and files give the same content_hash().
// Errors: st::Error of one line naming the key, the value or the file.
#pragma once
#include <string>

#include "scene/scene.hpp"
#include "scene/scene_limits.hpp"

namespace st {

bool is_grid_spec(const std::string& spec);  // starts with "grid:"
Scene load_grid_scene(const std::string& spec, const SceneOptions& options, const SceneLimits& limits);

}  // namespace st
