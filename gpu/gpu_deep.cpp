// The deep block of GpuMap's page table: see gpu_deep.hpp.
#include "gpu/gpu_deep.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <span>

#include "gpu/layout.hpp"
#include "tiles/core/deep_format.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::gpu {

namespace L = layout;

// The tile words st_deep.glsl reads, pinned to the deep tile format.
static_assert(L::kDtHeaderWords * 4 == deep::kHeaderBytes);
static_assert(L::kDtTexelCount * 4 == offsetof(deep::Header, texel_count));
static_assert(sizeof(deep::DirEntry) == 8 && offsetof(deep::DirEntry, vertex_count) == 4 &&
              offsetof(deep::DirEntry, flags) == 6 && deep::kFlagMonochrome == 1);
static_assert(L::kPtDeep < L::kPtHeaderWords && L::kDpDepthBias < L::kDpHeaderWords);

namespace {
// One (key, offset) pair per this many data words at most: a deep tile is at least 14
// words (its header and one texel's entry).
constexpr uint32_t kDataWordsPerPair = 14;

}  // namespace

float deep_depth_bias(const client::LightParams& lp, uint32_t level) {
  const LightSpace ls = LightSpace::from_array(LightKind(lp.kind), lp.params);
  if (!ls.parallel()) return 0.0f;  // the GPU passes serve suns only
  const double texel = ls.extent_uv() / double(uint64_t(1) << level);
  const Vec3d p = ls.origin();
  const Vec3d q = p - ls.forward() * (deep::kLookupBiasTexels * texel);
  const double b = ls.to_light(p).d - ls.to_light(q).d;  // affine: the same everywhere
  return std::isfinite(b) ? float(b) : 0.0f;
}

uint32_t DeepMirror::words(bool has_deep, uint64_t deep_bytes) {
  if (!has_deep) return 0;
  const uint64_t w = std::clamp<uint64_t>(deep_bytes / 4, 64, uint64_t(1) << 26);
  return uint32_t(w);
}

void DeepMirror::init(uint32_t at, uint32_t words, uint32_t* page, const client::LightParams& light) {
  at_ = at;
  light_ = light;
  pairs_ = (words - L::kDpHeaderWords) / (2 + kDataWordsPerPair);
  data_at_ = at + L::kDpHeaderWords + 2 * pairs_;
  data_words_ = at + words - data_at_;
  page[L::kPtDeep] = at;
  page[at + L::kDpLevel] = 0;
  page[at + L::kDpSideBits] = 0;
  page[at + L::kDpCount] = 0;
  page[at + L::kDpCapacity] = pairs_;
}

uint32_t DeepMirror::key(uint32_t tx, uint32_t ty) const {
  if (level_ == 0) return ~0u;
  const uint32_t bits = level_ - side_bits_;
  return tx >> bits || ty >> bits ? ~0u : (ty << bits) | tx;
}

uint64_t DeepMirror::tile_id(uint32_t tx, uint32_t ty) const {
  return kDeepTileIdBit | make_tile_id(level_ - side_bits_, tx, ty);
}

bool DeepMirror::place(uint32_t words, uint32_t& off) {
  uint32_t end = 0;  // of the tile before the gap
  size_t i = 0;
  for (; i < by_off_.size(); ++i) {
    if (by_off_[i].off - end >= words) break;
    end = by_off_[i].off + by_off_[i].words;
  }
  if (i == by_off_.size() && data_words_ - end < words) return false;
  off = end;
  by_off_.insert(by_off_.begin() + std::ptrdiff_t(i), Placed{0, off, words});
  return true;
}

