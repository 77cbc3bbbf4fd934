// What the client tools (`render`, `report`) read of a served map, through the public
// client API alone (shadowtile/client.hpp), as a game would: the map's light as the
// renderer's LightSpace (rebuilt from the serialized form MapInfo::light carries: the
// same doubles, so the same texels and depths), the map as an Evaluator over
// Map::depth / Map::pcf, and waiting for the tiles under a set of light-space points.
#pragma once
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "common/error.hpp"
#include "render/render.hpp"
#include "shadowtile/client.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/light.hpp"

namespace st::cli {

inline LightSpace light_of(const client::LightTransform& t) {
  return LightSpace::from_array(LightKind(t.kind_id()), t.to_array());
}

// The served map as an Evaluator: every lookup is the public Map's (lock, page-table walk,
// coarser answers where a tile is absent), bit for bit what a game's lookups answer.
class MapEvaluator final : public Evaluator {
 public:
  explicit MapEvaluator(client::Map map) : map_(std::move(map)) {}
  uint32_t finest_level() const override { return map_.finest_level(); }
  float depth(uint32_t level, uint64_t x, uint64_t y) const override { return map_.depth(level, x, y); }
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override {
    return map_.pcf(level, x, y, r, receiver);
  }

 private:
  client::Map map_;
};

// RenderOptions::filtered over the served map: each run of receivers of one kind (open or
// closed) in one Map::visibility_filtered batch with their normals (receiver-plane depth
// bias), so `render --server` answers its filtered path as the local render's
// pcf_on_plane does, bit for bit, under one lock per run.
inline auto filtered_lookups(const client::Map& map, uint32_t pcf_side) {
  return [&map, pcf_side](std::span<const Receiver> rec, std::span<const float> footprints, std::span<float> out) {
    constexpr size_t kRun = 256;
    client::WorldPoint points[kRun], normals[kRun];
    const size_t n = std::min({rec.size(), footprints.size(), out.size()});
    for (size_t i = 0; i < n;) {
      const bool closed = rec[i].closed;
      size_t e = i;
      for (; e < n && e - i < kRun && rec[e].closed == closed; ++e) {
        const Receiver& r = rec[e];
        points[e - i] = {r.pos.x, r.pos.y, r.pos.z}, normals[e - i] = {r.normal.x, r.normal.y, r.normal.z};
      }
      map.visibility_filtered(std::span(points, e - i), std::span(normals, e - i), footprints.subspan(i, e - i),
                              out.subspan(i, e - i), pcf_side, closed);
      i = e;
    }
  };
}

// A square of texels of `level` whose tiles a set of points needs.
struct TexelCell {
  uint64_t x0 = 0, y0 = 0, side = 0;
};

// The cells of `level` under the light-space points (u, v in [0, 1); others need nothing):
// squares of 2^(level - c) texels, c = max(skip_level, level - 7), the level the map's
// page table starts at or finer, each listed once. Prefetching a cell queues the tiles
// under it (Map::request_region), so few cells cover a view's receivers. cell_of (if not
// null) gets, per point, its cell's index in the result (-1: outside the map).
inline std::vector<TexelCell> cells_under(const std::vector<std::pair<double, double>>& uv, uint32_t level,
                                          uint32_t skip_level, std::vector<int64_t>* cell_of = nullptr) {
  const uint32_t c = std::min(level, std::max(skip_level, level >= 7 ? level - 7 : 0));
  const uint32_t shift = level - c;
  const uint64_t n = uint64_t(1) << c;
  auto key = [n](double u, double v) {
    const uint64_t x = std::min(n - 1, uint64_t(u * double(n))), y = std::min(n - 1, uint64_t(v * double(n)));
    return (y << 32) | x;
  };
  auto inside = [](double u, double v) { return u >= 0 && u < 1 && v >= 0 && v < 1; };
  std::vector<uint64_t> keys;
  keys.reserve(uv.size());
  for (const auto& [u, v] : uv)
    if (inside(u, v)) keys.push_back(key(u, v));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  std::vector<TexelCell> out;
  out.reserve(keys.size());
  for (uint64_t k : keys) out.push_back({(k & 0xFFFFFFFFu) << shift, (k >> 32) << shift, uint64_t(1) << shift});
  if (cell_of) {
    cell_of->clear();
    for (const auto& [u, v] : uv)
      cell_of->push_back(inside(u, v) ? int64_t(std::lower_bound(keys.begin(), keys.end(), key(u, v)) - keys.begin())
                                      : -1);
  }
  return out;
}

// Queues every cell's tiles and waits until all are resident (polling every 5 ms, asking
// again for those that are not), up to `timeout`; calls `check` on each round (it may
// throw: a tile given up never becomes resident). False on timeout.
template <typename Check>
bool fetch_cells(client::Map& map, uint32_t level, const std::vector<TexelCell>& cells,
                 std::chrono::milliseconds timeout, Check check) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    bool all = true;
    for (const TexelCell& c : cells)
      if (!map.region_resident(level, c.x0, c.y0, c.side, c.side)) {
        all = false;
        map.request_region(level, c.x0, c.y0, c.side, c.side, 1000);
      }
    check();
    if (all) return true;
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

}  // namespace st::cli
