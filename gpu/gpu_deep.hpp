// The deep block of GpuMap's page table (GPU_LAYOUT.md "The deep block"): the deep tiles
// (partial occluders, tiles/core/DEEP.md) a Map holds, read through its CacheView and
// mirrored into page-table words that shaders/st_deep.glsl reads. Internal to gpu/.
//
// The block has a fixed size, chosen when the page table is built (GpuOptions::deep_bytes):
// a header, sorted (key, word offset) pairs, the directory's bitmap (once it arrived: the
// shader feeds back only tiles that exist) and the tiles' words. Whenever the deep part's
// resident set changes (CacheView::deep_generation), the block follows it: a tile keeps its
// words where they are while it stays resident, a new tile takes the first gap that holds
// it (one that fits nowhere answers 1, as tiles still on their way do on the CPU), and the
// pairs are rewritten in key order. Every word goes through the page table's word writer,
// which sends only the 64-word blocks that changed, in the frame's own upload, so a frame
// sees the block wholly before or wholly after the change, and an arrival moves its own
// words and a few pairs, not the block.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "shadowtile/cache_view.hpp"

namespace st::gpu {

// The deep block's kDpDepthBias: the light-space depth a point loses moving toward the
// light along its ray by deep::kLookupBiasTexels texels of deep level `level` (render.cpp's
// deep_lookup_point), rounded once to float; 0 for a light that is not a sun's.
float deep_depth_bias(const client::LightParams& light, uint32_t level);

class DeepMirror {
 public:
  // Page-table words the block takes: 0 without a deep part.
  static uint32_t words(bool has_deep, uint64_t deep_bytes);
  // The block at page word `at`, `words` long (words(true, ...)): header with level 0 (no
  // directory yet: every lookup answers 1) into `page`, and page[kPtDeep] = at. `light`:
  // the map's (a sun's) light, for the depth bias once the deep level is known.
  void init(uint32_t at, uint32_t words, uint32_t* page, const client::LightParams& light);
  // Brings the block up to the view's resident deep tiles when they changed; `set(word,
  // value)` writes one page-table word. Returns the tiles on the device.
  uint32_t update(const client::CacheView& view, const std::function<void(uint32_t, uint32_t)>& set);
  uint32_t count() const { return count_; }      // deep tiles on the device
  uint32_t dropped() const { return dropped_; }  // resident tiles that did not fit, last layout
  uint32_t level() const { return level_; }      // D, 0 until the directory arrived
  // The feedback key of tile (tx, ty) (ty << (D - b) | tx), ~0u outside the grid or
  // before the directory; its pack id (kDeepTileIdBit | make_tile_id(D - b, tx, ty)).
  uint32_t key(uint32_t tx, uint32_t ty) const;
  uint64_t tile_id(uint32_t tx, uint32_t ty) const;

 private:
  struct Placed {
    uint32_t key = 0, off = 0, words = 0;  // off: from data_at_
  };
  struct Incoming {
    uint32_t key = 0;
    std::vector<uint32_t> words;
  };
  bool place(uint32_t words, uint32_t& off);  // first fit in the data words (gaps_ in offset order)
  uint32_t at_ = 0, pairs_ = 0, data_at_ = 0, data_words_ = 0, count_ = 0, dropped_ = 0;
  uint32_t level_ = 0, side_bits_ = 0;
  uint64_t generation_ = ~uint64_t(0);
  client::LightParams light_;
  std::vector<Placed> placed_;      // on the device, by key
  std::vector<uint8_t> seen_;       // per placed_: still resident (update's scratch)
  std::vector<Incoming> incoming_;  // resident, not on the device yet (scratch; capacity kept)
  std::vector<Placed> by_off_;      // placed_ by offset (place's scratch)
};

}  // namespace st::gpu