uint32_t DeepMirror::update(const client::CacheView& view, const std::function<void(uint32_t, uint32_t)>& set) {
  const uint64_t g = view.deep_generation();  // before reading: a later change shows next frame
  if (g == generation_) return count_;
  generation_ = g;
  if (level_ == 0) {
    // The directory, once (it never changes while the map is open): its bitmap at the start
    // of the data words, so that the shader feeds back only tiles that exist.
    uint32_t bitmap_words = 0;
    const client::DeepShape shape = view.deep_directory([&](std::span<const uint8_t> bitmap) {
      const uint32_t w = uint32_t((bitmap.size() + 3) / 4);
      if (w > data_words_ / 2) return;  // no room: no deep feedback (the Map's own lookups fetch)
      bitmap_words = w;
      for (uint32_t i = 0; i < w; ++i) {
        uint32_t v = 0;
        for (uint32_t k = 0; k < 4 && 4 * size_t(i) + k < bitmap.size(); ++k) v |= uint32_t(bitmap[4 * i + k]) << (8 * k);
        set(data_at_ + i, v);
      }
    });
    if (shape.level != 0) {
      level_ = shape.level, side_bits_ = shape.side_bits;
      if (bitmap_words) {
        set(at_ + L::kDpPresence, data_at_);
        data_at_ += bitmap_words, data_words_ -= bitmap_words;
      }
    }
  }
  // Which tiles stay, which arrive (their bytes copied: valid only during the visit).
  seen_.assign(placed_.size(), 0);
  size_t n_in = 0;
  if (level_ != 0)
    view.deep_tiles([&](const client::DeepTile& t) {
      const uint32_t k = key(t.tx, t.ty);
      if (k == ~0u) return;
      const auto it = std::lower_bound(placed_.begin(), placed_.end(), k, [](const Placed& p, uint32_t v) { return p.key < v; });
      if (it != placed_.end() && it->key == k) {
        seen_[size_t(it - placed_.begin())] = 1;
        return;
      }
      if (n_in == incoming_.size()) incoming_.emplace_back();
      Incoming& d = incoming_[n_in++];
      d.key = k;
      d.words.assign((t.bytes.size() + 3) / 4, 0);
      std::memcpy(d.words.data(), t.bytes.data(), t.bytes.size());  // little-endian words
    });
  size_t kept = 0;
  for (size_t i = 0; i < placed_.size(); ++i)
    if (seen_[i]) placed_[kept++] = placed_[i];
  placed_.resize(kept);
  std::sort(incoming_.begin(), incoming_.begin() + std::ptrdiff_t(n_in),
            [](const Incoming& a, const Incoming& b) { return a.key < b.key; });
  by_off_.assign(placed_.begin(), placed_.end());
  std::sort(by_off_.begin(), by_off_.end(), [](const Placed& a, const Placed& b) { return a.off < b.off; });
  dropped_ = 0;
  for (size_t i = 0; i < n_in; ++i) {
    const Incoming& d = incoming_[i];
    const uint32_t words = uint32_t(d.words.size());
    uint32_t off = 0;
    if (placed_.size() == pairs_ || !place(words, off)) {
      ++dropped_;  // tried again at the next change
      continue;
    }
    for (uint32_t w = 0; w < words; ++w) set(data_at_ + off + w, d.words[w]);
    placed_.push_back({d.key, off, words});
  }
  std::sort(placed_.begin(), placed_.end(), [](const Placed& a, const Placed& b) { return a.key < b.key; });
  const uint32_t n = uint32_t(placed_.size());
  for (uint32_t i = 0; i < n; ++i) {
    set(at_ + L::kDpHeaderWords + 2 * i, placed_[i].key);
    set(at_ + L::kDpHeaderWords + 2 * i + 1, data_at_ + placed_[i].off);
  }
  set(at_ + L::kDpLevel, level_);
  set(at_ + L::kDpSideBits, side_bits_);
  set(at_ + L::kDpCount, n);
  set(at_ + L::kDpDepthBias, std::bit_cast<uint32_t>(level_ ? deep_depth_bias(light_, level_) : 0.0f));
  count_ = n;
  return n;
}

}  // namespace st::gpu
