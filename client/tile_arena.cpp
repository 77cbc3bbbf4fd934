#include "client/tile_arena.hpp"

#include <algorithm>
#include <cstring>
#include <new>
#include <string>

#include "common/error.hpp"

namespace st::client {

TileArena::TileArena(uint32_t slot_count, uint32_t chunk_bytes, uint32_t max_chunks)
    : chunk_bytes_((std::max<uint32_t>(chunk_bytes, 1) + kAlign - 1) / kAlign * kAlign),
      max_chunks_(std::max<uint32_t>(max_chunks, 1)),
      homes_(slot_count) {}

uint32_t TileArena::new_chunk_locked() {
  std::unique_ptr<uint8_t, Free> data(static_cast<uint8_t*>(std::aligned_alloc(kAlign, chunk_bytes_)));
  if (!data) throw std::bad_alloc();
  uint32_t id;
  if (!free_ids_.empty()) {
    id = free_ids_.back();
    free_ids_.pop_back();
  } else {
    chunks_.emplace_back();
    id = uint32_t(chunks_.size() - 1);
  }
  chunks_[id].data = std::move(data);
  chunks_[id].used = chunks_[id].live = 0;
  ++held_;
  return id;
}

std::span<uint8_t> TileArena::reserve(uint32_t slot, size_t bytes) {
  if (bytes > chunk_bytes_)
    throw Error("tile arena: a tile of " + std::to_string(bytes) + " bytes exceeds the chunk's " +
                std::to_string(chunk_bytes_));
  std::lock_guard lock(mu_);
  release_locked(slot, bytes > 0);
  if (bytes == 0) return {};
  const uint32_t size = uint32_t((bytes + kAlign - 1) / kAlign * kAlign);  // <= chunk_bytes_
  // A full chunk keeps a live tile (one whose tiles all left started over, below).
  if (current_ == kNone || chunks_[current_].used + size > chunk_bytes_) {
    if (current_ != kNone && chunks_[current_].live == 0) free_chunk_locked(current_);  // emptied, yet too full
    current_ = kNone;
    if (held_ >= max_chunks_) return {};  // at the ceiling: the caller keeps the tile itself
    current_ = new_chunk_locked();
  }
  Chunk& c = chunks_[current_];
  uint8_t* at = c.data.get() + c.used;
  c.used += size;
  ++c.live;
  homes_[slot].chunk = current_;
  return {at, bytes};
}

std::span<const uint8_t> TileArena::place(uint32_t slot, std::span<const uint8_t> bytes) {
  const std::span<uint8_t> room = reserve(slot, bytes.size());
  if (room.data()) std::memcpy(room.data(), bytes.data(), bytes.size());
  return room;
}

void TileArena::free_chunk_locked(uint32_t id) noexcept {
  chunks_[id].data.reset();
  free_ids_.push_back(id);
  --held_;
  if (id == current_) current_ = kNone;
}

void TileArena::release_locked(uint32_t slot, bool keep_current) noexcept {
  Home& h = homes_[slot];
  if (h.chunk == kNone) return;
  const uint32_t id = h.chunk;
  h.chunk = kNone;
  Chunk& c = chunks_[id];
  if (--c.live > 0) return;
  if (id == current_) {
    c.used = 0;  // the chunk being filled starts over
    if (keep_current) return;
  }
  free_chunk_locked(id);
}

void TileArena::release(uint32_t slot) noexcept {
  std::lock_guard lock(mu_);
  release_locked(slot, false);
}

uint64_t TileArena::held_bytes() const noexcept {
  std::lock_guard lock(mu_);
  return uint64_t(held_) * chunk_bytes_;
}

}  // namespace st::client
