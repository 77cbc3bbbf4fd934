// The deep part of a remote map (internal to client/): a pack with the deep_shadow
// feature carries a deep shadow map (DSM 2000) of its partial occluders as a deep
// directory and deep tiles (tiles/core/deep_pack.hpp), fetched over the same connection
// and requests as the opaque tiles (ids with bit 63: tiles/PACK.md "Deep tiles"). The
// RemoteMap owns one and hands it the deep ids' answers.
//
// Lookups answer transmittance 1 (lit) where no deep tile covers the point, and also while
// the directory or the point's tile is still on its way (they queue its fetch): partial
// shadows appear when their tile arrives. A tile that cannot be had answers 1 for good.
// Resident tiles are kept up to `max_tiles`, the least recently used dropped first.
//
// Locking: one mutex, held by lookups for a lookup (no allocation: the want list is
// reserved) and by the fetcher for bookkeeping; tiles are inflated and validated outside it.
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "proto/messages.hpp"
#include "tiles/core/deep_pack.hpp"
#include "tiles/core/deep_tile.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::client {

class Notifier;

class DeepPart {
 public:
  DeepPart(std::string name, uint32_t tile_bytes, uint32_t max_tiles, uint32_t max_retries, uint16_t priority,
           std::shared_ptr<Notifier> notifier);

  // Light-space point (u, v in [0, 1), d the light-space depth); width: the footprint in
  // map units (0: the finest texel). noexcept: never blocks on the network or allocates.
  std::array<float, 3> lookup(double u, double v, float d, double width) const noexcept;
  bool directory_known() const noexcept;
  uint32_t level() const noexcept;  // the deep map's level (0 until the directory is known)
  // Every deep tile under [u0, u1) x [v0, v1) resident (the directory known); queues the
  // missing ones (as many as the want list holds).
  bool resident(double u0, double v0, double u1, double v1) const noexcept;
  size_t resident_tiles() const noexcept;
  // For mirrors of the deep part (gpu/: GpuMap): a count that changes whenever the
  // directory arrives or a tile becomes resident or is dropped, and a visit of the
  // directory's shape and every resident tile's (tx, ty) and bytes under the lock (the
  // bytes are valid only during the call).
  uint64_t generation() const noexcept;
  template <class Shape, class Visit>
  void inspect(Shape&& shape, Visit&& visit) const {
    std::lock_guard lock(mu_);
    if (!dir_) return;
    shape(dir_->level, dir_->side_bits);
    for (const auto& [id, t] : tiles_)
      if (t.state == State::resident && id != kDeepDirectoryId) {
        const TileAddress a = tile_address(id & ~kDeepTileIdBit);
        visit(uint32_t(a.x), uint32_t(a.y), std::span<const uint8_t>(t.bytes));
      }
  }

  // The directory's shape and bitmap (bit ty << (D - b) | tx, little-endian bytes: the
  // tile exists) under the lock: shape(level, side_bits, bytes); false (no call) until the
  // directory arrived. For a GPU mirror that feeds back only tiles that exist.
  template <class Visit>
  bool inspect_directory(Visit&& visit) const {
    std::lock_guard lock(mu_);
    if (!dir_) return false;
    visit(dir_->level, dir_->side_bits, std::span<const uint8_t>(dir_->bitmap));
    return true;
  }
  // Tiles (tx, ty) a GPU pass needed and found absent (its feedback): each the directory
  // names that is not resident, on its way or given up is queued like a lookup miss (up
  // to the want list's room). Returns how many were queued. Never blocks or allocates.
  size_t want(std::span<const std::array<uint32_t, 2>> tiles) const noexcept;

  // ---- fetcher side (through RemoteMap) ----
  void take_wanted(size_t max, uint32_t request_id, std::vector<proto::TileRequest>& out);
  bool has_work() const;
  void tile_arrived(const proto::TileMeta& meta, uint32_t request_id, std::span<const uint8_t> stored) noexcept;
  void tile_refused(uint64_t tile, uint32_t request_id, proto::ErrorCode code) noexcept;
  void connection_lost() noexcept;

 private:
  enum class State : uint8_t { queued, sent, resident, failed };
  struct Tile {
    State state = State::queued;
    uint32_t request_id = 0, retries = 0;
    uint64_t used = 0;  // lookup clock of the last use
    std::vector<uint8_t> bytes;
    DeepTileView view;
  };
  void want_locked(uint64_t id) const noexcept;
  void failed_locked(uint64_t id, Tile& t) noexcept;
  void evict_locked() noexcept;

  const std::string name_;
  const uint32_t tile_bytes_, max_tiles_, max_retries_;
  const uint16_t priority_;
  std::shared_ptr<Notifier> notifier_;
  mutable std::mutex mu_;
  std::optional<DeepDirectory> dir_;
  // Tiles sent, resident or failed; lookups only read it (find).
  std::unordered_map<uint64_t, Tile> tiles_;
  mutable std::vector<uint64_t> want_;  // queued by lookups (capacity fixed: kMaxWants)
  mutable uint64_t clock_ = 0;
  size_t resident_ = 0;
  uint64_t generation_ = 0;
  static constexpr size_t kMaxWants = 256;
};

}  // namespace st::client
