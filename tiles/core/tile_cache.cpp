#include "common/hash.hpp"
#include "tiles/core/tile_cache.hpp"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cassert>
#include <cerrno>
#include <cstring>
#include <string>

namespace st {
namespace {

constexpr uint64_t kMaxPoolBytes = uint64_t(1) << 40;
constexpr size_t kNpos = ~size_t(0);
constexpr size_t kInitialBuckets = 64;


}  // namespace

TileCache::TileCache(uint32_t slot_count, uint32_t slot_bytes)
    : slot_count_(slot_count), slot_bytes_(slot_bytes) {
  if (slot_count == 0 || slot_bytes == 0)
    throw Error("tile cache: slot_count and slot_bytes must be > 0 (got " +
                std::to_string(slot_count) + " x " + std::to_string(slot_bytes) + ")");
  if (uint64_t(slot_count) * slot_bytes > kMaxPoolBytes)
    throw Error("tile cache: pool of " + std::to_string(slot_count) + " x " +
                std::to_string(slot_bytes) + " bytes exceeds 2^40");
  pool_ = Pool(size_t(slot_count) * slot_bytes);
  slots_.resize(slot_count);
  // Free list in ascending slot order, so an empty cache fills slots 0, 1, 2, ...
  for (uint32_t s = slot_count; s-- > 0;) free_push(s);
  table_.resize(kInitialBuckets);
  journal_.assign(std::bit_ceil(std::max<uint64_t>(slot_count, 64)), kNoSlot);
}

TileCache::Pool::Pool(size_t bytes) : size(bytes) {
  // Anonymous pages read as zero until written: no up-front clearing of slots x slot_bytes.
  void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (p == MAP_FAILED)
    throw Error("tile cache: cannot map a pool of " + std::to_string(bytes) + " bytes: " + std::strerror(errno));
  data = static_cast<uint8_t*>(p);
}

TileCache::Pool::~Pool() {
  if (data) ::munmap(data, size);
}

std::span<const uint8_t> TileCache::tile_bytes(uint32_t slot) const {
  assert(slot < slot_count_);
  const Slot& n = slots_[slot];
  if (n.held) return {n.held, n.used};
  return {pool_.data + slot_offset(slot), n.used};
}

std::span<uint8_t> TileCache::slot_span(uint32_t slot, uint32_t bytes) {
  assert(slot < slot_count_ && bytes <= slot_bytes_);
  Slot& n = slots_[slot];
  n.written = std::max(n.written, bytes);
  return {pool_.data + slot_offset(slot), bytes};
}

void TileCache::note_touched(Slot& n) {
  if (n.written <= n.touched) return;
  written_total_ += n.written - n.touched;
  n.touched = n.written;
}

bool TileCache::release_pages(uint32_t slot) noexcept {
  assert(slot < slot_count_);
  Slot& n = slots_[slot];
  if (n.written != 0) return false;
  if (n.touched == 0) return true;
  static const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
  const uint64_t off = slot_offset(slot);
  const uint64_t end = (off + slot_bytes_) / page * page;              // the slot's last whole page ends here
  const uint64_t reach = (off + n.touched + page - 1) / page * page;  // the written pages end here
  // Only when the written part lies in whole pages of this slot alone.
  if (off % page != 0 || reach > end) return false;
  if (::madvise(pool_.data + off, reach - off, MADV_DONTNEED) != 0) return false;  // they read as zero again
  written_total_ -= n.touched;
  n.touched = 0;
  return true;
}

// ---------------------------------------------------------------- LRU and free lists

void TileCache::lru_unlink(uint32_t s) {
  Slot& n = slots_[s];
  assert(n.on_lru);
  if (n.prev != kNoSlot) slots_[n.prev].next = n.next;
  else lru_head_ = n.next;
  if (n.next != kNoSlot) slots_[n.next].prev = n.prev;
  else lru_tail_ = n.prev;
  n.prev = n.next = kNoSlot;
  n.on_lru = false;
}

void TileCache::lru_push_front(uint32_t s) {
  Slot& n = slots_[s];
  assert(!n.on_lru && n.pins == 0 && n.state == SlotState::resident);
  n.prev = kNoSlot;
  n.next = lru_head_;
  if (lru_head_ != kNoSlot) slots_[lru_head_].prev = s;
  else lru_tail_ = s;
  lru_head_ = s;
  n.on_lru = true;
}

void TileCache::free_push(uint32_t s) {
  Slot& n = slots_[s];
  n.state = SlotState::free;
  n.tile = kInvalidTile;
  n.prev = kNoSlot;
  n.next = free_head_;
  free_head_ = s;
  ++free_count_;
}

uint32_t TileCache::free_pop() {
  uint32_t s = free_head_;
  if (s == kNoSlot) return s;
  free_head_ = slots_[s].next;
  slots_[s].next = kNoSlot;
  --free_count_;
  return s;
}

void TileCache::drop_slot(uint32_t s) {
  Slot& n = slots_[s];
  assert(n.state != SlotState::free);
  if (n.on_lru) lru_unlink(s);
  if (n.pins > 0) --pinned_count_;
  if (n.state == SlotState::resident) {
    --resident_count_;
    journal(s);  // its tile leaves the pool (a filling slot never held a resident tile)
  }
  // Zero the written bytes so a slot's unused tail is always zero (deterministic uploads).
  note_touched(n);
  std::memset(pool_.data + slot_offset(s), 0, n.written);
  n.written = 0;
  n.held = nullptr;
  n.used = 0;
  n.pins = 0;
  free_push(s);
}

// ---------------------------------------------------------------- page table

size_t TileCache::find_bucket(TileId key) const noexcept {
  const size_t mask = table_.size() - 1;
  for (size_t i = mix64(key) & mask;; i = (i + 1) & mask) {
    if (table_[i].key == key) return i;
    if (table_[i].key == kInvalidTile) return kNpos;
  }
}

void TileCache::grow() {
  std::vector<Bucket> old(table_.size() * 2);
  old.swap(table_);
  const size_t mask = table_.size() - 1;
  for (const Bucket& b : old) {
    if (b.key == kInvalidTile) continue;
    size_t i = mix64(b.key) & mask;
    while (table_[i].key != kInvalidTile) i = (i + 1) & mask;
    table_[i] = b;
  }
}

PageEntry& TileCache::upsert(TileId key) {
  if (key == kInvalidTile) throw Error("tile cache: tile id 2^64-1 is reserved");
  size_t b = find_bucket(key);
  if (b != kNpos) return table_[b].entry;
  if ((table_used_ + 1) * 4 > table_.size() * 3) grow();  // load factor <= 3/4
  const size_t mask = table_.size() - 1;
  size_t i = mix64(key) & mask;
  while (table_[i].key != kInvalidTile) i = (i + 1) & mask;
  table_[i].key = key;
  table_[i].entry = PageEntry{};
  ++table_used_;
  return table_[i].entry;
}

// Backward-shift deletion keeps every probe chain unbroken without tombstones.
void TileCache::erase(TileId key) {
  size_t i = find_bucket(key);
  if (i == kNpos) return;
  const size_t mask = table_.size() - 1;
  for (size_t j = (i + 1) & mask; table_[j].key != kInvalidTile; j = (j + 1) & mask) {
    size_t home = mix64(table_[j].key) & mask;
    // Move j into the hole at i if its home is not cyclically within (i, j].
    bool home_in_range = (i < j) ? (home > i && home <= j) : (home > i || home <= j);
    if (!home_in_range) {
      table_[i] = table_[j];
      i = j;
    }
  }
  table_[i] = Bucket{};
  --table_used_;
}

PageEntry TileCache::lookup(TileId tile) const noexcept {
  size_t b = find_bucket(tile);
  return b == kNpos ? PageEntry{} : table_[b].entry;
}

PageEntry TileCache::access(TileId tile) noexcept {
  PageEntry e = lookup(tile);
  if (e.state == PageState::resident) {
    ++hits_;
    Slot& s = slots_[e.slot];
    if (s.on_lru && lru_head_ != e.slot) {
      lru_unlink(e.slot);
      lru_push_front(e.slot);
    }
  } else if (e.state != PageState::constant) {
    ++misses_;
  }
  return e;
}

void TileCache::touch(uint32_t slot) noexcept {
  if (slot >= slot_count_) return;
  const Slot& s = slots_[slot];
  if (s.state == SlotState::resident && s.on_lru && lru_head_ != slot) {
    lru_unlink(slot);
    lru_push_front(slot);
  }
}

void TileCache::set_constant(TileId tile, float value) {
  PageEntry& e = upsert(tile);
  if (e.state == PageState::resident) {
    uint32_t s = e.slot;
    if (slots_[s].pins > 0)
      throw Error("tile cache: tile " + std::to_string(tile) + " is pinned; cannot make it constant");
    drop_slot(s);
  }
  e = PageEntry{PageState::constant, kNoSlot, value};
}

bool TileCache::request(TileId tile) {
  if (lookup(tile).state != PageState::absent) return false;
  upsert(tile).state = PageState::requested;
  return true;
}

void TileCache::reserve_pages(size_t pages) {
  while ((pages + 1) * 4 > table_.size() * 3) grow();
}

void TileCache::cancel_request(TileId tile) {
  if (lookup(tile).state == PageState::requested) erase(tile);
}

// ---------------------------------------------------------------- filling slots

uint32_t TileCache::reserve(TileId tile) {
  if (tile == kInvalidTile) throw Error("tile cache: tile id 2^64-1 is reserved");
  uint32_t s = free_pop();
  if (s == kNoSlot) {
    s = lru_tail_;
    if (s == kNoSlot)
      throw CacheFullError("tile cache: all " + std::to_string(slot_count_) +
                           " slots are pinned; cannot make room for tile " + std::to_string(tile));
    erase(slots_[s].tile);  // the victim's page becomes absent
    drop_slot(s);
    ++evictions_;
    s = free_pop();
  }
  Slot& n = slots_[s];
  n.state = SlotState::filling;
  n.tile = tile;
  n.used = 0;
  n.pins = 1;
  ++pinned_count_;
  return s;
}

bool TileCache::commit(uint32_t slot, uint32_t used_bytes) {
  assert(slot < slot_count_);
  Slot& n = slots_[slot];
  assert(n.state == SlotState::filling && n.pins > 0);
  if (used_bytes > slot_bytes_) {
    const TileId tile = n.tile;
    abort(slot);
    throw Error("tile cache: tile " + std::to_string(tile) + " of " + std::to_string(used_bytes) +
                " bytes exceeds the slot size " + std::to_string(slot_bytes_));
  }
  const PageEntry now = lookup(n.tile);
  if (now.state == PageState::constant || now.state == PageState::resident) {
    abort(slot);
    return false;
  }
  n.used = used_bytes;
  // The rest of the slot zero again: past the tile, or all of it for a tile held elsewhere.
  note_touched(n);
  const uint32_t keep = n.held ? 0 : used_bytes;
  if (n.written > keep) std::memset(pool_.data + slot_offset(slot) + keep, 0, n.written - keep);
  n.written = keep;
  n.state = SlotState::resident;
  ++resident_count_;
  PageEntry& e = upsert(n.tile);
  e = PageEntry{PageState::resident, slot, 0};
  ++inserts_;
  journal(slot);
  unpin(slot);
  return true;
}

void TileCache::abort(uint32_t slot) {
  Slot& n = slots_[slot];
  assert(n.state == SlotState::filling);
  const TileId tile = n.tile;
  drop_slot(slot);  // clears what slot_span handed out
  cancel_request(tile);
}

bool TileCache::commit_held(uint32_t slot, std::span<const uint8_t> bytes) {
  assert(slot < slot_count_ && slots_[slot].state == SlotState::filling);
  slots_[slot].held = bytes.empty() ? nullptr : bytes.data();
  return commit(slot, uint32_t(std::min<size_t>(bytes.size(), ~uint32_t(0))));
}

uint32_t TileCache::insert(TileId tile, std::span<const uint8_t> bytes) {
  if (bytes.size() > slot_bytes_)
    throw Error("tile cache: tile " + std::to_string(tile) + " of " + std::to_string(bytes.size()) +
                " bytes exceeds the slot size " + std::to_string(slot_bytes_));
  uint32_t s = reserve(tile);
  if (!bytes.empty()) std::memcpy(slot_span(s, uint32_t(bytes.size())).data(), bytes.data(), bytes.size());
  if (!commit(s, uint32_t(bytes.size()))) return lookup(tile).slot;
  return s;
}

// ---------------------------------------------------------------- pinning

void TileCache::pin(uint32_t slot) {
  assert(slot < slot_count_);
  Slot& n = slots_[slot];
  assert(n.state != SlotState::free);
  if (n.pins++ == 0) {
    ++pinned_count_;
    if (n.on_lru) lru_unlink(slot);
  }
}

void TileCache::unpin(uint32_t slot) {
  assert(slot < slot_count_);
  Slot& n = slots_[slot];
  assert(n.pins > 0);
  if (--n.pins == 0) {
    --pinned_count_;
    if (n.state == SlotState::resident) lru_push_front(slot);
  }
}

bool TileCache::evict(TileId tile) {
  PageEntry e = lookup(tile);
  if (e.state != PageState::resident || slots_[e.slot].pins > 0) return false;
  erase(tile);
  drop_slot(e.slot);
  ++evictions_;
  return true;
}

CacheStats TileCache::stats() const {
  CacheStats s;
  s.hits = hits_;
  s.misses = misses_;
  s.evictions = evictions_;
  s.inserts = inserts_;
  s.resident = resident_count_;
  s.pinned = pinned_count_;
  s.free = free_count_;
  return s;
}

}  // namespace st
