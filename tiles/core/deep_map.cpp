// A deep shadow map as a grid of deep tiles: see deep_map.hpp.
#include "tiles/core/deep_map.hpp"

#include <algorithm>
#include <cmath>

#include "common/error.hpp"

namespace st {

namespace {
constexpr uint32_t kMaxMapLevel = 20;  // as interval.hpp's kMaxLevel
}

DeepMap::DeepMap(uint32_t level, uint32_t side_bits) : level_(level), side_bits_(side_bits) {
  if (level > kMaxMapLevel || side_bits > level || side_bits > deep::kMaxSideBits)
    throw Error("deep map: level " + std::to_string(level) + " with tiles of 2^" +
                std::to_string(side_bits) + " texels is not a valid map");
}

void DeepMap::add_tile(uint32_t tx, uint32_t ty, std::span<const uint8_t> bytes) {
  const uint32_t t = tiles_per_side();
  if (tx >= t || ty >= t)
    throw Error("deep map: tile " + std::to_string(tx) + "," + std::to_string(ty) + " lies outside the map");
  const uint64_t k = uint64_t(ty) * t + tx;
  auto it = std::lower_bound(tiles_.begin(), tiles_.end(), k,
                             [](const auto& e, uint64_t key) { return e.first < key; });
  if (it != tiles_.end() && it->first == k)
    throw Error("deep map: tile " + std::to_string(tx) + "," + std::to_string(ty) + " given twice");
  DeepTileView v = DeepTileView::open(bytes, "deep tile " + std::to_string(tx) + "," + std::to_string(ty));
  if (v.side_bits() != side_bits_)
    throw FormatError("deep tile " + std::to_string(tx) + "," + std::to_string(ty) + ": side 2^" +
                      std::to_string(v.side_bits()) + " in a map of 2^" + std::to_string(side_bits_) + " tiles");
  tiles_.insert(it, {k, v});
}

const DeepTileView* DeepMap::tile_at(double u, double v, double& lu, double& lv) const {
  const uint32_t t = tiles_per_side();
  auto cell = [&](double w, double& local) {
    double p = w * t;
    if (!std::isfinite(p)) p = 0;
    p = std::clamp(p, 0.0, double(t) - 1e-9);
    const uint32_t i = std::min(uint32_t(p), t - 1);
    local = p - i;
    return i;
  };
  const uint32_t tx = cell(u, lu), ty = cell(v, lv);
  const uint64_t k = uint64_t(ty) * t + tx;
  auto it = std::lower_bound(tiles_.begin(), tiles_.end(), k,
                             [](const auto& e, uint64_t key) { return e.first < key; });
  return it != tiles_.end() && it->first == k ? &it->second : nullptr;
}

std::array<float, 3> DeepMap::transmittance(double u, double v, float z) const {
  double lu, lv;
  const DeepTileView* tile = tile_at(u, v, lu, lv);
  if (!tile) return {1, 1, 1};
  const uint32_t s = tile->side(0);
  return tile->transmittance(std::min(uint32_t(lu * s), s - 1), std::min(uint32_t(lv * s), s - 1), z, 0);
}

std::array<float, 3> DeepMap::filtered(double u, double v, float z, double width) const {
  double lu, lv;
  const DeepTileView* tile = tile_at(u, v, lu, lv);
  if (!tile) return {1, 1, 1};
  // Tile-local width: the map's footprint times the tiles per side.
  const double w = width * double(tiles_per_side());
  return tile->filtered(lu, lv, z, std::isfinite(w) ? w : 0.0);
}

}  // namespace st
