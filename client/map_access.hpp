// What the library's own tools (the load tester, `shadowtile render`/`report`, the tests)
// reach behind the public API: the pack header, the skip grid, and the map as an
// st::Evaluator. Private to this repository: not installed, and a game never needs it.
#pragma once
#include "client/remote_map.hpp"
#include "shadowtile/client.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::client {

struct MapAccess {
  // The opened map behind a handle; throws st::Error for a default-constructed Map.
  static const RemoteMap& remote(const Map& m);
  // A handle over a RemoteMap made without a Client (benchmarks and tests that fill the
  // cache themselves through tile_arrived).
  static Map wrap(std::shared_ptr<RemoteMap> m) { return Map(std::move(m)); }
};

inline const PackHeader& pack_header(const Map& m) { return MapAccess::remote(m).header(); }
inline const CutGrid& skip_grid(const Map& m) { return MapAccess::remote(m).grid(); }
// The map as an Evaluator over its cache (depth / pcf / lit / pcf_footprint).
inline const Evaluator& evaluator(const Map& m) { return MapAccess::remote(m); }

}  // namespace st::client
