// The deep part of a remote map: see deep_part.hpp.
#include "client/deep_part.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "client/remote_map.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::client {

DeepPart::DeepPart(std::string name, uint32_t tile_bytes, uint32_t max_tiles, uint32_t max_retries,
                   uint16_t priority, std::shared_ptr<Notifier> notifier)
    : name_(std::move(name)),
      tile_bytes_(tile_bytes),
      max_tiles_(std::max<uint32_t>(max_tiles, 1)),
      max_retries_(max_retries),
      priority_(priority),
      notifier_(std::move(notifier)) {
  want_.reserve(kMaxWants);
  want_.push_back(kDeepDirectoryId);  // first of all: which deep tiles exist
}

bool DeepPart::directory_known() const noexcept {
  std::lock_guard lock(mu_);
  return dir_.has_value();
}

uint64_t DeepPart::generation() const noexcept {
  std::lock_guard lock(mu_);
  return generation_;
}

uint32_t DeepPart::level() const noexcept {
  std::lock_guard lock(mu_);
  return dir_ ? dir_->level : 0;
}

bool DeepPart::resident(double u0, double v0, double u1, double v1) const noexcept {
  std::lock_guard lock(mu_);
  if (!dir_) return false;
  const uint32_t t = dir_->tiles_per_side();
  auto cell = [t](double w) { return uint32_t(std::clamp(w * t, 0.0, double(t) - 1e-9)); };
  bool all = true;
  for (uint32_t ty = cell(v0); ty <= cell(v1); ++ty)
    for (uint32_t tx = cell(u0); tx <= cell(u1); ++tx) {
      if (!dir_->has(tx, ty)) continue;
      const uint64_t id = dir_->tile_id(tx, ty);
      auto it = tiles_.find(id);
      if (it != tiles_.end() && it->second.state == State::resident) {
        const_cast<Tile&>(it->second).used = ++clock_;  // asked for: the last to be dropped
        continue;
      }
      all = false;
      if (it == tiles_.end() || it->second.state == State::queued) want_locked(id);
    }
  return all;
}

size_t DeepPart::want(std::span<const std::array<uint32_t, 2>> tiles) const noexcept {
  std::lock_guard lock(mu_);
  if (!dir_) return 0;
  const size_t before = want_.size();
  const uint32_t t = dir_->tiles_per_side();
  for (const auto& [tx, ty] : tiles) {
    if (tx >= t || ty >= t || !dir_->has(tx, ty)) continue;
    const uint64_t id = dir_->tile_id(tx, ty);
    auto it = tiles_.find(id);
    if (it == tiles_.end() || it->second.state == State::queued) want_locked(id);
  }
  return want_.size() - before;
}

size_t DeepPart::resident_tiles() const noexcept {
  std::lock_guard lock(mu_);
  return resident_;
}

void DeepPart::want_locked(uint64_t id) const noexcept {
  if (want_.size() >= kMaxWants || std::find(want_.begin(), want_.end(), id) != want_.end()) return;
  want_.push_back(id);  // within the reserved capacity: no allocation
  notifier_->notify();
}

std::array<float, 3> DeepPart::lookup(double u, double v, float d, double width) const noexcept {
  constexpr std::array<float, 3> lit{1, 1, 1};
  if (!(u >= 0 && u < 1 && v >= 0 && v < 1) || !std::isfinite(d)) return lit;
  std::lock_guard lock(mu_);
  if (!dir_) return lit;  // the directory is on its way
  const uint32_t t = dir_->tiles_per_side();
  const double pu = u * t, pv = v * t;
  const uint32_t tx = std::min(uint32_t(pu), t - 1), ty = std::min(uint32_t(pv), t - 1);
  if (!dir_->has(tx, ty)) return lit;  // no partial occluder over this tile
  const uint64_t id = dir_->tile_id(tx, ty);
  auto it = tiles_.find(id);
  if (it == tiles_.end()) {
    want_locked(id);
    return lit;
  }
  const Tile& tile = it->second;
  if (tile.state == State::queued) want_locked(id);
  if (tile.state != State::resident) return lit;
  const_cast<Tile&>(tile).used = ++clock_;
  const double lu = pu - tx, lv = pv - ty;
  // The same arithmetic as DeepMap (deep_map.cpp): a point lookup reads the texel under
  // (u, v); a footprint is filtered within the tile (width in tile-local units).
  if (!(width > 0)) {
    const uint32_t s = tile.view.side(0);
    return tile.view.transmittance(std::min(uint32_t(lu * s), s - 1), std::min(uint32_t(lv * s), s - 1), d, 0);
  }
  const double w = width * double(t);
  return tile.view.filtered(lu, lv, d, std::isfinite(w) ? w : 0.0);
}

