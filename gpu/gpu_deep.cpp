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

uint32_t DeepMirror::update(const client::CacheView& view, const std::function<void(uint32_t, uint32_t)>& set) {
  const uint64_t g = view.deep_generation();
  if (g == generation_) return count_;
  generation_ = g;
  size_t n_tiles = 0;
  uint32_t level = 0, side_bits = 0;
  const client::DeepShape shape = view.deep_tiles([&](const client::DeepTile& t) {
    if (n_tiles == tiles_.size()) tiles_.emplace_back();
    Tile& d = tiles_[n_tiles++];
    d.key = t.tx | t.ty << 16;  // rekeyed below, once the shape is known
    d.words.assign((t.bytes.size() + 3) / 4, 0);
    std::memcpy(d.words.data(), t.bytes.data(), t.bytes.size());  // little-endian words
  });
  level = shape.level, side_bits = shape.side_bits;
  if (level == 0) n_tiles = 0;
  for (size_t i = 0; i < n_tiles; ++i) {
    const uint32_t tx = tiles_[i].key & 0xFFFFu, ty = tiles_[i].key >> 16;
    tiles_[i].key = (ty << (level - side_bits)) | tx;
  }
  std::sort(tiles_.begin(), tiles_.begin() + std::ptrdiff_t(n_tiles),
            [](const Tile& a, const Tile& b) { return a.key < b.key; });
  uint32_t n = 0, off = 0;
  dropped_ = 0;
  for (size_t i = 0; i < n_tiles; ++i) {
    const Tile& t = tiles_[i];
    if (n == pairs_ || off + t.words.size() > data_words_) {
      ++dropped_;
      continue;
    }
    set(at_ + L::kDpHeaderWords + 2 * n, t.key);
    set(at_ + L::kDpHeaderWords + 2 * n + 1, data_at_ + off);
    for (size_t w = 0; w < t.words.size(); ++w) set(data_at_ + off + uint32_t(w), t.words[w]);
    off += uint32_t(t.words.size());
    ++n;
  }
  set(at_ + L::kDpLevel, level);
  set(at_ + L::kDpSideBits, side_bits);
  set(at_ + L::kDpCount, n);
  set(at_ + L::kDpDepthBias, std::bit_cast<uint32_t>(level ? deep_depth_bias(light_, level) : 0.0f));
  count_ = n;
  return n;
}

}  // namespace st::gpu
