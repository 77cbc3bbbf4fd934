#include "server/payload_cache.hpp"

namespace st::server {

void PayloadCache::configure(size_t budget_bytes, std::span<const size_t> tiles_per_map) {
  std::lock_guard lock(mu_);
  budget_ = budget_bytes;
  bytes_ = 0;
  hand_ = 0;
  ring_.clear();
  holes_.clear();
  maps_.clear();
  maps_.resize(tiles_per_map.size());
  for (size_t m = 0; m < maps_.size(); ++m) {
    maps_[m].tiles = tiles_per_map[m];
    maps_[m].pages.resize((tiles_per_map[m] + kPageSlots - 1) / kPageSlots);
  }
}

PayloadCache::Bytes PayloadCache::find(uint32_t map, uint32_t tile) {
  std::lock_guard lock(mu_);
  if (map < maps_.size() && tile < maps_[map].tiles)
    if (Page* page = maps_[map].pages[tile / kPageSlots].get())
      if (Slot& s = page->slots[tile % kPageSlots]; s.bytes) {
        ++hits_;
        s.referenced = true;
        return s.bytes;
      }
  ++misses_;
  return nullptr;
}

bool PayloadCache::evict_one() {
  if (ring_.size() == holes_.size()) return false;  // nothing cached
  for (;; ++hand_) {
    if (hand_ >= ring_.size()) hand_ = 0;
    Resident& r = ring_[hand_];
    if (r.map == kHole) continue;
    auto& page = maps_[r.map].pages[r.tile / kPageSlots];
    Slot& s = page->slots[r.tile % kPageSlots];
    if (s.referenced) {  // second chance
      s.referenced = false;
      continue;
    }
    bytes_ -= cost_of(s.bytes);
    s.bytes.reset();  // a write still holding it keeps it alive until it ends
    if (--page->resident == 0) {
      page.reset();
      bytes_ -= sizeof(Page);
    }
    // The hole stays where the victim was: the next insertion fills it, so a new
    // payload is the last one the hand reaches (a full round before its first test).
    r.map = kHole;
    holes_.push_back(hand_++);
    return true;
  }
}

void PayloadCache::insert(uint32_t map, uint32_t tile, Bytes bytes) {
  if (!bytes) return;
  const size_t cost = cost_of(bytes);
  std::lock_guard lock(mu_);
  if (map >= maps_.size() || tile >= maps_[map].tiles) return;
  if (budget_ < sizeof(Page) || cost > budget_ / kMaxEntryShare) return;
  auto& page = maps_[map].pages[tile / kPageSlots];
  if (page && page->slots[tile % kPageSlots].bytes) return;
  // Room for the payload, and for its page if that is not held (evicting may free it).
  while (bytes_ + cost + (page ? 0 : sizeof(Page)) > budget_)
    if (!evict_one()) return;
  if (!page) {
    page = std::make_unique<Page>();
    bytes_ += sizeof(Page);
  }
  Slot& s = page->slots[tile % kPageSlots];
  s.bytes = std::move(bytes);
  s.referenced = false;
  ++page->resident;
  if (holes_.empty()) {
    ring_.push_back({map, tile});
  } else {
    ring_[holes_.back()] = {map, tile};
    holes_.pop_back();
  }
  bytes_ += cost;
}

size_t PayloadCache::bytes() const {
  std::lock_guard lock(mu_);
  return bytes_;
}

size_t PayloadCache::entries() const {
  std::lock_guard lock(mu_);
  return ring_.size() - holes_.size();
}

uint64_t PayloadCache::hits() const {
  std::lock_guard lock(mu_);
  return hits_;
}

uint64_t PayloadCache::misses() const {
  std::lock_guard lock(mu_);
  return misses_;
}

}  // namespace st::server