void DeepPart::take_wanted(size_t max, uint32_t request_id, std::vector<proto::TileRequest>& out) {
  std::lock_guard lock(mu_);
  size_t n = 0;
  while (n < max && !want_.empty()) {
    const uint64_t id = want_.front();
    want_.erase(want_.begin());
    Tile& t = tiles_[id];
    if (t.state == State::resident || t.state == State::failed || (t.state == State::sent && t.request_id))
      continue;
    t.state = State::sent;
    t.request_id = request_id;
    out.push_back(proto::TileRequest{id, priority_});
    ++n;
  }
}

bool DeepPart::has_work() const {
  std::lock_guard lock(mu_);
  return !want_.empty();
}

void DeepPart::failed_locked(uint64_t id, Tile& t) noexcept {
  if (++t.retries > max_retries_) {
    t.state = State::failed;  // answers 1 for good
    return;
  }
  t.state = State::queued;  // asked again (a full want list: by the next lookup)
  t.request_id = 0;
  want_locked(id);
}

void DeepPart::evict_locked() noexcept {
  while (resident_ > max_tiles_) {
    auto victim = tiles_.end();
    for (auto it = tiles_.begin(); it != tiles_.end(); ++it)
      if (it->second.state == State::resident && it->first != kDeepDirectoryId &&
          (victim == tiles_.end() || it->second.used < victim->second.used))
        victim = it;
    if (victim == tiles_.end()) return;
    tiles_.erase(victim);
    --resident_;
    ++generation_;
  }
}

void DeepPart::tile_arrived(const proto::TileMeta& meta, uint32_t request_id, std::span<const uint8_t> stored) noexcept {
  const uint64_t id = meta.tile_id;
  {
    std::lock_guard lock(mu_);
    auto it = tiles_.find(id);
    if (it == tiles_.end() || it->second.state != State::sent || it->second.request_id != request_id) return;
  }
  // Outside the lock: the end-to-end CRC, inflate, validate.
  std::vector<uint8_t> raw;
  std::optional<DeepDirectory> dir;
  std::optional<DeepTileView> view;
  bool ok = proto::tile_crc_matches(meta, stored) && meta.uncompressed_size <= tile_bytes_;
  if (ok) {
    try {
      const std::string what = "map '" + name_ + "': " + describe_tile(id);
      if (meta.flags & proto::kTileFlagZlib) raw = zlib_decompress(stored, meta.uncompressed_size, what);
      else if (stored.size() == meta.uncompressed_size) raw.assign(stored.begin(), stored.end());
      else throw FormatError(what + ": size");
      if (id == kDeepDirectoryId) dir = DeepDirectory::parse(raw, what);
      else view = DeepTileView::open(raw, what);
    } catch (...) {
      ok = false;
    }
  }
  std::lock_guard lock(mu_);
  auto it = tiles_.find(id);
  if (it == tiles_.end() || it->second.state != State::sent || it->second.request_id != request_id) return;
  Tile& t = it->second;
  if (ok && view && (!dir_ || view->side_bits() != dir_->side_bits)) ok = false;
  if (!ok) return failed_locked(id, t);
  t.state = State::resident;
  t.bytes = std::move(raw);  // the view points into the vector's buffer, which a move keeps
  ++generation_;
  if (dir) {
    dir_ = std::move(dir);
    return;
  }
  t.view = *view;
  t.used = ++clock_;
  ++resident_;
  evict_locked();
}

void DeepPart::tile_refused(uint64_t tile, uint32_t request_id, proto::ErrorCode code) noexcept {
  std::lock_guard lock(mu_);
  auto it = tiles_.find(tile);
  if (it == tiles_.end() || it->second.state != State::sent || it->second.request_id != request_id) return;
  if (code == proto::ErrorCode::cancelled) {
    tiles_.erase(it);
    return;
  }
  it->second.state = State::failed;
}

void DeepPart::connection_lost() noexcept {
  std::lock_guard lock(mu_);
  for (auto it = tiles_.begin(); it != tiles_.end();) {
    if (it->second.state == State::sent) {
      const uint64_t id = it->first;
      it = tiles_.erase(it);
      want_locked(id);
    } else {
      ++it;
    }
  }
}

}  // namespace st::client
