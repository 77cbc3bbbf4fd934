#include "server/payload_cache.hpp"

namespace st::server {

void PayloadCache::set_budget(size_t budget_bytes) {
  std::lock_guard lock(mu_);
  budget_ = budget_bytes;
  index_.clear();
  lru_.clear();
  bytes_ = 0;
}

PayloadCache::Bytes PayloadCache::find(const void* map, uint64_t tile) {
  std::lock_guard lock(mu_);
  auto it = index_.find(Key{map, tile});
  if (it == index_.end()) {
    ++misses_;
    return nullptr;
  }
  ++hits_;
  if (it->second != lru_.begin()) lru_.splice(lru_.begin(), lru_, it->second);
  return it->second->bytes;
}

void PayloadCache::insert(const void* map, uint64_t tile, Bytes bytes) {
  if (!bytes) return;
  const size_t cost = bytes->size() + kEntryOverhead;
  std::lock_guard lock(mu_);
  if (budget_ == 0 || cost > budget_ / kMaxEntryShare) return;
  const Key key{map, tile};
  if (index_.count(key)) return;
  while (!lru_.empty() && bytes_ + cost > budget_) {
    const Entry& victim = lru_.back();
    bytes_ -= victim.cost;
    index_.erase(victim.key);
    lru_.pop_back();  // the payload lives on while a write still references it
  }
  lru_.push_front(Entry{key, std::move(bytes), cost});
  index_.emplace(key, lru_.begin());
  bytes_ += cost;
}

size_t PayloadCache::bytes() const {
  std::lock_guard lock(mu_);
  return bytes_;
}

size_t PayloadCache::entries() const {
  std::lock_guard lock(mu_);
  return lru_.size();
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
